// Lanes (server/core/lanes.hpp): every run() runs each lane exactly once, finished before it returns, and passes an
// exception from either lane to its caller. Run under ThreadSanitizer too (scripts/test --sanitize thread).
#include "core/lanes.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <ctime>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace ladder::core {
namespace {

// Many short jobs back to back (the helper spinning), some after a pause (the helper asleep on its futex), some after
// a wake() or a rest() (a server between ticks) or both: each lane's work is done once per run and is visible to the
// caller when run() returns.
TEST(Lanes, EachLaneRunsOncePerRunAndIsDoneWhenRunReturns) {
  for (const bool parallel : {false, true}) {
    Lanes lanes;
    lanes.set_parallel(parallel);
    std::vector<long> data(2000, 0);
    long expected = 0;
    for (int run = 0; run < 20000; ++run) {
      // (the helper spins 1 ms before it sleeps: lanes.cpp, kSpin)
      if (run % 5000 == 4999) std::this_thread::sleep_for(std::chrono::milliseconds(3));  // let the helper sleep
      if (run % 3 == 0) lanes.wake();  // (every few runs, asleep or not: it runs nothing)
      if (run % 7 == 0) lanes.rest();  // (the next run or wake wakes it)
      if (run % 11 == 0) lanes.wake();
      if (run % 1000 == 999) {  // rested, given time to fall asleep, woken, run
        lanes.rest();
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
      if (run % 2000 == 1999) {  // woken, then let sleep again before the run
        lanes.wake();
        std::this_thread::sleep_for(std::chrono::milliseconds(3));
      }
      lanes.run([&](int lane) {
        const size_t from = lane == 0 ? 0 : data.size() / 2, to = lane == 0 ? data.size() / 2 : data.size();
        for (size_t i = from; i < to; ++i) data[i] += static_cast<long>(i) + run;
      });
      expected += run;
      // Both halves complete now (a lane run twice, or not waited for, shows here).
      ASSERT_EQ(data.front(), expected) << "run " << run << (parallel ? ", parallel" : "");
      ASSERT_EQ(data.back(), static_cast<long>(data.size() - 1) * (run + 1) + expected) << "run " << run;
    }
    for (size_t i = 0; i < data.size(); ++i) ASSERT_EQ(data[i], static_cast<long>(i) * 20000 + expected) << i;
  }
}

TEST(Lanes, AnExceptionFromEitherLaneReachesTheCallerAfterBothFinished) {
  Lanes lanes;
  lanes.set_parallel(true);
  for (const int thrower : {0, 1}) {
    int other_done = 0;
    try {
      lanes.run([&](int lane) {
        if (lane == thrower) throw std::runtime_error("lane " + std::to_string(lane));
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
        other_done = 1;
      });
      ADD_FAILURE() << "no exception from lane " << thrower;
    } catch (const std::runtime_error& e) {
      EXPECT_EQ(std::string(e.what()), "lane " + std::to_string(thrower));
    }
    EXPECT_EQ(other_done, 1) << "run() returned before the other lane finished";
    // And the next run is a normal one.
    int ran[2] = {0, 0};
    lanes.run([&](int lane) { ++ran[lane]; });
    EXPECT_EQ(ran[0], 1);
    EXPECT_EQ(ran[1], 1);
  }
}

// After rest() the helper sleeps at once instead of spinning for the next job (lanes.cpp's kSpin, 1 ms): measured as
// the process's processor time while the caller sleeps. Without rest() it would be about 1 ms a round (less only when
// the machine is so busy that the helper does not run; a slow machine does not make this fail).
TEST(Lanes, ARestedHelperSleepsWithoutSpinning) {
  const auto cpu_ms = [] {
    timespec ts{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
  };
  Lanes lanes;
  lanes.set_parallel(true);
  int ran[2] = {0, 0};
  lanes.run([&](int lane) { ++ran[lane]; });  // (starts the helper)
  constexpr int kRounds = 50;
  double idle = 0;
  for (int round = 0; round < kRounds; ++round) {
    lanes.wake();
    lanes.run([&](int lane) { ++ran[lane]; });
    lanes.rest();
    const double before = cpu_ms();
    std::this_thread::sleep_for(std::chrono::milliseconds(4));
    idle += cpu_ms() - before;
  }
  EXPECT_EQ(ran[0], kRounds + 1);
  EXPECT_EQ(ran[1], kRounds + 1);
  EXPECT_LT(idle / kRounds, 0.3) << "ms of processor time per 4 ms rest: the helper spun";
}

// A copy (a World copied) starts without a helper and works on its own; the original's helper is unaffected.
TEST(Lanes, ACopyRunsOnItsOwn) {
  Lanes a;
  a.set_parallel(true);
  int sum = 0;
  a.run([&](int lane) {
    if (lane == 0) ++sum;
  });
  Lanes b = a;
  EXPECT_FALSE(b.parallel()) << "a copy starts serial until its owner says otherwise";
  b.set_parallel(true);
  int ran[2] = {0, 0};
  b.run([&](int lane) { ++ran[lane]; });
  a.run([&](int lane) { ++ran[lane]; });
  EXPECT_EQ(ran[0], 2);
  EXPECT_EQ(ran[1], 2);
  EXPECT_EQ(sum, 1);
}

}  // namespace
}  // namespace ladder::core
