// SHAKE, the integrator `symplectic_euler`: a kick and a drift, then the positions brought back onto the hinges by
// the step's impulses, which change the velocities by the same impulses. Its position stage is shared with RATTLE
// (rattle.cpp), which splits the kick in two halves around it. Both are symplectic on the constraint manifold
// (Hairer, Lubich & Wanner, Geometric Numerical Integration, VII.1): energy errors stay bounded instead of drifting.
#include "core/world.hpp"

namespace ladder::core {

// Kick by h_kick, drift by h, drive the kinematic bodies to t + h, and solve the positions with the impulses applied
// to the velocities too (velocity_scale 1 / h).
void World::shake_positions(double h, double h_kick) {
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
  kick_drift(h_kick, h);
  drive_kinematic(t1);
  stats_.converged = solve_positions(ua0_, ub0_, 1.0 / h);
}

void World::step_shake(double h) {
  const double t1 = t_ + h;
  shake_positions(h, h);
  t_ = t1;
  if (options_.stabilization != Stabilization::None) project_velocities();
}

}  // namespace ladder::core
