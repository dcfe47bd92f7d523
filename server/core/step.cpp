// Time stepping. A step is a short list of named stages; the integrator decides which.
//
//  symplectic_euler (SHAKE):  kick(h) -> drift(h) -> solve C(q1) = 0 (impulses enter v too) -> project velocities
//  rattle (velocity Verlet):  kick(h/2) -> drift(h) -> solve C(q1) = 0 -> kick(h/2) -> project velocities
//  euler (the paper's):       accelerations with hinge forces -> x += h v, v += h a -> project positions, velocities
//  rk4:                       4 stages of the same accelerations -> project positions, velocities
//  projection:                kick(h) -> drift(h) -> project onto C(q1) = 0 along G(q) at the current iterate
//                             (impulses enter v too) -> nothing more
//  reduced:                   hinge forces at the start (the index-1 solve) -> symplectic Euler in each chain's
//                             own coordinates (its first body's pose, then every body's angle) -> every other body
//                             placed and moved by its hinge: no constraint solve, the hinges hold by construction
// SHAKE and RATTLE are symplectic on the constraint manifold (Hairer, Lubich & Wanner, Geometric Numerical
// Integration, VII.1): energy errors stay bounded instead of drifting. The explicit methods integrate the index-1
// equations and are kept on the manifold by projection after each step (post-stabilisation), which does not
// lower their order.
//
// projection is the "fast projection" of Goldenthal et al., Efficient Simulation of Inextensible Cloth (SIGGRAPH
// 2007), for hinges: the unconstrained step is projected back onto the hinges by Newton's method with the Jacobian
// re-linearised at every iterate, and the velocity is (q1 - q0) / h. The constraint forces thus act along the
// hinges' directions at the end of the step (close to backward Euler in the constraint forces), which is what makes
// it stable for stiff long chains at steps where SHAKE's start-of-step directions fail, at the price of first-order
// accuracy and numerical damping of fast modes. Each iteration is one fused pass (anchors, residual, build, factor,
// forward substitution) and one back-substitution pass that corrects the bodies; one iteration usually suffices at
// a loose tolerance. With stabilization = none no velocity projection follows: the cheapest step the core has.
//
// reduced integrates a chain in its minimal coordinates, as robotics codes integrate a serial arm in its joint
// angles (Featherstone, Rigid Body Dynamics Algorithms, 2008): the chain's first body has its full pose (or a drive)
// and each further body only its angle, since the hinge places it. The accelerations are those of the constrained
// equations at the start of the step, K lambda = -(a_free(p_a) - a_free(p_b)) (the same O(n) block-tridiagonal
// solve as the explicit integrators', one factorisation), the angular velocities and angles take a symplectic Euler
// step, and forward kinematics along each chain then puts every body where its hinge says, with the velocity its
// hinge gives. Hinge errors are rounding (a few ulps of the positions); there is no position or velocity
// projection and no Newton iteration. First order, like SHAKE, but not symplectic: a chain's mass matrix in its
// angles depends on the angles (docs/tradeoff.md measures its energy error). A chain held at one end grows from that
// end, whichever way its rows run; a chain held at both ends cannot, and SHAKE steps the world.
#include "core/world.hpp"
#include "core/hot_inline.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace ladder::core {

const char* to_string(Integrator i) {
  switch (i) {
    case Integrator::Euler: return "euler";
    case Integrator::SymplecticEuler: return "symplectic_euler";
    case Integrator::Rattle: return "rattle";
    case Integrator::RK4: return "rk4";
    case Integrator::Projection: return "projection";
    case Integrator::Reduced: return "reduced";
  }
  return "?";
}

const char* to_string(SolverKind s) {
  switch (s) {
    case SolverKind::Newton: return "newton";
    case SolverKind::NewtonLineSearch: return "newton_linesearch";
  }
  return "?";
}

Integrator integrator_from_string(const std::string& s) {
  for (Integrator i : {Integrator::Euler, Integrator::SymplecticEuler, Integrator::Rattle, Integrator::RK4,
                       Integrator::Projection, Integrator::Reduced})
    if (s == to_string(i)) return i;
  throw std::invalid_argument("unknown integrator '" + s +
                              "' (expected euler, symplectic_euler, rattle, rk4, projection or reduced)");
}

const char* to_string(Stabilization s) {
  switch (s) {
    case Stabilization::None: return "none";
    case Stabilization::Velocity: return "velocity";
    case Stabilization::Position: return "position";
  }
  return "?";
}

