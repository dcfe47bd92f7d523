#include "ladder/ladder.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>
#include <utility>
#include <variant>

namespace ladder::model {

using core::Kinematics;
using core::PartDef;
using core::Rot;

const char* to_string(EventKind k) {
  switch (k) {
    case EventKind::FlipFlop: return "flip_flop";
    case EventKind::Impact: return "impact";
    case EventKind::Lock: return "lock";
    case EventKind::Unlock: return "unlock";
    case EventKind::Break: return "break";
    case EventKind::Join: return "join";
    case EventKind::SolverWarning: return "solver_warning";
  }
  return "?";
}

const char* to_string(HingeStatus s) {
  switch (s) {
    case HingeStatus::Hinged: return "hinged";
    case HingeStatus::Locked: return "locked";
    case HingeStatus::Broken: return "broken";
  }
  return "?";
}

// The hand holding the top block: it stays where it took hold and turns the block about its centre, each tip a
// half-turn with a quintic smoothstep profile (zero angular velocity and acceleration at both ends). A pure
// function of time, so that a step can be redone from a snapshot (event location) and give the same motion.
struct Ladder::Hand {
  struct Tip { double t0, duration, delta; };
  Vec2 centre{0, 0};
  double base_angle = 0;
  std::vector<Tip> tips;

  Kinematics at(double t) const {
    Kinematics k;
    k.x = centre;
    k.theta = base_angle;
    for (const Tip& tip : tips) {
      const double u = (t - tip.t0) / tip.duration;
      if (u <= 0) continue;
      if (u >= 1) {
        k.theta += tip.delta;
        continue;
      }
      const double u2 = u * u, u3 = u2 * u;
      k.theta += tip.delta * u3 * (10 - 15 * u + 6 * u2);
      k.omega += tip.delta / tip.duration * 30 * u2 * (1 - 2 * u + u2);
      k.alpha += tip.delta / (tip.duration * tip.duration) * 60 * u * (1 - 3 * u + 2 * u2);
    }
    return k;
  }
};

namespace {

// Corner positions of block i in its own frame (origin at the centre), Figure 4: corners 0 and 1 on the right
// edge, 0 at the bottom on even blocks and at the top on odd ones; c ^ 2 is across the width.
// `half_width` and `half_length` are the hinge particles' distances from the centre lines (thickness / 2 and
// length / 2 at the corners; the arc centres of rounded ends, end_radius in from both edges, for rolling hinges).
Vec2 corner_local(int i, int c, double half_length, double half_width) {
  const double x = (c & 2) ? -half_width : half_width;
  const bool low = ((c & 1) == 0) == (i % 2 == 0);
  return {x, low ? -half_length : half_length};
}

// sigma = cross(e_c, w_c) of a block, from the numbering alone (it is +-1 whatever the inset): the lengthwise
// vector points up on even blocks and down on odd ones while the widthwise one points left on both, and moving to
// c ^ 1 reverses e_c while moving to c ^ 2 reverses w_c.
double side_sign(int block, int c) {
  const double chi = (c == 0 || c == 3) ? 1.0 : -1.0;
  return block % 2 == 0 ? chi : -chi;
}

std::string format_number(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", x);
  return buf;
}

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument(what);
}

}  // namespace

