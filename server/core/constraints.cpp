// The hinge constraints: C_k(q) = p_a - p_b = (x_a + R_a r_a) - (x_b + R_b r_b) = 0, two equations per hinge.
//
// Jacobian of row k with respect to body a's (x, y, theta): G_ka = [I | perp(u_a)], with u_a = R_a r_a; with
// respect to body b: G_kb = -[I | perp(u_b)]. With W = M^-1 = diag(1/m, 1/m, 1/I) per body (zero for kinematic
// bodies), K = G W G^T has the 2x2 blocks
//   K_kk     = (w_a + w_b) I + i_a perp(u_a) perp(u_a)^T + i_b perp(u_b) perp(u_b)^T
//   K_k-1,k  = -(w_s I + i_s perp(u_b,k-1) perp(u_a,k)^T)    (s: the body the two rows share)
// and is block-tridiagonal once rows are ordered along chains (topology.cpp).
#include "core/world.hpp"

#include <algorithm>
#include <cmath>

namespace ladder::core {

void World::world_anchors(std::vector<Vec2>& ua, std::vector<Vec2>& ub) const {
  const size_t n = rows_.size();
  ua.resize(n);
  ub.resize(n);
  for (size_t k = 0; k < n; ++k) {
    ua[k] = state_[rows_[k].a].q * rows_[k].ra;
    ub[k] = state_[rows_[k].b].q * rows_[k].rb;
  }
}

// Builds G(q) W G(q0)^T: with (ua, ub) == (ua0, ub0) the symmetric K above; with the anchors of two different
// configurations, the exact Jacobian of the residual C(q0 + W G(q0)^T mu) with respect to mu at the current q.
void World::build_newton_system(const std::vector<Vec2>& ua, const std::vector<Vec2>& ub, const std::vector<Vec2>& ua0,
                                const std::vector<Vec2>& ub0, BlockTridiag& sys) const {
  const int n = static_cast<int>(rows_.size());
  if (sys.size() != n) sys.resize(n);
  for (int k = 0; k < n; ++k) {
    const Row& r = rows_[k];
    const Body& A = bodies_[r.a];
    const Body& B = bodies_[r.b];
    Mat2 d = (A.inv_mass + B.inv_mass) * Mat2::Identity();
    d.noalias() += A.inv_inertia * perp(ua[k]) * perp(ua0[k]).transpose();
    d.noalias() += B.inv_inertia * perp(ub[k]) * perp(ub0[k]).transpose();
    sys.diag[k] = d;
    if (k == 0) continue;
    if (r.link_prev) {
      const Body& S = bodies_[r.a];
      sys.upper[k - 1] = -(S.inv_mass * Mat2::Identity() + S.inv_inertia * perp(ub[k - 1]) * perp(ua0[k]).transpose());
      sys.lower[k] = -(S.inv_mass * Mat2::Identity() + S.inv_inertia * perp(ua[k]) * perp(ub0[k - 1]).transpose());
    } else {
      sys.upper[k - 1].setZero();
      sys.lower[k].setZero();
    }
  }
}

void World::build_system(const std::vector<Vec2>& ua, const std::vector<Vec2>& ub, BlockTridiag& sys) const {
  build_newton_system(ua, ub, ua, ub, sys);
}

// Builds K at the current positions' anchors (ua, ub) into system_, factors it, and records for which state.
void World::factor_system(const std::vector<Vec2>& ua, const std::vector<Vec2>& ub) {
  build_system(ua, ub, system_);
  stats_.regularised_pivots += system_.factor();
  factor_version_ = state_version_;
}

double World::residuals(std::vector<Vec2>& c) const {
  const size_t n = rows_.size();
  c.resize(n);
  double worst = 0;
  for (size_t k = 0; k < n; ++k) {
    const Row& r = rows_[k];
    const BodyState& a = state_[r.a];
    const BodyState& b = state_[r.b];
    c[k] = (a.x + a.q * r.ra) - (b.x + b.q * r.rb);
    worst = std::max(worst, c[k].squaredNorm());
  }
  return std::sqrt(worst);
}

// q += W G(q0)^T mu for every body; with velocity_scale = 1/h the same change is made to the velocities (SHAKE:
// the multipliers are the impulses of the step), with 0 positions only (a projection).
void World::apply_correction(const std::vector<Vec2>& mu, const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0,
                             double velocity_scale) {
  const size_t nb = bodies_.size();
  f_.assign(nb, Vec2::Zero());    // per-body sum of row multipliers
  tau_.assign(nb, 0.0);           // per-body sum of their moments
  for (size_t k = 0; k < rows_.size(); ++k) {
    const Row& r = rows_[k];
    f_[r.a] += mu[k];
    tau_[r.a] += cross(ua0[k], mu[k]);
    f_[r.b] -= mu[k];
    tau_[r.b] -= cross(ub0[k], mu[k]);
    if (velocity_scale != 0) row_impulse_[k] += velocity_scale * mu[k];
  }
  for (size_t b = 0; b < nb; ++b) {
    const Body& body = bodies_[b];
    if (body.kinematic) continue;
    BodyState& s = state_[b];
    const Vec2 dx = body.inv_mass * f_[b];
    const double dth = body.inv_inertia * tau_[b];
    s.x += dx;
    s.th += dth;
    s.q = (s.q * rotation_of_small_angle(dth)).renormalised();
    s.v += velocity_scale * dx;
    s.w += velocity_scale * dth;
  }
  mark_state_changed();
}

// Solves C(q0 + W G(q0)^T mu) = 0 for mu by Newton's method, starting from the current q (= q0 plus the
// unconstrained motion). The default solver uses the factorised K(q0) as a fixed (chord) Jacobian: it converges
// linearly at a rate of about |w h| per iteration, and refreshes to the exact Jacobian if that rate is poor.
// The paper's solver (NewtonLineSearch) uses the exact Jacobian every iteration and backtracks along the Newton
// direction until the residual decreases (Numerical Recipes' lnsrch criterion).
bool World::solve_positions(const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0, double velocity_scale) {
  if (rows_.empty()) return true;
  const bool paper = options_.solver == SolverKind::NewtonLineSearch;
  bool exact = paper;
  BlockTridiag& newton = newton_;
  double res = residuals(c_);
  const double initial = res;
  for (int it = 0; it < options_.max_iterations; ++it) {
    if (!(res < 1e3 * initial + 1e-9)) break;  // diverging: give up, the caller redoes the step smaller
    if (res <= options_.tolerance) {
      stats_.residual = std::max(stats_.residual, res);
      return true;
    }
    ++stats_.iterations;
    mu_.resize(c_.size());
    for (size_t k = 0; k < c_.size(); ++k) mu_[k] = -c_[k];
    if (exact) {
      world_anchors(ua_, ub_);
      build_newton_system(ua_, ub_, ua0, ub0, newton);
      stats_.regularised_pivots += newton.factor();
      newton.solve(mu_);
    } else {
      system_.solve(mu_);
    }
    if (!paper) {
      apply_correction(mu_, ua0, ub0, velocity_scale);
      double next = residuals(c_);
      // A step that makes things worse is cut back by halves (the correction is linear in mu, so applying -mu/2
      // undoes half of it): near heavily loaded light bodies (the top of a long hanging chain) a full Newton
      // step can overshoot and cycle.
      for (int cut = 0; cut < 6 && next > res; ++cut) {
        for (Vec2& m : mu_) m *= -0.5;
        apply_correction(mu_, ua0, ub0, velocity_scale);
        for (Vec2& m : mu_) m = -m;
        next = residuals(c_);
      }
      if (next > 0.25 * res) exact = true;  // the chord is converging slowly: switch to the exact Jacobian
      res = next;
      continue;
    }
    // Backtracking: accept the largest step 2^-j whose residual satisfies f(new) <= (1 - 1e-4 step) f(old),
    // f = |C|^2 / 2; the 10th halving is kept whatever it gives (the next iteration re-linearises).
    const auto start = state_;
    const auto impulse_start = row_impulse_;
    double f0 = 0;
    for (const Vec2& ck : c_) f0 += 0.5 * ck.squaredNorm();
    double step = 1.0;
    for (int j = 0; j < 10; ++j) {
      apply_correction(mu_, ua0, ub0, velocity_scale);
      double f = 0;
      res = residuals(c_);
      for (const Vec2& ck : c_) f += 0.5 * ck.squaredNorm();
      if (f <= (1 - 1e-4 * step) * f0 || j == 9) break;  // after 10 halvings keep the last trial
      state_ = start;
      row_impulse_ = impulse_start;
      for (Vec2& m : mu_) m *= 0.5;
      step *= 0.5;
    }
  }
  stats_.residual = std::max(stats_.residual, res);
  return res <= options_.tolerance;
}

// Makes velocities satisfy the hinges: G v = 0 (kinematic bodies' prescribed velocities included), by the
// impulse G^T nu of least kinetic energy change, K nu = -G v. Factors K at the current positions and keeps
// the factorisation for the next step's position solve.
void World::project_velocities() {
  ensure_built();
  if (rows_.empty()) return;
  world_anchors(ua_, ub_);
  factor_system(ua_, ub_);
  const size_t n = rows_.size();
  mu_.resize(n);
  for (size_t k = 0; k < n; ++k) {
    const BodyState& a = state_[rows_[k].a];
    const BodyState& b = state_[rows_[k].b];
    mu_[k] = -((a.v + a.w * perp(ua_[k])) - (b.v + b.w * perp(ub_[k])));
  }
  system_.solve(mu_);
  for (size_t k = 0; k < n; ++k) {
    const Row& r = rows_[k];
    const Body& A = bodies_[r.a];
    const Body& B = bodies_[r.b];
    BodyState& a = state_[r.a];
    BodyState& b = state_[r.b];
    a.v += A.inv_mass * mu_[k];
    a.w += A.inv_inertia * cross(ua_[k], mu_[k]);
    b.v -= B.inv_mass * mu_[k];
    b.w -= B.inv_inertia * cross(ub_[k], mu_[k]);
    row_impulse_[k] += mu_[k];
  }
}

// Accelerations of every body under the applied forces and the hinge forces that keep the hinges' accelerations
// consistent (index-1 formulation, used by the explicit integrators); the hinge forces times impulse_weight are
// added to the step's row impulses:
//   K lambda = -(a_free(p_a) - a_free(p_b)),  a_free(p) = W F + (W tau) perp(u) - w^2 u  (driven bodies: their own)
void World::constraint_accelerations(std::vector<Vec2>& lin, std::vector<double>& ang, double impulse_weight,
                                     double h) {
  const size_t nb = bodies_.size();
  std::vector<Vec2>& force = force_;
  std::vector<double>& torque = torque_;
  accumulate_forces(force, torque, h);
  lin.resize(nb);
  ang.resize(nb);
  for (size_t b = 0; b < nb; ++b) {
    if (bodies_[b].kinematic) {
      lin[b] = kin_acc_[b];
      ang[b] = kin_alpha_[b];
    } else {
      lin[b] = bodies_[b].inv_mass * force[b];
      ang[b] = bodies_[b].inv_inertia * torque[b];
    }
  }
  if (rows_.empty()) return;
  world_anchors(ua_, ub_);
  if (factor_version_ != state_version_) factor_system(ua_, ub_);
  const size_t n = rows_.size();
  mu_.resize(n);
  for (size_t k = 0; k < n; ++k) {
    const Row& r = rows_[k];
    const BodyState& a = state_[r.a];
    const BodyState& b = state_[r.b];
    const Vec2 acc_a = lin[r.a] + ang[r.a] * perp(ua_[k]) - a.w * a.w * ua_[k];
    const Vec2 acc_b = lin[r.b] + ang[r.b] * perp(ub_[k]) - b.w * b.w * ub_[k];
    mu_[k] = -(acc_a - acc_b);
  }
  system_.solve(mu_);
  for (size_t k = 0; k < n; ++k) {
    const Row& r = rows_[k];
    const Body& A = bodies_[r.a];
    const Body& B = bodies_[r.b];
    lin[r.a] += A.inv_mass * mu_[k];
    ang[r.a] += A.inv_inertia * cross(ua_[k], mu_[k]);
    lin[r.b] -= B.inv_mass * mu_[k];
    ang[r.b] -= B.inv_inertia * cross(ub_[k], mu_[k]);
    row_impulse_[k] += impulse_weight * mu_[k];
  }
}

}  // namespace ladder::core