Stabilization stabilization_from_string(const std::string& s) {
  for (Stabilization k : {Stabilization::None, Stabilization::Velocity, Stabilization::Position})
    if (s == to_string(k)) return k;
  throw std::invalid_argument("unknown stabilization '" + s + "' (expected none, velocity or position)");
}

SolverKind solver_from_string(const std::string& s) {
  for (SolverKind k : {SolverKind::Newton, SolverKind::NewtonLineSearch})
    if (s == to_string(k)) return k;
  throw std::invalid_argument("unknown solver '" + s + "' (expected newton or newton_linesearch)");
}

void World::drive_kinematic(double t) {
  const size_t nb = bodies_.size();
  kin_acc_.resize(nb);
  kin_alpha_.resize(nb);
  for (const int b : kinematic_bodies_) {
    BodyState& s = state_[b];
    const Part& p = parts_[bodies_[b].anchor_part];
    if (!p.drive) {  // held still
      s.v.setZero();
      s.w = 0;
      kin_acc_[b].setZero();
      kin_alpha_[b] = 0;
      continue;
    }
    const Kinematics k = p.drive(t);
    s.th = k.theta - p.rel_th;
    s.q = Rot::of(s.th);
    s.x = k.x - s.q * p.rel_x;
    const Vec2 d = s.x - k.x;
    s.w = k.omega;
    s.v = k.v + k.omega * perp(d);
    kin_acc_[b] = k.a + k.alpha * perp(d) - k.omega * k.omega * d;
    kin_alpha_[b] = k.alpha;
  }
  mark_state_changed();
}

// Gravity and damping on one dynamic body at the current state.
void World::body_force(int b, Vec2& f, double& tau) const {
  const Body& body = bodies_[b];
  const BodyState& s = state_[b];
  const Vec2 g = options_.gravity;
  const double cl = options_.linear_damping, ca = options_.angular_damping;
  if (body.single_part) {
    f = body.mass * (g - cl * s.v);
    tau = -ca * body.inertia * s.w;
    return;
  }
  f.setZero();
  tau = 0;
  for (int i : body_parts_[b]) {  // damping acts on each part's own motion
    const Part& p = parts_[i];
    const Vec2 d = s.q * p.rel_x;
    const Vec2 fp = p.mass * (g - cl * (s.v + s.w * perp(d)));
    f += fp;
    tau += cross(d, fp) - ca * p.inertia * s.w;
  }
}

// Applied forces at the current state: gravity, damping, hinge friction and the users' forces (those weighted over
// the step of length h that they act for, AppliedForce::over_step).
void World::accumulate_forces(std::vector<Vec2>& f, std::vector<double>& tau, double h) const {
  const size_t nb = bodies_.size();
  f.assign(nb, Vec2::Zero());
  tau.assign(nb, 0.0);
  for (size_t b = 0; b < nb; ++b)
    if (!bodies_[b].kinematic) body_force(static_cast<int>(b), f[b], tau[b]);
  if (options_.hinge_friction != 0) {
    for (const Row& r : rows_) {
      const double t = options_.hinge_friction * (state_[r.b].w - state_[r.a].w);
      tau[r.a] += t;
      tau[r.b] -= t;
    }
  }
  for (const AppliedForce& af : forces_) {
    if (!(t_ < af.until)) continue;
    const Part& p = parts_[af.part];
    const BodyState& s = state_[p.body];
    const Vec2 d = s.q * (p.rel_x + p.rel_q * af.local);
    const Vec2 force = af.over_step(t_, h);
    f[p.body] += force;
    tau[p.body] += cross(d, force);
  }
}

void World::kick(double h, const std::vector<Vec2>& f, const std::vector<double>& tau) {
  for (size_t b = 0; b < bodies_.size(); ++b) {
    const Body& body = bodies_[b];
    if (body.kinematic) continue;
    state_[b].v += (h * body.inv_mass) * f[b];
    state_[b].w += h * body.inv_inertia * tau[b];
  }
}

void World::drift(double h) {
  for (size_t b = 0; b < bodies_.size(); ++b) {
    if (bodies_[b].kinematic) continue;
    BodyState& s = state_[b];
    const double dth = h * s.w;
    s.x += h * s.v;
    s.th += dth;
    s.q = (s.q * rotation_of_small_angle(dth)).renormalised();
  }
  mark_state_changed();
}