Ladder::Ladder(const LadderSpec& spec, const core::Options& options) : spec_(spec), world_(options) {
  require(spec.blocks >= 1, "ladder.blocks must be at least 1");
  require(std::isfinite(spec.length) && spec.length > 0, "ladder.length must be a positive number of metres");
  require(std::isfinite(spec.thickness) && spec.thickness > 0, "ladder.thickness must be a positive number of metres");
  require(std::isfinite(spec.mass) && spec.mass > 0, "ladder.mass must be a positive number of kilograms");
  require(spec.masses.empty() || static_cast<int>(spec.masses.size()) == spec.blocks,
          "ladder.masses must list one mass per block");
  for (double m : spec.masses) require(std::isfinite(m) && m > 0, "ladder.masses must all be positive");
  require(std::isfinite(spec.tip_duration) && spec.tip_duration > 0, "ladder.tip_duration must be positive");
  require(std::isfinite(spec.kick_omega) && std::isfinite(spec.tilt), "initial conditions must be finite");
  for (int i = 0; i < spec.blocks; ++i) mass_ += block_mass(i);

  require(std::isfinite(spec.hinge_inset) && spec.hinge_inset >= 0 && spec.hinge_inset < 0.5,
          "ladder.hinge_inset must be at least 0 and below 0.5");
  require(std::isfinite(spec.end_radius) && spec.end_radius >= 0 && spec.end_radius <= 0.5 * spec.thickness,
          "ladder.end_radius must be at least 0 and at most half of ladder.thickness");
  require(spec.hinge == HingeKind::Rolling || spec.end_radius == 0,
          "ladder.end_radius needs ladder.hinge = \"rolling\" (a corner hinge turns about the corner itself)");
  require(spec.hinge == HingeKind::Corner || spec.hinge_inset == 0,
          "ladder.hinge_inset is for corner hinges; a rolling hinge's pivot is set by ladder.end_radius");
  require(std::isfinite(spec.unlock_threshold) && spec.unlock_threshold >= 0, "ladder.unlock_threshold must be >= 0");
  require(std::isfinite(spec.capture_distance) && spec.capture_distance >= 0, "ladder.capture_distance must be >= 0");
  inertia_factor_ = (spec.length * spec.length + spec.thickness * spec.thickness) / 12;
  // W, L: the hinge particles' spacing across and along the block (the corners, or a rolling hinge's arc centres,
  // end_radius r in from both edges); r: the arcs' radius, 0 for corner hinges.
  const double r = spec.end_radius;
  const double L = spec.length - 2 * r, W = 2 * (0.5 - spec.hinge_inset) * spec.thickness - 2 * r;
  // Corner particles of mass m_c at (+-W/2, +-L/2) and the rest at the centre reproduce a uniform rectangle's
  // inertia m (length^2 + T^2) / 12 (T the thickness) when 4 m_c (W^2 + L^2) / 4 = m (length^2 + T^2) / 12.
  const double corner_share =
      (spec.length * spec.length + spec.thickness * spec.thickness) / (12 * (W * W + L * L));
  require(4 * corner_share <= 1, "ladder.end_radius leaves the arc centres too close to the block's centre to carry "
                                 "its moment of inertia (the block must be longer: length - 2 end_radius >= about "
                                 "0.58 length)");
  // Lay the blocks out from the top, each hung by its hinge corner from the block above; then tilt the whole.
  const int n = spec.blocks;
  // At rest every block's line from its upper pivot to its lower one is vertical (docs/model.md section 7): the
  // corners' diagonal, or for rolling hinges, whose contacts lie straight below the arc centres while each pair's
  // mean angle is zero, the line between its arc centres moved r up and down.
  const double lean = std::atan2(W, L);
  const bool hanging = spec.start == Start::Hanging && spec.top != Top::Free;
  const auto corner_of = [](int k) { return (k % 2 == 1) ? 0 : 3; };  // hinge k's corner in the initial state
  std::vector<Vec2> centre(static_cast<size_t>(n)), hinge(static_cast<size_t>(n), Vec2::Zero());
  std::vector<double> angle(static_cast<size_t>(n), 0.0);
  angle[0] = hanging && spec.top == Top::Pinned ? -lean : 0.0;
  for (int k = 1; k < n; ++k) angle[k] = hanging ? (k % 2 == 1 ? lean : -lean) : 0.0;
  const auto lay_out = [&] {
    centre[0] = -(Rot::of(angle[0]) * corner_local(0, 3, 0.5 * L, 0.5 * W));  // top-left corner (or arc) at the origin
    for (int k = 1; k < n; ++k) {
      const Vec2 above = centre[k - 1] + Rot::of(angle[k - 1]) * corner_local(k - 1, corner_of(k), 0.5 * L, 0.5 * W);
      // A rolling pair's contact is r below the upper arc centre along the pair's mean angle (straight down when
      // the pair is straight), and the lower arc centre r further on.
      const Vec2 down = Rot::of(0.5 * (angle[k - 1] + angle[k])) * Vec2(0, -r);
      hinge[k] = above + down;
      centre[k] = above + 2 * down - Rot::of(angle[k]) * corner_local(k, corner_of(k), 0.5 * L, 0.5 * W);
    }
  };
  lay_out();
  // With rolling hinges and the top block held upright, the first pair's mean angle is not zero, its contact is off
  // the vertical through the blocks below, and the angles above are not at rest. Newton's method on each block's
  // moment about its upper contact (its weight at its centre, the weight below at its lower contact) finds the
  // angles that are, with a finite-difference Jacobian (tridiagonal: block k's moment depends on the angles of
  // blocks k - 1 to k + 1 only, so three layouts with every third angle moved give all of it). docs/model.md
  // section 9.
  if (hanging && r > 0 && spec.top == Top::Held && n > 1) {
    std::vector<double> below(static_cast<size_t>(n) + 1, 0.0);  // mass of blocks k to n - 1
    for (int k = n - 1; k >= 1; --k) below[k] = below[k + 1] + block_mass(k);
    const auto moments = [&](std::vector<double>& out) {
      lay_out();
      out.assign(static_cast<size_t>(n), 0.0);
      for (int k = 1; k < n; ++k) {
        out[k] = block_mass(k) * (centre[k].x() - hinge[k].x());
        if (k + 1 < n) out[k] += below[k + 1] * (hinge[k + 1].x() - hinge[k].x());
      }
    };
    const auto un = static_cast<size_t>(n);
    const std::vector<double> laid = angle;  // kept if the solve fails (a degenerate ladder): then a hair from rest
    std::vector<double> res, moved, lo(un), di(un), up(un), step(un);
    constexpr double kDelta = 1e-7;
    for (int iteration = 0; iteration < 10; ++iteration) {
      moments(res);
      for (int colour = 0; colour < 3; ++colour) {
        for (int j = 1 + colour; j < n; j += 3) angle[j] += kDelta;
        moments(moved);
        for (int j = 1 + colour; j < n; j += 3) {
          angle[j] -= kDelta;
          for (int k = std::max(1, j - 1); k <= std::min(n - 1, j + 1); ++k)
            (k == j ? di[k] : k == j - 1 ? up[k] : lo[k]) = (moved[k] - res[k]) / kDelta;
        }
      }
      // Thomas's algorithm on lo[k] x[k-1] + di[k] x[k] + up[k] x[k+1] = -res[k], k = 1..n-1.
      for (int k = 1; k < n; ++k) {
        step[k] = -res[k];
        if (k > 1) {
          const double f = lo[k] / di[k - 1];
          di[k] -= f * up[k - 1];
          step[k] -= f * step[k - 1];
        }
      }
      double largest = 0;
      for (int k = n - 1; k >= 1; --k) {
        if (k + 1 < n) step[k] -= up[k] * step[k + 1];
        step[k] /= di[k];
        angle[k] += step[k];
        largest = std::max(largest, std::abs(step[k]));
      }
      if (!(largest > 1e-15)) break;
    }
    if (!std::all_of(angle.begin(), angle.end(), [](double a) { return std::isfinite(a); })) angle = laid;
    lay_out();
  }
  const Rot tilt = Rot::of(spec.tilt);
  for (int i = 0; i < n; ++i) {
    const double m = block_mass(i);
    PartDef def;
    for (int c = 0; c < 4; ++c) def.particles.push_back({m * corner_share, corner_local(i, c, 0.5 * L, 0.5 * W)});
    def.particles.push_back({m * (1 - 4 * corner_share), Vec2::Zero()});
    def.position = tilt * centre[i];
    def.angle = spec.tilt + angle[i];
    // Optional kick: block 1 turning about hinge 1, the blocks below carried along with hinge 2's velocity.
    if (i == 1) {
      def.omega = spec.kick_omega;
      def.velocity = spec.kick_omega * core::perp(tilt * (centre[1] - hinge[1]));
    } else if (i >= 2) {
      def.velocity = spec.kick_omega * core::perp(tilt * (hinge[2] - hinge[1]));
    }
    def.kinematic = i == 0 && spec.top == Top::Held;
    world_.add_part(def);
  }
  hinges_.resize(static_cast<size_t>(spec.blocks));
  hinges_[0] = {3, spec.top == Top::Free ? HingeStatus::Broken : HingeStatus::Hinged, 0};
  if (spec.top == Top::Held) {
    hand_ = std::make_shared<Hand>();
    hand_->centre = world_.part_position(0);
    hand_->base_angle = spec.tilt;
    world_.set_drive(0, [hand = hand_](double t) { return hand->at(t); });
  } else if (spec.top == Top::Pinned) {
    PartDef pin;
    pin.particles.push_back({0.0, Vec2::Zero()});
    pin.kinematic = true;
    world_particle_ = world_.first_particle(world_.add_part(pin));
    world_.connect(world_particle_, particle(0, 3));
  }
  measure_coef_.resize(static_cast<size_t>(spec.blocks));
  released_at_.assign(static_cast<size_t>(spec.blocks), -std::numeric_limits<double>::infinity());
  flipped_at_.assign(static_cast<size_t>(spec.blocks), -std::numeric_limits<double>::infinity());
  for (int k = 1; k < spec.blocks; ++k) {
    const int c = corner_of(k);
    hinges_[k] = {c, HingeStatus::Hinged, 0};
    set_measure_coef(k);
    world_.connect(particle(k - 1, c), particle(k, c), roll_radius());
  }
  world_.finalize();
  set_options(options);
  world_.reserve_snapshot(before_[0]);  // (the first step's copy of the world: World::reserve_step)
}

void Ladder::set_options(const core::Options& options) {
  world_.set_options(options);
  // A flip-flop may happen once |s| is below this; the far corners are then within ~tolerance of each other.
  const double s_detect = 2 * std::max(options.tolerance, 1e-15) / spec_.length;
  if (s_detect != s_detect_) s_cache_valid_ = false;  // the last measure's violations were judged against the old
  s_detect_ = s_detect;
}

bool Ladder::held() const { return spec_.top == Top::Held && world_.is_kinematic(0); }

Vec2 Ladder::lengthwise(int i) const {
  check_block(i);
  return world_.part_rotation(i) * unit_local(i, 0);
}

// Block i's lengthwise unit vector in its own frame from corner 2 pair to 2 pair + 1 (pair 0: corner 0 to 1; pair 1:
// corner 2 to 3). From c ^ 1 to c it is the negative, exactly.
Vec2 Ladder::unit_local(int i, int pair) const {
  const int c = 2 * pair;
  return (world_.particle_local(particle(i, c ^ 1)) - world_.particle_local(particle(i, c))).normalized();
}

double Ladder::hinge_measure(int k) const {
  if (k < 1 || k >= spec_.blocks)
    throw std::invalid_argument("hinge_measure: no hinge " + std::to_string(k) + " between two blocks");
  return measure(k, world_.part_rotation(k - 1), world_.part_rotation(k));
}

