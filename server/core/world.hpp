// The physics engine: particles grouped into rigid bodies, joined by hinges made by combining particles.
//
// Model (after Glencross & Murta, "A Virtual Jacob's Ladder", section 2):
//  - a particle has a mass and a fixed offset in its part;
//  - a part is a rigid group of particles created together (a ladder block is one part of five particles);
//  - combine(p, q) of particles of two bodies makes a hinge: the two particles are held coincident;
//    combine of two particles that already form a hinge welds their bodies into one rigid body (a lock);
//  - separate(p, q) undoes either: a weld becomes a hinge again, a hinge is broken.
// A body is a connected set of parts under welds. Bodies, not particles, carry the dynamic state: in 2-D a rigid
// body's configuration (x, y, theta) has a constant mass matrix diag(m, m, I), so the constrained equations of
// motion are those of a particle system with holonomic constraints and every classic constrained integrator
// (SHAKE, RATTLE, projected Runge-Kutta) applies unchanged.
//
// The hinge graph over dynamic bodies must be a set of chains (each dynamic body in at most two hinges, no loops);
// kinematic bodies (held blocks, the world) may carry any number. A chain's hinge system is block-tridiagonal and
// solved in O(n) (block_tridiag.hpp). combine() refuses a hinge that would break this shape.
//
// The core does no I/O: errors are thrown as std::invalid_argument / std::logic_error with a message; the
// callers (scene loader, daemon) turn them into reports.
#pragma once

#include "core/block_tridiag.hpp"
#include "core/lanes.hpp"
#include "core/geometry.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace ladder::core {

// A rolling row's contact over a midpoint step at the current iterate (midpoint.cpp, rolling()): r u+, kappa r ubar
// and the slopes of kappa r ubar in the two bodies' t.
struct RollingTerms {
  Vec2 end, mid, dmid_a, dmid_b;
};

enum class Integrator { Euler, SymplecticEuler, Rattle, RK4, Projection, Reduced, Midpoint };
enum class SolverKind { Newton, NewtonLineSearch };
// What keeps the state on the constraint manifold after a step, beyond what the integrator does itself:
//  - none: nothing (explicit integrators drift off the hinges; SHAKE and projection keep positions exact, their
//    velocities are consistent to O(h) only);
//  - velocity: velocities projected onto G v = 0 (explicit integrators' positions still drift, slowly);
//  - position: positions projected onto C(q) = 0, then velocities (the default; for SHAKE, RATTLE and projection,
//    whose positions are exact already, the same as velocity).
enum class Stabilization { None, Velocity, Position };
const char* to_string(Integrator);
const char* to_string(SolverKind);
const char* to_string(Stabilization);
// Parse a name as used in scene files; throws std::invalid_argument listing the valid names.
Integrator integrator_from_string(const std::string&);
SolverKind solver_from_string(const std::string&);
Stabilization stabilization_from_string(const std::string&);

struct Options {
  Integrator integrator = Integrator::Midpoint;
  SolverKind solver = SolverKind::Newton;  // all but projection, whose solve is its own (step.cpp)
  Stabilization stabilization = Stabilization::Position;
  double tolerance = 1e-12;   // hinge position error the constraint solve drives below [m]
  int max_iterations = 30;    // per nonlinear solve (docs/benchmarks.md: 20 left whipping chains short)
  Vec2 gravity{0.0, -9.81};   // [m/s^2]
  double linear_damping = 0;  // force -c m v on each part [1/s]
  double angular_damping = 0; // torque -c I w on each part [1/s]
  double hinge_friction = 0;  // viscous torque -c (w_b - w_a) at each hinge [N m s]
  // Error-controlled adaptive step: step(h) covers h with as many sub-steps as keep each one's estimated local error
  // (step doubling, World::step_adaptive()) below error_tolerance, a displacement of positions and angles [m]
  // (velocities are not measured). Off: one step of h.
  bool adaptive = false;
  double error_tolerance = 1e-6;  // [m]
  // Threads a step may use: 2 lets the midpoint step solve a long chain's two halves at once (World::kSplitRows,
  // docs/model.md section 3.2). The results are the same bits with 1 or 2.
  int threads = 2;
  // The midpoint step's windows: after a whole Newton pass, a long chain's rows short of the tolerances in one short
  // stretch are solved alone (docs/model.md section 3.1). Off: whole passes only (a reference for tests, benchmarks).
  bool windows = true;
};

// Prescribed motion of a kinematic part (a held block): pose, velocity and acceleration at time t.
struct Kinematics {
  Vec2 x{0, 0}, v{0, 0}, a{0, 0};
  double theta = 0, omega = 0, alpha = 0;
};
using Drive = std::function<Kinematics(double t)>;

struct ParticleDef {
  double mass = 0;
  Vec2 local{0, 0};  // offset from the part's reference point, in the part's frame
};

struct PartDef {
  std::vector<ParticleDef> particles;
  Vec2 position{0, 0};  // where the reference point is, world frame
  double angle = 0;     // [rad], counter-clockwise
  Vec2 velocity{0, 0};  // of the centre of mass
  double omega = 0;     // [rad/s]
  bool kinematic = false;  // held: moves only as its drive says (static when it has none)
};

enum class JointKind { Hinge, Weld };

