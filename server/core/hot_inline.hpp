// HOT_INLINE: forces a lambda inline (GCC's attribute, placed after its parameter list). The sweeps hand each row to
// a lambda, and GCC does not always inline a large one into the sweep's loop: a call per row (with its register
// spills) cost 10 % of the step. For the core's own .cpp files; not part of any interface.
// The ASan/UBSan build (scripts/test --sanitize address,undefined) defines LADDER_NO_FORCED_INLINE and leaves the
// choice to the compiler: with that instrumentation the forced inlining made GCC take 5 minutes over midpoint.cpp
// alone (1 minute without), and the instrumented tests run no slower without it (docs/robustness.md).
#pragma once

#ifdef LADDER_NO_FORCED_INLINE
#define HOT_INLINE
#else
#define HOT_INLINE __attribute__((always_inline))
#endif
