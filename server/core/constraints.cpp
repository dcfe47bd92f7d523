// The hinge constraints: C_k(q) = p_a - p_b = (x_a + R_a r_a) - (x_b + R_b r_b) = 0, two equations per hinge.
//
// Jacobian of row k with respect to body a's (x, y, theta): G_ka = [I | perp(u_a)], with u_a = R_a r_a; with
// respect to body b: G_kb = -[I | perp(u_b)]. With W = M^-1 = diag(1/m, 1/m, 1/I) per body (zero for kinematic
// bodies), K = G W G^T has the 2x2 blocks
//   K_kk     = (w_a + w_b) I + i_a perp(u_a) perp(u_a)^T + i_b perp(u_b) perp(u_b)^T
//   K_k-1,k  = -(w_s I + i_s perp(u_b,k-1) perp(u_a,k)^T)    (s: the body the two rows share)
// and is block-tridiagonal once rows are ordered along chains (topology.cpp).
#include "core/world.hpp"
#include "core/hot_inline.hpp"

#include <algorithm>
#include <cmath>

namespace ladder::core {

namespace {

// K_kk with (ua, ub) == (ua0, ub0); with the anchors of two configurations, the diagonal block of the exact Newton
// Jacobian G(q) W G(q0)^T.
[[gnu::always_inline]] inline Mat2 diagonal_block(const Vec2& ua, const Vec2& ub, const Vec2& ua0, const Vec2& ub0, double wa, double ia, double wb,
                    double ib) {
  Mat2 d = (wa + wb) * Mat2::Identity();
  d.noalias() += ia * perp(ua) * perp(ua0).transpose();
  d.noalias() += ib * perp(ub) * perp(ub0).transpose();
  return d;
}

// The coupling of two rows through the body s they share: -(w_s I + i_s perp(p) perp(q)^T).
[[gnu::always_inline]] inline Mat2 coupling_block(const Vec2& p, const Vec2& q, double ws, double is) {
  return -(ws * Mat2::Identity() + is * perp(p) * perp(q).transpose());
}

}  // namespace

void World::world_anchors(std::vector<Vec2>& ua, std::vector<Vec2>& ub) const {
  const size_t n = rows_.size();
  ua.resize(n);
  ub.resize(n);
  for (size_t k = 0; k < n; ++k) row_levers(k, ua[k], ub[k]);
}

// The velocity projection that ends a step leaves the anchors of the state it projected in ua0_/ub0_; the next
// step starts from that state, so it needs no pass of its own.
void World::start_anchors() {
  if (anchors_version_ == state_version_ && ua0_.size() == rows_.size()) return;
  world_anchors(ua0_, ub0_);
  anchors_version_ = state_version_;
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
    sys.diag[k] = diagonal_block(ua[k], ub[k], ua0[k], ub0[k], A.inv_mass, A.inv_inertia, B.inv_mass, B.inv_inertia);
    if (k == 0) continue;
    if (r.link_prev) {
      sys.upper[k - 1] = coupling_block(ub[k - 1], ua0[k], A.inv_mass, A.inv_inertia);
      sys.lower[k] = coupling_block(ua[k], ub0[k - 1], A.inv_mass, A.inv_inertia);
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
    c[k] = row_residual(k);
    worst = std::max(worst, c[k].squaredNorm());
  }
  return std::sqrt(worst);
}

double World::position_residual() {
  if (residual_version_ != state_version_) {
    residual_ = residuals(work_.c);
    residual_version_ = state_version_;
  }
  return residual_;
}

// q += W G(q0)^T mu for every body; with velocity_scale = 1/h the same change is made to the velocities (SHAKE:
// the multipliers are the impulses of the step), with 0 positions only (a projection).
void World::apply_correction(const std::vector<Vec2>& mu, const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0,
                             double velocity_scale) {
  const size_t nb = bodies_.size();
  work_.f.assign(nb, Vec2::Zero());    // per-body sum of row multipliers
  work_.tau.assign(nb, 0.0);           // per-body sum of their moments
  for (size_t k = 0; k < rows_.size(); ++k) {
    const Row& r = rows_[k];
    work_.f[r.a] += mu[k];
    work_.tau[r.a] += cross(ua0[k], mu[k]);
    work_.f[r.b] -= mu[k];
    work_.tau[r.b] -= cross(ub0[k], mu[k]);
    if (velocity_scale != 0 && records_impulse(r)) row_impulse_[k] += velocity_scale * mu[k];
  }
  for (size_t b = 0; b < nb; ++b)
    if (!bodies_[b].kinematic) correct_body(static_cast<int>(b), work_.f[b], work_.tau[b], velocity_scale);
  mark_state_changed();
}

// The residuals work_.c at the current state and, in the same pass, the chord system's forward substitution of -work_.c
// into work_.mu: the first Newton iteration needs it unless the state already satisfies the hinges.
double World::forward_residual(const BlockTridiag& sys) {
  work_.c.resize(rows_.size());
  double worst = 0;
  sys.forward(work_.mu, [this, &worst](int k) HOT_INLINE {
    work_.c[k] = row_residual(static_cast<size_t>(k));
    worst = std::max(worst, work_.c[k].squaredNorm());
    return Vec2(-work_.c[k]);
  });
  residual_ = std::sqrt(worst);
  residual_version_ = state_version_;
  return residual_;
}

// The exact Newton matrix G(q) W G(q0)^T at the current anchors, built, factored and forward-substituted against
// -work_.c in one pass (newton_, work_.mu). The same blocks as build_newton_system().
void World::factor_exact_forward(const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0) {
  Vec2 ub_prev = Vec2::Zero();
  const auto row = [&](int k, Mat2& d, Mat2& l, Mat2& u_prev, Vec2& rhs) HOT_INLINE {
    const Row& r = rows_[k];
    const Body& A = bodies_[r.a];
    const Body& B = bodies_[r.b];
    Vec2 ua, ub;
    row_levers(static_cast<size_t>(k), ua, ub);
    d = diagonal_block(ua, ub, ua0[k], ub0[k], A.inv_mass, A.inv_inertia, B.inv_mass, B.inv_inertia);
    if (r.link_prev) {
      u_prev = coupling_block(ub_prev, ua0[k], A.inv_mass, A.inv_inertia);
      l = coupling_block(ua, ub0[k - 1], A.inv_mass, A.inv_inertia);
    } else {
      u_prev.setZero();
      l.setZero();
    }
    ub_prev = ub;
    rhs = -work_.c[k];
  };
  stats_.regularised_pivots += newton_.factor_forward(static_cast<int>(rows_.size()), row, work_.mu);
}

// Back-substitutes the forward-substituted work_.mu of `sys` and applies the correction q += W G(q0)^T mu body by body
// as soon as a body's multipliers are final, then the new residual of each hinge as soon as both its bodies are:
// one pass instead of three (back substitution, apply_correction(), residuals()). Rows are ordered along chains
// and a dynamic body is in at most two rows, k and k+1 with rows_[k+1].link_prev (topology.cpp), so when the sweep
// reaches row k, the body it shares with row k+1 has both its multipliers. Each body's sums are formed in row
// order from zero, as apply_correction() forms them, so the two give bit-identical states.
double World::correct_along_chain(const BlockTridiag& sys, const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0,
                                  double velocity_scale) {
  const bool impulses = velocity_scale != 0;
  const Row* rows = rows_.data();
  const Vec2* mu = work_.mu.data();  // backward() writes mu[k] before calling with k; nothing resizes it meanwhile
  Vec2* c = work_.c.data();
  double worst = 0;
  const auto check = [&](int k) HOT_INLINE {
    c[k] = row_residual(static_cast<size_t>(k));
    worst = std::max(worst, c[k].squaredNorm());
  };
  sys.backward(work_.mu, [&](int k) HOT_INLINE {
    const Row& r = rows[k];
    const Vec2 m = mu[k];
    if (r.corrects_b) {  // its row-k term, then (r.b being rows[k + 1].a) its row-(k + 1) term
      Vec2 f;
      double tau;
      load_on_b(k, mu, ua0.data(), ub0.data(), f, tau);
      correct_body(r.b, f, tau, velocity_scale);
    }
    if (r.corrects_a) correct_body(r.a, m, cross(ua0[k], m), velocity_scale);
    if (impulses && records_impulse(r)) row_impulse_[k] += velocity_scale * m;
    if (!r.link_prev) check(k);
    if (r.shares_next) check(k + 1);
  });
  mark_state_changed();
  residual_ = std::sqrt(worst);
  residual_version_ = state_version_;
  return residual_;
}

// Solves C(q0 + W G(q0)^T mu) = 0 for mu by Newton's method, starting from the current q (= q0 plus the
// unconstrained motion). The default solver uses the factorised K(q0) as a fixed (chord) Jacobian: it converges
// linearly at a rate of about |w h| per iteration, and refreshes to the exact Jacobian if that rate is poor.
// The paper's solver (NewtonLineSearch) uses the exact Jacobian every iteration and backtracks along the Newton
// direction until the residual decreases (Numerical Recipes' lnsrch criterion).
//
// Each iteration of the default solver is two passes along the chains: a forward substitution (fused with the
// build and factorisation when the Jacobian is the exact one, and with the residual on the first iteration) and a
// backward one that applies the correction and measures the new residual (correct_along_chain()).
bool World::solve_positions(const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0, double velocity_scale) {
  if (rows_.empty()) return true;
  const bool paper = options_.solver == SolverKind::NewtonLineSearch;
  bool exact = paper;
  // At a loose tolerance the unconstrained step often stays within it: a residual pass alone is then cheaper than
  // the one fused with the first forward substitution. At a tight one it almost never does, and the pass would be
  // waste (and would change nothing: the default 1e-12 m keeps its arithmetic).
  if (!paper && options_.tolerance >= 1e-7 && position_residual() <= options_.tolerance) {
    stats_.residual = std::max(stats_.residual, residual_);
    return true;
  }
  double res = paper ? residuals(work_.c) : forward_residual(system_);
  const double initial = res;
  for (int it = 0; it < options_.max_iterations; ++it) {
    if (!(res < 1e3 * initial + 1e-9)) break;  // diverging: give up, the caller redoes the step smaller
    if (res <= options_.tolerance) {
      stats_.residual = std::max(stats_.residual, res);
      return true;
    }
    ++stats_.iterations;
    res = paper ? linesearch_iteration(ua0, ub0, velocity_scale)
                : newton_iteration(it > 0, exact, res, ua0, ub0, velocity_scale);
  }
  stats_.residual = std::max(stats_.residual, res);
  return res <= options_.tolerance;
}

// A correction mu (work_.mu, applied along ua0/ub0) that left the residual `next` above the `res` it started from is
// cut back by halves, at most six times (the correction is linear in mu, so applying -mu/2 undoes half of it): near
// heavily loaded light bodies (the top of a long hanging chain) a full Newton step can overshoot and cycle. Returns the
// residual it ends at.
double World::cut_back(double res, double next, const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0,
                       double velocity_scale) {
  for (int cut = 0; cut < 6 && next > res; ++cut) {
    for (Vec2& m : work_.mu) m *= -0.5;
    apply_correction(work_.mu, ua0, ub0, velocity_scale);
    for (Vec2& m : work_.mu) m = -m;
    next = residuals(work_.c);
  }
  return next;
}

// One iteration of the default solver from the residual work_.c (res its largest), returning the new largest residual.
// `forward` says whether work_.mu still needs the forward substitution (forward_residual() did it for the first).
double World::newton_iteration(bool forward, bool& exact, double res, const std::vector<Vec2>& ua0,
                               const std::vector<Vec2>& ub0, double velocity_scale) {
  if (exact)
    factor_exact_forward(ua0, ub0);
  else if (forward)
    system_.forward(work_.mu, [this](int k) HOT_INLINE { return Vec2(-work_.c[k]); });
  const double next = cut_back(res, correct_along_chain(exact ? newton_ : system_, ua0, ub0, velocity_scale), ua0,
                               ub0, velocity_scale);
  if (next > 0.25 * res) exact = true;  // the chord is converging slowly: switch to the exact Jacobian
  return next;
}

// One iteration of the paper's solver: the exact Jacobian, then backtracking: accept the largest step 2^-j whose
// residual satisfies f(new) <= (1 - 1e-4 step) f(old), f = |C|^2 / 2; the 10th halving is kept whatever it gives
// (the next iteration re-linearises).
double World::linesearch_iteration(const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0,
                                   double velocity_scale) {
  work_.mu.resize(work_.c.size());
  for (size_t k = 0; k < work_.c.size(); ++k) work_.mu[k] = -work_.c[k];
  world_anchors(work_.ua, work_.ub);
  build_newton_system(work_.ua, work_.ub, ua0, ub0, newton_);
  stats_.regularised_pivots += newton_.factor();
  newton_.solve(work_.mu);
  const auto start = state_;
  const auto impulse_start = row_impulse_;
  double f0 = 0;
  for (const Vec2& ck : work_.c) f0 += 0.5 * ck.squaredNorm();
  double step = 1.0, res = 0;
  for (int j = 0; j < 10; ++j) {
    apply_correction(work_.mu, ua0, ub0, velocity_scale);
    double f = 0;
    res = residuals(work_.c);
    for (const Vec2& ck : work_.c) f += 0.5 * ck.squaredNorm();
    if (f <= (1 - 1e-4 * step) * f0 || j == 9) break;  // after 10 halvings keep the last trial
    state_ = start;
    row_impulse_ = impulse_start;
    for (Vec2& m : work_.mu) m *= 0.5;
    step *= 0.5;
  }
  return res;
}

// The projection integrator's solve: K(q) at the current iterate built, factored and forward-substituted against
// -C(q) in one pass (system_, work_.mu), the anchors left in work_.ua / work_.ub as the correction's directions.
// Returns the largest residual at the current state.
double World::factor_current_forward() {
  const int n = static_cast<int>(rows_.size());
  work_.ua.resize(rows_.size());
  work_.ub.resize(rows_.size());
  work_.c.resize(rows_.size());
  double worst = 0;
  const auto row = [this, &worst](int k, double* d, Mat2& u_prev, Vec2& rhs) HOT_INLINE {
    const Row& r = rows_[k];
    symmetric_row(k, work_.ua, work_.ub, d, u_prev);
    work_.c[k] = (state_[r.a].x + work_.ua[k]) - (state_[r.b].x + work_.ub[k]);
    worst = std::max(worst, work_.c[k].squaredNorm());
    rhs = -work_.c[k];
  };
  stats_.regularised_pivots += system_.factor_forward_symmetric(n, row, work_.mu);
  factor_version_ = state_version_;
  residual_ = std::sqrt(worst);
  residual_version_ = state_version_;
  return residual_;
}

// Newton's method on C(q + W G(q)^T mu) = 0 re-linearised at every iterate q: its Jacobian at mu = 0 is K(q)
// exactly, so it converges quadratically. A correction that makes the residual worse is cut back (cut_back()).
bool World::solve_projection(double velocity_scale) {
  if (rows_.empty()) return true;
  // At a loose tolerance the unconstrained step often stays within it (half the steps of a free chain at 1 um and
  // 1 ms): a residual pass alone is then cheaper than the fused factorisation that would measure it.
  if (position_residual() <= options_.tolerance) {
    stats_.residual = std::max(stats_.residual, residual_);
    return true;
  }
  double res = factor_current_forward();
  const double initial = res;
  for (int it = 0;; ++it) {
    if (res <= options_.tolerance) {
      stats_.residual = std::max(stats_.residual, res);
      return true;
    }
    if (it >= options_.max_iterations || !(res < 1e3 * initial + 1e-9)) break;
    if (it > 0) factor_current_forward();
    ++stats_.iterations;
    res = cut_back(res, correct_along_chain(system_, work_.ua, work_.ub, velocity_scale), work_.ua, work_.ub,
                   velocity_scale);
  }
  stats_.residual = std::max(stats_.residual, res);
  return false;
}

// Makes velocities satisfy the hinges: G v = 0 (kinematic bodies' prescribed velocities included), by the
// impulse G^T nu of least kinetic energy change, K nu = -G v. Factors K at the current positions and keeps
// the factorisation (system_) and the anchors (ua0_, ub0_) for the next step's position solve. Two passes: the
// forward one builds K, factors it and forward-substitutes -G v; the backward one back-substitutes and applies the
// impulses to each body once its multipliers are final (in row order per body, as a row-by-row loop would).
void World::project_velocities() {
  ensure_built();
  mark_motion_changed();
  if (rows_.empty()) return;
  const int n = static_cast<int>(rows_.size());
  ua0_.resize(rows_.size());
  ub0_.resize(rows_.size());
  const auto row = [this](int k, double* d, Mat2& u_prev, Vec2& rhs) HOT_INLINE {
    const Row& r = rows_[k];
    const BodyState& a = state_[r.a];
    const BodyState& b = state_[r.b];
    symmetric_row(k, ua0_, ub0_, d, u_prev);
    const Vec2& ua = ua0_[k];
    const Vec2& ub = ub0_[k];
    rhs = -((a.v + a.w * perp(ua)) - (b.v + b.w * perp(ub)));
  };
  stats_.regularised_pivots += system_.factor_forward_symmetric(n, row, work_.mu);
  factor_version_ = anchors_version_ = state_version_;
  system_.backward(work_.mu, [this](int k) HOT_INLINE {
    const Row& r = rows_[k];
    const Vec2& m = work_.mu[k];
    const Body& B = bodies_[r.b];
    BodyState& b = state_[r.b];
    b.v -= B.inv_mass * m;
    b.w -= B.inv_inertia * cross(ub0_[k], m);
    if (r.shares_next) {  // r.b is rows_[k + 1].a: its second row's impulse, in row order
      b.v += B.inv_mass * work_.mu[k + 1];
      b.w += B.inv_inertia * cross(ua0_[k + 1], work_.mu[k + 1]);
    }
    if (!r.link_prev) {
      const Body& A = bodies_[r.a];
      BodyState& a = state_[r.a];
      a.v += A.inv_mass * m;
      a.w += A.inv_inertia * cross(ua0_[k], m);
    }
    if (records_impulse(r)) row_impulse_[k] += m;
  });
}

// Accelerations of every body under the applied forces and the hinge forces that keep the hinges' accelerations
// consistent (index-1 formulation, used by the explicit integrators); the hinge forces times impulse_weight are
// added to the step's row impulses:
//   K lambda = -(a_free(p_a) - a_free(p_b)),  a_free(p) = W F + (W tau) perp(u) - w^2 u  (driven bodies: their own)
void World::constraint_accelerations(std::vector<Vec2>& lin, std::vector<double>& ang, double impulse_weight,
                                     double h) {
  const size_t nb = bodies_.size();
  std::vector<Vec2>& force = work_.force;
  std::vector<double>& torque = work_.torque;
  accumulate_forces(force, torque, h);
  lin.resize(nb);
  ang.resize(nb);
  for (size_t b = 0; b < nb; ++b) {
    if (bodies_[b].kinematic) {
      lin[b] = work_.kin_acc[b];
      ang[b] = work_.kin_alpha[b];
    } else {
      lin[b] = bodies_[b].inv_mass * force[b];
      ang[b] = bodies_[b].inv_inertia * torque[b];
    }
  }
  if (rows_.empty()) return;
  world_anchors(work_.ua, work_.ub);
  if (factor_version_ != state_version_) factor_system(work_.ua, work_.ub);
  const size_t n = rows_.size();
  work_.mu.resize(n);
  for (size_t k = 0; k < n; ++k) {
    const Row& r = rows_[k];
    const BodyState& a = state_[r.a];
    const BodyState& b = state_[r.b];
    const Vec2 acc_a = lin[r.a] + ang[r.a] * perp(work_.ua[k]) - a.w * a.w * work_.ua[k];
    const Vec2 acc_b = lin[r.b] + ang[r.b] * perp(work_.ub[k]) - b.w * b.w * work_.ub[k];
    work_.mu[k] = -(acc_a - acc_b);
    if (r.rolls) work_.mu[k] -= rolling_acceleration(k);
  }
  system_.solve(work_.mu);
  for (size_t k = 0; k < n; ++k) {
    const Row& r = rows_[k];
    const Body& A = bodies_[r.a];
    const Body& B = bodies_[r.b];
    lin[r.a] += A.inv_mass * work_.mu[k];
    ang[r.a] += A.inv_inertia * cross(work_.ua[k], work_.mu[k]);
    lin[r.b] -= B.inv_mass * work_.mu[k];
    ang[r.b] -= B.inv_inertia * cross(work_.ub[k], work_.mu[k]);
    if (records_impulse(r)) row_impulse_[k] += impulse_weight * work_.mu[k];
  }
}

// The explicit integrators' post-stabilisation (euler.cpp, rk4.cpp): back onto C(q) = 0 along the mass-metric
// normal (a Newton projection of the positions), then onto G v = 0; neither lowers their order.
void World::stabilise_explicit() {
  if (options_.stabilization == Stabilization::Position) {
    start_anchors();
    factor_system(ua0_, ub0_);
    stats_.converged = solve_positions(ua0_, ub0_, 0.0);
  } else {
    stats_.residual = position_residual();  // what is left unprojected, for the statistics
  }
  if (options_.stabilization != Stabilization::None) project_velocities();
}

}  // namespace ladder::core
