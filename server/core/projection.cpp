// The integrator `projection`: the "fast projection" of Goldenthal et al., Efficient Simulation of Inextensible
// Cloth (SIGGRAPH 2007), for hinges. The unconstrained step is projected back onto the hinges by Newton's method with
// the Jacobian re-linearised at every iterate, and the velocity is (q1 - q0) / h. The constraint forces thus act
// along the hinges' directions at the end of the step (close to backward Euler in the constraint forces), which is
// what makes it stable for stiff long chains at steps where SHAKE's start-of-step directions fail, at the price of
// first-order accuracy and numerical damping of fast modes. Each iteration is one fused pass (anchors, residual,
// build, factor, forward substitution) and one back-substitution pass that corrects the bodies; one iteration usually
// suffices at a loose tolerance. With stabilization = none no velocity projection follows: the cheapest step the core
// has.
#include "core/world.hpp"

namespace ladder::core {

void World::step_projection(double h) {
  const double t1 = t_ + h;
  // As in SHAKE (shake.cpp): an error this step did not make is removed first, positions only.
  if (position_residual() > options_.tolerance) solve_projection(0.0);
  kick_drift(h, h);
  drive_kinematic(t1);
  stats_.converged = solve_projection(1.0 / h);
  t_ = t1;
  if (options_.stabilization != Stabilization::None) project_velocities();
}

}  // namespace ladder::core
