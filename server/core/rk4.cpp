// Classic RK4, the integrator `rk4`, on the index-1 equations (the hinge forces from
// K lambda = -(a_free(p_a) - a_free(p_b)) at each stage), kept on the hinges by post-stabilisation
// (World::stabilise_explicit, constraints.cpp), which does not lower its order.
#include "core/world.hpp"

#include <vector>

namespace ladder::core {

void World::step_rk4(double h) {
  const double t0 = t_, t1 = t_ + h;
  const size_t nb = bodies_.size();
  drive_kinematic(t0);  // their accelerations enter the first stage
  // On (x, theta, v, w); the rotation is composed from the start rotation so that q stays unit.
  const std::vector<BodyState> y0 = state_;
  std::vector<BodyState> k[4];
  const double weight[4] = {h / 6, h / 3, h / 3, h / 6};
  const double offset[4] = {0, 0.5 * h, 0.5 * h, h};
  for (int stage = 0; stage < 4; ++stage) {
    if (stage > 0) {
      const double c = offset[stage];
      for (size_t b = 0; b < nb; ++b) {
        if (bodies_[b].kinematic) continue;
        const BodyState& prev = k[stage - 1][b];
        BodyState& s = state_[b];
        s.x = y0[b].x + c * prev.x;
        s.th = y0[b].th + c * prev.th;
        s.q = y0[b].q * rotation_of_small_angle(c * prev.th);
        s.v = y0[b].v + c * prev.v;
        s.w = y0[b].w + c * prev.w;
      }
      drive_kinematic(t0 + c);
      t_ = t0 + c;
    }
    constraint_accelerations(work_.acc_lin, work_.acc_ang, weight[stage], h);
    // Store the derivative of the stage: (dx, dth) = (v, w), (dv, dw) = (a, alpha), packed in a BodyState.
    k[stage].resize(nb);
    for (size_t b = 0; b < nb; ++b) {
      k[stage][b].x = state_[b].v;
      k[stage][b].th = state_[b].w;
      k[stage][b].v = work_.acc_lin[b];
      k[stage][b].w = work_.acc_ang[b];
    }
  }
  for (size_t b = 0; b < nb; ++b) {
    if (bodies_[b].kinematic) continue;
    BodyState& s = state_[b];
    // Weights 1, 2, 2, 1 (written out: an Eigen expression returned from a lambda would outlive its operands).
    const Vec2 dx = (h / 6) * (k[0][b].x + 2.0 * k[1][b].x + 2.0 * k[2][b].x + k[3][b].x);
    const Vec2 dv = (h / 6) * (k[0][b].v + 2.0 * k[1][b].v + 2.0 * k[2][b].v + k[3][b].v);
    const double dth = (h / 6) * (k[0][b].th + 2 * k[1][b].th + 2 * k[2][b].th + k[3][b].th);
    const double dw = (h / 6) * (k[0][b].w + 2 * k[1][b].w + 2 * k[2][b].w + k[3][b].w);
    s.x = y0[b].x + dx;
    s.th = y0[b].th + dth;
    s.q = (y0[b].q * rotation_of_small_angle(dth)).renormalised();
    s.v = y0[b].v + dv;
    s.w = y0[b].w + dw;
  }
  mark_state_changed();
  drive_kinematic(t1);
  t_ = t1;
  stabilise_explicit();
}

}  // namespace ladder::core
