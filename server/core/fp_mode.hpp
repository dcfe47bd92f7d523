// The floating-point mode a step runs in: subnormal numbers flushed to zero (x86-64's MXCSR flags FTZ, results, and
// DAZ, operands). A disturbance that travels down a long chain decays exponentially ahead of its front, so some band
// of blocks always carries spins, turns and corrections whose squares and products fall below 2.2e-308, and the
// processor takes a slow path (tens to hundreds of cycles) for every operation on them: measured on the 10 000-block
// ladder swinging after its tip, 7.3 ms a step on one thread with them and 3.2 ms flushed (docs/benchmarks.md,
// "Seventh round"). A flushed value is below 2.2e-308 in size, nothing a physical quantity here is measured by.
// World::step() sets the mode and restores the caller's on return; Lanes runs each job in its poster's mode, so a
// step's bits do not depend on the threads. Elsewhere (other architectures) the mode is left as it is.
#pragma once

#if defined(__SSE2__)
#include <xmmintrin.h>
#endif

namespace ladder::core {

#if defined(__SSE2__)
constexpr unsigned kFlushSubnormals = 0x8040;  // MXCSR: FTZ (bit 15) and DAZ (bit 6)
constexpr unsigned kFpControl = ~0x3fu;        // MXCSR's control bits (its low six are sticky exception flags)
inline unsigned fp_mode() { return _mm_getcsr(); }
inline void set_fp_mode(unsigned mode) { _mm_setcsr(mode); }
#else
constexpr unsigned kFlushSubnormals = 0;
constexpr unsigned kFpControl = 0;
inline unsigned fp_mode() { return 0; }
inline void set_fp_mode(unsigned) {}
#endif

// Subnormals flushed for the guard's lifetime; the mode before is restored after.
class FlushSubnormals {
 public:
  FlushSubnormals() : saved_(fp_mode()) {
    if ((saved_ & kFlushSubnormals) != kFlushSubnormals) set_fp_mode(saved_ | kFlushSubnormals);
  }
  ~FlushSubnormals() {
    if (fp_mode() != saved_) set_fp_mode(saved_);
  }
  FlushSubnormals(const FlushSubnormals&) = delete;
  FlushSubnormals& operator=(const FlushSubnormals&) = delete;

 private:
  unsigned saved_;
};

}  // namespace ladder::core