// kick(h_kick) then drift(h) with the forces at the current state. Without hinge friction or users' forces a body's
// force depends on its own state only, so the three stages are one pass over the bodies (the same arithmetic).
void World::kick_drift(double h_kick, double h) {
  if (options_.hinge_friction != 0 || !forces_.empty()) {
    accumulate_forces(force_, torque_, h);
    kick(h_kick, force_, torque_);
    drift(h);
    return;
  }
  for (size_t b = 0; b < bodies_.size(); ++b) {
    const Body& body = bodies_[b];
    if (body.kinematic) continue;
    BodyState& s = state_[b];
    Vec2 f;
    double tau;
    if (body.single_part) {  // body_force()'s common case, inline
      f = body.mass * (options_.gravity - options_.linear_damping * s.v);
      tau = -options_.angular_damping * body.inertia * s.w;
    } else {
      body_force(static_cast<int>(b), f, tau);
    }
    s.v += (h_kick * body.inv_mass) * f;
    s.w += h_kick * body.inv_inertia * tau;
    const double dth = h * s.w;
    s.x += h * s.v;
    s.th += dth;
    s.q = (s.q * rotation_of_small_angle(dth)).renormalised();
  }
  mark_state_changed();
}

void World::step(double h, bool adaptive, Snapshot* before) {
  if (!(h > 0) || !std::isfinite(h)) throw std::invalid_argument("step: the time step must be a positive number");
  ensure_built();
  const bool whole = options_.adaptive && adaptive;
  // One reduced step leaves the state it started from in other_state_; anything else needs a copy first.
  const bool swapped = before && !whole && options_.integrator == Integrator::Reduced && reduced_applies();
  if (before) {
    if (!swapped) before->bodies = state_;
    before->forces = forces_;
    before->t = t_;
    before->structure = structure_;
    before->adaptive_h = adaptive_h_;
  }
  if (whole)
    step_adaptive(h);
  else
    step_fixed(h);
  if (swapped) before->bodies.swap(other_state_);
}

namespace {

// Order of accuracy p of each integrator (global error O(h^p)), for the adaptive step's error estimate.
int order(Integrator i) {
  switch (i) {
    case Integrator::Rattle: return 2;
    case Integrator::RK4: return 4;
    case Integrator::Euler:
    case Integrator::SymplecticEuler:
    case Integrator::Projection:
    case Integrator::Reduced: return 1;
  }
  return 1;
}

}  // namespace

// The largest displacement between the current state and `other` over the dynamic bodies [m]: the centre's plus
// the turn times the radius of gyration (a typical point's displacement from the turn).
double World::difference(const std::vector<BodyState>& other) const {
  double worst = 0;
  for (size_t b = 0; b < bodies_.size(); ++b) {
    const Body& body = bodies_[b];
    if (body.kinematic) continue;
    const double d = (state_[b].x - other[b].x).norm() +
                     std::sqrt(body.inertia * body.inv_mass) * std::abs(state_[b].th - other[b].th);
    worst = std::max(worst, std::isnan(d) ? std::numeric_limits<double>::infinity() : d);
  }
  return worst;
}