// s of hinge k from the rotations of blocks k - 1 and k: sigma cross(R_a u_a, R_b u_b) = sigma cross(u_a, R u_b) with
// R = R_a^-1 R_b, = cos (sigma cross(u_a, u_b)) + sin (sigma u_a.u_b), the units in the blocks' frames (no rotated
// vectors). The two coefficients are kept per hinge; sigma is +-1, so this gives the bits of
// sigma (cos cross + sin dot), but for the sign of an exact zero (which the comparisons on s cannot see).
[[gnu::always_inline]] inline double Ladder::measure(int k, const core::Rot& qa, const core::Rot& qb) const {
  const std::array<double, 2>& m = measure_coef_[static_cast<size_t>(k)];
  const double cos = qa.c * qb.c + qa.s * qb.s, sin = qa.c * qb.s - qa.s * qb.c;
  return cos * m[0] + sin * m[1];
}

void Ladder::set_measure_coef(int k) {
  const int c = hinges_[static_cast<size_t>(k)].corner;
  // From corner c to c ^ 1 on both blocks: reversing both (c odd) leaves the cross product as it is.
  const Vec2 ua = unit_local(k - 1, c >> 1), ub = unit_local(k, c >> 1);
  const double sigma = side_sign(k - 1, c);
  measure_coef_[static_cast<size_t>(k)] = {sigma * core::cross(ua, ub), sigma * ua.dot(ub)};
}

// ds/dt = sigma (a.b) (w_k - w_{k-1}): turning block k by dphi changes s by sigma (a.b) dphi, block k-1 the other
// way. A hinge counts as crossing only while it is moving into the forbidden half: a pair that has just been
// unlocked sits a hair inside it (s <= s_det / 2), and the integrator's own O(h^2 w^2) error in the pair's
// relative angle must not lock it again while it is turning apart.
bool Ladder::approaching(int k) const {
  const int c = hinges_[k].corner;
  const Vec2 a = corner(k - 1, c ^ 1) - corner(k - 1, c), b = corner(k, c ^ 1) - corner(k, c);
  return side_sign(k - 1, c) * a.dot(b) * (world_.part_omega(k) - world_.part_omega(k - 1)) > 0;
}

bool Ladder::any_violation(std::vector<double>& s, bool* clamped) const {
  const size_t n = hinges_.size();
  s.resize(n);
  if (n > 0) s[0] = -1.0;
  // In the world's halves (World::for_halves), on its two threads for a long ladder: each hinge's value depends on
  // its two blocks only, so the values are the same either way.
  bool lane_any[2] = {false, false}, lane_inside[2] = {false, false};
  world_.for_halves(n, [&](size_t from, size_t to, int lane) {
    // Raw pointers and locals: writes through out would otherwise make the compiler reload hinges_ and s_detect_
    // for every hinge.
    const HingeInfo* hinge = hinges_.data();
    const double detect = s_detect_;
    double* out = s.data();
    bool any = false, inside = false;
    const size_t first = std::max<size_t>(from, 1);
    if (first >= to) return;
    core::Rot q_prev = world_.part_rotation(static_cast<int>(first - 1));  // each block's rotation once
    for (size_t k = first; k < to; ++k) {
      const core::Rot q = world_.part_rotation(static_cast<int>(k));
      const core::Rot qa = std::exchange(q_prev, q);
      if (hinge[k].status != HingeStatus::Hinged) {
        out[k] = -1.0;
        continue;
      }
      double v = measure(static_cast<int>(k), qa, q);
      if (v > detect && !approaching(static_cast<int>(k))) {  // inside, but not crossing
        v = detect;
        inside = true;
      }
      out[k] = v;
      any = any || v > detect;
    }
    lane_any[lane] = any;
    lane_inside[lane] = inside;
  });
  if (clamped) *clamped = lane_inside[0] || lane_inside[1];
  return lane_any[0] || lane_any[1];
}

void Ladder::violations_at_start(std::vector<double>& s) {
  if (s_cache_valid_ && s_cache_version_ == world_.state_version() && s_cache_structure_ == world_.structure()) {
    s.swap(s_cache_);  // the values move to s; the cache holds none until the step's end measure refills it
    s_cache_valid_ = false;
    return;
  }
  any_violation(s);
}

// Every event's energy goes into the ledger. A flip-flop's event says what was lost since the last one (or since the
// start): its own landing, the pairs' meetings with their stops, and the motion (losses()).
void Ladder::emit(EventKind kind, int k, double energy, std::string detail) {
  losses_.removed[static_cast<size_t>(kind)] += energy;
  since_flip_.removed[static_cast<size_t>(kind)] += energy;
  if (kind == EventKind::FlipFlop) {
    const auto& r = since_flip_.removed;
    const auto at = [&](EventKind e) { return r[static_cast<size_t>(e)]; };
    detail = "lost " + format_number(since_flip_.total()) + " J since " +
             (flip_flops_ == 0 ? "the start" : "the last flip-flop") + ": landing " +
             format_number(energy) + " J, stops " + format_number(at(EventKind::Impact) + at(EventKind::Lock)) +
             " J, damping and integrator " + format_number(since_flip_.motion) + " J";
    if (at(EventKind::Join) != 0) detail += ", joins " + format_number(at(EventKind::Join)) + " J";
    since_flip_ = {};
    lost_by_last_flip_ = losses_.total();
    ++flip_flops_;
  }
  events_.push_back({world_.time(), kind, k, energy, std::move(detail)});
}

// The motion's loss over the piece of time just taken (Losses::motion), from the energy at its start; the work its
// accepted steps put in is in piece_work_. Energies of the dynamic bodies, whose set a piece does not change. The
// blocks locked to the held block move with the hand: what their energy gained over the piece is the hand's work.
void Ladder::book_motion(const PieceStart& start) {
  const double lost = start.world.total() + piece_work_ - world_.energy().total();
  losses_.motion += lost;
  since_flip_.motion += lost;
  work_put_in_ += piece_work_ + (hand_blocks_energy() - start.hand_blocks);
  piece_work_ = 0;
}

// World's energies count the dynamic bodies; a block locked to the held block is in the hand's kinematic body, so it
// is added here (its part's motion: the hand's).
double Ladder::energy() const {
  return world_.kinetic_energy() + world_.potential_energy() + hand_blocks_energy();
}

double Ladder::hand_blocks_energy() const {
  if (!held()) return 0;
  double e = 0;
  for (const int i : world_.body_parts(world_.body_of_part(0))) {
    if (i >= spec_.blocks || world_.is_kinematic(i)) continue;
    e += block_kinetic(i) + block_potential(i);
  }
  return e;
}

double Ladder::block_potential(int i) const {
  return -block_mass(i) * world_.options().gravity.dot(world_.part_position(i));
}

double Ladder::block_kinetic(int i) const {
  const double w = world_.part_omega(i);
  return 0.5 * block_mass(i) * (world_.part_velocity(i).squaredNorm() + inertia_factor_ * w * w);
}

// The kinetic energy of every block but a held one [J]. Unlike World::kinetic_energy() (dynamic bodies only), a block
// welded to the hand still counts, with the hand's motion: so an event's energy is what its velocity fix removed
// from the blocks, not the energy of a block that joined or left the hand's body.
double Ladder::blocks_kinetic() const {
  double e = 0;
  for (int i = 0; i < spec_.blocks; ++i)
    if (!world_.is_kinematic(i)) e += block_kinetic(i);
  return e;
}

std::vector<Event> Ladder::take_events() { return std::exchange(events_, {}); }

