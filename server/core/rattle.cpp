// RATTLE, the integrator `rattle`: a half kick, SHAKE's drift and position solve (shake.cpp), then the second half
// kick with the forces at the end of the step and the velocities projected onto the hinges. Symmetric and
// symplectic on the constraint manifold (Hairer, Lubich & Wanner, Geometric Numerical Integration, VII.1.4).
#include "core/world.hpp"

namespace ladder::core {

void World::step_rattle(double h) {
  const double t1 = t_ + h;
  shake_positions(h, 0.5 * h);
  accumulate_forces(work_.force, work_.torque, h);
  kick(0.5 * h, work_.force, work_.torque);
  t_ = t1;
  if (options_.stabilization != Stabilization::None) project_velocities();
}

}  // namespace ladder::core