// Result of a restructuring operation: what it became and the kinetic energy the velocity fix removed.
struct Restructure {
  JointKind kind = JointKind::Hinge;
  bool removed = false;        // separate() of a hinge: the joint is gone
  double energy_removed = 0;   // [J], >= 0 up to rounding
};

// Hot per-body state: 64 bytes, one cache line.
struct BodyState {
  Vec2 x{0, 0};     // centre of mass [m]
  Vec2 v{0, 0};     // [m/s]
  Rot q;            // rotation, kept equal to (cos th, sin th)
  double th = 0;    // unwrapped angle [rad]
  double w = 0;     // [rad/s]
};
static_assert(sizeof(BodyState) == 64, "BodyState is one cache line");

// A force a user applies at a point fixed in a part (given in the part's frame) until a time.
struct AppliedForce {
  int part = 0;
  Vec2 local{0, 0};
  Vec2 force{0, 0};  // [N], world frame
  double until = 0;  // [s]

  // The force to apply over a step [t0, t0 + h]: weighted by the fraction of the step it still covers, so that a
  // push shorter than a step gives its own impulse F (until - t0), not F h; zero once it has ended.
  Vec2 over_step(double t0, double h) const {
    return t0 < until ? Vec2(std::min(1.0, (until - t0) / h) * force) : Vec2::Zero();
  }
};

struct Snapshot {
  std::vector<BodyState> bodies;
  std::vector<AppliedForce> forces;  // a redone step must apply the same forces
  double t = 0;
  std::uint64_t structure = 0;
  double adaptive_h = 0;  // the adaptive step's next trial sub-step: a redone step chooses the same sub-steps
  // The midpoint step's first guess: a redone step starts its solve from the same one (World::hinge_force_ and its
  // history; the history empty in a step's `before`, World::step).
  std::vector<Vec2> hinge_forces, hinge_forces_1, hinge_forces_2;
  int force_steps = 0;
  double force_step_h = 0;
  int guess_window_wait = 0, guess_window_backoff = 0;  // whether the step tries a window from its first guess
};

// Per-step solver figures, for statistics and warnings.
struct StepStats {
  int iterations = 0;          // nonlinear iterations in the last step (all solves)
  double residual = 0;         // largest hinge position error after the last solve [m]
  // The midpoint step's largest angular residual times the body's radius of gyration at its last iterate (a bound
  // on it when the step ended on the bound of Newton's remainder) [m]; its solve stops below 1e-4 of the tolerance
  // (docs/model.md section 3.1). 0 for the other integrators.
  double angular_residual = 0;
  int regularised_pivots = 0;  // singular pivot blocks met (degenerate configuration)
  bool converged = true;       // the position solve reached the tolerance
  // Work done on the dynamic bodies over the step [J] by the users' applied forces and by driven (kinematic) bodies
  // through their hinges: with gravity's in the potential energy and damping's negative, what an exact step's
  // energy may gain at most. The watchdog compares the step's energy gain with it.
  double work = 0;
  // Energy that damping and hinge friction removed from the dynamic bodies over the step [J]: the midpoint
  // integrator's exact ledger, E(t + h) - E(t) = work - dissipated to the solver's tolerance. 0 for the other
  // integrators, whose energy change has no such exact split.
  double dissipated = 0;
  // The adaptive step's figures (Options::adaptive): sub-steps accepted and rejected, and the largest accepted
  // sub-step's error estimate [m] (above the tolerance only where the smallest sub-step, 1/1024 of the step, was
  // not enough).
  int substeps = 1, rejected = 0;
  double error_estimate = 0;
  // Midpoint steps that ended on the bound of Newton's remainder instead of a pass measuring the last iterate; their
  // residual is the end state's largest hinge gap (docs/model.md section 3.1).
  int bound_ends = 0;
  // Midpoint solves still short after solver.max_iterations and rescued: by the exact Newton near the solution, or
  // from a shorter step's solution (docs/model.md section 3.1).
  int rescues = 0;
  // Midpoint passes that measured an iterate's residual alone, expecting it to be the answer (a first guess with good
  // odds, MidpointWork::GuessOdds, or an iterate near the tolerance), and those of them that found it was not, so that
  // a full Newton pass followed: the cost of a wrong expectation.
  int checks = 0, short_checks = 0;
  // Midpoint passes over a window of the rows alone, after a pass found the rows short of the tolerances in one
  // short stretch (docs/model.md section 3.1), and the windows opened by the check of a step's first guess.
  int window_passes = 0, guess_windows = 0;
  int window_lo = -1, window_hi = -1;  // the rows of the step's window, when it had one (-1: none)

  // Adds the solver figures of a later step inside the same step() (a sub-step): counts and work summed, the worst
  // residual, converged only if both were.
  void add(const StepStats& s) {
    iterations += s.iterations;
    residual = std::max(residual, s.residual);
    angular_residual = std::max(angular_residual, s.angular_residual);
    regularised_pivots += s.regularised_pivots;
    converged = converged && s.converged;
    work += s.work;
    dissipated += s.dissipated;
    bound_ends += s.bound_ends;
    rescues += s.rescues;
    checks += s.checks;
    short_checks += s.short_checks;
    window_passes += s.window_passes;
    guess_windows += s.guess_windows;
    if (s.window_lo >= 0) window_lo = s.window_lo, window_hi = s.window_hi;
  }
};

