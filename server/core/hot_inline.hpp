// HOT_INLINE: forces a lambda inline (GCC's attribute, placed after its parameter list). The sweeps hand each row to
// a lambda, and GCC does not always inline a large one into the sweep's loop: a call per row (with its register
// spills) cost 10 % of the step. For the core's own .cpp files; not part of any interface.
#pragma once

#define HOT_INLINE __attribute__((always_inline))