// Why the step just taken, h long, from a state of energy e0 cannot stand, or "" when it can: a non-finite state; a
// hinge solve that failed by more than a micrometre; or an energy jump, an energy gain beyond the work put in
// (StepStats::work) of more than twice the kinetic energy at the start plus that work, i.e. a step that would more
// than triple the motion's energy out of nothing. Healthy steps, even at 20 ms, stay below once (measured over the
// ladder, knobs and extremes tests); the server's largest poke at 1 ms made a step gain 12 times it (354 J from
// 29 J), which a flip-flop then removed as an impact. Gains below a floor never count: the energy of every block
// moving at 1 mm/s or at twice tolerance / h (a hinge error the solver leaves, up to the tolerance, becomes a
// velocity of up to tolerance / h in the next step), plus the whole ladder lifted by the tolerance at every hinge
// (measured: 2.4e-4 J in one step of the long ladder at rest with the fast preset's 1 um), plus rounding.
std::string Ladder::diverged(const core::Energy& e0, double h) const {
  const core::Energy e1 = world_.energy();
  if (!e1.finite) return "the step made a non-finite state";
  const core::StepStats& st = world_.last_step();
  if (!st.converged && !(st.residual < 1e-6)) return "hinge solve failed";
  const core::Options& o = world_.options();
  const double v_floor = std::max(1e-3, 2 * o.tolerance / h);
  const double floor = 0.5 * mass_ * v_floor * v_floor + mass_ * o.gravity.norm() * o.tolerance * spec_.blocks +
                       1e-12 * std::abs(e0.potential);
  const double gain = e1.total() - e0.total() - st.work;
  if (gain > 2 * (e0.kinetic + std::abs(st.work)) + floor)
    return "energy jump of " + format_number(gain) + " J in one step";
  return {};
}

std::string Ladder::too_violent(double h, const std::string& usual) const {
  double far = 0;
  for (int i = 0; i < world_.part_count(); ++i) far = std::max(far, world_.part_position(i).cwiseAbs().maxCoeff());
  // A coordinate of magnitude `far` is held to within its spacing, 2^-52 far or more: past 1e-8 m (4.5e7 m out)
  // the hinges cannot close to within 1 % of the 1e-6 m the watchdog allows, whatever the step.
  const double spacing = std::nextafter(far, HUGE_VAL) - far;
  if (spacing > 1e-8)
    return "the ladder is " + format_number(far) + " m from the origin, where coordinates are rounded to " +
           format_number(spacing) + " m, too coarse for its hinges: no smaller sim.dt can help (a free ladder falls "
           "for ever; reset it)";
  // With the adaptive step, h is one of its sub-steps: sim.dt is the step the user set.
  const std::string step = world_.options().adaptive && frame_h_ > 0 && h < frame_h_
                               ? format_number(frame_h_) + " s (in adaptive sub-steps, the last of " +
                                     format_number(h) + " s)"
                               : format_number(h) + " s";
  return "the motion is too violent for sim.dt = " + step + " and these settings (" + usual + ")";
}

void Ladder::step_guarded(double h, int depth, const core::Snapshot* start) {
  const core::Energy e0 = world_.energy();
  if (start) {
    world_.step(h, !locating_);
  } else {
    core::Snapshot& before = before_[static_cast<std::size_t>(depth)];
    world_.step(h, !locating_, &before);  // the world before the step, for the watchdog to take the step back
    start = &before;
  }
  rescued_solves_ += world_.last_step().rescues;
  const std::string why = diverged(e0, h);
  if (!why.empty()) {
    world_.restore(*start);
    if (depth >= kMaxHalvings) {
      // A hinge error within solver.tolerance is a velocity of up to tolerance / h in the next step: against steps
      // this short a coarse tolerance is noise that no smaller step can cure (measured: the classic ladder at rest
      // with sim.dt = 1e-6 s, sim.adaptive and solver.tolerance = 1e-7 m failed 0.14 ms in; with 1e-12 m it runs).
      const double noise = world_.options().tolerance / h;
      const std::string tolerance =
          noise < 1e-4 ? std::string()
                       : "; or a smaller solver.tolerance: its " + format_number(world_.options().tolerance) +
                             " m is a velocity error of up to " + format_number(noise) + " m/s in steps of " +
                             format_number(h) + " s (the default is 1e-12 m)";
      throw std::runtime_error(why + " even with 1/" + std::to_string(1 << kMaxHalvings) + " of the time step at t = " +
                               format_number(world_.time()) + " s: " +
                               too_violent(step_h_,  // (h: a piece of it, when the step was cut at an event)
                                           world_.options().integrator == core::Integrator::Euler
                                               ? "sim.integrator = euler gains energy at every step: use another "
                                                 "(midpoint, the default, keeps it), or a much smaller sim.dt" +
                                                     tolerance
                                               : "try a smaller sim.dt, or check masses, forces, grips, damping and "
                                                 "the tip duration" +
                                                     tolerance));
    }
    if (depth == 0 && !halving_) emit(EventKind::SolverWarning, 0, 0, why + ": steps redone in halves");
    halving_ = true;
    step_guarded(0.5 * h, depth + 1);
    step_guarded(0.5 * h, depth + 1);
    return;
  }
  // A step taken whole ends an episode of halving, or of solves stopped short; a trial step of event location does
  // not (locate() tries a failing step over and over at nearby lengths, and each success between would report the
  // episode again: 27 warnings in one step were seen).
  if (depth == 0 && !locating_) halving_ = false;
  const core::StepStats& st = world_.last_step();
  piece_work_ += st.work;
  if (!st.converged && !warned_) {
    std::string what = "hinge solve stopped at residual " + format_number(st.residual) + " m";
    if (world_.options().integrator == core::Integrator::Midpoint)  // its angular equations may be what stopped it
      what += " (angular residual " + format_number(st.angular_residual) + " m, after " +
              std::to_string(st.iterations) + " iterations)";
    emit(EventKind::SolverWarning, 0, 0, what);
  }
  if (!st.converged || !locating_) warned_ = !st.converged;
}

// With the adaptive step on, the step is walked in the sub-steps the engine's error control suggests, each one
// checked by Algorithm 1 as a step of its own: a hinge crossing is located within a sub-step, not within h. The
// location's trial steps are single steps, each a fraction of the piece the error control just covered (usually in
// one sub-step, sometimes a few): with error control of their own, dozens of trials each cut into up to 1024
// sub-steps made a violent frame cost minutes.
void Ladder::advance(double h, const std::function<bool()>& interrupted) {
  frame_h_ = h;
  apply_grips(h);
  if (!world_.options().adaptive) {
    advance_by(h);
    return;
  }
  // No sub-step below h / 1024, however the pieces before it went: each step then costs at most 1024 sub-steps, as
  // docs/scenes.md says (sim.error_tolerance).
  world_.set_adaptive_floor(h / 1024);
  int pieces = 0;
  for (double done = 0; h - done > 1e-9 * h; ++pieces) {
    if (pieces > 0 && interrupted && interrupted()) throw Interrupted{pieces};
    const double left = h - done, trial = world_.adaptive_step();
    const double s = core::next_piece(trial > 0 ? std::max(trial, h / 1024) : left, left);
    advance_by(s);
    done += s;
  }
}