// Error-controlled adaptive stepping by step doubling (Hairer, Norsett & Wanner, Solving ODEs I, II.4): each trial
// sub-step s is taken once whole and once as two halves from the same start. Their difference over 2^p - 1 (p the
// integrator's order) estimates the halves' local error (Richardson); a trial within the tolerance is accepted with
// the halves' state, the more accurate of the two, and the next trial is scaled by 0.9 (tol / err)^(1 / (p + 1)),
// at most 2x up and 5x down (10x after a failure). A non-finite trial or a failed hinge solve counts as an error
// beyond any tolerance (one that stopped short of the hinge tolerance but within the error tolerance does not).
// Sub-steps never go below h / 1024: one that still misses the tolerance there is accepted (error_estimate and
// converged say so, and the step goes on to its end) unless it made a non-finite state, which is left for the
// caller's watchdog to undo.
// A trial costs three steps; the trial size is remembered from call to call (and in snapshots).
void World::step_adaptive(double h) {
  const double t_end = t_ + h, h_min = h / 1024, tol = options_.error_tolerance;
  const double p = order(options_.integrator), richardson = std::pow(2.0, p) - 1;
  StepStats total;
  total.substeps = 0;
  double trial = adaptive_h_ > 0 ? std::min(adaptive_h_, h) : h;
  for (int trials = 0;; ++trials) {
    const double remaining = t_end - t_;
    if (!(remaining > 1e-9 * h)) break;
    const double s = next_piece(trial, remaining);
    // Half a sub-step below the resolution of the clock (a tiny step late in a long run) would never get there, and
    // neither would a run of trials with no end: the rest is then taken as one plain step.
    if (!(t_ + 0.5 * s > t_) || trials >= 4096) {
      step_fixed(remaining);
      total.add(stats_);
      ++total.substeps;
      break;
    }
    const Snapshot start = save();
    step_fixed(s);
    // A solve that stopped short of the hinge tolerance but within the error tolerance spoils no estimate.
    const auto solved = [&] { return stats_.converged || stats_.residual <= tol; };
    const bool whole_ok = finite() && solved();
    const int whole_iterations = stats_.iterations;
    whole_ = state_;
    restore(start);
    step_fixed(0.5 * s);
    StepStats halves = stats_;
    const bool first_ok = finite() && solved();
    if (first_ok) {
      step_fixed(t_end - t_ <= 0.5 * s * (1 + 1e-12) ? t_end - t_ : 0.5 * s);
      halves.add(stats_);
    }
    const bool halves_ok = first_ok && finite() && solved();
    const double err = whole_ok && halves_ok ? difference(whole_) / richardson : std::numeric_limits<double>::infinity();
    total.iterations += whole_iterations;  // every trial's solves count; only an accepted one's state does
    if (err <= tol || s <= h_min * (1 + 1e-9)) {
      total.add(halves);
      total.error_estimate = std::max(total.error_estimate, err);
      ++total.substeps;
      if (!finite()) {  // even the smallest sub-step made garbage: left as it is for the caller's watchdog
        adaptive_h_ = trial;
        stats_ = total;
        return;
      }
      // At the smallest sub-step the error may exceed the tolerance, even be infinite: the trial then stays there.
      // A sub-step cut short by the end of the step says nothing about the trial size.
      const double grow = err > 0 ? std::clamp(0.9 * std::pow(tol / err, 1 / (p + 1)), 0.2, 2.0) : 2.0;
      trial = std::max(h_min, s < trial ? std::max(trial, s * grow) : s * grow);
    } else {
      restore(start);
      total.iterations += halves.iterations;
      total.regularised_pivots += halves.regularised_pivots;
      ++total.rejected;
      const double shrink = std::isfinite(err) ? std::max(0.2, 0.9 * std::pow(tol / err, 1 / (p + 1))) : 0.1;
      trial = std::max(h_min, s * shrink);
    }
  }
  t_ = t_end;
  adaptive_h_ = trial;
  stats_ = total;
}

void World::step_fixed(double h) {
  stats_ = {};
  last_h_ = h;
  // The row impulses and the start state serve weld_moment() only, which is void unless a weld existed during the
  // step (a weld made later changes the structure), so a model without welds does not pay for them.
  if (has_welds_) {
    std::fill(row_impulse_.begin(), row_impulse_.end(), Vec2::Zero());
    step_start_ = state_;
  }
  step_structure_ = structure_;
  step_forces_ = forces_;
  const double t0 = t_;
  start_work();
  switch (options_.integrator) {
    case Integrator::SymplecticEuler: step_shake(h, false); break;
    case Integrator::Rattle: step_shake(h, true); break;
    case Integrator::Euler: step_explicit(h, false); break;
    case Integrator::RK4: step_explicit(h, true); break;
    case Integrator::Projection: step_projection(h); break;
    case Integrator::Reduced: step_reduced(h); break;
  }
  stats_.work = finish_work(t0, h);
  mark_motion_changed();  // whatever stage changed velocities last
  std::erase_if(forces_, [this](const AppliedForce& af) { return !(t_ < af.until); });
}

namespace {

// Velocity of the point at offset d (world frame) from a body's centre of mass.
Vec2 point_velocity(const BodyState& s, const Vec2& d) { return s.v + s.w * perp(d); }

}  // namespace

