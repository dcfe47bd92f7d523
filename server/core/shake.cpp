// The position-solve integrators: SHAKE (symplectic_euler), RATTLE and the fast projection.
//
// SHAKE and RATTLE are symplectic on the constraint manifold (Hairer, Lubich & Wanner, Geometric Numerical
// Integration, VII.1): energy errors stay bounded instead of drifting.
//
// projection is the "fast projection" of Goldenthal et al., Efficient Simulation of Inextensible Cloth (SIGGRAPH
// 2007), for hinges: the unconstrained step is projected back onto the hinges by Newton's method with the Jacobian
// re-linearised at every iterate, and the velocity is (q1 - q0) / h. The constraint forces thus act along the
// hinges' directions at the end of the step (close to backward Euler in the constraint forces), which is what makes
// it stable for stiff long chains at steps where SHAKE's start-of-step directions fail, at the price of first-order
// accuracy and numerical damping of fast modes. Each iteration is one fused pass (anchors, residual, build, factor,
// forward substitution) and one back-substitution pass that corrects the bodies; one iteration usually suffices at
// a loose tolerance. With stabilization = none no velocity projection follows: the cheapest step the core has.
#include "core/world.hpp"
#include "core/hot_inline.hpp"

#include <algorithm>
#include <cmath>

namespace ladder::core {

void World::step_shake(double h, bool rattle) {
  const double t1 = t_ + h;
  // SHAKE turns whatever position error it removes into velocity (divided by h). An error the step did not
  // make (a join, the leftover of a restructure) must not: it is projected away first, positions only. Without
  // this a short step (event location takes steps of 1e-10 s) turns a 1e-12 m leftover into metres per second.
  if (position_residual() > options_.tolerance) {
    start_anchors();
    factor_system(ua0_, ub0_);
    solve_positions(ua0_, ub0_, 0.0);
  }
  start_anchors();
  if (factor_version_ != state_version_) factor_system(ua0_, ub0_);
  kick_drift(rattle ? 0.5 * h : h, h);
  drive_kinematic(t1);
  stats_.converged = solve_positions(ua0_, ub0_, 1.0 / h);
  if (rattle) {
    accumulate_forces(work_.force, work_.torque, h);
    kick(0.5 * h, work_.force, work_.torque);
  }
  t_ = t1;
  if (options_.stabilization != Stabilization::None) project_velocities();
}

void World::step_projection(double h) {
  const double t1 = t_ + h;
  // As in step_shake(): an error this step did not make is removed first, positions only.
  if (position_residual() > options_.tolerance) solve_projection(0.0);
  kick_drift(h, h);
  drive_kinematic(t1);
  stats_.converged = solve_projection(1.0 / h);
  t_ = t1;
  if (options_.stabilization != Stabilization::None) project_velocities();
}

}  // namespace ladder::core
