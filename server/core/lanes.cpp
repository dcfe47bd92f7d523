// Lanes (lanes.hpp): one helper thread, handed each job through two counters.
#include "core/lanes.hpp"

#include <chrono>

#include "core/fp_mode.hpp"

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define LADDER_PAUSE() _mm_pause()
#else
#define LADDER_PAUSE() std::this_thread::yield()
#endif

namespace ladder::core {

namespace {
// How long the helper spins for the next job before it sleeps: longer than the gap between two steps at ladderd's
// 1 kHz, so that a chain stepped without pause keeps it awake. A sleeping helper is slow to come back: on the
// 2-vCPU VM of docs/benchmarks.md a futex wake-up took 20 to 60 us after 0.1 ms asleep but 2 to 3 ms after 2 ms
// (the idle virtual processor is descheduled), longer than a step. With a 50 us spin the helper slept between the
// server's ticks and the caller ran both halves of most passes itself (docs/benchmarks.md, the fifth round). The
// cost: while a long chain runs, the helper holds its processor; a paused server's sleeps after 1 ms. (Under
// SCHED_FIFO, ladderd puts it to sleep between ticks with rest(): the kernel stops a real-time thread that never
// sleeps for 50 ms of every second.)
constexpr auto kSpin = std::chrono::microseconds(1000);
}  // namespace

Lanes::~Lanes() {
  if (!helper_.joinable()) return;
  stop_.store(true);
  posted_.fetch_add(1);
  posted_.notify_one();
  helper_.join();
}

void Lanes::helper_loop() {
  unsigned seen = 0;
  for (;;) {
    unsigned posted = posted_.load(std::memory_order_acquire);
    if (posted == seen) {
      const auto until = std::chrono::steady_clock::now() + kSpin;
      for (int i = 0; (posted = posted_.load(std::memory_order_acquire)) == seen; ++i) {
        LADDER_PAUSE();
        if ((i & 63) == 63 && (resting_.load() || std::chrono::steady_clock::now() > until)) break;
      }
      // Sleep. sleeping_ and posted_ are sequentially consistent on both sides: either run() sees sleeping_ and
      // wakes the futex, or this thread sees the new job before it waits.
      if (posted == seen) {
        sleeping_.store(true);
        while ((posted = posted_.load()) == seen) posted_.wait(seen);
        sleeping_.store(false);
      }
    }
    seen = posted;
    if (stop_.load()) return;
    unsigned expected = seen - 1;  // the job is run by whoever claims it first: this thread or run()'s caller
    if (!claimed_.compare_exchange_strong(expected, seen)) continue;
    try {
      // (the control bits only: each thread's own exception flags differ, and a write of the mode costs)
      if (const unsigned mode = fp_mode(); (mode ^ mode_) & kFpControl)
        set_fp_mode((mode_ & kFpControl) | (mode & ~kFpControl));
      fn_(job_, 1);
    } catch (...) {
      error_ = std::current_exception();
    }
    done_.store(seen, std::memory_order_release);
  }
}

void Lanes::rest() {
  if (parallel_ && helper_.joinable()) resting_.store(true);
}

void Lanes::wake() {
  // After rest() the helper may be asleep or about to be (it has seen resting_ but not yet said it sleeps): a ticket
  // reaches it either way.
  const bool rested = resting_.exchange(false);
  if (!parallel_ || !helper_.joinable() || !(rested || sleeping_.load())) return;
  // An empty ticket, claimed before it is posted (only this thread posts): the helper wakes, finds it taken (as when
  // run()'s caller runs lane 1 itself) and spins for the next.
  const unsigned ticket = posted_.load() + 1;
  claimed_.store(ticket);
  posted_.store(ticket);
  posted_.notify_one();
}

void Lanes::run_erased(Fn fn, void* job) {
  if (!helper_.joinable()) helper_ = std::thread([this] { helper_loop(); });
  fn_ = fn;
  job_ = job;
  mode_ = fp_mode();
  error_ = nullptr;
  resting_.store(false);
  const unsigned ticket = posted_.fetch_add(1) + 1;
  if (sleeping_.load()) posted_.notify_one();
  std::exception_ptr mine;
  try {
    fn(job, 0);
  } catch (...) {
    mine = std::current_exception();
  }
  // The helper's lane, if the helper has not started it (it sleeps, or another thread has its processor: a server's
  // publishing threads): then this thread runs it, and a busy machine costs at most the one-thread time.
  unsigned expected = ticket - 1;
  if (claimed_.compare_exchange_strong(expected, ticket)) {
    try {
      fn(job, 1);
    } catch (...) {
      if (!mine) mine = std::current_exception();
    }
    if (mine) std::rethrow_exception(mine);
    return;
  }
  for (int i = 0; done_.load(std::memory_order_acquire) != ticket; ++i) {
    if (i < 4096)
      LADDER_PAUSE();
    else
      std::this_thread::yield();  // (the helper is not running: another process has the processor)
  }
  if (mine) std::rethrow_exception(mine);
  if (error_) std::rethrow_exception(error_);
}

}  // namespace ladder::core
