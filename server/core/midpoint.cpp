// The energy-consistent midpoint step (Integrator::Midpoint). docs/model.md derives it; in short, per dynamic body
// with mass m, inertia I, centre x, velocity v, rotation q and spin w, and per hinge row k an impulse L_k (+L_k on
// its body a, -L_k on its body b, sigma = +1 / -1):
//
//   x+ = x + h vbar,                     vbar = (v + v+) / 2
//   q+ = q R(turn),   tan(turn / 2) = t,  t = h wbar / 2,  wbar = (w + w+) / 2      (the Cayley map)
//   m (v+ - v) = h (m g + F - c m vbar) + sum_k sigma L_k
//   I (w+ - w) = h (tau_F - beta wbar) + sum_k sigma lbar_k x L_k  + hinge friction
//   every hinge closed at the end: x_a+ + q_a+ r_a = x_b+ + q_b+ r_b
//
// where lbar = (q + q+) r / 2 is the lever at the midpoint. Because q+ r - q r = 2 t perp(lbar) exactly, each force's
// work over the step is F . (its point's displacement) exactly, and the hinge impulses, whose two points move
// alike, do none: E(t + h) - E(t) = (work of users' forces and drives) - (damping and friction) with no error but
// the solver's, for any h. Linear momentum is kept exactly; angular momentum too, since x_a + lbar_a = x_b + lbar_b
// at the midpoint of a step that starts and ends with the hinge closed. The method is symmetric, hence second order,
// and, like every midpoint rule, A-stable: a mode of frequency omega is seen at (2 / h) atan(h omega / 2) at any
// step, where SHAKE and the explicit methods need h omega < 2 (a long hanging chain's stiff rocking breaks that).
//
// The unknowns are each body's t and each row's L; vbar is linear in the L. Newton's method on the hinge closures,
// with each body's angular equation eliminated, gives one 2x2-block tridiagonal system per iteration (O(n), solved by
// BlockTridiag::factor_forward). Its Jacobian carries the geometric stiffness of the tensions (the term
// sigma (q+ r) . L in `jac`), which is what keeps the solve convergent for a long chain at a large step.
#include "core/world.hpp"
#include "core/hot_inline.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <type_traits>

