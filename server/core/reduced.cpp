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

namespace ladder::core {

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
    step_shake(h);
    return;
  }
  const double t1 = t_ + h;
  // The drives' accelerations at the start: always anew, since after a restore() work_.kin_acc holds a later time's.
  drive_kinematic(t_);
  // The free forces: gravity and damping inline, unless users' forces or hinge friction need the general sum. Without
  // damping a one-part body's is its weight alone.
  const bool general = options_.hinge_friction != 0 || !forces_.empty();
  const bool undamped = !general && options_.linear_damping == 0 && options_.angular_damping == 0;
  const Vec2 g = options_.gravity;
  if (general) accumulate_forces(work_.force, work_.torque, h);
  const double cl = options_.linear_damping, ca = options_.angular_damping;
  const auto free_force = [&](int i, Vec2& f, double& tau) HOT_INLINE {
    const Body& body = bodies_[i];
    if (general) {
      f = work_.force[i], tau = work_.torque[i];
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
    if (body.kinematic) return Vec2(work_.kin_acc[i] + work_.kin_alpha[i] * perp(u) - (s.w * s.w) * u);
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
    if (r.rolls) rhs -= rolling_acceleration(static_cast<size_t>(k));
  };
  if (n > 0) {
    stats_.regularised_pivots += system_.factor_forward_symmetric<false>(n, row, work_.mu);
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
    system_.backward(work_.mu, [&](int k) HOT_INLINE {
      const Row& r = rows_[k];
      Vec2 f;
      double tau;
      load_on_b(k, work_.mu.data(), ua0_.data(), ub0_.data(), f, tau);
      if (!bodies_[r.b].kinematic) advance(r.b, f, tau, false);
      if (records_impulse(r)) row_impulse_[k] += h * work_.mu[k];
    });
  // Each chain's first body, in its first row only: its whole pose unless the chain grows from its other end.
  for (const ReducedChain& c : reduced_chains_) {
    const Row& r = rows_[c.first];
    const Vec2& l = work_.mu[c.first];
    if (!bodies_[r.a].kinematic) advance(r.a, l, cross(ua0_[c.first], l), !c.from_end);
  }
  for (const int b : loose_bodies_) advance(b, Vec2::Zero(), 0.0, true);
  for (const int b : kinematic_bodies_) other_state_[static_cast<size_t>(b)] = state_[static_cast<size_t>(b)];
  state_.swap(other_state_);
  drive_kinematic(t1);  // the driven ends, where their drives are at the end
  // Pass 3: every other body where its hinge puts it, moving as its hinge moves, from each chain's first body on.
  // (A rolling row's levers reach its contact point, from both bodies' angles, which are final by now.)
  const auto place = [&](int k, bool to_a) HOT_INLINE {
    const Row& r = rows_[k];
    Vec2 ua, ub;
    row_levers(static_cast<size_t>(k), ua, ub);
    BodyState& to = state_[to_a ? r.a : r.b];
    const BodyState& from = state_[to_a ? r.b : r.a];
    const Vec2& p_from = to_a ? ub : ua;
    const Vec2& p_to = to_a ? ua : ub;
    to.x = (from.x + p_from) - p_to;
    to.v = (from.v + from.w * perp(p_from)) - to.w * perp(p_to);
  };
  for (const ReducedChain& c : reduced_chains_) {
    if (c.from_end) {
      for (int k = c.last; k >= c.first; --k) place(k, true);
    } else {
      for (int k = c.first; k <= c.last; ++k) place(k, false);
    }
  }
  t_ = t1;
  mark_state_changed();
}

}  // namespace ladder::core
