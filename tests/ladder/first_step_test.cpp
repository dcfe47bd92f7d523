// A model's first step allocates no more than the steps after it: World::finalize() reserves the midpoint step's
// scratch (World::reserve_step) and model::Ladder the watchdog's copy of the world (World::reserve_snapshot), so that
// a server's first tick after a load or a reset does not fault in megabytes of pages (6 ms at 10 000 blocks on the
// test machine: docs/benchmarks.md, "Fifteenth round"). The bytes are counted by this program's own global operator
// new (a replacement for this test program alone), between the two ends of each step.
#include "ladder/ladder.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <new>

namespace {
std::atomic<bool> counting{false};
std::atomic<std::size_t> allocated{0};

void* allocate(std::size_t n, std::size_t align) {
  if (counting.load(std::memory_order_relaxed)) allocated.fetch_add(n, std::memory_order_relaxed);
  void* p = align <= alignof(std::max_align_t) ? std::malloc(n ? n : 1)
                                               : std::aligned_alloc(align, (std::max<std::size_t>(n, 1) + align - 1) /
                                                                               align * align);
  if (!p) throw std::bad_alloc();
  return p;
}
}  // namespace

void* operator new(std::size_t n) { return allocate(n, alignof(std::max_align_t)); }
void* operator new(std::size_t n, std::align_val_t a) { return allocate(n, static_cast<std::size_t>(a)); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }

namespace {

using namespace ladder;

// The bytes one step of `l` allocates.
std::size_t step_bytes(model::Ladder& l) {
  allocated = 0;
  counting = true;
  l.advance(1e-3);
  counting = false;
  return allocated.load();
}

// The free chain of config/scenes/free-chain.toml with 3000 blocks (a chain solved in two halves, on two threads): the
// step's scratch alone is about 500 bytes a block. Measured: without the two reserves the first step allocated
// 1 659 325 bytes, with them 123 149 (what is left is a few smaller first-time buffers), and the next ten steps none.
TEST(FirstStep, AllocatesNoMoreThanTheStepsAfterIt) {
  model::LadderSpec spec;
  spec.blocks = 3000;
  spec.length = 0.06, spec.thickness = 0.01, spec.mass = 0.02;
  spec.top = model::Top::Pinned;
  spec.start = model::Start::Straight;
  spec.logic = false;
  spec.kick_omega = 5.0;
  core::Options options;
  options.threads = 2;
  model::Ladder ladder(spec, options);
  const std::size_t first = step_bytes(ladder);
  std::size_t later = 0;
  for (int i = 0; i < 10; ++i) later = std::max(later, step_bytes(ladder));
  EXPECT_LE(first, later + 256 * 1024) << "the first step allocated " << first << " bytes, the next ten at most " << later;
}

}  // namespace