// The next piece of a walk through a step with `remaining` of it left: at most `trial` long, and the whole rest when
// it would leave a sliver under 1 % of the piece (World::step_adaptive(), Ladder::advance()).
inline double next_piece(double trial, double remaining) {
  const double s = std::min(trial, remaining);
  return remaining - s < 0.01 * s ? remaining : s;
}

// Kinetic and gravitational potential energy of the dynamic bodies, from one pass that also checks the whole state.
struct Energy {
  double kinetic = 0, potential = 0;  // [J]
  bool finite = true;                 // World::finite() at the same time
  double total() const { return kinetic + potential; }
};

class World {
 public:
  explicit World(const Options& options = {});

  const Options& options() const { return options_; }
  // Changes options live; the caller validates values (scene loader / daemon).
  void set_options(const Options& options);

  // --- building ---
  int add_part(const PartDef& def);  // returns the part index; its particles get consecutive indices
  int first_particle(int part) const { return parts_[part].first_particle; }
  void set_drive(int part, Drive drive);  // makes the part kinematic, following the drive
  void release(int part);                 // the part becomes dynamic (a released hold)
  bool is_kinematic(int part) const { return parts_[part].kinematic; }

  // Hinges two particles while building a model whose velocities are already consistent: no velocity fix, and
  // the bodies and hinge rows are rebuilt once, before the next step (so building n hinges costs O(n)).
  // `roll_radius` > 0 makes it a rolling hinge (below, combine()).
  void connect(int pa, int pb, double roll_radius = 0);
  // Rebuilds now if connect() was called; throws if the hinges do not form chains. Then sizes the step's scratch
  // (reserve_step()).
  void finalize() {
    ensure_built();
    reserve_step();
  }
  // Gives the midpoint step's scratch room for the current structure and touches its pages, so that the first step
  // after a model is built does not (about 5 MB and 6 ms at 10 000 blocks on the test machine: a server's first tick
  // after a load or a reset). Capacity only: every vector keeps its size and contents (the Newton system's blocks,
  // which every pass writes before it reads them, are sized as the first step would size them), so no step changes.
  void reserve_step();
  // The same for a snapshot that step() will fill (its `before`).
  void reserve_snapshot(Snapshot& s) const;

  // --- restructuring (the paper's combine and separate) ---
  // A new hinge with `roll_radius` r > 0 is a rolling hinge: the two particles are the centres of two arcs of radius
  // r, one fixed in each part, that roll on each other without slipping (docs/model.md section 9). They are held 2 r
  // apart along the direction psi = (theta_a + theta_b) / 2 + psi0 (theta the parts' angles; psi0 from where the
  // particles are when the hinge is made), and the hinge acts at the contact point, halfway between them. r = 0 is
  // the plain hinge. On a pair that is already hinged, combine welds (whatever the radius), and separate() of the
  // weld gives back the hinge it was, rolling or not.
  Restructure combine(int pa, int pb, double roll_radius = 0);
  Restructure separate(int pa, int pb);
  // The joint between two particles, or -1.
  int find_joint(int pa, int pb) const;
  JointKind joint_kind(int joint) const { return joints_[joint].kind; }

  // --- time stepping ---
  // One step of h; with Options::adaptive (unless `adaptive` is false) as many sub-steps as its error control needs.
  // With `before`, the state before the step is left there, as save() would have returned it but for the midpoint's
  // older forces (below), so that a caller can take the step back with restore(): the reduced integrator hands over
  // the buffer it stepped from, no copy. The history of hinge forces behind the last step's (hinge_force_1_ and _2_,
  // two copies a step) is left out: restore() of such a snapshot starts the history again (force_steps at most 1),
  // and the next steps then start from the last forces alone until three steps of one length have passed. A watchdog
  // that takes a step back redoes it in shorter steps, which do not use the history anyway.
  void step(double h, bool adaptive = true, Snapshot* before = nullptr);
  // A step is coming: the midpoint step's second thread (Options::threads), if it sleeps, starts waking now, while
  // the caller does its own work first (step() calls it too, before its snapshot). Changes no result.
  void wake_threads() { lanes_.wake(); }
  // No step is coming for a while (a server between ticks): the second thread sleeps now rather than spinning for
  // the next one (Lanes::rest); wake_threads() or the next step wakes it. Changes no result.
  void rest_threads() { lanes_.rest(); }
  double time() const { return t_; }
  // Sets the clock without stepping: a caller that counts its steps corrects the running sum of step lengths, which
  // rounding puts off by a few ulps (9.9999999999999 after 10 000 steps of 1 ms). Changes nothing else.
  void set_clock(double t) { t_ = t; }
  const StepStats& last_step() const { return stats_; }
  // The adaptive step's next trial sub-step [s] (Options::adaptive), 0 before the first.
  double adaptive_step() const { return adaptive_h_; }
  // The adaptive step's smallest sub-step [s], when a caller walks one step in several pieces (Ladder::advance): each
  // piece's own h / 1024 would let the sub-steps shrink from piece to piece without end (3.9e-11 s was seen, a step
  // taking minutes). 0 (the default): h / 1024 of each step_adaptive(h).
  void set_adaptive_floor(double s) { adaptive_floor_ = s; }
  // Changes whenever positions (or the time) change; velocities alone do not change it. With structure(), lets a
  // caller reuse what it computed from the positions.
  std::uint64_t state_version() const { return state_version_; }
  std::uint64_t structure() const { return structure_; }
  Snapshot save() const;
  void restore(const Snapshot& s);