// Records what StepStats::work needs from the start of a step: the velocities of the kinematic anchors and of the
// applied forces' points (a handful: the hold, the users' pushes and grips), and clears the kinematic rows' impulses.
void World::start_work() {
  kinematic_v0_.clear();
  for (int k : kinematic_rows_) {
    const Row& r = rows_[k];
    const bool a_kinematic = bodies_[r.a].kinematic;
    const BodyState& s = state_[a_kinematic ? r.a : r.b];
    kinematic_v0_.push_back(point_velocity(s, s.q * (a_kinematic ? r.ra : r.rb)));
    row_impulse_[k].setZero();
  }
  force_arm_.clear();
  force_v0_.clear();
  for (const AppliedForce& af : step_forces_) {
    const Part& p = parts_[af.part];
    const BodyState& s = state_[p.body];
    force_arm_.push_back(s.q * (p.rel_x + p.rel_q * af.local));
    force_v0_.push_back(point_velocity(s, force_arm_.back()));
  }
}

// The work done on the dynamic bodies over the step just taken: each force times its point's mean velocity over the
// step, h long, the point taken at its start-of-step lever arm as accumulate_forces() applies it (so that for
// symplectic Euler a push's work is exactly the kinetic energy it adds); each kinematic row's impulse (on the dynamic side: +J on body a, -J on body b) times its kinematic
// anchor's mean velocity (the hinge holds the two anchors' velocities equal).
double World::finish_work(double t0, double h) const {
  double work = 0;
  for (size_t i = 0; i < step_forces_.size(); ++i) {
    const AppliedForce& af = step_forces_[i];
    const Part& p = parts_[af.part];
    if (bodies_[p.body].kinematic) continue;
    const Vec2 v1 = point_velocity(state_[p.body], force_arm_[i]);
    work += af.over_step(t0, h).dot(0.5 * (force_v0_[i] + v1)) * h;
  }
  for (size_t i = 0; i < kinematic_rows_.size(); ++i) {
    const Row& r = rows_[static_cast<size_t>(kinematic_rows_[i])];
    const bool a_kinematic = bodies_[r.a].kinematic;
    const BodyState& s = state_[a_kinematic ? r.a : r.b];
    const Vec2 v1 = point_velocity(s, s.q * (a_kinematic ? r.ra : r.rb));
    const Vec2 j = row_impulse_[static_cast<size_t>(kinematic_rows_[i])];
    work += (a_kinematic ? -j : j).dot(0.5 * (kinematic_v0_[i] + v1));
  }
  return work;
}

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
    accumulate_forces(force_, torque_, h);
    kick(0.5 * h, force_, torque_);
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

// The chains as the reduced step walks them, once per structure. rows_ is ordered along chains (topology.cpp), but
// a chain's direction there is whichever end order_rows() met first: one held at its last row's body b grows from
// that end instead. A chain with both ends driven cannot grow from either, and SHAKE steps the world.
bool World::reduced_applies() {
  if (reduced_structure_ == structure_) return reduced_ok_;
  reduced_structure_ = structure_;
  reduced_ok_ = true;
  reduced_chains_.clear();
  std::vector<char> hinged(bodies_.size(), 0);
  const int n = static_cast<int>(rows_.size());
  for (int k = 0; k < n;) {
    int last = k;
    while (last + 1 < n && rows_[last + 1].link_prev) ++last;
    const bool driven_start = bodies_[rows_[k].a].kinematic, driven_end = bodies_[rows_[last].b].kinematic;
    if (driven_start && driven_end) reduced_ok_ = false;
    for (int j = k; j <= last; ++j) hinged[rows_[j].a] = hinged[rows_[j].b] = 1;
    reduced_chains_.push_back({k, last, driven_end && !driven_start});
    k = last + 1;
  }
  loose_bodies_.clear();
  for (size_t b = 0; b < bodies_.size(); ++b)
    if (!hinged[b] && !bodies_[b].kinematic) loose_bodies_.push_back(static_cast<int>(b));
  return reduced_ok_;
}

