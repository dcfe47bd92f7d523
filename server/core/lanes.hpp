// Two lanes of work for one step: run(job) calls job(0) on the calling thread and job(1) on a helper thread, and
// returns when both are done. The midpoint step splits a long chain's Newton passes in two this way (midpoint.cpp:
// one half eliminated from the top, the other from the bottom). What a step computes never depends on whether the
// helper exists: with one thread, run() calls job(0) and then job(1) on the caller, and the two lanes write disjoint
// data, so the results are the same bits.
//
// The helper is started on the first parallel run() and waits between jobs by spinning for up to 1 ms (longer than
// the gap between two steps at 1 kHz: lanes.cpp, kSpin) and then sleeping on a futex (std::atomic::wait), so a
// paused server costs no processor; after rest() it sleeps at once (a server between ticks), and wake() wakes it.
// Lane 1 is run by whichever thread claims it first: when the helper is slow to wake (asleep, or its processor taken
// by another thread), the caller runs it after lane 0, so a busy machine costs at most the time of one thread. A
// Lanes copied or moved into place starts without a helper (a World returned by value, a snapshot).
#pragma once

#include <atomic>
#include <exception>
#include <thread>
#include <type_traits>

namespace ladder::core {

class Lanes {
 public:
  Lanes() = default;
  Lanes(const Lanes&) {}
  Lanes& operator=(const Lanes&) { return *this; }
  ~Lanes();

  // Whether run() may use a helper thread (the results do not depend on it).
  void set_parallel(bool parallel) { parallel_ = parallel; }
  bool parallel() const { return parallel_; }

  // Work is coming: a sleeping helper is woken now, so that the time it takes to wake (tens of microseconds on an
  // idle machine, milliseconds on a busy one) overlaps the caller's serial work before its next run(). It then
  // spins for the next job as after one. Costs one atomic load when the helper is awake or absent.
  void wake();
  // No work is coming for a while (a server's wait for its next tick): the helper goes to sleep now instead of
  // spinning out its 1 ms, and wake() or the next run() wakes it. Under SCHED_FIFO a helper spinning through every
  // gap holds its processor at real-time priority all the time, and the kernel's real-time throttling
  // (sched_rt_runtime_us, 95 % by default) then stops it for the rest of each second: ticks 50 ms late.
  void rest();

  // job(0) on the calling thread and job(1) on the helper (both on the caller when not parallel). An exception from
  // either is rethrown here, after both have finished.
  template <class Job>
  void run(Job&& job) {
    if (!parallel_) {
      job(0);
      job(1);
      return;
    }
    using J = std::remove_reference_t<Job>;
    run_erased([](void* j, int lane) { (*static_cast<J*>(j))(lane); }, &job);
  }

 private:
  using Fn = void (*)(void*, int);
  void run_erased(Fn fn, void* job);
  void helper_loop();

  bool parallel_ = false;
  std::thread helper_;
  Fn fn_ = nullptr;
  void* job_ = nullptr;
  unsigned mode_ = 0;  // the poster's floating-point mode (fp_mode.hpp), which the job runs in
  std::exception_ptr error_;
  std::atomic<unsigned> posted_{0};     // jobs posted (the helper runs each new one it claims; wake() posts none)
  std::atomic<unsigned> claimed_{0};    // the last job claimed, by the helper or by run()'s caller
  std::atomic<unsigned> done_{0};       // the last job the helper finished
  std::atomic<bool> sleeping_{false};   // the helper waits on posted_'s futex: run() must wake it
  std::atomic<bool> resting_{false};    // rest() was called: the helper sleeps without spinning first
  std::atomic<bool> stop_{false};
};

}  // namespace ladder::core