void Ladder::advance_by(double h) {
  world_.wake_threads();  // (its wake-up overlaps the energy and hinge measures before the step)
  step_h_ = h;
  piece_work_ = 0;
  if (!spec_.logic) {
    const PieceStart e0 = piece_start();
    step_guarded(h, 0);
    book_motion(e0);
    return;
  }
  const std::size_t events_before = events_.size();
  double remaining = h;
  std::vector<double>& s0 = s_start_;
  std::vector<double>& s1 = s_end_;
  for (int guard = 0; remaining > 0; ++guard) {
    violations_at_start(s0);
    const PieceStart e0 = piece_start();  // with piece_work_ zero: at the start, or after book_motion()
    step_guarded(remaining, 0);
    const core::Snapshot& start = before_[0];  // the world before the step, for event location
    bool clamped = false;
    if (!any_violation(s1, &clamped)) {
      s_cache_.swap(s1);
      s_cache_version_ = world_.state_version();
      s_cache_structure_ = world_.structure();
      s_cache_valid_ = !clamped;
      book_motion(e0);
      break;
    }
    if (guard >= 64) {  // a pathological pile-up of events in one step: keep going, but say so
      emit(EventKind::SolverWarning, 0, 0, "more than 64 restructuring events in one step");
      book_motion(e0);
      break;
    }
    int k = -1;
    locating_ = true;
    double tau = 0;
    try {
      tau = locate(start, s0, remaining, k);
    } catch (...) {
      locating_ = false;
      throw;
    }
    locating_ = false;
    book_motion(e0);  // up to the crossing, where the world now is
    restructure(k);
    remaining -= tau * remaining;
    if (remaining <= 1e-12 * h) break;
  }
  check_unlocks();
  // After a restructure or a halved step, every joint's gap is checked directly: the solver's residual covers the
  // hinges between bodies only, so a gap frozen into a weld by a violent step would otherwise go unseen (measured:
  // 5.2 cm at sim.dt = 0.1 s in the classic scene). Only then, so that a quiet step pays nothing.
  if ((events_.size() > events_before || halving_) && !(world_.max_hinge_error() < 1e-6))
    throw std::runtime_error("a hinge was left " + format_number(world_.max_hinge_error()) + " m apart at t = " +
                             format_number(world_.time()) + " s: " + too_violent(h, "try a smaller sim.dt"));
}

// Finds the first hinge to cross into a forbidden quadrant during the step of length h from `start` (the world is
// at the step's end on entry), and leaves the world at the instant it crosses: s in [0, s_detect/2]. The root is
// found by the Illinois variant of regula falsi on the fraction of the step, each trial a real step from `start`.
double Ladder::locate(const core::Snapshot& start, const std::vector<double>& s0, double h, int& hinge) {
  const double target = 0.25 * s_detect_, band = 0.25 * s_detect_;
  std::vector<double> s_hi;
  any_violation(s_hi);
  double hi = 1.0;
  int k = -1;
  double tau = 0;
  for (int round = 0; round < 64; ++round) {
    // The candidate crossing first by linear interpolation of s over [0, hi].
    k = -1;
    double best = 2.0;
    for (size_t j = 1; j < s_hi.size(); ++j) {
      if (!(s_hi[j] > s_detect_)) continue;
      const double est = s0[j] >= 0 ? 0.0 : hi * (-s0[j]) / (s_hi[j] - s0[j]);
      if (est < best) best = est, k = static_cast<int>(j);
    }
    double lo = 0, glo = s0[k] - target, top = hi, ghi = s_hi[k] - target;
    tau = 0;
    int side = 0;
    bool found = glo >= -band;  // already at (or just past) the boundary when the step began
    for (int it = 0; it < 80 && !found; ++it) {
      tau = (lo * ghi - top * glo) / (ghi - glo);
      if (!(tau > lo && tau < top)) tau = 0.5 * (lo + top);
      world_.restore(start);
      piece_work_ = 0;
      step_guarded(tau * h, 0, &start);
      const double g = hinge_measure(k) - target;
      if (std::abs(g) <= band) {
        found = true;
        break;
      }
      if (g > 0) {
        top = tau, ghi = g;
        if (side == 1) glo *= 0.5;
        side = 1;
      } else {
        lo = tau, glo = g;
        if (side == -1) ghi *= 0.5;
        side = -1;
      }
      if ((top - lo) * h < 1e-15) break;
    }
    if (!found) {  // the bracket collapsed: take its end just past the boundary
      tau = top;
      world_.restore(start);
      piece_work_ = 0;
      if (tau > 0) step_guarded(tau * h, 0, &start);
    } else if (tau == 0) {
      world_.restore(start);
      piece_work_ = 0;
    }
    // Another hinge may have crossed even earlier; then locate that one inside [0, tau].
    std::vector<double> now;
    any_violation(now);
    bool earlier = false;
    for (size_t j = 1; j < now.size(); ++j) earlier = earlier || (static_cast<int>(j) != k && now[j] > s_detect_);
    if (!earlier || tau == 0) {
      hinge = k;
      return tau;
    }
    now[k] = -1;
    s_hi = now;
    hi = tau;
  }
  // Dozens of hinges crossing within one step: act on the last one located, the rest follow at once.
  emit(EventKind::SolverWarning, k, 0, "event location gave up ordering simultaneous crossings");
  hinge = k;
  return tau;
}

// Algorithm 1's action for a hinge that entered a forbidden quadrant: flip-flop (Algorithm 2) when the pair is
// folded (|a + b| large), the stop (Algorithm 3's lock, or an impact) when it is straight.
//
// A pair that folds again within a step of its own flip-flop may be pressed face to face at both ends: the flip-flop
// left it with no relative turn and the loads closed it about the new hinge at once. Flipping back then repeats
// without end, a flip-flop every few nanoseconds with nothing between (a block grabbed and held below a hanging pair
// did it: 64 a step, and locating them made a step of 16 blocks 1.5 ms instead of 10 us). So such a fold's face
// contact is judged by its moments about both ends, as a lock is (contact_moments()): pressed at both, the pair
// locks face to face, and opens about whichever end the loads first pull (check_unlocks()); pulled harder at the
// hinge it has, it opens there (an impact); pulled harder at the other end, it flip-flops as Algorithm 2 says.
// (docs/model.md section 5.)
void Ladder::restructure(int k) {
  const int c = hinges_[k].corner;
  if (!folded(k)) {
    meet_stop(k);
    return;
  }
  // Face (default): at the fold the two blocks meet face to face, both corner pairs at once, so the meeting is a
  // momentary weld (the combine on the hinged pair) before the old hinge is undone. Corner: only the far corners
  // meet (see FlipImpact), the paper's rule taken literally.
  const double before = blocks_kinetic();
  if (spec_.flip_impact == FlipImpact::Face) {
    world_.combine(particle(k - 1, c), particle(k, c));
    if (world_.time() - flipped_at_[static_cast<size_t>(k)] <= step_h_) {
      if (held_again(k, before, "face to face: let go at this instant, the free motion closed the pair straight "
                                "back"))
        return;
      contact_moments(moments_, k);
      const double moment = moments_[static_cast<size_t>(k)], other = other_moments_[static_cast<size_t>(k)];
      if (moment >= -spec_.unlock_threshold && other >= -spec_.unlock_threshold) {
        hinges_[k].status = HingeStatus::Locked;
        emit(EventKind::Lock, k, before - blocks_kinetic(),
             moment >= 0 && other >= 0
                 ? "face to face, pressed with " + format_number(moment) + " N m at the hinge and " +
                       format_number(other) + " N m at the other end"
                 : "face to face, " + lock_moment(moment) + " at the hinge and " + lock_moment(other) +
                       " at the other end");
        return;
      }
      if (moment < other) {  // pulled open harder at the hinge it has: it opens there, and the hinge stays
        world_.separate(particle(k - 1, c), particle(k, c));
        released(k);
        emit(EventKind::Impact, k, before - blocks_kinetic(), "face to face, pulled open at the hinge with " +
                                                                  format_number(-moment) + " N m");
        return;
      }
    }
    world_.separate(particle(k - 1, c), particle(k, c));  // the weld lets go
  }
  move_hinge(k);
  emit(EventKind::FlipFlop, k, before - blocks_kinetic());
}