void World::step_reduced(double h) {
  if (!reduced_applies()) {
    step_shake(h, false);
    return;
  }
  const double t1 = t_ + h;
  // The drives' accelerations at the start: always anew, since after a restore() kin_acc_ holds a later time's.
  drive_kinematic(t_);
  // The free forces: gravity and damping inline, unless users' forces or hinge friction need the general sum. Without
  // damping a one-part body's is its weight alone.
  const bool general = options_.hinge_friction != 0 || !forces_.empty();
  const bool undamped = !general && options_.linear_damping == 0 && options_.angular_damping == 0;
  const Vec2 g = options_.gravity;
  if (general) accumulate_forces(force_, torque_, h);
  const double cl = options_.linear_damping, ca = options_.angular_damping;
  const auto free_force = [&](int i, Vec2& f, double& tau) HOT_INLINE {
    const Body& body = bodies_[i];
    if (general) {
      f = force_[i], tau = torque_[i];
    } else if (body.single_part) {  // body_force()'s common case, inline
      f = body.mass * (g - cl * state_[i].v);
      tau = -ca * body.inertia * state_[i].w;
    } else {
      body_force(i, f, tau);
    }
  };
  // A body's acceleration at anchor u without the hinges (a driven body's: its drive's).
  const auto free_acceleration = [&](int i, const Vec2& u) HOT_INLINE {
    const Body& body = bodies_[i];
    const BodyState& s = state_[i];
    if (body.kinematic) return Vec2(kin_acc_[i] + kin_alpha_[i] * perp(u) - (s.w * s.w) * u);
    if (undamped && body.single_part) return Vec2(g - (s.w * s.w) * u);
    Vec2 f;
    double tau;
    free_force(i, f, tau);
    return Vec2(body.inv_mass * f + (body.inv_inertia * tau) * perp(u) - (s.w * s.w) * u);
  };
  // Pass 1: K at the start, factored, with the hinge forces' right-hand side forward-substituted.
  const int n = static_cast<int>(rows_.size());
  ua0_.resize(rows_.size());
  ub0_.resize(rows_.size());
  const auto row = [&](int k, double* d, Mat2& u_prev, Vec2& rhs) HOT_INLINE {
    const Row& r = rows_[k];
    symmetric_row(k, ua0_, ub0_, d, u_prev);
    rhs = -(free_acceleration(r.a, ua0_[k]) - free_acceleration(r.b, ub0_[k]));
  };
  if (n > 0) {
    stats_.regularised_pivots += system_.factor_forward_symmetric<false>(n, row, mu_);
    factor_version_ = 0;  // only what backward() needs is kept: nothing may take system_ for a full factorisation
  }
  // Pass 2, backwards: each body's hinge forces once both its rows' are known, then its angular velocity and angle
  // (a free chain's first body: its whole pose) by symplectic Euler. The new state goes to the other buffer, which
  // then changes places with state_: the state before the step is kept without a copy (step()'s `before`).
  other_state_.resize(state_.size());
  const auto advance = [&](int i, Vec2 f, double tau, bool whole) HOT_INLINE {
    const Body& body = bodies_[i];
    const BodyState& o = state_[i];
    BodyState& s = other_state_[i];
    if (!(undamped && body.single_part)) {
      Vec2 f0;
      double tau0;
      free_force(i, f0, tau0);
      f += f0;
      tau += tau0;
    }
    s.w = o.w + h * body.inv_inertia * tau;
    const double dth = h * s.w;
    s.th = o.th + dth;
    s.q = (o.q * rotation_of_small_angle(dth)).renormalised();
    if (whole) {
      s.v = o.v + h * (body.inv_mass * f + (undamped && body.single_part ? g : Vec2::Zero()));
      s.x = o.x + h * s.v;
    }
  };
  if (n > 0)
    system_.backward(mu_, [&](int k) HOT_INLINE {
      const Row& r = rows_[k];
      Vec2 f;
      double tau;
      load_on_b(k, mu_.data(), ua0_.data(), ub0_.data(), f, tau);
      if (!bodies_[r.b].kinematic) advance(r.b, f, tau, false);
      if (records_impulse(r)) row_impulse_[k] += h * mu_[k];
    });
  // Each chain's first body, in its first row only: its whole pose unless the chain grows from its other end.
  for (const ReducedChain& c : reduced_chains_) {
    const Row& r = rows_[c.first];
    const Vec2& l = mu_[c.first];
    if (!bodies_[r.a].kinematic) advance(r.a, l, cross(ua0_[c.first], l), !c.from_end);
  }
  for (const int b : loose_bodies_) advance(b, Vec2::Zero(), 0.0, true);
  for (const int b : kinematic_bodies_) other_state_[static_cast<size_t>(b)] = state_[static_cast<size_t>(b)];
  state_.swap(other_state_);
  drive_kinematic(t1);  // the driven ends, where their drives are at the end
  // Pass 3: every other body where its hinge puts it, moving as its hinge moves, from each chain's first body on.
  const auto place = [&](BodyState& to, const Vec2& r_to, const BodyState& from, const Vec2& r_from) HOT_INLINE {
    const Vec2 p_from = from.q * r_from, p_to = to.q * r_to;
    to.x = (from.x + p_from) - p_to;
    to.v = (from.v + from.w * perp(p_from)) - to.w * perp(p_to);
  };
  for (const ReducedChain& c : reduced_chains_) {
    if (c.from_end) {
      for (int k = c.last; k >= c.first; --k) place(state_[rows_[k].a], rows_[k].ra, state_[rows_[k].b], rows_[k].rb);
    } else {
      for (int k = c.first; k <= c.last; ++k) place(state_[rows_[k].b], rows_[k].rb, state_[rows_[k].a], rows_[k].ra);
    }
  }
  t_ = t1;
  mark_state_changed();
}

