// The paper's explicit Euler, the integrator `euler`, on the index-1 equations: the hinge forces from
// K lambda = -(a_free(p_a) - a_free(p_b)), then positions and velocities advanced from the start's accelerations,
// kept on the hinges by post-stabilisation (World::stabilise_explicit, constraints.cpp).
#include "core/world.hpp"

namespace ladder::core {

void World::step_euler(double h) {
  const double t0 = t_, t1 = t_ + h;
  const size_t nb = bodies_.size();
  drive_kinematic(t0);  // their accelerations enter the hinge forces
  constraint_accelerations(work_.acc_lin, work_.acc_ang, h, h);
  for (size_t b = 0; b < nb; ++b) {
    if (bodies_[b].kinematic) continue;
    BodyState& s = state_[b];
    s.x += h * s.v;
    s.th += h * s.w;
    s.q = (s.q * rotation_of_small_angle(h * s.w)).renormalised();
    s.v += h * work_.acc_lin[b];
    s.w += h * work_.acc_ang[b];
  }
  mark_state_changed();
  drive_kinematic(t1);
  t_ = t1;
  stabilise_explicit();
}

}  // namespace ladder::core