  // Impulse [N s] at a world point of a part, applied now; velocities are then made consistent with the
  // hinges (the impulse travels through the chain). Returns kinetic energy change [J].
  double apply_impulse(int part, const Vec2& point, const Vec2& impulse);
  // Force [N] at a point fixed in a part (given in the part's frame), applied until time `until`.
  void add_force(int part, const Vec2& local_point, const Vec2& force, double until);
  // Makes velocities consistent with the hinges by the least-kinetic-energy impulse (used after any change of
  // velocities or of kinematic drives from outside the step).
  void project_velocities();

  // --- queries ---
  int part_count() const { return static_cast<int>(parts_.size()); }
  int particle_count() const { return static_cast<int>(particles_.size()); }
  int body_count() const { return static_cast<int>(bodies_.size()); }
  int body_of_part(int part) const { return parts_[part].body; }
  int part_of_particle(int p) const { return particles_[p].part; }
  Vec2 particle_local(int p) const { return particles_[p].local; }  // in the part frame, from the part COM
  const std::vector<int>& body_parts(int body) const;  // (valid until the structure changes)
  Vec2 particle_position(int p) const;
  Vec2 particle_velocity(int p) const;
  Vec2 part_position(int part) const;  // centre of mass
  double part_angle(int part) const;   // unwrapped [rad]
  // Both at once, inline (the server exports every block's 60 times a second): the same bits as part_motion().
  void part_pose(int part, Vec2& x, double& th) const {
    const Part& p = parts_[static_cast<size_t>(part)];
    const BodyState& s = state_[static_cast<size_t>(p.body)];
    x = s.x + s.q * p.rel_x;
    th = s.th + p.rel_th;
  }
  // Inline: Algorithm 1 measures every hinge from its two blocks' rotations after every step.
  Rot part_rotation(int part) const {
    const PartFrame& p = part_frames_[static_cast<size_t>(part)];
    return state_[p.body].q * p.rel_q;
  }
  Vec2 part_velocity(int part) const;
  double part_omega(int part) const { return state_[part_frames_[static_cast<size_t>(part)].body].w; }

  double kinetic_energy() const;    // dynamic bodies only [J]
  double potential_energy() const;  // gravity, dynamic bodies only [J]
  Energy energy() const;            // both, in one pass (no pass when nothing moved since the last call)
  Vec2 linear_momentum(const std::vector<int>& parts) const;
  double angular_momentum(const std::vector<int>& parts, const Vec2& about) const;
  double max_hinge_error() const;   // largest gap of a hinge or weld: two hinged particles' distance (rolling: its
                                    // arc centres' distance from 2 r along the rolling direction) [m]
  bool finite() const;              // no NaN or infinity anywhere in the state
  // fn(from, to, lane) over [0, count) in the step's two halves, on its two threads when it has them (in_halves
  // below), for a caller's per-block pass that only reads the world: what it computes must not depend on the halves.
  template <class Fn>
  void for_halves(size_t count, Fn&& fn) const {
    in_halves(count, std::forward<Fn>(fn));
  }

  // Moment [N m, counter-clockwise] that a weld exerted, on average over the last step, on the parts on
  // particle pb's side of it, taken about the weld point, or, given particles about_a and about_b of the welded
  // body, about their midpoint at mid-step (a face contact's other end). Used to decide when a lock lets go.
  double weld_moment(int pa, int pb, int about_a = -1, int about_b = -1) const;

 private:
  struct Particle { double mass; int part; Vec2 local; };
  struct Part {
    int first_particle = 0, particle_count = 0;
    double mass = 0, inertia = 0;  // about its own centre of mass
    int body = -1;
    Vec2 rel_x{0, 0};              // part pose in its body's frame
    Rot rel_q;
    double rel_th = 0;
    bool kinematic = false;
    Drive drive;
  };
  // Each part's body and rotation in it, as in parts_ (set together with them): what part_rotation() and
  // part_omega() read, 24 bytes a part instead of a Part's cache lines (Algorithm 1 reads every block's each step).
  struct PartFrame {
    Rot rel_q;
    int body = -1;
  };
  // A joint between particles pa and pb; a rolling one (radius > 0) keeps its contact direction's offset psi0
  // (combine()).
  struct Joint {
    int pa, pb;
    JointKind kind;
    bool alive;
    double radius = 0, psi0 = 0;
  };
  struct Body {
    double mass = 0, inertia = 0, inv_mass = 0, inv_inertia = 0;
    double own_inertia = 0;  // the sum of its parts' moments about their own centres (inertia, for one part)
    double gyration = 0;     // sqrt(inertia / mass), 0 when kinematic
    bool kinematic = false;
    bool single_part = true;  // one part: its frame is the body frame (the common case, no loop over parts)
    int anchor_part = -1;  // the part whose frame is the body frame; a driven part if the body is kinematic
  };
  // One hinge in the solver's order: body a, body b, anchors in the body frames. Rows k-1 and k share body
  // rows[k].a == rows[k-1].b exactly when link_prev is set. The last four flags are derived from the others (in
  // rebuild()) so that the sweeps test one byte instead of loading the next row and both bodies: 64 bytes in all.
  struct Row {
    Vec2 ra, rb;  // first: Eigen aligns a Vec2 to 16 bytes, and two ints before it would pad the row to 80
    int a, b;
    int part_a, part_b;
    int joint;
    bool link_prev;
    bool shares_next;  // rows[k + 1].link_prev: body b is the next row's body a
    bool corrects_a;   // body a is dynamic and in no earlier row: this row's sweep step corrects it
    bool corrects_b;   // body b is dynamic
    bool kinematic_side;  // body a or b is kinematic: the row's impulses are recorded for the work its drive does
    bool rolls;           // a rolling hinge: its levers move with the contact point (roll_[k])
  };
  // A rolling row's arc radius and the offset of its contact direction from its bodies' mean angle:
  // u = (cos psi, sin psi), psi = (th_a + th_b) / 2 + psi0, u pointing from body a's arc centre toward body b's.
  struct Roll {
    double radius = 0, psi0 = 0;
  };
  static_assert(sizeof(Row) == 64, "a Row is one cache line");