bool Ladder::folded(int k) const {
  const int c = hinges_[k].corner;
  const Vec2 a = corner(k - 1, c ^ 1) - corner(k - 1, c), b = corner(k, c ^ 1) - corner(k, c);
  return (a.normalized() + b.normalized()).norm() > std::sqrt(2.0);
}

void Ladder::move_hinge(int k) {
  HingeInfo& h = hinges_[k];
  const int c = h.corner;
  world_.separate(particle(k - 1, c), particle(k, c));                          // Algorithm 2, line 1
  world_.combine(particle(k - 1, c ^ 1), particle(k, c ^ 1), roll_radius());  // lines 2-3
  h.corner = c ^ 1;
  set_measure_coef(k);
  ++h.flips;
  flipped_at_[static_cast<size_t>(k)] = world_.time();
}

// A straight pair turning into the forbidden half meets its stop, a one-sided contact (docs/model.md section 5). The
// meeting is perfectly inelastic: the weld's velocity fix (Algorithm 3's combine) stops the pair's relative turn. The
// contact then stays, as a lock, only if it has to keep pushing: if its moment at this instant pulls, the loads open
// the pair by themselves and the weld is undone at once, so that the meeting is one impact. (Welding at every meeting
// and letting go after the next step, as the model did before, made most meetings a lock and an unlock one step
// apart.)
// A lock's contact moment in words: "pressed with M N m", or, for a pull the threshold lets the stop hold, "pulled
// open with only M N m (within ladder.unlock_threshold, T N m)" rather than a negative press.
std::string Ladder::lock_moment(double moment) const {
  if (moment >= 0) return "pressed with " + format_number(moment) + " N m";
  return "pulled open with only " + format_number(-moment) + " N m (within ladder.unlock_threshold, " +
         format_number(spec_.unlock_threshold) + " N m)";
}

void Ladder::meet_stop(int k) {
  const int c = hinges_[k].corner;
  const double before = blocks_kinetic();
  world_.combine(particle(k - 1, c), particle(k, c));
  if (held_again(k, before, "pressed: let go at this instant, the free motion turned the pair straight back into "
                            "the stop"))
    return;
  contact_moments(moments_, k);
  const double moment = moments_[static_cast<size_t>(k)];
  if (moment >= -spec_.unlock_threshold) {
    hinges_[k].status = HingeStatus::Locked;
    emit(EventKind::Lock, k, before - blocks_kinetic(), lock_moment(moment));
    return;
  }
  world_.separate(particle(k - 1, c), particle(k, c));
  released(k);
  emit(EventKind::Impact, k, before - blocks_kinetic(), "pulled open with " + format_number(-moment) + " N m");
}

void Ladder::set_clock(double t) {
  const double was = world_.time();
  if (t == was) return;
  world_.set_clock(t);
  for (double& r : released_at_)
    if (r == was) r = t;
  for (double& f : flipped_at_)
    if (f == was) f = t;
  for (auto e = events_.rbegin(); e != events_.rend() && e->t == was; ++e) e->t = t;
}

void Ladder::released(int k) { released_at_[static_cast<size_t>(k)] = world_.time(); }

// Met again at the instant it was let go (an impact or an unlock): its moment pulled, yet the free motion from that
// very state closed the pair straight back (the loads change sign there), so the contact holds: hinge k (welded by
// the caller) is locked and true is returned. The world is at the state of that release, so this meeting removes
// nothing; the release is taken back if its event is still to be taken, else a lock with `detail` is reported.
// (Without this, a pair whose moment pulls by a hair could meet its stop again and again.) False if hinge k was not
// let go at this instant.
bool Ladder::held_again(int k, double before, const char* detail) {
  if (released_at_[static_cast<size_t>(k)] != world_.time()) return false;
  hinges_[k].status = HingeStatus::Locked;
  const double removed = before - blocks_kinetic();
  if (!take_back_release(k, removed)) emit(EventKind::Lock, k, removed, detail);
  return true;
}

// Takes back hinge k's release at this instant, if its event is still to be taken: an impact becomes the lock it
// turned out to be (one event, with the energy of both meetings), an unlock is dropped (the lock goes on). `removed`
// is what the meeting again removed: nothing but rounding when nothing moved the pair since its release, but another
// hinge's restructure at the same instant can have (a neighbour's impact; measured: 8.1e-5 J on a violently kicked
// ladder), and the ledger keeps it: in the lock's energy, or, after an unlock, as a lock event of its own unless it
// is rounding's. False if there is no such event.
bool Ladder::take_back_release(int k, double removed) {
  for (auto e = events_.rbegin(); e != events_.rend() && e->t == world_.time(); ++e) {
    if (e->hinge != k) continue;
    if (e->kind == EventKind::Unlock) {
      if (!(std::abs(removed) <= 1e-12 * blocks_kinetic())) return false;  // reported: the unlock, then a lock
      events_.erase(std::next(e).base());
      return true;
    }
    if (e->kind != EventKind::Impact) return false;
    const auto from = static_cast<size_t>(EventKind::Impact), to = static_cast<size_t>(EventKind::Lock);
    for (Losses* l : {&losses_, &since_flip_}) {
      l->removed[from] -= e->energy_removed;
      l->removed[to] += e->energy_removed + removed;
    }
    e->energy_removed += removed;
    e->kind = EventKind::Lock;
    e->detail = std::string(folded(k) ? "pressed: the free motion closed the pair face to face again ("
                                      : "pressed: the free motion turned the pair straight back into the stop (") +
                e->detail + " at first)";
    return true;
  }
  return false;
}

// The moment [N m] that the contact of each locked hinge, and of hinge `meeting`, welded a moment ago, carries at this
// instant (index k; 0 for the others), signed by contact_moment(). It comes from the hinge forces of the index-1
// equations: one explicit Euler step of a thousandth of the step under way, with nothing projected, on a copy of the
// world. Its velocity change is exactly that step times the accelerations at its start, so World::weld_moment() over it
// is the instantaneous moment, free of any solver tolerance. (Over a step of the scene's own integrator the moment is a
// mean over that step, so a lock would let go up to a step late and a meeting could be judged by loads that come later;
// over a short one, the impulse that closes a hinge gap of up to the solver's tolerance would swamp it.)
void Ladder::contact_moments(std::vector<double>& moments, int meeting) {
  moments.assign(hinges_.size(), 0.0);
  other_moments_.assign(hinges_.size(), 0.0);
  probe_ = world_;  // a copy (its buffers reused), so that the world keeps its own last step's figures and caches
  core::Options euler = world_.options();
  euler.integrator = core::Integrator::Euler;
  euler.stabilization = core::Stabilization::None;
  euler.adaptive = false;
  probe_.set_options(euler);
  // After a step the grips' forces of that step have run out: the probe takes those of the next step (from this
  // state, as advance() will), or a lock that a hand presses would be judged without the hand.
  if (!grips_.empty() && !(world_.time() < grips_until_)) add_grip_forces(probe_, grips_h_);
  probe_.step(1e-3 * step_h_, false);
  for (size_t k = 1; k < hinges_.size(); ++k)
    if (hinges_[k].status == HingeStatus::Locked || static_cast<int>(k) == meeting) {
      moments[k] = contact_moment(probe_, static_cast<int>(k));
      if (folded(static_cast<int>(k))) other_moments_[k] = contact_moment(probe_, static_cast<int>(k), true);
    }
}