void World::step_explicit(double h, bool rk4) {
  const double t0 = t_, t1 = t_ + h;
  const size_t nb = bodies_.size();
  drive_kinematic(t0);  // their accelerations enter the first stage
  if (!rk4) {
    constraint_accelerations(acc_lin_, acc_ang_, h, h);
    for (size_t b = 0; b < nb; ++b) {
      if (bodies_[b].kinematic) continue;
      BodyState& s = state_[b];
      s.x += h * s.v;
      s.th += h * s.w;
      s.q = (s.q * rotation_of_small_angle(h * s.w)).renormalised();
      s.v += h * acc_lin_[b];
      s.w += h * acc_ang_[b];
    }
    mark_state_changed();
  } else {
    // Classic RK4 on (x, theta, v, w); the rotation is composed from the start rotation so that q stays unit.
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
      constraint_accelerations(acc_lin_, acc_ang_, weight[stage], h);
      // Store the derivative of the stage: (dx, dth) = (v, w), (dv, dw) = (a, alpha), packed in a BodyState.
      k[stage].resize(nb);
      for (size_t b = 0; b < nb; ++b) {
        k[stage][b].x = state_[b].v;
        k[stage][b].th = state_[b].w;
        k[stage][b].v = acc_lin_[b];
        k[stage][b].w = acc_ang_[b];
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
  }
  drive_kinematic(t1);
  t_ = t1;
  // Post-stabilisation: back onto C(q) = 0 along the mass-metric normal, then onto G v = 0.
  if (options_.stabilization == Stabilization::Position) {
    start_anchors();
    factor_system(ua0_, ub0_);
    stats_.converged = solve_positions(ua0_, ub0_, 0.0);
  } else {
    stats_.residual = position_residual();  // what is left unprojected, for the statistics
  }
  if (options_.stabilization != Stabilization::None) project_velocities();
}

Snapshot World::save() const {
  if (dirty_) throw std::logic_error("save: the model has unbuilt hinges; call finalize() first");
  return {state_, forces_, t_, structure_, adaptive_h_};
}

void World::restore(const Snapshot& s) {
  if (s.structure != structure_) throw std::logic_error("restore: the snapshot belongs to another model structure");
  state_ = s.bodies;
  forces_ = s.forces;
  t_ = s.t;
  adaptive_h_ = s.adaptive_h;
  mark_state_changed();
}

double World::apply_impulse(int part, const Vec2& point, const Vec2& impulse) {
  ensure_built();
  if (part < 0 || part >= part_count()) throw std::invalid_argument("impulse: no such part " + std::to_string(part));
  if (!point.allFinite() || !impulse.allFinite()) throw std::invalid_argument("impulse: point and impulse must be finite");
  const int b = parts_[part].body;
  if (bodies_[b].kinematic) throw std::invalid_argument("impulse: the block is held and does not move freely");
  const double before = kinetic_energy();
  BodyState& s = state_[b];
  s.v += bodies_[b].inv_mass * impulse;
  s.w += bodies_[b].inv_inertia * cross(point - s.x, impulse);
  mark_motion_changed();
  project_velocities();
  return kinetic_energy() - before;
}

void World::add_force(int part, const Vec2& local_point, const Vec2& force, double until) {
  if (part < 0 || part >= part_count()) throw std::invalid_argument("force: no such part " + std::to_string(part));
  if (!local_point.allFinite() || !force.allFinite() || std::isnan(until))
    throw std::invalid_argument("force: point, force and end time must be finite");
  forces_.push_back({part, local_point, force, until});
}

}  // namespace ladder::core