  Vec2 joint_gap(const Joint& j) const;  // queries.cpp
  double rolling_offset(int pa, int pb) const;  // topology.cpp

  // topology.cpp
  void rebuild();
  static void order_rows(const std::vector<Body>& bodies, std::vector<Row>& rows);
  void ensure_built() {
    if (dirty_) rebuild();
  }
  struct PartMotion { Vec2 x, v; double th, w; Rot q; };
  PartMotion part_motion(int part) const;
  void set_body_from_parts(int body, const std::vector<int>& parts, const std::vector<PartMotion>& motion);

  // constraints.cpp
  void world_anchors(std::vector<Vec2>& ua, std::vector<Vec2>& ub) const;
  void start_anchors();  // ua0_, ub0_ at the current state (kept from the last velocity projection when still valid)
  // A rolling row's contact offset r u at the current state (or at the bodies' states given): its levers are
  // q_a ra + r u and q_b rb - r u, and its gap (x_a + q_a ra) - (x_b + q_b rb) + 2 r u. The Jacobian of that gap is
  // a plain hinge's at the contact point (docs/model.md section 9), so every solve works with these levers as they
  // are. The angles are the unwrapped ones: the contact direction turns continuously through any number of turns.
  // roll_direction: u alone (unit_at, geometry.hpp).
  Vec2 roll_direction(size_t k, const BodyState& a, const BodyState& b) const {
    return unit_at(0.5 * (a.th + b.th) + roll_[k].psi0);
  }
  Vec2 roll_direction(size_t k) const { return roll_direction(k, state_[rows_[k].a], state_[rows_[k].b]); }
  Vec2 roll_offset(size_t k, const BodyState& a, const BodyState& b) const {
    return roll_[k].radius * roll_direction(k, a, b);
  }
  Vec2 roll_offset(size_t k) const { return roll_offset(k, state_[rows_[k].a], state_[rows_[k].b]); }
  // What a rolling row's gap accelerates by beyond a plain hinge's at its contact point, -w^2 u on each lever:
  // the gap's second derivative has -w_a^2 (q_a ra) + w_b^2 (q_b rb) - 2 r psi'^2 u, psi' = (w_a + w_b) / 2, which is
  // the plain hinge's -w_a^2 u_a + w_b^2 u_b plus (w_a - w_b)^2 / 2 r u (the index-1 equations of the explicit and
  // reduced integrators need it).
  Vec2 rolling_acceleration(size_t k) const {
    const BodyState& a = state_[rows_[k].a];
    const BodyState& b = state_[rows_[k].b];
    const double dw = a.w - b.w;
    return (0.5 * dw * dw) * roll_offset(k, a, b);
  }
  // Row k's levers (world frame, from each body's centre to the hinge point) at the current state.
  [[gnu::always_inline]] void row_levers(size_t k, Vec2& ua, Vec2& ub) const {
    const Row& r = rows_[k];
    ua = state_[r.a].q * r.ra;
    ub = state_[r.b].q * r.rb;
    if (r.rolls) {
      const Vec2 u = roll_offset(k);
      ua += u;
      ub -= u;
    }
  }
  Vec2 row_residual(size_t k) const {
    const Row& r = rows_[k];
    const BodyState& a = state_[r.a];
    const BodyState& b = state_[r.b];
    const Vec2 gap = (a.x + a.q * r.ra) - (b.x + b.q * r.rb);
    return r.rolls ? Vec2(gap + 2 * roll_offset(k, a, b)) : gap;
  }
  double position_residual();  // residuals(work_.c), or the last solve's when the positions have not changed since
  // q += W (f, tau) for one dynamic body, f and tau its sums of row multipliers and their moments; with
  // velocity_scale = 1/h the same change is made to its velocity (SHAKE: the multipliers are the step's impulses).
  // Inline: it is the innermost work of every Newton iteration.
  [[gnu::always_inline]] void correct_body(int b, const Vec2& f, double tau, double velocity_scale) {
    const Body& body = bodies_[b];
    BodyState& s = state_[b];
    const Vec2 dx = body.inv_mass * f;
    const double dth = body.inv_inertia * tau;
    s.x += dx;
    s.th += dth;
    s.q = turned_by_small_correction(s.q, dth);
    s.v += velocity_scale * dx;
    s.w += velocity_scale * dth;
  }
  // The force and moment that row k's multiplier (negated: it acts on its body b) and, when row k + 1 shares that
  // body, row k + 1's put on rows_[k].b, summed in that order as every sweep sums them.
  [[gnu::always_inline]] void load_on_b(int k, const Vec2* mu, const Vec2* ua, const Vec2* ub, Vec2& f,
                                        double& tau) const {
    f = -mu[k];
    tau = -cross(ub[k], mu[k]);
    if (rows_[k].shares_next) {
      f += mu[k + 1];
      tau += cross(ua[k + 1], mu[k + 1]);
    }
  }
  double forward_residual(const BlockTridiag& sys);
  double correct_along_chain(const BlockTridiag& sys, const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0,
                             double velocity_scale);
  void factor_exact_forward(const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0);
  double cut_back(double res, double next, const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0,
                  double velocity_scale);
  double newton_iteration(bool forward, bool& exact, double res, const std::vector<Vec2>& ua0,
                          const std::vector<Vec2>& ub0, double velocity_scale);
  double linesearch_iteration(const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0, double velocity_scale);
  void build_system(const std::vector<Vec2>& ua, const std::vector<Vec2>& ub, BlockTridiag& sys) const;
  void factor_system(const std::vector<Vec2>& ua, const std::vector<Vec2>& ub);
  void build_newton_system(const std::vector<Vec2>& ua, const std::vector<Vec2>& ub,
                           const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0, BlockTridiag& sys) const;
  double residuals(std::vector<Vec2>& c) const;
  void apply_correction(const std::vector<Vec2>& mu, const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0,
                        double velocity_scale);
  bool solve_positions(const std::vector<Vec2>& ua0, const std::vector<Vec2>& ub0, double velocity_scale);
  void constraint_accelerations(std::vector<Vec2>& lin, std::vector<double>& ang, double impulse_weight, double h);