// The moment [N m] the weld of hinge k carried over `world`'s last step, signed so that > 0 pushes block k out of the
// forbidden half (a contact's sense) and < 0 pulls it back in. Turning block k by +dphi changes s by
// sigma (a.b) dphi, so the allowed sense is -sign(sigma a.b). With other_end, a folded pair's: about the midpoint of
// the blocks' other ends, signed for a hinge there (the sense that opens the pair about that end).
double Ladder::contact_moment(const core::World& world, int k, bool other_end) const {
  const int c = hinges_[k].corner, e = other_end ? c ^ 1 : c;
  const double moment = other_end ? world.weld_moment(particle(k - 1, c), particle(k, c), particle(k - 1, e),
                                                      particle(k, e))
                                  : world.weld_moment(particle(k - 1, c), particle(k, c));
  const Vec2 a = (corner(k - 1, e ^ 1) - corner(k - 1, e)).normalized();
  const Vec2 b = (corner(k, e ^ 1) - corner(k, e)).normalized();
  return side_sign(k - 1, e) * a.dot(b) > 0 ? -moment : moment;
}

// Algorithm 4's trigger: after each step, a lock lets go as soon as its contact, instead of pushing block k out of the
// forbidden quadrant, has to pull it back in (a contact cannot pull). One at a time, the one pulled hardest first,
// each time with the moments found anew: letting one lock go changes what its neighbours carry (a lock next to it
// no longer carries the block beyond), and letting several go on the moments of the welded chain freed pairs that
// the loads still pressed (double-ripple.toml: a pair let go and met its stop again at the same instant).
void Ladder::check_unlocks() {
  const auto locked = [](const HingeInfo& h) { return h.status == HingeStatus::Locked; };
  while (std::any_of(hinges_.begin(), hinges_.end(), locked)) {
    contact_moments(moments_);
    // A face-to-face lock's pull is the harder of its two ends' (other_moments_ is 0 for a straight lock).
    const auto pull = [&](size_t j) { return std::min(moments_[j], other_moments_[j]); };
    int k = -1;
    for (size_t j = 1; j < hinges_.size(); ++j)
      if (locked(hinges_[j]) && pull(j) < -spec_.unlock_threshold && (k < 0 || pull(j) < pull(static_cast<size_t>(k))))
        k = static_cast<int>(j);
    if (k < 0) return;
    const int c = hinges_[k].corner;
    world_.separate(particle(k - 1, c), particle(k, c));
    hinges_[k].status = HingeStatus::Hinged;
    const double m = moments_[static_cast<size_t>(k)], other = other_moments_[static_cast<size_t>(k)];
    if (m <= other) {
      released(k);
      emit(EventKind::Unlock, k, 0, "pulled open with " + format_number(-m) + " N m");
    } else {  // a face-to-face pair opening about its other end: the hinge moves there, with nothing to land
      move_hinge(k);
      released(k);
      emit(EventKind::Unlock, k, 0, "pulled open at the blocks' other ends with " + format_number(-other) +
                                        " N m: the hinge moved there");
      emit(EventKind::FlipFlop, k, 0);
    }
  }
}

void Ladder::check_block(int i) const {
  if (i < 0 || i >= spec_.blocks)
    throw std::invalid_argument("no block " + std::to_string(i) + " (blocks are 0.." + std::to_string(spec_.blocks - 1) + ")");
}

void Ladder::check_on_block(int i, const Vec2& local, const char* what) const {
  check_block(i);
  const double along = 0.5 * spec_.length, across = 0.5 * spec_.thickness;
  if (std::abs(local.x()) <= 1.01 * across && std::abs(local.y()) <= 1.01 * along) return;  // (false for NaN)
  const auto mm = [](double v) {  // four digits: beyond them the distance is rounding (1.1e-14 mm)
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.4g", std::abs(v * 1e3) < 1e-9 ? 0.0 : v * 1e3);
    return std::string(buf);
  };
  throw std::invalid_argument(std::string(what) + " is " + mm(local.x()) + " mm across and " + mm(local.y()) +
                              " mm along block " + std::to_string(i) + " from its centre, outside the block (at most " +
                              mm(across) + " mm across and " + mm(along) + " mm along)");
}

void Ladder::check_hinge(int k) const {
  if (k < 0 || k >= spec_.blocks)
    throw std::invalid_argument("no hinge " + std::to_string(k) + " (hinges are 0.." + std::to_string(spec_.blocks - 1) +
                                "; hinge 0 is the top block's hold)");
}

double Ladder::tip_end_time() const {
  double end = 0;
  if (hand_)
    for (const auto& t : hand_->tips) end = std::max(end, t.t0 + t.duration);
  return end;
}

void Ladder::tip() {
  if (!held()) throw std::invalid_argument("the top block is not held, so it cannot be tipped");
  if (time() < tip_end_time())
    throw std::invalid_argument("a tip is already in progress (it ends at t = " + std::to_string(tip_end_time()) + " s)");
  // Turning block 0 by +dpsi changes hinge 1's s by -sigma (a.b) dpsi: the allowed sense is sign(sigma a.b).
  double sense = -1;  // clockwise, as in the paper, when hinge 1 says nothing
  if (spec_.blocks >= 2 && hinges_[1].status != HingeStatus::Broken) {
    const int c = hinges_[1].corner;
    const Vec2 a = (corner(0, c ^ 1) - corner(0, c)).normalized();
    const Vec2 b = (corner(1, c ^ 1) - corner(1, c)).normalized();
    const double d = side_sign(0, c) * a.dot(b);
    if (d > 0) sense = 1;
  }
  hand_->tips.push_back({time(), spec_.tip_duration, sense * std::numbers::pi});
}

void Ladder::break_hinge(int k) {
  check_hinge(k);
  HingeInfo& h = hinges_[k];
  if (h.status == HingeStatus::Broken) throw std::invalid_argument("hinge " + std::to_string(k) + " is already broken");
  if (k == 0) {
    if (spec_.top == Top::Held) {
      // The hand lets the top block go with its motion: its energy joins the blocks' (energy()), put in by the hand.
      const double e_before = energy();
      world_.release(0);
      work_put_in_ += energy() - e_before;
    } else {
      world_.separate(world_particle_, particle(0, 3));
    }
  } else {
    if (h.status == HingeStatus::Locked) world_.separate(particle(k - 1, h.corner), particle(k, h.corner));
    world_.separate(particle(k - 1, h.corner), particle(k, h.corner));
  }
  h.status = HingeStatus::Broken;
  emit(EventKind::Break, k, 0);
}

