// Lock-free hand-off of the latest state from the physics thread to the publishing thread.
#pragma once

#include "ladder.h"

#include <atomic>
#include <cstdint>
#include <vector>

namespace ladder::daemon {

// One published state, in the wire layout so that the writer can lend its arrays to DDS without a copy.
struct StateFrame {
  std::uint32_t generation = 0;
  std::uint64_t step = 0, commands_applied = 0;
  double t = 0, energy = 0;
  bool paused = false;
  std::vector<double> poses;  // x, y, theta per block
  std::vector<std::uint8_t> hinge_corner;
  std::vector<ladder_msg_HingeStatus> hinge_status;
  std::vector<std::uint32_t> hinge_flips;
  std::vector<ladder_msg_Grip> grips;
};

// A triple buffer: one producer fills back() and publish()es it, one consumer take()s the newest published value.
// Neither ever waits for the other, and the slots' vectors are reused, so the steady state allocates nothing.
// A value published before the consumer took the previous one replaces it (publish() then returns true).
template <class T>
class Latest {
 public:
  T& back() { return slots_[back_]; }
  bool publish() {
    const int old = middle_.exchange(back_ | kFresh, std::memory_order_acq_rel);
    back_ = old & kIndex;
    return (old & kFresh) != 0;
  }
  // The newest value not yet taken, or nullptr. Valid until the next take().
  const T* take() {
    if ((middle_.load(std::memory_order_acquire) & kFresh) == 0) return nullptr;
    const int old = middle_.exchange(front_, std::memory_order_acq_rel);
    front_ = old & kIndex;
    return &slots_[front_];
  }

 private:
  static constexpr int kIndex = 3, kFresh = 4;
  T slots_[3];
  int back_ = 0, front_ = 2;  // owned by the producer and the consumer
  std::atomic<int> middle_{1};
};

}  // namespace ladder::daemon