  // step.cpp
  void step_fixed(double h);
  void step_adaptive(double h);
  double difference(const std::vector<BodyState>& other) const;
  void drive_kinematic(double t);
  void accumulate_forces(std::vector<Vec2>& f, std::vector<double>& tau, double h) const;
  void body_force(int b, Vec2& f, double& tau) const;
  void kick(double h, const std::vector<Vec2>& f, const std::vector<double>& tau);
  void drift(double h);
  void kick_drift(double h_kick, double h);
  // The integrators, each in its own file (docs/model.md section 3).
  void shake_positions(double h, double h_kick);  // shake.cpp: SHAKE's position stage, shared with RATTLE
  void step_shake(double h);       // shake.cpp: symplectic_euler
  void step_rattle(double h);      // rattle.cpp
  void step_projection(double h);  // projection.cpp
  void step_euler(double h);       // euler.cpp
  void step_rk4(double h);         // rk4.cpp
  void stabilise_explicit();       // constraints.cpp: the explicit integrators' post-stabilisation
  void step_reduced(double h);     // reduced.cpp
  void step_midpoint(double h);    // midpoint.cpp
  void rescue_guess(double h, const double* scales, size_t count);  // midpoint.cpp
  void apply_seed(double s);                                         // midpoint.cpp
  bool rescuing_ = false;  // in rescue_guess's shorter steps
  struct {
    std::vector<Vec2> lam;
    std::vector<double> t;
  } seed_;                   // the last rescue stage's impulses and turns
  double seed_scale_ = 0;   // what the next stage scales them by (0: its own first guess)
  bool reduced_applies();
  double factor_current_forward();
  void symmetric_row(int k, std::vector<Vec2>& ua, std::vector<Vec2>& ub, double* d, Mat2& u_prev) const;
  bool solve_projection(double velocity_scale);
  void mark_state_changed() {
    ++state_version_;
    ++motion_version_;
  }
  void mark_motion_changed() { ++motion_version_; }  // velocities only

  Options options_;
  std::vector<Particle> particles_;
  std::vector<Part> parts_;
  std::vector<PartFrame> part_frames_;  // parts_[i].rel_q and .body
  std::vector<Joint> joints_;
  std::vector<Body> bodies_;
  std::vector<std::vector<int>> body_parts_;
  std::vector<Row> rows_;
  std::vector<Roll> roll_;  // per row; radius 0 for a plain hinge
  std::vector<BodyState> state_;
  std::vector<BodyState> other_state_;  // the reduced step writes here, then swaps: it holds the state before it
  std::vector<AppliedForce> forces_;
  double t_ = 0;
  std::uint64_t structure_ = 0;
  bool dirty_ = false;

  // Factorisation of G M^-1 G^T at the state with version factor_version_: the velocity projection that ends a
  // step factors it, and the next step's position solve reuses it as its (chord) Newton matrix.
  BlockTridiag system_;
  BlockTridiag newton_;  // the exact (non-symmetric) Newton matrix, when the chord is not enough
  std::uint64_t state_version_ = 1, factor_version_ = 0;
  // Changes with any position or velocity (state_version_ with positions only): energy() is kept for it, so that a
  // step's energy at its start is the last one's at its end, one pass per step for the watchdog instead of two.
  std::uint64_t motion_version_ = 1;
  mutable std::uint64_t energy_version_ = 0, energy_structure_ = 0;
  mutable Energy energy_;
  StepStats stats_;