void Ladder::join_hinge(int k) {
  check_hinge(k);
  HingeInfo& h = hinges_[k];
  if (h.status != HingeStatus::Broken) throw std::invalid_argument("hinge " + std::to_string(k) + " is not broken");
  if (k == 0 && spec_.top == Top::Free) throw std::invalid_argument("the top block has no hold or pin to join");
  if (k == 0 && spec_.top == Top::Held) {
    // A user's grip on block 0 would be left on a block the hand moves (a drag of it taken and doing nothing).
    if (!grips_.empty() && grips_.front().block == 0)
      throw std::invalid_argument("block 0 is grabbed; release it before the hand takes it back (join 0)");
    // The hand takes hold of the block where it is and stops it: the motion it stops is the join's loss, and the
    // block leaves the blocks' energy (energy()) with its potential energy, which the hand takes out.
    const double before = world_.kinetic_energy(), e_before = energy();
    hand_->centre = world_.part_position(0);
    hand_->base_angle = world_.part_angle(0);
    hand_->tips.clear();
    world_.set_drive(0, [hand = hand_](double t) { return hand->at(t); });
    world_.project_velocities();
    h.status = HingeStatus::Hinged;
    const double removed = before - world_.kinetic_energy();
    work_put_in_ += energy() - e_before + removed;
    emit(EventKind::Join, k, removed);
    return;
  }
  const int pa = k == 0 ? world_particle_ : particle(k - 1, h.corner), pb = particle(k, h.corner);
  // Rolling hinges: how far the two rounded ends are from touching (their arc centres 2 r apart).
  const double radius = k == 0 ? 0.0 : roll_radius();
  const double gap = std::abs((world_.particle_position(pa) - world_.particle_position(pb)).norm() - 2 * radius);
  if (gap > spec_.capture_distance)
    throw std::invalid_argument("hinge " + std::to_string(k) + ": the " +
                                (radius > 0 ? std::string("rounded ends") : std::string("corners")) + " are " +
                                format_number(gap * 1e3) + " mm apart, more than the capture distance of " +
                                format_number(spec_.capture_distance * 1e3) + " mm");
  const core::Restructure r = world_.combine(pa, pb, radius);
  h.status = HingeStatus::Hinged;
  emit(EventKind::Join, k, r.energy_removed);
}

double Ladder::poke(int block, const std::optional<Vec2>& point, const Vec2& impulse) {
  check_block(block);
  // (A point off the block would turn it by the lever of a point it does not have: 1e3 rad/s from 1 N s at 5 m.)
  if (point)
    check_on_block(block, core::Rot::of(block_angle(block)).apply_inverse(*point - block_centre(block)), "the point");
  const double gained = world_.apply_impulse(block, point ? *point : block_centre(block), impulse);
  work_put_in_ += gained;
  return gained;
}

void Ladder::push(int block, const Vec2& local_point, const Vec2& force, double duration) {
  check_block(block);
  if (!(duration > 0) || !std::isfinite(duration)) throw std::invalid_argument("push: the duration must be positive");
  check_on_block(block, local_point, "the point");
  // The held block itself: a force on it does nothing. (A block locked to it is pushed: the force moves no block,
  // but it weighs in the lock's moments, and can open it: Stop.PairPressedFaceToFaceLocksAndOpensAboutTheEndPulled.)
  if (world_.is_kinematic(block)) throw std::invalid_argument("push: the block is held and does not move freely");
  world_.add_force(block, local_point, force, time() + duration);
}

void Ladder::grab(const Grip& g) {
  check_block(g.block);
  if (g.block == 0 && held()) throw std::invalid_argument("block 0 is held by the hand; grab another block");
  if (!std::isfinite(g.stiffness) || g.stiffness < 0)
    throw std::invalid_argument("grab: the stiffness must be >= 0 (0 for the default)");
  const auto it = std::lower_bound(grips_.begin(), grips_.end(), g.block,
                                   [](const Grip& a, int b) { return a.block < b; });
  if (it != grips_.end() && it->block == g.block)
    *it = g;
  else
    grips_.insert(it, g);
}

Ladder::Grip& Ladder::grip_of(int block) {
  check_block(block);  // a block that does not exist, named as such (it was "not grabbed")
  for (Grip& g : grips_)
    if (g.block == block) return g;
  throw std::invalid_argument(grips_.empty() ? "nothing is grabbed; grab a block first"
                                             : "block " + std::to_string(block) + " is not grabbed");
}

void Ladder::drag(int block, const Vec2& target, const double* angle) {
  Grip& g = grip_of(block);
  g.target = target;
  if (angle) {
    g.hold_angle = true;
    g.angle = *angle;
  }
}

void Ladder::release(int block) {
  Grip& g = grip_of(block);
  grips_.erase(grips_.begin() + (&g - grips_.data()));
}

// The turn of `angle` nearest the block's own angle (unwrapped, so several turns from 0 after tips): the grip's
// torsional spring then turns it at most half a turn. An angle already that near is kept exactly as given.
double Ladder::nearest_turn(double angle, int block) const {
  const double block_angle_now = block_angle(block);
  if (std::abs(angle - block_angle_now) <= std::numbers::pi) return angle;
  return block_angle_now + std::remainder(angle - block_angle_now, 2 * std::numbers::pi);
}

void Ladder::apply(const Action& action) {
  struct Dispatch {
    Ladder& l;
    void operator()(const Tip&) const { l.tip(); }
    void operator()(const Poke& p) const { l.poke(p.block, p.at, p.impulse); }
    void operator()(const Push& p) const { l.push(p.block, p.at, p.force, p.duration); }
    void operator()(const Grab& g) const {
      l.check_block(g.block);  // before its pose is read
      Grip grip;
      grip.block = g.block;
      grip.local = g.local;
      grip.stiffness = g.stiffness;
      grip.target = g.target ? *g.target : l.block_centre(g.block) + l.world_.part_rotation(g.block) * g.local;
      grip.hold_angle = g.angle.has_value();
      grip.angle = g.angle ? l.nearest_turn(*g.angle, g.block) : 0;
      l.grab(grip);
    }
    void operator()(const Drag& d) const {
      double angle = d.angle.value_or(0);
      const bool grabbed =
          std::any_of(l.grips_.begin(), l.grips_.end(), [&](const Grip& g) { return g.block == d.block; });
      if (grabbed && d.angle) angle = l.nearest_turn(angle, d.block);  // (a block not grabbed is refused by drag)
      l.drag(d.block, d.target, d.angle ? &angle : nullptr);
    }
    void operator()(const Release& r) const { l.release(r.block); }
    void operator()(const Break& b) const { l.break_hinge(b.hinge); }
    void operator()(const Join& j) const { l.join_hinge(j.hinge); }
  };
  std::visit(Dispatch{*this}, action);
}

// Each grip as forces held over the next step. With the block's mass m (moment of inertia I), natural frequency
// w, stiffness m w^2 (I w^2) and critical damping 2 m w (2 I w). An explicit step of a spring is stable while
// w h < 2, and 0.2 keeps it accurate; the chain attached to the block only adds inertia, so the block alone is the
// stiffest case. The torque is applied as a couple at the block's two ends.
void Ladder::apply_grips(double h) {
  grips_until_ = time() + h;
  grips_h_ = h;
  add_grip_forces(world_, h);
}

// Each grip's spring and damper, from `world`'s state, as forces until world.time() + h.
void Ladder::add_grip_forces(core::World& world, double h) const {
  for (const Grip& g : grips_) {
    const int part = g.block;
    const double m = block_mass(g.block);
    const double w = std::min(g.stiffness > 0 ? std::sqrt(g.stiffness / m) : 100.0, 0.2 / h);
    const core::Rot q = world.part_rotation(part);
    const Vec2 r = q * g.local;
    const Vec2 p = world.part_position(part) + r;
    const double omega = world.part_omega(part);
    const Vec2 v = world.part_velocity(part) + omega * Vec2(-r.y(), r.x());
    world.add_force(part, g.local, m * w * w * (g.target - p) - 2 * m * w * v, world.time() + h);
    if (!g.hold_angle) continue;
    const double inertia = m * (spec_.length * spec_.length + spec_.thickness * spec_.thickness) / 12;
    const double torque = inertia * w * w * (g.angle - world.part_angle(part)) - 2 * inertia * w * omega;
    const double a = 0.5 * spec_.length;
    const Vec2 arm = q * Vec2(a, 0), f = torque / (2 * a * a) * Vec2(-arm.y(), arm.x());
    world.add_force(part, Vec2(a, 0), f, world.time() + h);
    world.add_force(part, Vec2(-a, 0), -f, world.time() + h);
  }
}

}  // namespace ladder::model