namespace ladder::core {

namespace {

// 2 atan(t): the turn of a step whose half-angle tangent is t. A series for the common small t (the omitted
// t^13 / 13 term is below half an ulp of t for |t| <= 0.05), libm beyond.
double turn_of(double t) {
  if (!(std::abs(t) <= 0.05)) return 2 * std::atan(t);
  const double t2 = t * t;
  return 2 * t * (1 - t2 * (1.0 / 3 - t2 * (1.0 / 5 - t2 * (1.0 / 7 - t2 * (1.0 / 9 - t2 * (1.0 / 11))))));
}

// The rotation by 2 atan(t), exactly unit up to rounding.
Rot cayley(double t) {
  const double k = 1 / (1 + t * t);
  return {(1 - t * t) * k, 2 * t * k};
}

// Lever u (world frame, at the start) at the midpoint and at the end of a turn with half-angle tangent t.
struct Levers {
  Vec2 mid, end;
};
[[gnu::always_inline]] inline Levers levers(const Vec2& u, double t, double k) {  // k = 1 / (1 + t^2)
  const Vec2 pu = perp(u);
  return {k * (u + t * pu), k * ((1 - t * t) * u + (2 * t) * pu)};
}

// A rolling row's contact over the step (docs/model.md section 9): from its direction u0 at the start and its two
// bodies' half-angle tangents, the direction at the end u+ = u0 R(atan t_a + atan t_b) and kappa r ubar, the share
// of the contact offset that each body's midpoint lever carries (ubar = (u0 + u+) / 2): 2 r (u+ - u0) =
// 2 (t_a + t_b) perp(kappa r ubar) exactly, with kappa = 2 / (1 - t_a t_b + sqrt((1 + t_a^2)(1 + t_b^2))).
// And the slopes of kappa r ubar in t_a and t_b, for the Newton matrix:
// d u+ / d t_a = perp(u+) / (1 + t_a^2), d kappa / d t_a = -(kappa^2 / 2) (t_a (1 + t_b^2) / s - t_b) with s the
// square root above, and the same with a and b exchanged. ka and kb are 1 / (1 + t_a^2) and 1 / (1 + t_b^2). With
// kSlopes false the slopes are left out (a pass that measures the residual alone).
using Rolling = RollingTerms;  // world.hpp
template <bool kSlopes = true>
[[gnu::always_inline]] inline Rolling rolling(const Vec2& u0, double r, double ta, double tb, double ka, double kb) {
  const double s = std::sqrt((1 + ta * ta) * (1 + tb * tb)), c = 1 - ta * tb;
  const double q = 1 / (s * (c + s));  // one division for 1 / s and 2 / (c + s)
  const double inv = q * (c + s), kappa = 2 * q * s;
  const Vec2 turn(c * inv, (ta + tb) * inv);  // R(atan t_a + atan t_b)
  const Vec2 u1(turn.x() * u0.x() - turn.y() * u0.y(), turn.y() * u0.x() + turn.x() * u0.y());
  const Vec2 sum = u0 + u1;
  if constexpr (!kSlopes) {
    return {r * u1, (0.5 * kappa * r) * sum, Vec2::Zero(), Vec2::Zero()};
  } else {
    const Vec2 pu1 = perp(u1);
    const double half_kk = 0.5 * kappa * kappa;
    const double dka = half_kk * (tb - ta * (1 + tb * tb) * inv), dkb = half_kk * (ta - tb * (1 + ta * ta) * inv);
    return {r * u1, (0.5 * kappa * r) * sum, (0.5 * r) * (dka * sum + (kappa * ka) * pu1),
            (0.5 * r) * (dkb * sum + (kappa * kb) * pu1)};
  }
}

// rolling_newton: a rolling row's contact offset kappa r ubar turns with both of its bodies, so each body's angular
// residual depends on its neighbour's turn t as well as on its own: d rho_i / d t_j = -(h / 4 I_i) dmid_j x L_k
// (and the hinge friction's -(h / 4 I_i) 2 c_f, there with corner hinges too). The body-by-body elimination of the
// turns has no place for that term; leaving it out made Newton's method linear (ladder-bench's rolling ladders of
// 1000 blocks, at rest in the hand and tipped: 5.0 and 6.1 iterations a step, the corner hinge's 1.0 and 3.7). With a
// rolling row the step therefore keeps each row's body b's turn beside the row's impulse as unknowns, 3x3 blocks
// still tridiagonal along a chain (BlockTridiag3), with every derivative exact: the Newton matrix is the Jacobian.
// A chain's first body, when it moves, is eliminated into its first block exactly (it couples to nothing else).

// Newton-matrix coupling of a body's two rows through it: hbar I + e perp(end) perp(mid)^T.
[[gnu::always_inline]] inline Mat2 coupling(double ha, double e, const Vec2& end, const Vec2& mid) {
  const Vec2 pe = perp(end), pm = perp(mid);
  Mat2 m;
  m << ha + e * pe.x() * pm.x(), e * pe.x() * pm.y(), e * pe.y() * pm.x(), ha + e * pe.y() * pm.y();
  return m;
}

}  // namespace

// The angular residual (times the radius of gyration) is driven this much below the hinge tolerance: a residual left
// there is a systematic error of the spin, which the energy would show as a drift. A solve whose angular residuals are
// below the tolerance itself but no longer fall by kStall per iteration has converged as far as it will: a body whose
// turn stiffness is floored (below) converges only linearly, and rounding stops every body somewhere (measured: 189
// of 2000 steps of a whipping 10 000-block chain ended 20 iterations at 1e-15 m and were reported as failed solves).
constexpr double kRhoShare = 1e-4;
constexpr double kStall = 0.25;
// An iterate within this factor of the tolerance is expected to be the last (Newton's convergence is quadratic).
constexpr double kNearlyThere = 1e3;
constexpr double kEpsilon = 0x1p-52;
// Newton's corrections of a turn are limited to kMaxTurnChange in t = tan(turn / 2) per iteration (about 0.2 rad), and
// t itself to kMaxT (a quarter turn in one step, far beyond any motion a step resolves). Far from the solution the
// full correction can overshoot into turns of many radians, where the Cayley map's levers fold back and the
// iteration never returns (measured: t = 1e3 to 1e4 within a few iterations in the whip of a 10 000-block chain at
// 1 ms); near it the corrections are far below the limits, so the convergence is Newton's.
constexpr double kMaxTurnChange = 0.1;
constexpr double kMaxT = 1;
constexpr double kJacFloor = 0.05;  // the floor of a body's turn stiffness (finish_body)
// A solve still short after solver.max_iterations is rescued (step_midpoint, rescue_guess below): within kNearGap of
// closing the hinges, by kExactIterations more iterations of the exact Newton; farther, by Newton again from the
// solution of shorter steps from the same start (a homotopy in the step's length: kRescueFirst, then kRescueSecond,
// as shares of h), and last by kLongIterations more from where that left it, the turn stiffness floored as after each
// homotopy (the exact Newton of a near try just before diverged there). (Measured at a step of the whipping
// 10 000-block chain whose Newton cycled for 30 iterations: with 200 allowed, the steps of 0.990 to 1.015 ms from the
// same start every 0.001 ms all converged, in 10 to 150 iterations.)
constexpr double kNearGap = 1e-6;
constexpr int kExactIterations = 10;
constexpr int kLongIterations = 200;
constexpr std::array<double, 2> kRescueFirst = {0.5, 0.8};
constexpr std::array<double, 5> kRescueSecond = {0.25, 0.5, 0.7, 0.85, 0.95};
// A Newton correction so small that what it leaves is known without measuring it (newton_remainder below): the step
// ends there when the remainder's bound is below kRemainderShare of the hinge tolerance and kSpinRemainderShare of the
// angular one. The gaps are measured at the end state all the same; the angular residual is not, so its share is
// what makes the bound's claim safe (the bound is taken twice already), and 1/4 is enough: with 1/100 a rolling
// ladder of 10 000 blocks at rest never ended on the bound (its turn corrections of 1.5e-12 times impulse corrections
// of 2e-4 N s at the top put the bound at 1.6e-17 m against a line of 1e-18 m) and paid a pass a step to measure it.
constexpr double kRemainderShare = 1e-2;
constexpr double kSpinRemainderShare = 0.25;
constexpr double kInfinity = std::numeric_limits<double>::infinity();
// A window of a chain (docs/model.md section 3.1). A Newton pass measures where its rows short of the tolerances (a gap
// beyond it by more than rounding, or a body's angular residual above its line) lie. When they lie in one stretch
// that, with kWindowMargin rows and a quarter of its length more on each side, is at most kWindowShare of the rows
// (the front of a whip or a ripple: the rest of the chain met its tolerances at the first guess), and the pass was an
// exact Newton step (no turn stiffness floored, no correction limited: near the solution), the next passes solve that
// window alone, as a system of its own, holding the impulses and turns outside it. A row outside depends on the
// window only through a body it shares with the window's first or last row, so each window pass measures the two
// rows beyond its edges too. What the opening pass's correction left of the outside rows' residuals is bounded as
// newton_remainder bounds a whole step's, and a converged window ends the step as a step that ends on that bound does
// (every gap measured at the end state); when the bound is not small enough, one whole pass measures every row
// first. A window's own last correction, when it was exact and near, is bounded as a whole step's too (with the two
// impulses beyond its edges, which its first and last bodies' angular equations hold), and the two rows beyond its
// edges are then measured at the end iterate: within the tolerances, the step ends without the window pass that would
// have measured that iterate, on the same bits (window_edges_within below). (Opened from inexact passes too, windows
// changed which iterate a whipping chain's cycling solves were rescued from, and one step of the 10 000-block free
// chain was redone in halves.) Corner hinges without hinge friction, users' forces or free bodies only (a rolling
// contact's or the friction's terms reach a body's neighbour's turn), and chains of at least kWindowMinRows rows.
constexpr int kWindowMinRows = 256, kWindowMargin = 32;
constexpr double kWindowShare = 0.25;
// A window from the first guess (docs/model.md section 3.1): where the guess met the tolerances everywhere but in one
// short stretch (the free chain's whip: the rows above its front), the step solves that window from the guess, after a
// pass that measures the guess's residual alone, and takes no whole Newton step. Against a window opened after a whole
// pass, that costs the check (a third of a whole pass) and about two window passes more (the 10 000-block free chain:
// five window passes a step instead of three), and saves the whole pass: measured, it pays with windows of up to
// kWindowShare of the rows, as the others. Where the window's solution opens the rows beyond its edges (a tipped
// ladder: the tip changes the tension down the whole chain), whole passes must follow, and the try has cost the check
// and the window's passes. A step tries when the last try succeeded; after a failed one (whole passes after the
// window, or a check that found no window) it waits 1, 2, 4, ... steps, up to kGuessWindowWait, before the next.
// Whether a step tries changes its bits, so the wait is saved in snapshots with the first guess
// (World::guess_window_wait_).
constexpr int kGuessWindowWait = 64;
// A chain of at least World::kSplitRows rows is solved in two halves, one from each end (BlockTridiag's twisted use),
// on two threads when the World may use them (Options::threads): each Newton pass then takes about half the time.
// Shorter ones gain less than a hand-over costs. The halves are the same whether or not they run concurrently, so a
// step's bits do not depend on the threads; they differ from the one-sided elimination's in rounding only.

namespace {
// What a pass over the rows measures (per lane: the two halves of a split pass keep their own, merged after). A cache
// line each: the two lanes update theirs at every row, and sharing a line made the two threads' caches pass it back
// and forth all through a pass.
struct alignas(64) PassAcc {
  double worst_rho = 0, worst_gap2 = 0, largest_gap2 = 0;  // the residuals (finish_body, count_gap)
  double fine_rho = 0;  // a check's worst angular residual of the bodies within their line (window_from_guess)
  bool exact = true;                                       // newton_remainder's: no floored or limited turn
  double dt_max = 0, cross_max = 0, lam_max2 = 0;          // its tracked corrections, the largest impulse
  int pivots = 0;                                          // regularised pivots
  int bad_lo = std::numeric_limits<int>::max(), bad_hi = -1;  // the first and last rows short of the tolerances
  // Rows lo to hi marked when `bad`, by selects rather than a branch (the residuals it tests lie near their lines).
  void mark_if(bool bad, int lo, int hi) {
    bad_lo = std::min(bad_lo, bad ? lo : std::numeric_limits<int>::max());
    bad_hi = std::max(bad_hi, bad ? hi : -1);
  }
  void merge(const PassAcc& o) {
    worst_rho = std::max(worst_rho, o.worst_rho);
    fine_rho = std::max(fine_rho, o.fine_rho);
    worst_gap2 = std::max(worst_gap2, o.worst_gap2);
    largest_gap2 = std::max(largest_gap2, o.largest_gap2);
    exact = exact && o.exact;
    dt_max = std::max(dt_max, o.dt_max);
    cross_max = std::max(cross_max, o.cross_max);
    lam_max2 = std::max(lam_max2, o.lam_max2);
    pivots += o.pivots;
    bad_lo = std::min(bad_lo, o.bad_lo);
    bad_hi = std::max(bad_hi, o.bad_hi);
  }
};
// The order a pass visits the rows in: from the top (a row finishes its body b, and body a at a chain's start) or from
// the bottom (its body a, and body b at a chain's end).
using FromTop = std::integral_constant<int, 0>;
using FromBottom = std::integral_constant<int, 1>;
}  // namespace

namespace {
// Room for `count` elements in v, its pages touched (written with `value`); v keeps its size and contents.
template <class T>
void touch(std::vector<T>& v, size_t count, const T& value) {
  if (v.capacity() >= count) return;
  const size_t size = v.size();
  v.resize(count, value);
  v.resize(size);
}
}  // namespace

void World::reserve_step() {
  if (options_.integrator != Integrator::Midpoint) return;
  MidpointWork& m = mid_;
  const size_t nb = bodies_.size(), n = rows_.size();
  for (std::vector<double>* v : {&m.t, &m.kt, &m.rho, &m.inv_jac, &m.alpha, &m.beta, &m.spin_gain, &m.damp,
                                 &m.stiff_coef, &m.lift})
    touch(*v, nb, 0.0);
  for (std::vector<Vec2>* v : {&m.vbar, &m.vfree}) touch(*v, nb, Vec2(Vec2::Zero()));
  for (std::vector<Vec2>* v : {&m.lam, &m.dlam, &m.mid_a, &m.mid_b, &m.end_a, &m.end_b, &ua0_, &ub0_, &hinge_force_,
                               &hinge_force_1_, &hinge_force_2_})
    touch(*v, n, Vec2(Vec2::Zero()));
  if (newton_.size() != static_cast<int>(n)) newton_.resize(static_cast<int>(n));
}

void World::reserve_snapshot(Snapshot& s) const {
  touch(s.bodies, state_.size(), state_.empty() ? BodyState{} : state_.front());
  touch(s.hinge_forces, rows_.size(), Vec2(Vec2::Zero()));
}

void World::step_midpoint(double h) {
  MidpointWork& m = mid_;
  const double t0 = t_, t1 = t_ + h;
  const size_t nb = bodies_.size(), n = rows_.size();
  const Vec2 g = options_.gravity;
  const double cl = options_.linear_damping, ca = options_.angular_damping, cf = options_.hinge_friction;

  // An error this step did not make (a join, the leftover of a restructure) is projected away first, positions only,
  // as SHAKE does: the midpoint would turn it into a velocity of error / h.
  if (position_residual() > options_.tolerance) {
    start_anchors();
    factor_system(ua0_, ub0_);
    solve_positions(ua0_, ub0_, 0.0);
  }
  // The driven bodies move to their poses at the end; what they were at the start serves the work and the friction.
  // A rolling row's contact direction at the start (before the drives move their bodies), unless the last step's
  // end measured it (a predicted end, below) and nothing has moved or changed since.
  if (has_rolling_ && !(m.roll_u0_version == state_version_ && m.roll_u0_structure == structure_ &&
                        m.roll_u0.size() == n)) {
    m.roll_u0.resize(n);
    in_halves(n, [&](size_t from, size_t to, int) HOT_INLINE {
      for (size_t k = from; k < to; ++k)
        if (rows_[k].rolls) m.roll_u0[k] = roll_direction(k);
    });
  }
  m.kinematic_start.clear();
  for (const int b : kinematic_bodies_) m.kinematic_start.push_back(state_[static_cast<size_t>(b)]);
  m.kinematic_anchor.clear();  // the kinematic rows' driven anchors at the start
  for (const int k : kinematic_rows_) {
    const Row& r = rows_[static_cast<size_t>(k)];
    const bool ak = bodies_[r.a].kinematic;
    const BodyState& s = state_[ak ? r.a : r.b];
    m.kinematic_anchor.push_back(s.x + s.q * (ak ? r.ra : r.rb));
  }
  drive_kinematic(t1);

  // Per body: the constants of the step (kept while the bodies, h and the damping stay: constants_key) and the first
  // guess t = h w / 2.
  const MidpointWork::BodyConstantsKey constants_key{structure_, h, cl, ca};
  const bool constants_kept = m.constants_key == constants_key && m.alpha.size() == nb && m.beta.size() == nb &&
                              m.spin_gain.size() == nb && m.damp.size() == nb;
  m.t.resize(nb);
  m.rho.resize(nb);
  m.inv_jac.resize(nb);
  m.spin_gain.resize(nb);
  m.damp.resize(nb);
  m.alpha.resize(nb);
  m.beta.resize(nb);
  m.vbar.resize(nb);
  m.vfree.resize(nb);
  m.kt.resize(nb);  // 1 / (1 + t^2)
  const double quarter_h = 0.25 * h, half_h = 0.5 * h, inv_damped = 1 / (2 + h * cl), inv_h = 1 / h;
  // A long chain's passes run in two halves (World::kSplitRows), and so do the step's loops over the bodies and the
  // rows (in_halves).
  const int split = split_chain() ? static_cast<int>(n) / 2 : 0;
  lanes_.set_parallel(options_.threads >= 2);
  const auto halves = [&](size_t count, auto&& fn) { in_halves(count, fn); };
  double lane_max[2] = {0, 0};  // the largest h / (4 I) times the radius of gyration (newton_remainder), per lane
  const auto start_bodies = [&](auto compute_constants) HOT_INLINE {
    halves(nb, [&](size_t from, size_t to, int l) HOT_INLINE {
      for (size_t b = from; b < to; ++b) {
        const Body& body = bodies_[b];
        const BodyState& s = state_[b];
        if (body.kinematic) {
          m.alpha[b] = 0;
          m.vbar[b] = Vec2::Zero();
          continue;
        }
        if constexpr (decltype(compute_constants)::value) {
          // Damping: -c m vbar on the centre and -beta wbar on the spin, the exact sum of each part's -c m_p v_p and
          // -c_a I_p w (the parts' centres average to the body's).
          m.beta[b] = cl * (body.inertia - body.own_inertia) + ca * body.own_inertia;
          m.spin_gain[b] = quarter_h * body.inv_inertia;  // h / (4 I)
          lane_max[l] = std::max(lane_max[l], m.spin_gain[b] * body.gyration);
          m.damp[b] = 1 + (half_h * m.beta[b]) * body.inv_inertia;
          m.alpha[b] = body.inv_mass * inv_damped;  // 1 / (m (2 + h c))
        }
        // vbar - v without the hinges (kept as a difference: its rounding is then that of the change, not of v).
        m.vfree[b] = m.alpha[b] * ((h * body.mass) * (g - cl * s.v));
        m.t[b] = 0.5 * h * s.w;
        m.kt[b] = 1 / (1 + m.t[b] * m.t[b]);  // kept beside every t (turn_by)
      }
    });
  };
  if (constants_kept) {
    start_bodies(std::false_type{});
  } else {
    start_bodies(std::true_type{});
    m.constants_key = constants_key;
    m.spin_gyration = std::max(lane_max[0], lane_max[1]);
  }
  const double spin_gyration = m.spin_gyration;
  // The driven bodies' turns over the step, for the hinge friction against them: t = tan(turn / 2).
  for (size_t i = 0; i < kinematic_bodies_.size(); ++i) {
    const size_t b = static_cast<size_t>(kinematic_bodies_[i]);
    const Rot rel = m.kinematic_start[i].q.inverse() * state_[b].q;
    m.t[b] = rel.s / (1 + rel.c);
    m.kt[b] = 1 / (1 + m.t[b] * m.t[b]);
  }
  // The users' forces, as impulses over the step at their start levers (world frame).
  m.force_lever.clear();
  for (const AppliedForce& af : forces_) {
    const Part& p = parts_[static_cast<size_t>(af.part)];
    m.force_lever.push_back(state_[static_cast<size_t>(p.body)].q * (p.rel_x + p.rel_q * af.local));
    if (bodies_[p.body].kinematic) continue;
    m.vfree[p.body] += (m.alpha[p.body] * h) * af.over_step(t0, h);
  }

  // Per row: the impulses start from the mean forces of the last steps (first_force; hinge_force_ and its history,
  // part of the state, so that a redone step, a resumed log and a re-simulation take the same bits); the levers at
  // the start.
  m.lam.resize(n);
  if (hinge_force_.size() != n || hinge_force_1_.size() != n || hinge_force_2_.size() != n) {
    hinge_force_.assign(n, Vec2::Zero());
    hinge_force_1_.assign(n, Vec2::Zero());
    hinge_force_2_.assign(n, Vec2::Zero());
    force_steps_ = 0;
  }
  // The first guess of a row's mean force over the step, from the last three steps' F0 (the last), F1 and F2, when
  // they are steps of this length: F0 + F1 - F2, the next value of a sequence a + b n + c (-1)^n through them. A
  // constant or steadily changing force is predicted exactly, as by F0, and so is a force that alternates from step
  // to step: the midpoint rule maps a hinge chain's stiff modes (h omega >> 2) to near h Omega = pi, undamped, so a
  // chain at rest or swinging slowly carries them at the level of its solve's rounding and each stop short of exact,
  // and F0 alone is off by twice their amplitude every step (a held ladder of 10 000 blocks: its velocities
  // alternate in sign at 2e-9 m/s, and its hinges open by 5e-12 m at F0's guess, beyond the 1e-12 m tolerance). A
  // mode z^n with z = exp(i theta) is predicted with the error |z - 1|^2 |z + 1| against F0's |z - 1|: far less near
  // theta = 0 and theta = pi, at most 2x more in between (docs/benchmarks.md, "Seventh round": 2.23 to 2.0
  // iterations a step on a tipped 10 000-block ladder, 0.94 to 0.71 on a held one).
  const bool history = force_steps_ >= 3 && force_step_h_ == h;
  const auto first_force = [&](size_t k) HOT_INLINE -> Vec2 {
    return hinge_force_[k] + (hinge_force_1_[k] - hinge_force_2_[k]);
  };
  m.mid_a.resize(n);
  m.mid_b.resize(n);
  m.end_a.resize(n);
  m.end_b.resize(n);
  m.dlam.resize(n);
  // The arc-centre levers (a plain hinge's whole levers; a rolling row's contact offset is added per iterate):
  // dynamic sides at the start, driven sides at the end.
  ua0_.resize(n);
  ub0_.resize(n);
  // The longest arc-centre lever and contact radius (newton_remainder): a rolling contact's offset adds at most
  // twice its radius to a lever.
  // (The maxima in locals, stored once: in the lanes' array, side by side, the two threads would write one cache line
  // at every row, and each row's stores would make them a chain through memory.)
  double lane_lever2[2] = {0, 0}, lane_radius[2] = {0, 0};
  halves(n, [&](size_t from, size_t to, int l) HOT_INLINE {
    double lever2 = 0, radius = 0;
    for (size_t k = from; k < to; ++k) {
      m.lam[k] = h * (history ? first_force(k) : hinge_force_[k]);
      ua0_[k] = state_[rows_[k].a].q * rows_[k].ra;
      ub0_[k] = state_[rows_[k].b].q * rows_[k].rb;
      lever2 = std::max({lever2, ua0_[k].squaredNorm(), ub0_[k].squaredNorm()});
      if (rows_[k].rolls) radius = std::max(radius, roll_[k].radius);
    }
    lane_lever2[l] = lever2;
    lane_radius[l] = radius;
  });
  const double lever =
      std::sqrt(std::max(lane_lever2[0], lane_lever2[1])) + 2 * std::max(lane_radius[0], lane_radius[1]);
  if (rescuing_ && seed_scale_ > 0) apply_seed(seed_scale_);  // a rescue's later stage (rescue_guess)
  anchors_version_ = 0;       // not the current state's (the driven bodies have moved)

  const double tol = options_.tolerance;
  StepStats& st = stats_;
  st.converged = false;
  const bool forced = !forces_.empty();
  if (forced) {
    m.force_ang.resize(nb);
    m.force_stiff.resize(nb);
  }
  m.stiff_coef.resize(nb);
  m.lift.resize(nb);
  // The exact Newton (3x3 blocks, every turn an unknown): always with rolling rows, and otherwise as a rescue's end
  // game (below).
  bool three = false;
  const auto make_exact = [&] {
    three = true;
    m.roll.resize(n);
    m.jac.resize(nb);
    m.couple_ab.resize(n);
    m.couple_ba.resize(n);
  };
  if (has_rolling_) make_exact();
  // What this iteration's Newton step was (newton_remainder) is gathered per lane (PassAcc): its Jacobian exact (no
  // turn stiffness floored, no correction limited) and, when it is tracked, its largest turn correction and the
  // largest product of a body's turn correction and its rows' impulse corrections (their 1-norms).
  // A long chain's passes are split (World::kSplitRows): rows [0, split) from the top on lane 0, [split, n) from the
  // bottom on lane 1. The body the two middle rows share (`skip`, when it moves) is finished before the halves start
  // and corrected by lane 0, so that each lane writes only its own rows' and bodies' terms.
  int skip = -1;
  if (split > 0) {
    const Row& r = rows_[static_cast<size_t>(split)];
    if (r.link_prev && !bodies_[r.a].kinematic) skip = r.a;
    if (three) m.newton3.resize(static_cast<int>(n));
    else if (newton_.size() != static_cast<int>(n)) newton_.resize(static_cast<int>(n));
    if (three) m.dx.resize(n);
  }
  // The rows whose rolling contacts each half of a split pass finds (roll_rows); the shared body's two rows' are
  // found before the halves start, as the body is finished then.
  const int top_end = skip >= 0 ? split - 1 : split, bottom_start = skip >= 0 ? split + 1 : split;
  PassAcc lane[2];
  // A dynamic body's vbar - v at the current impulses of its rows (`prev`, `next` as finish_body's).
  const auto mean_velocity = [&](int i, int prev, int next) HOT_INLINE {
    Vec2 lin = Vec2::Zero();
    if (prev >= 0) lin -= m.lam[prev];
    if (next >= 0) lin += m.lam[next];
    m.vbar[i] = m.vfree[i] + m.alpha[i] * lin;
  };
  // One body's residual and Newton terms at the current iterate, from its rows: `prev` the row whose body b it is
  // (or -1), `next` the row whose body a it is (or -1). Stores the levers of those rows on its side. `newton`
  // (std::true_type or std::false_type): whether the Newton terms are wanted too, or the residual alone (a pass that
  // only checks whether the iterate is the answer; if it is not, a full pass follows and computes them). A rolling
  // row's contact terms are read from m.roll, which every pass fills ahead of the rows that read them (roll_rows).
  const auto finish_body = [&](int i, int prev, int next, PassAcc& acc, auto newton) HOT_INLINE {
    constexpr bool kNewton = decltype(newton)::value;
    const double ti = m.t[i], k = m.kt[i];
    double ang = 0, stiff = 0, friction_rows = 0, ang_abs = 0;  // ang_abs: the size of its terms, for rounding
    // With rolling rows (rolling_newton above): sum of dmid_i x L over them, and dmid_j x L per row.
    double own_roll = 0, couple_prev = 0, couple_next = 0;
    if (prev >= 0) {
      const Vec2& l = m.lam[prev];
      Levers v = levers(ub0_[prev], ti, k);
      stiff -= v.end.dot(l);  // the arc centre's lever (a rolling contact's share is own_roll)
      if (rows_[prev].rolls) {
        const Rolling& c = m.roll[prev];
        v.mid -= c.mid;
        v.end -= c.end;
        if constexpr (kNewton) {
          own_roll += cross(c.dmid_b, l);
          couple_prev = cross(c.dmid_a, l);
        }
      }
      m.mid_b[prev] = v.mid;
      m.end_b[prev] = v.end;
      ang -= cross(v.mid, l);
      ang_abs += std::abs(cross(v.mid, l));
      if (cf != 0) {  // the friction impulse h cf (wbar_b - wbar_a) on a, its opposite on b; wbar = 2 t / h
        ang -= 2 * cf * (ti - m.t[rows_[prev].a]);
        friction_rows += 1;
      }
    }
    if (next >= 0) {
      const Vec2& l = m.lam[next];
      Levers v = levers(ua0_[next], ti, k);
      stiff += v.end.dot(l);
      if (rows_[next].rolls) {
        const Rolling& c = m.roll[next];
        v.mid += c.mid;
        v.end += c.end;
        if constexpr (kNewton) {
          own_roll += cross(c.dmid_a, l);
          couple_next = cross(c.dmid_b, l);
        }
      }
      m.mid_a[next] = v.mid;
      m.end_a[next] = v.end;
      ang += cross(v.mid, l);
      ang_abs += std::abs(cross(v.mid, l));
      if (cf != 0) {
        ang += 2 * cf * (m.t[rows_[next].b] - ti);
        friction_rows += 1;
      }
    }
    if (forced) {
      ang += m.force_ang[i];
      ang_abs += std::abs(m.force_ang[i]);
      stiff += m.force_stiff[i];
    }
    const double c = m.spin_gain[i], damp = m.damp[i];
    mean_velocity(i, prev, next);
    const double rho = ti * damp - 0.5 * h * state_[i].w - c * ang;
    m.rho[i] = rho;
    if constexpr (kNewton) {
      // Floored: a hinge pushed hard enough would make it vanish, and Newton then takes the floor's direction
      // instead of a singular one (the answer is the same; the iteration's path is not).
      const double jac = damp + c * (stiff * k + 2 * cf * friction_rows - own_roll);
      if (!(jac >= kJacFloor)) acc.exact = false;
      if (three) {  // the exact Newton's terms (rolling_newton above); 1 / jac only where a body is eliminated (row3)
        m.jac[i] = jac;
        if (prev >= 0) m.couple_ba[prev] = -c * (couple_prev + 2 * cf);
        else m.inv_jac[i] = 1 / std::max(jac, kJacFloor);
        if (next >= 0) m.couple_ab[next] = -c * (couple_next + 2 * cf);
      } else {
        const double inv_jac = 1 / std::max(jac, kJacFloor);
        m.inv_jac[i] = inv_jac;
        m.stiff_coef[i] = 2 * c * k * inv_jac;
        m.lift[i] = 2 * k * rho * inv_jac;
      }
    }
    // What rounding alone leaves of rho: a few ulps of its largest terms (a long chain's tension puts moments of
    // several N m s on each block that cancel to a small net turn).
    const double floor = 8 * kEpsilon * (std::abs(ti * damp) + 0.5 * h * std::abs(state_[i].w) + c * ang_abs);
    const double rho_excess = std::max(std::abs(rho) - floor, 0.0) * bodies_[i].gyration;
    acc.worst_rho = std::isfinite(rho_excess) ? std::max(acc.worst_rho, rho_excess) : kInfinity;
    const bool short_rho = !(rho_excess <= kRhoShare * tol);  // (a window's bounds: below; a select, as count_gap's)
    const int hi = std::max(prev, next), lo = std::min(prev, next) >= 0 ? std::min(prev, next) : hi;  // (its rows)
    acc.mark_if(short_rho && hi >= 0, lo, hi);
    if constexpr (!kNewton) acc.fine_rho = std::max(acc.fine_rho, short_rho ? 0.0 : rho_excess);  // (window_from_guess)
  };
  // A body's turn moved by Newton's correction dt, limited (kMaxTurnChange, kMaxT).
  // With `track` (std::true_type) it records what newton_remainder needs; dl is the sum of the 1-norms of the
  // impulse corrections of the body's rows.
  const auto turn_by = [&](int i, double dt, auto track, double dl, PassAcc& acc) HOT_INLINE {
    const double t = std::clamp(m.t[i] + std::clamp(dt, -kMaxTurnChange, kMaxTurnChange), -kMaxT, kMaxT);
    if constexpr (decltype(track)::value) {
      if (t != m.t[i] + dt) acc.exact = false;  // limited (or not finite)
      acc.dt_max = std::max(acc.dt_max, std::abs(dt));
      acc.cross_max = std::max(acc.cross_max, std::abs(dt) * dl);
    }
    m.t[i] = t;
    m.kt[i] = 1 / (1 + t * t);
  };
  // A body's correction once its rows' are known: dt = (-rho + h / (4 I) sum sigma mid x dL) / jac.
  const auto correct_body = [&](int i, int prev, int next, auto track, PassAcc& acc) HOT_INLINE {
    double dang = 0, dl = 0;
    if (prev >= 0) dang -= cross(m.mid_b[prev], m.dlam[prev]);
    if (next >= 0) dang += cross(m.mid_a[next], m.dlam[next]);
    if constexpr (decltype(track)::value) {
      if (prev >= 0) dl += m.dlam[prev].cwiseAbs().sum();
      if (next >= 0) dl += m.dlam[next].cwiseAbs().sum();
    }
    turn_by(i, (-m.rho[i] + m.spin_gain[i] * dang) * m.inv_jac[i], track, dl, acc);
  };
  reduced_applies();  // (once per structure) loose_bodies_: the dynamic bodies in no hinge
  double last_rho = kInfinity, final_gap = 0;
  int limit = options_.max_iterations;  // this solve's last iteration (a rescue extends it)
  int far_rescues = 0;  // the far rescues tried: from shorter steps (kRescueFirst, then kRescueSecond), then long
  bool predicted = false;  // the step ended on newton_remainder's bound: its gaps are measured at the end state
  // A window: rows [win_lo, win_hi] solved alone while the others hold (kWindowShare above); -1 when passes are whole.
  const bool may_window =
      options_.windows && !has_rolling_ && !forced && cf == 0 && loose_bodies_.empty() &&
      static_cast<int>(n) >= kWindowMinRows;
  // Whether this step tries a window from its first guess (below), which the first pass then checks.
  const bool try_guess_window = may_window && !rescuing_ && guess_window_wait_ == 0;
  // A hinge gap between the points pa and pb, counted into the largest gap and, less what rounding alone leaves of it
  // (a few ulps of the positions: 6 km down a chain of 100 000 blocks they are 1e-12 m), into the worst excess. An
  // excess beyond the tolerance marks row k short (PassAcc::mark_if: a window's bounds), unless `marks` is
  // std::false_type (the end state's measure, which no window reads). No branch on the gap: at rest the gaps lie about
  // the tolerance and their rounding floor, and tests that skipped the square root of the gaps within either went
  // either way at random (callgrind's branch model: 1.6 million mispredictions in 300 steps of a held ladder of 10 000
  // blocks at rest; docs/benchmarks.md, "The rest regression found"). The excess's positive part is taken by
  // arithmetic for the same reason: GCC compiled std::max(excess, 0.0) after the square root as a branch (0.6 million
  // of the same run's mispredictions). But in a step that tries a window from its first guess (a free chain's whip,
  // step after step: the tries back off at rest) most gaps are far below the worst so far and the tolerance, and
  // there a branch that skips them is well predicted and saves their floor and square root (`skip_within`; a gap no
  // larger than the worst so far nor than the tolerance leaves the worst excess and the marks as they are, its excess
  // being at most the gap; a NaN gap is always measured): the same values either way (the 10 000-block free chain: 7 %
  // of its time).
  const auto count_gap = [tol, skip_within = try_guess_window](const Vec2& gap, const Vec2& pa, const Vec2& pb,
                                                                PassAcc& acc, int k, auto marks) HOT_INLINE {
    const double gap2 = gap.squaredNorm();
    acc.largest_gap2 = std::max(acc.largest_gap2, gap2);
    if (skip_within && gap2 <= acc.worst_gap2 && gap2 <= tol * tol) return;
    const double floor = 8 * kEpsilon * (pa.cwiseAbs().maxCoeff() + pb.cwiseAbs().maxCoeff());
    const double over = std::sqrt(gap2) - floor;
    const double excess = 0.5 * (over + std::abs(over));  // max(over, 0.0) (but a zero's sign), NaN kept
    acc.worst_gap2 = std::isfinite(excess) ? std::max(acc.worst_gap2, excess * excess) : kInfinity;
    if constexpr (decltype(marks)::value) acc.mark_if(!(excess <= tol), k, k);
  };
  bool expect_converged = m.guess_odds.expect_right() || try_guess_window;
  int win_lo = -1, win_hi = -1;
  bool window_used = false;  // at most one window a step
  PassAcc edge;              // what a window pass measures of the two rows beyond its edges
  // A bound of the angular residual the rows outside the window are left with (kInfinity: none, and a whole pass
  // measures them once the window has converged).
  double outside_rho = kInfinity;
  // Whether a pass measured every row and body it saw within the tolerances.
  const auto within = [&](const PassAcc& a) {
    return !(std::sqrt(a.worst_gap2) > tol) && !(a.worst_rho > kRhoShare * tol);
  };
  // The window a pass's measure opens, or false (kWindowShare).
  const auto open_window = [&](const PassAcc& a) {
    if (!may_window || window_used || three || a.bad_hi < 0) return false;
    const int width = a.bad_hi - a.bad_lo + 1, margin = kWindowMargin + width / 4;
    const int lo = std::max(a.bad_lo - margin, 0), hi = std::min(a.bad_hi + margin, static_cast<int>(n) - 1);
    if (hi - lo + 1 > kWindowShare * static_cast<double>(n)) return false;
    win_lo = lo, win_hi = hi;
    window_used = true;
    return true;
  };
  // A window from the step's first guess (docs/model.md section 3.1, kGuessWindowWait): when the check of the guess
  // finds the rows short of the tolerances in one short stretch, that window is solved alone from the guess, and the
  // rows outside it, which the check found within their tolerances, are left as they are: no whole Newton step and no
  // bound (outside_rho is what the check measured). It fails when whole passes must follow (the window's solution
  // opens the rows beyond its edges: a change of tension that runs down the whole chain).
  bool guess_window = false, whole_after_window = false;
  const auto window_from_guess = [&](const PassAcc& a) {
    if (!try_guess_window || !(a.worst_gap2 < kInfinity) || !(a.worst_rho < kInfinity) || !open_window(a))
      return false;
    outside_rho = a.fine_rho;
    last_rho = a.worst_rho;
    ++st.guess_windows;
    return guess_window = true;
  };
  for (int iteration = 0;; ++iteration) {
    lane[0] = lane[1] = PassAcc{};
    if (forced) {  // the users' forces' moments at their midpoint levers, and their loads along the end levers
      std::fill(m.force_ang.begin(), m.force_ang.end(), 0.0);
      std::fill(m.force_stiff.begin(), m.force_stiff.end(), 0.0);
      for (size_t f = 0; f < forces_.size(); ++f) {
        const AppliedForce& af = forces_[f];
        const int b = parts_[static_cast<size_t>(af.part)].body;
        if (bodies_[b].kinematic) continue;
        const Vec2 j = h * af.over_step(t0, h);
        const Levers v = levers(m.force_lever[f], m.t[b], m.kt[b]);
        m.force_ang[b] += cross(v.mid, j);
        m.force_stiff[b] += v.end.dot(j);
      }
    }
    if (expect_converged)
      for (const int b : loose_bodies_) finish_body(b, -1, -1, lane[0], std::false_type{});
    // Row k's bodies finished and its gap measured. From the top (side FromTop): body a at a chain's start, body b
    // always, with its next row's side when it has one. From the bottom: body b at a chain's end, body a always, with
    // its previous row's side.
    const auto residual_row = [&](int k, PassAcc& acc, auto newton, auto side) HOT_INLINE {
      const Row& r = rows_[static_cast<size_t>(k)];
      const bool ak = bodies_[r.a].kinematic, bk = bodies_[r.b].kinematic;
      // (a driven side's levers enter no angular equation: only its end point counts)
      const auto driven_a = [&] { m.mid_a[k] = m.end_a[k] = r.rolls ? Vec2(ua0_[k] + m.roll[k].end) : ua0_[k]; };
      const auto driven_b = [&] { m.mid_b[k] = m.end_b[k] = r.rolls ? Vec2(ub0_[k] - m.roll[k].end) : ub0_[k]; };
      if constexpr (decltype(side)::value == FromTop::value) {
        if (ak) {
          driven_a();
        } else if (!r.link_prev) {
          finish_body(r.a, -1, k, acc, newton);
        }
        if (bk)
          driven_b();
        else if (r.b != skip)
          finish_body(r.b, k, r.shares_next ? k + 1 : -1, acc, newton);
      } else {
        if (bk) {
          driven_b();
        } else if (!r.shares_next) {
          finish_body(r.b, k, -1, acc, newton);
        }
        if (ak)
          driven_a();
        else if (r.a != skip)
          finish_body(r.a, r.link_prev ? k - 1 : -1, k, acc, newton);
      }
      const BodyState& a = state_[r.a];
      const BodyState& b = state_[r.b];
      const Vec2 pa = ak ? Vec2(a.x + m.end_a[k]) : Vec2(a.x + h * (a.v + m.vbar[r.a]) + m.end_a[k]);
      const Vec2 pb = bk ? Vec2(b.x + m.end_b[k]) : Vec2(b.x + h * (b.v + m.vbar[r.b]) + m.end_b[k]);
      const Vec2 gap = pa - pb;
      count_gap(gap, pa, pb, acc, k, std::true_type{});
      return gap;
    };
    // The same, then the row's Newton blocks, for BlockTridiag's factorisation.
    const auto row = [&](int k, Mat2& d, Mat2& lower, Mat2& u_prev, Vec2& rhs, PassAcc& acc, auto side)
        HOT_INLINE {
      const Vec2 gap = residual_row(k, acc, std::true_type{}, side);
      const Row& r = rows_[static_cast<size_t>(k)];
      const bool ak = bodies_[r.a].kinematic, bk = bodies_[r.b].kinematic;
      // A dL = -gap + sum_i sigma lift_i perp(end_i), with A_kj = sum over the bodies i of rows k and j of
      // sigma_ik sigma_ij (h alpha_i I + e_i perp(end_ik) perp(mid_ij)^T).
      const double ha = ak ? 0.0 : h * m.alpha[r.a], ea = ak ? 0.0 : m.stiff_coef[r.a];
      const double hb = bk ? 0.0 : h * m.alpha[r.b], eb = bk ? 0.0 : m.stiff_coef[r.b];
      d = coupling(ha, ea, m.end_a[k], m.mid_a[k]) + coupling(hb, eb, m.end_b[k], m.mid_b[k]);
      rhs = -gap;
      if (!ak) rhs += m.lift[r.a] * perp(m.end_a[k]);
      if (!bk) rhs -= m.lift[r.b] * perp(m.end_b[k]);
      if (r.link_prev) {  // the shared body: b of row k - 1, a of row k
        lower = -coupling(ha, ea, m.end_a[k], m.mid_b[k - 1]);
        u_prev = -coupling(ha, ea, m.end_b[k - 1], m.mid_a[k]);
      } else {
        lower.setZero();
        u_prev.setZero();
      }
    };
    // With rolling rows, row k's 3x3 blocks in the unknowns (dL_k, dt_b(k)) (rolling_newton above): its gap's and its
    // body b's angular residual's derivatives; a driven body b's turn is fixed (an identity row). A chain's first
    // body, when it moves, is eliminated: dt_a = (-rho_a + c_a perp(mid_a) . dL_k - couple_ab dt_b) / jac_a.
    const auto row3 = [&](int k, Mat3& d, Coupling3& cp, Vec3& rhs, PassAcc& acc, auto side) HOT_INLINE {
      const Vec2 gap = residual_row(k, acc, std::true_type{}, side);
      const Row& r = rows_[static_cast<size_t>(k)];
      const bool ak = bodies_[r.a].kinematic, bk = bodies_[r.b].kinematic;
      const double ha = ak ? 0.0 : h * m.alpha[r.a], hb = bk ? 0.0 : h * m.alpha[r.b];
      const Vec2 slope_a = (2 * m.kt[r.a]) * perp(m.end_a[k]);    // d gap / d t_a
      const Vec2 slope_b = (-2 * m.kt[r.b]) * perp(m.end_b[k]);   // d gap / d t_b
      d.setZero();
      d(0, 0) = d(1, 1) = ha + hb;
      rhs << -gap, 0.0;
      if (bk) {
        d(2, 2) = 1;
      } else {
        d.block<2, 1>(0, 2) = slope_b;
        d.block<1, 2>(2, 0) = m.spin_gain[r.b] * perp(m.mid_b[k]).transpose();
        d(2, 2) = m.jac[r.b];
        rhs(2) = -m.rho[r.b];
      }
      if (r.link_prev) {  // body a is the previous row's body b: its turn is the previous block's third unknown
        cp.l = cp.u = -ha;
        cp.s = slope_a;
        cp.g = bk ? 0.0 : m.couple_ba[k];
        cp.p = -m.spin_gain[r.a] * perp(m.mid_a[k]);
        cp.e = bk ? 0.0 : m.couple_ab[k];
        return;
      }
      cp = Coupling3{};
      if (!ak) {
        const double inv = m.inv_jac[r.a];
        const Vec3 col(slope_a.x(), slope_a.y(), bk ? 0.0 : m.couple_ba[k]);
        Vec3 w;
        w << (m.spin_gain[r.a] * inv) * perp(m.mid_a[k]), bk ? 0.0 : -m.couple_ab[k] * inv;
        d.noalias() += col * w.transpose();
        rhs += (m.rho[r.a] * inv) * col;
      }
    };
    // The rolling contacts (rolling()) of rows [from, to), with their slopes for a Newton pass (`slopes`,
    // std::true_type) or without them for a pass that measures the residual alone, found before the pass reads them:
    // their square root and division, which every term of a row waits for, then overlap from row to row (their
    // inputs, the turns, are fixed through a pass).
    const auto roll_rows = [&](int from, int to, auto slopes) HOT_INLINE {
      for (int k = from; k < to; ++k) {
        const Row& r = rows_[static_cast<size_t>(k)];
        if (r.rolls)
          m.roll[k] = rolling<decltype(slopes)::value>(m.roll_u0[k], roll_[k].radius, m.t[r.a], m.t[r.b], m.kt[r.a],
                                                       m.kt[r.b]);
      }
    };
    // The rows' 3x3 blocks over rows [first, last), their contacts found kRollChunk rows at a time ahead of the rows
    // that read them (a row's bodies read its own and, from the top, the next row's; from the bottom, the previous
    // row's): the chunk is still in the cache when it is read.
    constexpr int kRollChunk = 64;
    const auto rows3_down = [&](int first, int last, PassAcc& acc) HOT_INLINE {
      return [&, first, last](int k, auto&&... a) HOT_INLINE {
        if (has_rolling_ && (k - first) % kRollChunk == 0)
          roll_rows(k == first ? k : k + 1, std::min(k + kRollChunk + 1, last), std::true_type{});
        return row3(k, a..., acc, FromTop{});
      };
    };
    const auto rows3_up = [&](int first, int last, PassAcc& acc) HOT_INLINE {
      return [&, first, last](int k, auto&&... a) HOT_INLINE {
        if (has_rolling_ && (last - 1 - k) % kRollChunk == 0)
          roll_rows(std::max(k - kRollChunk, first), k == last - 1 ? last : k, std::true_type{});
        return row3(k, a..., acc, FromBottom{});
      };
    };
    // The Newton pass: each row's blocks built, factored and forward-substituted, in one pass or two halves.
    const auto newton_pass = [&] {
      const int rows = static_cast<int>(n);
      if (split == 0) {
        const auto top = [&](auto&&... a) HOT_INLINE { return row(a..., lane[0], FromTop{}); };
        lane[0].pivots += three ? m.newton3.factor_forward(rows, rows3_down(0, rows, lane[0]), m.dx)
                                : newton_.factor_forward(rows, top, m.dlam);
        return;
      }
      // (the shared body's two rows' contacts first: it is finished before the halves)
      if (has_rolling_ && skip >= 0) roll_rows(split - 1, split + 1, std::true_type{});
      if (skip >= 0) finish_body(skip, split - 1, split, lane[0], std::true_type{});
      lanes_.run([&](int l) {
        if (l == 0) {
          const auto top = [&](auto&&... a) HOT_INLINE { return row(a..., lane[0], FromTop{}); };
          lane[0].pivots += three ? m.newton3.factor_down(split, rows3_down(0, top_end, lane[0]), m.dx)
                                  : newton_.factor_down(split, top, m.dlam);
        } else {
          const auto bottom = [&](auto&&... a) HOT_INLINE { return row(a..., lane[1], FromBottom{}); };
          lane[1].pivots += three ? m.newton3.factor_up(split, rows, rows3_up(bottom_start, rows, lane[1]), m.dx)
                                  : newton_.factor_up(split, rows, bottom, m.dlam);
        }
      });
      lane[0].pivots += three ? m.newton3.meet(split, m.dx) : newton_.meet(split, m.dlam);
    };
    // When this iterate is likely the answer (the last one was within a few orders of the tolerance, or the step's
    // first guess has good odds: MidpointWork::GuessOdds), the residual alone is measured first, and the Newton blocks
    // only if it falls short: a pass with a third to a half of the arithmetic of a full one. Either way the same
    // values are computed.
    bool checked = false;
    // A window's pass: its rows built, factored and forward-substituted as a system of their own (its edge rows'
    // neighbours outside are held: their corrections are zero), with the two rows beyond its edges measured.
    const auto window_pass = [&] {
      if (newton_.size() != static_cast<int>(n)) newton_.resize(static_cast<int>(n));
      ++st.window_passes;
      st.window_lo = win_lo, st.window_hi = win_hi;
      const int saved_skip = std::exchange(skip, -1);  // (a whole pass's split plays no part)
      edge = PassAcc{};
      if (win_lo > 0) {
        m.dlam[static_cast<size_t>(win_lo - 1)].setZero();
        residual_row(win_lo - 1, edge, std::true_type{}, FromTop{});
        const Row& r = rows_[static_cast<size_t>(win_lo)];  // its body b, the first row's body a, is the window's
        if (r.link_prev && !bodies_[r.a].kinematic)
          finish_body(r.a, win_lo - 1, win_lo, lane[0], std::true_type{});
      }
      const auto top = [&](auto&&... a) HOT_INLINE { return row(a..., lane[0], FromTop{}); };
      lane[0].pivots += newton_.factor_down(win_hi + 1, top, m.dlam, win_lo);
      if (win_hi + 1 < static_cast<int>(n)) {
        m.dlam[static_cast<size_t>(win_hi + 1)].setZero();
        residual_row(win_hi + 1, edge, std::false_type{}, FromTop{});
      }
      skip = saved_skip;
    };
    // After a window's correction that ends on its bound, the two rows beyond its edges, which the correction does not
    // solve (their impulses are held, the window's first and last bodies turn), are measured at the end iterate as the
    // next window pass would measure them (its first and last bodies' angular residuals with them), and the step ends
    // as that pass would end it: on the same iterate, without the pass.
    const auto window_edges_within = [&] {
      const int saved_skip = std::exchange(skip, -1);
      edge = PassAcc{};
      if (win_lo > 0) residual_row(win_lo - 1, edge, std::false_type{}, FromTop{});
      if (win_hi + 1 < static_cast<int>(n)) {
        const Row& r = rows_[static_cast<size_t>(win_hi + 1)];
        if (r.link_prev && !bodies_[r.a].kinematic)
          finish_body(r.a, win_hi, win_hi + 1, edge, std::false_type{});
        residual_row(win_hi + 1, edge, std::false_type{}, FromTop{});
      }
      skip = saved_skip;
      return within(edge);
    };
    const bool windowed = win_lo >= 0;
    if (windowed) {
      window_pass();
    } else if (expect_converged) {
      if (split == 0) {
        if (has_rolling_) roll_rows(0, static_cast<int>(n), std::false_type{});
        PassAcc acc;  // (a local, merged after: not a lane of the array the other passes reach through references)
        for (int k = 0; k < static_cast<int>(n); ++k) residual_row(k, acc, std::false_type{}, FromTop{});
        lane[0].merge(acc);
      } else {
        if (has_rolling_ && skip >= 0) roll_rows(split - 1, split + 1, std::false_type{});
        if (skip >= 0) finish_body(skip, split - 1, split, lane[0], std::false_type{});
        lanes_.run([&](int l) {
          if (has_rolling_)
            roll_rows(l == 0 ? 0 : bottom_start, l == 0 ? top_end : static_cast<int>(n), std::false_type{});
          PassAcc acc;  // (as above)
          if (l == 0)
            for (int k = 0; k < split; ++k) residual_row(k, acc, std::false_type{}, FromTop{});
          else
            for (int k = static_cast<int>(n) - 1; k >= split; --k)
              residual_row(k, acc, std::false_type{}, FromBottom{});
          lane[l].merge(acc);
        });
      }
      lane[0].merge(lane[1]);
      checked = within(lane[0]);
      ++st.checks;
      if (!checked) {
        ++st.short_checks;
        if (iteration == 0 && window_from_guess(lane[0])) continue;
        lane[0] = lane[1] = PassAcc{};
      }
    }
    if (!checked && !windowed) {
      for (const int b : loose_bodies_) finish_body(b, -1, -1, lane[0], std::true_type{});
      if (n > 0) newton_pass();
      whole_after_window = guess_window;
      lane[0].merge(lane[1]);
      lane[1] = PassAcc{};
    }
    st.regularised_pivots += lane[0].pivots;
    lane[0].pivots = 0;
    const double worst_rho = lane[0].worst_rho;
    const double worst_gap = std::sqrt(lane[0].worst_gap2);
    st.residual = std::sqrt(lane[0].largest_gap2);
    st.angular_residual = worst_rho;
    const bool stalled = worst_rho > kStall * last_rho;
    last_rho = worst_rho;
    // Converged (a body whose turn stiffness is floored may end at the tolerance itself: kStall).
    const bool settled = !(worst_gap > tol) && (!(worst_rho > kRhoShare * tol) || (!(worst_rho > tol) && stalled));
    if (windowed) {
      if (settled || !std::isfinite(worst_gap) || !std::isfinite(worst_rho) || iteration >= limit) {
        win_lo = win_hi = -1;  // whole passes again (or the rescue's, below)
        const bool edges = within(edge);
        if (settled && edges && outside_rho < kInfinity) {  // the rows outside, on the bound
          predicted = true;  // (the gaps are measured at the end state, below)
          st.angular_residual = std::max({worst_rho, edge.worst_rho, outside_rho});
          break;
        }
        if (settled) {  // every row measured once more (the residual alone if the edges' rows were within tolerance)
          expect_converged = edges;
          continue;
        }
      }
    }
    if (settled) {
      st.converged = true;
      final_gap = worst_gap;
      break;
    }
    if (!std::isfinite(worst_gap) || !std::isfinite(worst_rho)) break;
    if (iteration >= limit) {
      // Rescue (docs/model.md section 3.1). Near: the exact Newton from this iterate (a body whose turn stiffness is
      // floored converges only linearly). Far: Newton cycled; it starts again from the solution of a shorter step.
      if (worst_gap <= kNearGap) {
        if (three) break;  // (the exact Newton already: rounding, or a tolerance out of reach, stops it)
        make_exact();
        if (split > 0) m.newton3.resize(static_cast<int>(n)), m.dx.resize(n);
        limit = iteration + kExactIterations;
      } else if (!rescuing_ && far_rescues < 3) {
        // Twice from shorter steps' solutions; the third time on from here, for Newton wanders out of its cycle in
        // the end (kLongIterations).
        if (far_rescues == 0) rescue_guess(h, kRescueFirst.data(), kRescueFirst.size());
        if (far_rescues == 1) rescue_guess(h, kRescueSecond.data(), kRescueSecond.size());
        limit = iteration + (far_rescues < 2 ? options_.max_iterations + 1 : kLongIterations);
        ++far_rescues;
        if (!has_rolling_) three = false;  // (from far the floored Newton fares better than the exact one)
      } else {
        break;
      }
      ++st.rescues;
      last_rho = kInfinity;
      expect_converged = false;
      continue;  // (this iterate's terms are found again, with the exact Newton's or at the new guess)
    }
    expect_converged = worst_gap < kNearlyThere * tol && worst_rho < kNearlyThere * tol;
    // Back-substitution: each row's correction, and each body's as soon as its rows' are known. When the iterate was
    // close (as expect_converged), the corrections' sizes are tracked for newton_remainder, and what the step needs
    // if it ends there is found on the way (final_row): the largest impulse, and the bodies' mean velocities at the
    // final impulses, as finish_body computes them. From the top the rows run backwards (row k + 1's impulse is final
    // by row k); from the bottom, forwards (row k - 1's is).
    const auto final_row = [&](int k, PassAcc& acc, auto side) HOT_INLINE {
      const Row& r = rows_[static_cast<size_t>(k)];
      acc.lam_max2 = std::max(acc.lam_max2, m.lam[k].squaredNorm());
      if constexpr (decltype(side)::value == FromTop::value) {
        if (!bodies_[r.b].kinematic) mean_velocity(r.b, k, r.shares_next ? k + 1 : -1);
        if (!r.link_prev && !bodies_[r.a].kinematic) mean_velocity(r.a, -1, k);
      } else {
        if (!bodies_[r.a].kinematic && r.a != skip) mean_velocity(r.a, r.link_prev ? k - 1 : -1, k);
        if (!r.shares_next && !bodies_[r.b].kinematic) mean_velocity(r.b, k, -1);
      }
    };
    // Row k's correction applied: its impulse (but row `split`'s, applied at the meeting) and the turns of the bodies
    // that are final by then.
    const auto done2 = [&](int k, auto track, PassAcc& acc, auto side) HOT_INLINE {
      constexpr bool kTrack = decltype(track)::value;
      const Row& r = rows_[static_cast<size_t>(k)];
      if (split == 0 || k != split || windowed) m.lam[k] += m.dlam[k];
      if constexpr (decltype(side)::value == FromTop::value) {
        if (!bodies_[r.b].kinematic) correct_body(r.b, k, r.shares_next ? k + 1 : -1, track, acc);
        if (!r.link_prev && !bodies_[r.a].kinematic) correct_body(r.a, -1, k, track, acc);
      } else {
        if (!bodies_[r.a].kinematic && r.a != skip) correct_body(r.a, r.link_prev ? k - 1 : -1, k, track, acc);
        if (!r.shares_next && !bodies_[r.b].kinematic) correct_body(r.b, k, -1, track, acc);
      }
      if constexpr (kTrack) final_row(k, acc, side);
    };
    const auto done3 = [&](int k, auto track, PassAcc& acc, auto side) HOT_INLINE {
      constexpr bool kTrack = decltype(track)::value;
      constexpr bool kTop = decltype(side)::value == FromTop::value;
      const Row& r = rows_[static_cast<size_t>(k)];
      const Vec3& x = m.dx[k];
      if (split == 0 || k != split) m.lam[k] += x.head<2>();
      double dl = 0;
      if constexpr (kTrack) dl = x.head<2>().cwiseAbs().sum();
      const bool bk = bodies_[r.b].kinematic;
      if (!r.link_prev && !bodies_[r.a].kinematic)
        turn_by(r.a, (-m.rho[r.a] + m.spin_gain[r.a] * perp(m.mid_a[k]).dot(x.head<2>()) -
                      (bk ? 0.0 : m.couple_ab[k] * x(2))) * m.inv_jac[r.a], track, dl, acc);
      if constexpr (kTop) {  // row k + 1's correction, the other of body b's rows, is known
        double dl_next = 0;
        if constexpr (kTrack)
          if (r.shares_next) dl_next = m.dx[k + 1].head<2>().cwiseAbs().sum();
        if (!bk) turn_by(r.b, x(2), track, dl + dl_next, acc);
      } else {  // body b's turn waits for row k + 1 when it has one; body a's (row k - 1's b) is due now
        if (!bk && !r.shares_next) turn_by(r.b, x(2), track, dl, acc);
        if (r.link_prev && r.a != skip && !bodies_[r.a].kinematic) {
          double dl_prev = 0;
          if constexpr (kTrack) dl_prev = m.dx[k - 1].head<2>().cwiseAbs().sum();
          turn_by(r.a, m.dx[k - 1](2), track, dl_prev + dl, acc);
        }
      }
      if constexpr (kTrack) final_row(k, acc, side);
    };
    // The window opening after this pass (`opening`): the corrections of the rows outside it are tracked apart
    // (`out`), for the bound of what they leave.
    bool opening = false;
    PassAcc out[2];
    // (`open`: std::true_type when opening, so that the other passes' rows take their lane without a test)
    const auto region = [&](int k, int l, auto open) HOT_INLINE -> PassAcc& {
      if constexpr (decltype(open)::value) return k < win_lo || k > win_hi ? out[l] : lane[l];
      return lane[l];
    };
    const auto update = [&](auto track, auto open) HOT_INLINE {
      if (windowed) {  // the window's rows, and its first row's body a (a whole pass corrects it with the row before)
        newton_.backward(m.dlam, [&](int k) HOT_INLINE { done2(k, track, lane[0], FromTop{}); }, win_hi + 1, win_lo);
        const Row& r = rows_[static_cast<size_t>(win_lo)];
        if (r.link_prev && !bodies_[r.a].kinematic) {
          correct_body(r.a, win_lo - 1, win_lo, track, lane[0]);
          if constexpr (decltype(track)::value) mean_velocity(r.a, win_lo - 1, win_lo);
        }
      } else if (n > 0 && split == 0) {
        if (three)
          m.newton3.backward(m.dx, [&](int k) HOT_INLINE { done3(k, track, lane[0], FromTop{}); });
        else
          newton_.backward(m.dlam, [&](int k) HOT_INLINE { done2(k, track, region(k, 0, open), FromTop{}); });
      } else if (n > 0) {
        // The shared body's turn needs row split's impulse final (lane 0 corrects it): applied first.
        m.lam[split] += three ? Vec2(m.dx[split].head<2>()) : m.dlam[split];
        lanes_.run([&](int l) {
          if (l == 0) {
            if (three)
              m.newton3.backward(m.dx, [&](int k) HOT_INLINE { done3(k, track, lane[0], FromTop{}); }, split);
            else
              newton_.backward(
                  m.dlam, [&](int k) HOT_INLINE { done2(k, track, region(k, 0, open), FromTop{}); }, split);
          } else {
            if (three)
              m.newton3.downward(split, m.dx, [&](int k) HOT_INLINE { done3(k, track, lane[1], FromBottom{}); });
            else
              newton_.downward(split, m.dlam,
                               [&](int k) HOT_INLINE { done2(k, track, region(k, 1, open), FromBottom{}); });
          }
        });
      }
      for (const int b : loose_bodies_) {
        correct_body(b, -1, -1, track, lane[0]);
        if constexpr (decltype(track)::value) mean_velocity(b, -1, -1);
      }
    };
    // lane[0] still holds this iterate's exact (a floored turn stiffness); the tracking starts afresh.
    lane[0].dt_max = lane[0].cross_max = lane[0].lam_max2 = 0;
    // A window opens after a whole Newton pass whose rows short of the tolerances lie in one short stretch
    // (kWindowShare above), its corrections tracked for the bound of what they leave outside it.
    opening = !windowed && !checked && lane[0].exact && open_window(lane[0]);
    // A window's correction is tracked too when the rows outside it are bounded: the step may end on its bound (below).
    const bool track = (expect_converged && lane[0].exact && !forced && (cf == 0 || three) &&
                        (!windowed || outside_rho < kInfinity)) ||
                       opening;
    if (opening)
      update(std::true_type{}, std::true_type{});
    else if (track)
      update(std::true_type{}, std::false_type{});
    else
      update(std::false_type{}, std::false_type{});
    lane[0].merge(lane[1]);
    if (opening) {  // the bound of the rows outside alone; then the whole pass's (below), which may end the step
      out[0].merge(out[1]);
      const PassAcc& o = out[0];
      if (!(lane[0].exact && o.exact)) {  // a correction limited: far from the solution, no window (see above)
        win_lo = win_hi = -1;
        window_used = false;
      } else {
        const double gap_bound = 2 * 10.6 * lever * o.dt_max * o.dt_max;
        const double rho_bound =
            2 * spin_gyration * lever * (10.6 * std::sqrt(o.lam_max2) * o.dt_max * o.dt_max + 1.5 * o.cross_max);
        if (gap_bound <= kRemainderShare * tol && rho_bound <= kSpinRemainderShare * kRhoShare * tol)
          outside_rho = rho_bound;
      }
      lane[0].merge(o);  // (o holds tracked corrections alone)
    }
    const bool exact = lane[0].exact;
    const double dt_max = lane[0].dt_max, cross_max = lane[0].cross_max;
    double lam_max2 = lane[0].lam_max2;
    if (windowed) {  // the window's first and last bodies' rows outside it (their impulses are held)
      if (win_lo > 0) lam_max2 = std::max(lam_max2, m.lam[static_cast<size_t>(win_lo - 1)].squaredNorm());
      if (win_hi + 1 < static_cast<int>(n))
        lam_max2 = std::max(lam_max2, m.lam[static_cast<size_t>(win_hi + 1)].squaredNorm());
    }
    ++st.iterations;
    // newton_remainder: after an exact Newton step what is left of the residual is the equations' second-order
    // remainder in the correction: the gaps and vbar are linear in the impulses, the levers are the Cayley map's of
    // the turns. Let dt be the largest turn correction, L the longest lever with a rolling contact's 2 r added,
    // |d end / d t| <= 2 |u| and |d^2 end / d t^2| <= 5.3 |u| for |t| <= 1 (a contact's offset turns with both of
    // its bodies, each by atan t: its slopes and curvatures are below r times those), mid = (u + end) / 2, and two
    // rows a body. A gap (two turns, each by at most dt) moves by at most (5.3 L / 2) (2 dt)^2 = 10.6 L dt^2 beyond its
    // linear part; a body's angular residual times its radius of gyration, through its rows' moments (h / 4I) mid x L,
    // by at most (h / 4I) rg (2 (2.65 L / 2) (2 dt)^2 |L| + 1.5 L X) with X = cross_max: (the slope of mid in the
    // turns times the change of the turns) times (the change of the impulse) over the body's rows, a neighbour's turn
    // included through a rolling contact. Both bounds are taken twice; when they are kRemainderShare and
    // kSpinRemainderShare of the tolerances, the pass that would measure this iterate would find it converged, and it
    // is not run: the gaps are measured at the end state instead (below; a few operations a row instead of the pass's
    // levers and residuals).
    if (track && exact) {
      const double gap_bound = 2 * 10.6 * lever * dt_max * dt_max;
      const double rho_limit = kSpinRemainderShare * kRhoShare * tol;
      if (gap_bound <= kRemainderShare * tol && 2 * spin_gyration * lever * 1.5 * cross_max <= rho_limit) {
        const double rho_bound =
            2 * spin_gyration * lever * (10.6 * std::sqrt(lam_max2) * dt_max * dt_max + 1.5 * cross_max);
        if (rho_bound <= rho_limit && (!windowed || window_edges_within())) {
          predicted = true;
          st.angular_residual = windowed ? std::max({rho_bound, edge.worst_rho, outside_rho}) : rho_bound;
          break;
        }
      }
    }
  }
  m.guess_odds.record(st.iterations == 0);
  if (may_window && !rescuing_) {  // the wait before the next window from a guess (kGuessWindowWait)
    if (!try_guess_window) {
      --guess_window_wait_;
    } else if (guess_window && !whole_after_window) {
      guess_window_wait_ = guess_window_backoff_ = 0;
    } else if (st.iterations > 0) {  // (a right guess tells nothing)
      guess_window_backoff_ = std::min(std::max(2 * guess_window_backoff_, 1), kGuessWindowWait);
      guess_window_wait_ = guess_window_backoff_;
    }
  }

  // Work and dissipation of the step, exactly as the scheme accounts them, and the end of the step. The sums keep
  // this order (the bodies' dissipation, then the hinge friction's; the friction's work, the users' forces', the
  // drives'), but the bodies' dissipation and their end are one pass: a force's work, which needs its body's start
  // velocity, is found before it.
  m.force_work.clear();
  for (size_t i = 0; i < forces_.size(); ++i) {
    const AppliedForce& af = forces_[i];
    const int b = parts_[static_cast<size_t>(af.part)].body;
    if (bodies_[b].kinematic) continue;
    const Levers v = levers(m.force_lever[i], m.t[b], m.kt[b]);
    m.force_work.push_back(af.over_step(t0, h).dot(h * (state_[b].v + m.vbar[b]) + (v.end - m.force_lever[i])));
  }
  double lane_dissipated[2] = {0, 0};
  halves(nb, [&](size_t from, size_t to, int l) HOT_INLINE {
    double d = 0;
    for (size_t b = from; b < to; ++b) {
      const Body& body = bodies_[b];
      if (body.kinematic) continue;
      BodyState& s = state_[b];
      const double t = m.t[b];
      const Vec2& vbar = m.vbar[b];
      const double wbar = 2 * t * inv_h;
      d += h * (cl * body.mass * (s.v + vbar).squaredNorm() + m.beta[b] * wbar * wbar);
      s.x += h * (s.v + vbar);
      s.v += 2 * vbar;
      s.w = 4 * t * inv_h - s.w;
      s.q = (s.q * cayley(t)).renormalised();
      s.th += turn_of(t);
    }
    lane_dissipated[l] = d;
  });
  double work = 0, dissipated = split == 0 ? lane_dissipated[0] : lane_dissipated[0] + lane_dissipated[1];
  if (cf != 0)
    for (const Row& r : rows_) {
      const double wa = 2 * m.t[r.a] * inv_h, wb = 2 * m.t[r.b] * inv_h;
      const bool ak = bodies_[r.a].kinematic, bk = bodies_[r.b].kinematic;
      if (ak && bk) continue;
      dissipated += h * cf * (wb - wa) * (wb - wa);
      if (ak) work += h * cf * wa * (wa - wb);  // the drive's share: what its turn does through the friction
      if (bk) work += h * cf * wb * (wb - wa);
    }
  for (const double w : m.force_work) work += w;
  for (size_t i = 0; i < kinematic_rows_.size(); ++i) {  // (the driven bodies were at their end poses already)
    const size_t k = static_cast<size_t>(kinematic_rows_[i]);
    const Row& r = rows_[k];
    const bool ak = bodies_[r.a].kinematic;
    const BodyState& s = state_[ak ? r.a : r.b];
    Vec2 moved = s.x + s.q * (ak ? r.ra : r.rb) - m.kinematic_anchor[i];
    if (r.rolls) {  // and the driven side's share of the contact's roll, 2 t perp(kappa r ubar) (a) or minus it (b)
      const Rolling c = rolling<false>(m.roll_u0[k], roll_[k].radius, m.t[r.a], m.t[r.b], m.kt[r.a], m.kt[r.b]);
      moved += (ak ? 2 * m.t[r.a] : -2 * m.t[r.b]) * perp(c.mid);
    }
    work += (ak ? -m.lam[k] : m.lam[k]).dot(moved) / h;  // the impulse over h is the mean force
    row_impulse_[k] = m.lam[k];
  }
  st.work = work;
  st.dissipated = dissipated;
  t_ = t1;
  mark_state_changed();
  // Per row: the mean force (the next step's first guess), the impulse where a weld needs it and, when the step ended
  // on the remainder bound, the gap of the end state (as residual_row counts an iterate's) and a rolling contact's
  // direction there, the next step's start (the same bits as computed there).
  // (the oldest forces' vector takes the new ones: the history moves without a copy)
  hinge_force_2_.swap(hinge_force_1_);
  hinge_force_1_.swap(hinge_force_);
  force_steps_ = force_step_h_ == h ? std::min(force_steps_ + 1, 3) : 1;
  force_step_h_ = h;
  const auto end_row = [&](size_t k) HOT_INLINE {
    hinge_force_[k] = m.lam[k] * inv_h;
    if (has_welds_) row_impulse_[k] = m.lam[k];
  };
  if (predicted) {
    const auto end_rows = [&](size_t from, size_t to, PassAcc& acc) HOT_INLINE {
      for (size_t k = from; k < to; ++k) {
        end_row(k);
        const Row& r = rows_[k];
        const BodyState& a = state_[r.a];
        const BodyState& b = state_[r.b];
        const Vec2 pa = a.x + a.q * r.ra, pb = b.x + b.q * r.rb;
        Vec2 gap = pa - pb;
        if (r.rolls) {
          const Vec2 u = roll_direction(k, a, b);
          gap += (2 * roll_[k].radius) * u;
          m.roll_u0[k] = u;
        }
        count_gap(gap, pa, pb, acc, static_cast<int>(k), std::false_type{});
      }
    };
    lane[0] = lane[1] = PassAcc{};
    halves(n, [&](size_t from, size_t to, int l) {
      PassAcc acc;  // (a local: see the start's levers)
      end_rows(from, to, acc);
      lane[l] = acc;
    });
    lane[0].merge(lane[1]);
    const double worst2 = lane[0].worst_gap2, largest2 = lane[0].largest_gap2;
    final_gap = std::sqrt(worst2);
    st.residual = std::sqrt(largest2);
    m.roll_u0_version = state_version_;
    m.roll_u0_structure = structure_;
    st.converged = !(final_gap > tol);
    ++st.bound_ends;
  } else {
    halves(n, [&](size_t from, size_t to, int) HOT_INLINE {
      for (size_t k = from; k < to; ++k) end_row(k);
    });
  }
  // The hinges are closed to the tolerance (less rounding) at the iterate the positions were just set from: the next
  // step need not measure them again before it starts.
  if (st.converged) {
    residual_ = final_gap;
    residual_version_ = state_version_;
  }
  if (options_.stabilization == Stabilization::Velocity) project_velocities();
}

// The rescue's first guess for a midpoint step of length h whose Newton's method cycled: a homotopy in the step's
// length. The steps of lengths s_1 h < s_2 h < ... from the same start are solved in turn, each from the last one's
// turns and impulses scaled to its length (the turn angle and the impulse in proportion; the first from the usual
// guess), and the last one's, scaled to h, replace the iterate. A shorter step's equations are nearer the start's
// guess, and each stage starts near its solution. The world is left as it was, but for the iterate and the step's
// statistics (the shorter steps' iterations count). Of the step's work only what its start computed is kept aside
// (the per-iterate terms are found again): with the start state's copy and the seed, about 200 bytes a block.
void World::rescue_guess(double h, const double* scales, size_t count) {
  MidpointWork& m = mid_;
  MidpointWork kept;  // the step's constants and its drive's turns, swapped out while the shorter steps run
  const auto keep = [&] {
    kept.t.swap(m.t);
    kept.kt.swap(m.kt);
    kept.alpha.swap(m.alpha);
    kept.beta.swap(m.beta);
    kept.spin_gain.swap(m.spin_gain);
    kept.damp.swap(m.damp);
    kept.vfree.swap(m.vfree);
    kept.kinematic_start.swap(m.kinematic_start);
    kept.kinematic_anchor.swap(m.kinematic_anchor);
    kept.force_lever.swap(m.force_lever);
    kept.roll_u0.swap(m.roll_u0);
    std::swap(kept.roll_u0_version, m.roll_u0_version);
    std::swap(kept.roll_u0_structure, m.roll_u0_structure);
    std::swap(kept.guess_odds, m.guess_odds);
  };
  keep();
  const std::vector<BodyState> state = state_;
  const std::vector<Vec2> forces = hinge_force_, forces_1 = hinge_force_1_, forces_2 = hinge_force_2_, ua0 = ua0_,
                          ub0 = ub0_;
  const int force_steps = force_steps_;
  const double force_step_h = force_step_h_;
  const auto forces_back = [&] {
    hinge_force_ = forces;
    hinge_force_1_ = forces_1;
    hinge_force_2_ = forces_2;
    force_steps_ = force_steps;
    force_step_h_ = force_step_h;
  };
  const double t = t_;
  StepStats stats = stats_;  // this step's, with the shorter steps' solves counted in
  double last = 0;           // the last stage's share of h
  rescuing_ = true;
  try {
    for (size_t i = 0; i < count; ++i) {
      state_ = state;
      for (size_t j = 0; j < kinematic_bodies_.size(); ++j)  // driven to the end of h: back to the start
        state_[static_cast<size_t>(kinematic_bodies_[j])] = kept.kinematic_start[j];
      forces_back();
      t_ = t;
      mark_state_changed();
      stats_ = {};
      seed_scale_ = last > 0 ? scales[i] / last : 0;  // step_midpoint starts from seed_ scaled by this
      step_midpoint(scales[i] * h);
      stats.iterations += stats_.iterations;
      stats.rescues += stats_.rescues;
      stats.regularised_pivots += stats_.regularised_pivots;
      stats.checks += stats_.checks;
      stats.short_checks += stats_.short_checks;
      seed_.lam.swap(m.lam);
      seed_.t.swap(m.t);
      last = scales[i];
    }
  } catch (...) {
    rescuing_ = false;
    throw;
  }
  rescuing_ = false;
  keep();  // (back)
  state_ = state;
  forces_back();
  ua0_ = ua0;
  ub0_ = ub0;
  t_ = t;
  stats_ = stats;
  mark_state_changed();
  seed_scale_ = 0;
  apply_seed(1 / last);
}

// The iterate from the last rescue stage's solution (seed_), its turns and impulses scaled by s.
void World::apply_seed(double s) {
  MidpointWork& m = mid_;
  m.lam.resize(seed_.lam.size());
  for (size_t k = 0; k < m.lam.size(); ++k) m.lam[k] = seed_.lam[k] * s;
  for (size_t b = 0; b < bodies_.size(); ++b) {
    if (bodies_[b].kinematic) continue;
    m.t[b] = std::tan(std::atan(seed_.t[b]) * s);
    m.kt[b] = 1 / (1 + m.t[b] * m.t[b]);
  }
}

}  // namespace ladder::core