  // The last step's impulses, for weld_moment() and for the work of driven bodies: per row [N s] (applied at the
  // step's anchors; every row while a weld exists, else the rows with a kinematic body only), per body the state
  // at the start of the step, and the step length.
  std::vector<Vec2> row_impulse_;
  // The midpoint step's mean hinge forces over the last step [N] (its impulses over h), per row, and over the two
  // steps before it: the next step's first guess, which saves it Newton iterations wherever the forces change little
  // from step to step (midpoint.cpp, first_force). Saved in snapshots, so that a redone step, a re-simulation and a
  // resumed log (a re-run from the start) take the same bits. The last step's are carried across a rebuild for the
  // hinges that remain, zero for a new one; the older two are not (force_steps_ starts again at 1). The three are
  // always the same length.
  std::vector<Vec2> hinge_force_, hinge_force_1_, hinge_force_2_;
  int force_steps_ = 0;      // consecutive midpoint steps of force_step_h_ behind those forces, at most 3
  double force_step_h_ = 0;  // their length [s]
  // The midpoint steps to wait before the next tries a window from its first guess, and the wait after the next failed
  // try (midpoint.cpp, kGuessWindowWait). Saved in snapshots too: whether a step tries changes its bits.
  int guess_window_wait_ = 0, guess_window_backoff_ = 0;
  std::vector<BodyState> step_start_;
  std::vector<AppliedForce> step_forces_;  // the applied forces as the last step used them
  std::uint64_t step_structure_ = 0;  // structure the last step ran on; weld_moment() is void after a restructure
  double last_h_ = 0;
  double adaptive_h_ = 0;  // the adaptive step's next trial sub-step [s]; 0 = the whole step
  double adaptive_floor_ = 0;  // set_adaptive_floor()

  bool has_welds_ = false;
  bool has_rolling_ = false;  // a rolling row exists (rebuild())
  // The rows with a kinematic body (rebuild()), and for the step under way their kinematic anchors' velocities at
  // its start; the applied forces' lever arms and points' velocities at its start. For StepStats::work.
  std::vector<int> kinematic_rows_;
  std::vector<int> kinematic_bodies_;  // (rebuild()) so that driving them is not a pass over every body
  std::vector<Vec2> kinematic_v0_, force_arm_, force_v0_;
  void start_work();
  double finish_work(double t0, double h) const;
  // True when row k's impulses are recorded this step (see row_impulse_).
  bool records_impulse(const Row& r) const { return has_welds_ || r.kinematic_side; }

  // State versions at which ua0_/ub0_ and residual_ were computed: a step that starts where the last one ended
  // reuses them instead of another pass over the chain.
  std::uint64_t anchors_version_ = 0, residual_version_ = 0;
  double residual_ = 0;

  // The reduced step's view of the structure (reduced_applies()), for the structure it was made for: each chain's rows
  // [first, last] and whether it grows from its last row's body b (driven) instead of its first row's body a;
  // whether every chain has at most one driven end (else SHAKE steps); and the dynamic bodies in no hinge.
  struct ReducedChain {
    int first, last;
    bool from_end;
  };
  std::uint64_t reduced_structure_ = ~std::uint64_t{0};
  bool reduced_ok_ = false;
  std::vector<ReducedChain> reduced_chains_;
  std::vector<int> loose_bodies_;

  // The midpoint step's unknowns and per-step scratch (midpoint.cpp): per body the half-angle tangent t = tan(turn / 2)
  // and the mean velocity's change vbar - v, with the sums and Newton terms of the current iterate; per row the impulse, the levers at
  // the midpoint and the end.
  struct MidpointWork {
    std::vector<double> t, rho, inv_jac, alpha, beta, spin_gain, damp, stiff_coef, lift, force_ang, force_stiff;
    std::vector<double> kt;  // per body 1 / (1 + t^2), kept with t
    std::vector<Vec2> vbar, vfree, lam, dlam, mid_a, mid_b, end_a, end_b;
    std::vector<BodyState> kinematic_start;
    std::vector<Vec2> force_lever;  // applied forces' levers at the start, world frame
    std::vector<double> force_work;  // their work over the step
    std::vector<Vec2> kinematic_anchor;  // the kinematic rows' driven anchors at the start, world frame
    std::vector<Vec2> roll_u0;           // per row: a rolling row's contact direction at the start
    // The state and structure for which a step's end measured roll_u0 (its predicted end, midpoint.cpp).
    std::uint64_t roll_u0_version = 0, roll_u0_structure = 0;
    // What alpha, beta, spin_gain and damp (and spin_gyration, their largest h / 4I times a body's radius of
    // gyration) were computed for: they depend on the bodies (which change only with the structure), the step's
    // length and the damping, not on the state, and are kept from step to step while these stay.
    struct BodyConstantsKey {
      std::uint64_t structure = ~std::uint64_t{0};
      double h = 0, linear_damping = 0, angular_damping = 0;
      bool operator==(const BodyConstantsKey&) const = default;
    };
    BodyConstantsKey constants_key;
    double spin_gyration = 0;
    // Whether a step's first guess is likely to solve it, from how the last steps' guesses fared: the first pass then
    // measures the residual alone, and builds the Newton blocks only if the guess falls short. The odds are kept
    // apart for each pattern of the last three outcomes (a chain at rest goes round a cycle of guessed and iterated
    // steps, e.g. three iterated and one guessed: docs/benchmarks.md, "Ninth round"), each moved half the way to
    // every outcome (so that a cycle is learnt in a few turns), and start at what the last outcome was. They decide
    // which pass runs first, never what it computes: a step's bits do not depend on them.
    struct GuessOdds {
      static constexpr unsigned kPatterns = 8;  // the last three outcomes, the newest in bit 0 (1: a right guess)
      unsigned last = 0;
      std::array<double, kPatterns> odds = {0, 1, 0, 1, 0, 1, 0, 1};
      // The residual-alone pass costs about a third of a Newton pass (about 200 against 630 instructions a row on the
      // held ladder), so it pays to go first when a right guess is likelier than that: a right one saves the rest of
      // a Newton pass, a wrong one costs the check.
      bool expect_right() const { return odds[last] > 1.0 / 3; }
      void record(bool right) {
        double& p = odds[last];
        p += 0.5 * ((right ? 1.0 : 0.0) - p);
        last = ((last << 1) | (right ? 1u : 0u)) % kPatterns;
      }
    } guess_odds;
    // With rolling rows (midpoint.cpp, rolling_newton): per body the exact d rho / d t, per row d rho_a / d t_b and
    // d rho_b / d t_a, the 3x3 Newton system and its solution (dL_k, dt_b(k)).
    std::vector<double> jac, couple_ab, couple_ba;
    std::vector<RollingTerms> roll;  // per rolling row, this pass's contact terms (midpoint.cpp, roll_rows)
    BlockTridiag3 newton3;
    std::vector<Vec3> dx;
  };
  MidpointWork mid_;

