// Time stepping. A step is a short list of named stages; the integrator decides which.
//
//  symplectic_euler (SHAKE):  kick(h) -> drift(h) -> solve C(q1) = 0 (impulses enter v too) -> project velocities
//  rattle (velocity Verlet):  kick(h/2) -> drift(h) -> solve C(q1) = 0 -> kick(h/2) -> project velocities
//  euler (the paper's):       accelerations with hinge forces -> x += h v, v += h a -> project positions, velocities
//  rk4:                       4 stages of the same accelerations -> project positions, velocities
//  projection:                kick(h) -> drift(h) -> project onto C(q1) = 0 along G(q) at the current iterate
//                             (impulses enter v too) -> nothing more
//  midpoint (the default):    Newton on the hinge impulses and each body's turn: every hinge closed at the end,
//                             energy and momentum exact
//  reduced:                   hinge forces at the start (the index-1 solve) -> symplectic Euler in each chain's
//                             own coordinates (its first body's pose, then every body's angle) -> every other body
//                             placed and moved by its hinge: no constraint solve, the hinges hold by construction
//
// Each integrator's step is in its own file: shake.cpp (symplectic_euler, with the position stage RATTLE shares),
// rattle.cpp, projection.cpp, euler.cpp, rk4.cpp (the two explicit ones post-stabilised by constraints.cpp),
// reduced.cpp and midpoint.cpp. This file holds what they share: forces, drives, the fixed and adaptive steps, the
// work of a step, snapshots and impulses.
#include "core/world.hpp"
#include "core/fp_mode.hpp"
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
    case Integrator::Midpoint: return "midpoint";
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
                       Integrator::Projection, Integrator::Reduced, Integrator::Midpoint})
    if (s == to_string(i)) return i;
  throw std::invalid_argument("unknown integrator '" + s +
                              "' (expected euler, symplectic_euler, rattle, rk4, projection, reduced or midpoint)");
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
  work_.kin_acc.resize(nb);
  work_.kin_alpha.resize(nb);
  for (const int b : kinematic_bodies_) {
    BodyState& s = state_[b];
    const Part& p = parts_[bodies_[b].anchor_part];
    if (!p.drive) {  // held still
      s.v.setZero();
      s.w = 0;
      work_.kin_acc[b].setZero();
      work_.kin_alpha[b] = 0;
      continue;
    }
    const Kinematics k = p.drive(t);
    s.th = k.theta - p.rel_th;
    s.q = Rot::of(s.th);
    s.x = k.x - s.q * p.rel_x;
    const Vec2 d = s.x - k.x;
    s.w = k.omega;
    s.v = k.v + k.omega * perp(d);
    work_.kin_acc[b] = k.a + k.alpha * perp(d) - k.omega * k.omega * d;
    work_.kin_alpha[b] = k.alpha;
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
    accumulate_forces(work_.force, work_.torque, h);
    kick(h_kick, work_.force, work_.torque);
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
  const FlushSubnormals flush;  // (fp_mode.hpp)
  ensure_built();
  wake_threads();
  const bool whole = options_.adaptive && adaptive;
  // One reduced step leaves the state it started from in other_state_; anything else needs a copy first.
  const bool swapped = before && !whole && options_.integrator == Integrator::Reduced && reduced_applies();
  if (before) {
    before->forces = forces_;
    before->t = t_;
    before->structure = structure_;
    before->adaptive_h = adaptive_h_;
    before->force_steps = std::min(force_steps_, 1);  // the history is not kept (World::step in world.hpp)
    before->force_step_h = force_step_h_;
    before->guess_window_wait = guess_window_wait_;
    before->guess_window_backoff = guess_window_backoff_;
    before->hinge_forces_1.clear();
    before->hinge_forces_2.clear();
    if (split_chain()) {  // in the step's halves (in_halves)
      if (!swapped) before->bodies.resize(state_.size());
      before->hinge_forces.resize(hinge_force_.size());
      in_halves(state_.size(), [&](size_t from, size_t to, int) {
        if (!swapped) std::copy(state_.begin() + from, state_.begin() + to, before->bodies.begin() + from);
        const size_t rows = hinge_force_.size(), r0 = rows * from / state_.size(), r1 = rows * to / state_.size();
        std::copy(hinge_force_.begin() + r0, hinge_force_.begin() + r1, before->hinge_forces.begin() + r0);
      });
    } else {
      if (!swapped) before->bodies = state_;
      before->hinge_forces = hinge_force_;
    }
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
    case Integrator::Rattle:
    case Integrator::Midpoint: return 2;
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
    const double d = (state_[b].x - other[b].x).norm() + body.gyration * std::abs(state_[b].th - other[b].th);
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
// Sub-steps never go below h / 1024 (or the floor a caller set, set_adaptive_floor()): one that still misses the
// tolerance there is accepted (error_estimate and converged say so, and the step goes on to its end) unless it made a
// non-finite state, which is left for the caller's watchdog to undo.
// A trial costs three steps; the trial size is remembered from call to call (and in snapshots).
void World::step_adaptive(double h) {
  const double t_end = t_ + h, h_min = adaptive_floor_ > 0 ? std::min(adaptive_floor_, h) : h / 1024;
  const double tol = options_.error_tolerance;
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
    work_.whole = state_;
    restore(start);
    step_fixed(0.5 * s);
    StepStats halves = stats_;
    const bool first_ok = finite() && solved();
    if (first_ok) {
      step_fixed(t_end - t_ <= 0.5 * s * (1 + 1e-12) ? t_end - t_ : 0.5 * s);
      halves.add(stats_);
    }
    const bool halves_ok = first_ok && finite() && solved();
    const double err =
        whole_ok && halves_ok ? difference(work_.whole) / richardson : std::numeric_limits<double>::infinity();
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
    case Integrator::SymplecticEuler: step_shake(h); break;
    case Integrator::Rattle: step_rattle(h); break;
    case Integrator::Euler: step_euler(h); break;
    case Integrator::RK4: step_rk4(h); break;
    case Integrator::Projection: step_projection(h); break;
    case Integrator::Reduced: step_reduced(h); break;
    case Integrator::Midpoint: step_midpoint(h); break;  // its own exact work and dissipation
  }
  if (options_.integrator != Integrator::Midpoint) stats_.work = finish_work(t0, h);
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
    Vec2 ua, ub;
    row_levers(static_cast<size_t>(k), ua, ub);
    kinematic_v0_.push_back(point_velocity(s, a_kinematic ? ua : ub));
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
    Vec2 ua, ub;
    row_levers(static_cast<size_t>(kinematic_rows_[i]), ua, ub);
    const Vec2 v1 = point_velocity(s, a_kinematic ? ua : ub);
    const Vec2 j = row_impulse_[static_cast<size_t>(kinematic_rows_[i])];
    work += (a_kinematic ? -j : j).dot(0.5 * (kinematic_v0_[i] + v1));
  }
  return work;
}

Snapshot World::save() const {
  if (dirty_) throw std::logic_error("save: the model has unbuilt hinges; call finalize() first");
  return {state_, forces_, t_, structure_, adaptive_h_,
          hinge_force_, hinge_force_1_, hinge_force_2_, force_steps_, force_step_h_,
          guess_window_wait_, guess_window_backoff_};
}

void World::restore(const Snapshot& s) {
  if (s.structure != structure_) throw std::logic_error("restore: the snapshot belongs to another model structure");
  state_ = s.bodies;
  forces_ = s.forces;
  t_ = s.t;
  adaptive_h_ = s.adaptive_h;
  hinge_force_ = s.hinge_forces;
  if (s.hinge_forces_1.size() == s.hinge_forces.size() && s.hinge_forces_2.size() == s.hinge_forces.size()) {
    hinge_force_1_ = s.hinge_forces_1;
    hinge_force_2_ = s.hinge_forces_2;
  } else {  // a step's `before`: without the history (World::step), which starts again
    hinge_force_1_.assign(s.hinge_forces.size(), Vec2::Zero());
    hinge_force_2_.assign(s.hinge_forces.size(), Vec2::Zero());
  }
  force_steps_ = s.force_steps;
  force_step_h_ = s.force_step_h;
  guess_window_wait_ = s.guess_window_wait;
  guess_window_backoff_ = s.guess_window_backoff;
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