  // A chain of at least kSplitRows rows has the midpoint step's passes solved in two halves (midpoint.cpp), and its
  // per-body loops run in the same halves: the step's, the snapshot's copy and the energy's, so that each half's data
  // stays with the thread that works on it. in_halves(count, fn) calls fn(from, to, lane) for [0, count / 2) and
  // [count / 2, count), on two threads when Options::threads allows, or fn(0, count, 0) for a shorter chain. What it
  // computes depends on the chain's length only, never on the threads.
  static constexpr int kSplitRows = 2048;
  bool split_chain() const { return static_cast<int>(rows_.size()) >= kSplitRows; }
  template <class Fn>
  void in_halves(size_t count, Fn&& fn) const {
    if (!split_chain()) return fn(size_t{0}, count, 0);
    lanes_.set_parallel(options_.threads >= 2);
    lanes_.run([&](int l) { fn(l == 0 ? size_t{0} : count / 2, l == 0 ? count / 2 : count, l); });
  }
  mutable Lanes lanes_;  // the second thread (Options::threads)

  // The arc-centre levers at the start of a step, kept while the state has not moved (anchors_version_).
  std::vector<Vec2> ua0_, ub0_;
  // The other integrators' per-step scratch (their files, constraints.cpp and step.cpp), kept from step to step only
  // so that a step does not allocate it: the hinges' levers, residuals and multipliers, the per-body sums of their
  // forces and moments, the users' forces and torques, the explicit methods' accelerations and the drives' (kin_acc,
  // kin_alpha), and the adaptive step's trial taken whole.
  struct StepWork {
    std::vector<Vec2> ua, ub, c, mu, f, force, acc_lin, kin_acc;
    std::vector<double> tau, torque, acc_ang, kin_alpha;
    std::vector<BodyState> whole;
  };
  StepWork work_;
};

// Row k of K = G W G^T at the current state for BlockTridiag::factor_forward_symmetric(), its anchors stored in
// ua[k] and ub[k]: D_k = (w_a + w_b) I + i_a perp(u_a) perp(u_a)^T + i_b perp(u_b) perp(u_b)^T as {d00, d01, d11}
// (perp(u) perp(u)^T = [uy^2, -ux uy; -ux uy, ux^2]) and U_{k-1} = -(w_s I + i_s perp(u_b,k-1) perp(u_a,k)^T).
// In the header: the velocity projection (constraints.cpp) and the reduced step (step.cpp) inline it in their sweeps.
[[gnu::always_inline]] inline void World::symmetric_row(int k, std::vector<Vec2>& ua, std::vector<Vec2>& ub,
                                                        double* d, Mat2& u_prev) const {
  const Row& r = rows_[k];
  const Body& A = bodies_[r.a];
  const Body& B = bodies_[r.b];
  Vec2 pa, pb;
  row_levers(static_cast<size_t>(k), pa, pb);
  ua[k] = pa;
  ub[k] = pb;
  const double w = A.inv_mass + B.inv_mass, ia = A.inv_inertia, ib = B.inv_inertia;
  d[0] = w + ia * pa.y() * pa.y() + ib * pb.y() * pb.y();
  d[1] = -(ia * pa.x() * pa.y() + ib * pb.x() * pb.y());
  d[2] = w + ia * pa.x() * pa.x() + ib * pb.x() * pb.x();
  if (r.link_prev) {
    const Vec2& p = ub[k - 1];  // perp(p) perp(pa)^T = [py pay, -py pax; -px pay, px pax]
    u_prev << -(A.inv_mass + ia * p.y() * pa.y()), ia * p.y() * pa.x(), ia * p.x() * pa.y(),
        -(A.inv_mass + ia * p.x() * pa.x());
  } else {
    u_prev.setZero();
  }
}

}  // namespace ladder::core
