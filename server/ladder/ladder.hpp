// The Jacob's ladder built from the engine's primitives (paper sections 4-5). (Its ribbons are cosmetic: the viewer
// derives them from the hinges, docs/viewer.md.)
//
// Blocks are seen side-on: a rectangle `length` tall and `thickness` wide, with four corner particles and a centre
// particle (number 4), numbered as in the paper's Figure 4:
//  - corner c XOR 1 walks along the length, c XOR 2 across the width;
//  - hinge k joins blocks k-1 and k at corner c on both blocks, c in {0, 1} for odd k and {2, 3} for even k;
//  - in the initial column, corners 0 and 1 are on the right edge; the lengthwise vector (corner 0 -> 1) points
//    up on even blocks and down on odd ones; hinge k starts at corner 0 (odd k) or 3 (even k), i.e. at block
//    k-1's bottom corner on the right edge for odd k, the left edge for even k.
// Each corner carries 1/12 of the block's mass and the centre 2/3, which gives exactly the mass, centre and
// moment of inertia of a uniform rectangle.
//
// Hinge k allows relative rotation through one half-turn only (Figure 5). With a = block k-1's and b = block k's
// unit vector from the hinged corner along the length, and sigma = cross(e_c, w_c) of block k-1 (+1 or -1: the
// side its body lies on), s = sigma * cross(a, b) is <= 0 in the allowed half and crosses zero only when the pair
// is straight (a = -b) or folded (a = b). Algorithm 1 acts when s > 0: flip-flop if |a + b| is large (folded),
// else the pair meets its straight stop, a one-sided contact: an impact, or a lock while the loads press it there.
// Crossings are located in time so the restructure happens where s = 0: at that instant the far corners of a folded
// pair coincide, and the flip-flop moves the hinge there without any position jump.
#pragma once

#include "core/world.hpp"
#include "ladder/action.hpp"

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace ladder::model {

using core::Vec2;

enum class Top { Held, Pinned, Free };
// Initial configuration. Straight: the blocks in one vertical column (not at rest under gravity: with corner
// hinges each block hangs tilted). Hanging: at rest in static equilibrium. Taking moments about hinge k for the
// blocks below it shows that hinge k, block k's centre and hinge k+1 lie on the block's diagonal, so in equilibrium
// every diagonal is vertical, whatever the masses: block angles +-atan(thickness / length), alternating.
enum class Start { Hanging, Straight };
// How a flip-flop makes velocities consistent. Corner: the paper's Algorithm 2 literally, a perfectly inelastic
// meeting of the two far corners only (it conserves a held pair's free block's angular momentum about the new
// hinge); for blocks longer than 1.4x their thickness it reverses the pair's relative spin, so the pair rattles
// between its two hinges, losing 3/4 of its relative energy per rattle until it comes to rest. Face: the two
// faces meet (perfectly inelastic for the whole face, a momentary weld), the pair stops folding at once and the
// hinge moves; the impulses are still internal, so free bodies keep their linear and angular momentum.
enum class FlipImpact { Face, Corner };
// The hinge between two blocks. Corner: the paper's, two corner particles combined (a pin at the corner). Rolling: the
// real toy's, rounded block ends (arcs of radius end_radius at each corner, centred end_radius in from both edges)
// rolling on each other without slipping, the pivot at their contact point, where the tapes cross (docs/model.md
// section 9); end_radius 0 is the corner hinge.
enum class HingeKind { Corner, Rolling };

struct LadderSpec {
  int blocks = 6;
  double length = 0.064;     // [m], along the hinges' axis of travel (vertical in the hanging ladder)
  double thickness = 0.013;  // [m]
  double mass = 0.025;       // [kg] per block, unless `masses` is given
  std::vector<double> masses;  // per-block masses [kg]; empty = all `mass`
  Top top = Top::Held;         // held in a hand (kinematic), pinned to the world at its top-left corner, or free
  Start start = Start::Hanging;
  FlipImpact flip_impact = FlipImpact::Face;
  bool logic = true;           // Algorithm 1: flip-flops, locks and unlocks
  double tip_duration = 0.3;   // [s] for the hand to turn the top block through 180 degrees
  // [N m] a meeting with the straight stop is a lock unless the stop would have to pull harder than this, and a lock
  // lets go once it would
  double unlock_threshold = 1e-5;
  double capture_distance = 0.005; // [m] farthest apart two corners may be for a join
  // Hinge particles sit this fraction of the thickness in from the edge: 0 is the paper's corners, 0.5 the middle
  // of the block's end, near where the real toy's ribbons cross (paper, section 4). Corner pivots make each
  // toppling block lift the whole chain below it by up to the thickness, a potential well that deepens with the
  // number of blocks below (docs/model.md); an inset pivot shrinks it.
  double hinge_inset = 0;
  HingeKind hinge = HingeKind::Corner;
  double end_radius = 0;     // [m] rolling hinges: 0 to thickness / 2 (fully rounded ends)
  double kick_omega = 0;     // initial angular velocity of block 1 about its top hinge [rad/s]
  double tilt = 0;           // initial rotation of the whole column about its top-left corner [rad]
};

// Impact: a straight pair met its stop and the loads pull it open again, so the contact does not stay (one event,
// the energy of the meeting removed); Lock: it met the stop and the loads press it there, so the pair is held
// straight until an Unlock (docs/model.md section 5).
enum class EventKind { FlipFlop, Impact, Lock, Unlock, Break, Join, SolverWarning };
inline constexpr int kEventKinds = 7;
static_assert(static_cast<int>(EventKind::SolverWarning) + 1 == kEventKinds, "kEventKinds counts EventKind");
const char* to_string(EventKind);

struct Event {
  double t = 0;
  EventKind kind = EventKind::FlipFlop;
  int hinge = 0;              // hinge k joins blocks k-1 and k; hinge 0 is the top block's hold or pin
  double energy_removed = 0;  // [J] by the velocity fix of a restructure
  std::string detail;
};

// Energy the blocks lost [J], by where it went: each kind of event's velocity fix (a flip-flop's landing, an impact
// or a lock against the stop, a join), and the motion between events (damping, hinge friction and the integrator's
// own error: over each step, the energy at its start plus the work the hand and the users' forces put in, less the
// energy at its end).
struct Losses {
  std::array<double, kEventKinds> removed{};  // by EventKind
  double motion = 0;
  double total() const {
    double sum = motion;
    for (double r : removed) sum += r;
    return sum;
  }
};

enum class HingeStatus { Hinged, Locked, Broken };
const char* to_string(HingeStatus);

struct HingeInfo {
  int corner = 0;  // the particle number hinged on both blocks
  HingeStatus status = HingeStatus::Hinged;
  int flips = 0;   // flip-flops so far
};

class Ladder {
 public:
  Ladder(const LadderSpec& spec, const core::Options& options);
  Ladder(const Ladder&) = delete;
  Ladder& operator=(const Ladder&) = delete;

  // Advances the simulation by h, locating every flip-flop and lock inside the step and applying Algorithm 1.
  // With the adaptive step, `interrupted` (when given) is asked between two of its sub-steps, and true ends the step
  // there by throwing Interrupted: the ladder is left at the end of the last sub-step, inside the step.
  void advance(double h, const std::function<bool()>& interrupted = {});
  struct Interrupted {
    int substeps_taken = 0;
  };

  // --- interventions; each throws std::invalid_argument with the reason when it cannot be done ---
  // The one dispatch of an action (a client's, a log's or a timeline's) to the interventions below; what the
  // action leaves open it settles here: a poke without a point is at the block's centre, a grab without a target
  // holds its point where it is, and a grip's angle is the turn nearest the block's own (a hand turns a block the
  // short way).
  void apply(const Action& action);
  void tip();                      // turn the held top block 180 degrees in the allowed direction
  double tip_end_time() const;     // when the last tip finishes
  void break_hinge(int k);
  void join_hinge(int k);
  // An impulse at a world point (none: the block's centre); returns dKE.
  double poke(int block, const std::optional<Vec2>& point, const Vec2& impulse);
  void push(int block, const Vec2& local_point, const Vec2& force, double duration);
  // A user's hand on a block: the point `local` of the block (in its frame) is pulled toward the world point
  // `target` by a critically damped spring-damper and, when `hold_angle`, the block is turned toward `angle` by a
  // torsional one. stiffness <= 0 picks a natural frequency of 100 rad/s for the block alone; any frequency is
  // capped at 0.2 / dt so that the explicit evaluation stays stable. Several blocks may be held at once (one grip
  // per block; grabbing a held block again replaces its grip). The forces are evaluated at the start of each step
  // and held over it.
  struct Grip {
    int block = -1;
    Vec2 local{0, 0}, target{0, 0};
    bool hold_angle = false;
    double angle = 0;      // [rad] target angle when hold_angle
    double stiffness = 0;  // [N/m]; 0 = the default
  };
  void grab(const Grip& grip);
  void drag(int block, const Vec2& target, const double* angle = nullptr);  // moves a grip's target
  void release(int block);
  const std::vector<Grip>& grips() const { return grips_; }
  // Changes the engine options live (the caller validates them).
  void set_options(const core::Options& options);

  // --- state ---
  const LadderSpec& spec() const { return spec_; }
  // The arc radius of the hinges between blocks: end_radius for rolling hinges, 0 for corner ones.
  double roll_radius() const { return spec_.hinge == HingeKind::Rolling ? spec_.end_radius : 0.0; }
  int blocks() const { return spec_.blocks; }
  double time() const { return world_.time(); }
  // The caller's clock, counted in steps (scene::Simulation), replaces the world's running sum of step lengths at the
  // end of a step; what was stamped with this instant (its events, releases and flip-flops) is stamped anew, so the
  // rules that look at "this instant" hold across it. Call it between steps only.
  void set_clock(double t);
  Vec2 block_centre(int i) const { return world_.part_position(i); }
  double block_angle(int i) const { return world_.part_angle(i); }
  void block_pose(int i, Vec2& centre, double& angle) const { world_.part_pose(i, centre, angle); }
  Vec2 lengthwise(int i) const;  // unit vector from corner 0 to corner 1
  Vec2 corner(int block, int c) const { return world_.particle_position(particle(block, c)); }
  const std::vector<HingeInfo>& hinges() const { return hinges_; }
  bool held() const;
  double hinge_measure(int k) const;  // s of the class comment (> 0 means inside a forbidden quadrant)
  // Kinetic and potential energy of every block but a held one [J] (what a State publishes): a block locked to the
  // held block counts too, moving with the hand, so the sum does not jump when one locks to it or lets go.
  double energy() const;
  // Every loss since construction, and the part of it up to the last flip-flop with the number of flip-flops (each
  // flip-flop's event says what was lost since the one before).
  const Losses& losses() const { return losses_; }
  // The work put into the blocks since construction [J]: the hand's drive (through the hinge it holds and on the
  // blocks locked to the held block, which it moves), pushes and grips over the steps, and pokes; and the energy of
  // the top block when the hand lets it go (`break 0`), less its potential energy when the hand takes it back
  // (`join 0`; its kinetic energy is the join's loss). So energy at the start + work_put_in() - losses().total() is
  // the energy now, to the ledger's rounding.
  double work_put_in() const { return work_put_in_; }
  double lost_by_last_flip() const { return lost_by_last_flip_; }
  int flip_flops() const { return flip_flops_; }
  // Solves the world rescued after their iteration limit (core::StepStats::rescues), over every step taken, the
  // watchdog's halves and event location's trials included.
  long rescued_solves() const { return rescued_solves_; }
  std::vector<Event> take_events();
  const core::World& world() const { return world_; }
  core::World& world() { return world_; }

  static int particle(int block, int c) { return 5 * block + c; }
  // Throws std::invalid_argument naming the valid range when block i does not exist.
  void check_block(int i) const;
  // Throws std::invalid_argument naming `what` unless `local` (from block i's centre, in its frame: x across its
  // thickness, y along its length) lies on the block, within 1 % of its half-sizes for rounding.
  void check_on_block(int i, const Vec2& local, const char* what) const;

 private:
  struct Hand;  // the held top block's prescribed motion
  void check_hinge(int k) const;
  bool any_violation(std::vector<double>& s, bool* clamped = nullptr) const;
  void violations_at_start(std::vector<double>& s);
  bool approaching(int k) const;
  double measure(int k, const core::Rot& qa, const core::Rot& qb) const;
  double locate(const core::Snapshot& start, const std::vector<double>& s0, double h, int& hinge);
  void restructure(int k);
  void meet_stop(int k);
  std::string lock_moment(double moment) const;
  void released(int k);
  bool held_again(int k, double before, const char* detail);
  bool take_back_release(int k, double removed);
  void contact_moments(std::vector<double>& moments, int meeting = -1);
  double contact_moment(const core::World& world, int k, bool other_end = false) const;
  bool folded(int k) const;   // hinge k's pair is nearer face to face than straight
  void move_hinge(int k);     // the hinge to the blocks' other ends (Algorithm 2, lines 1-3)
  double blocks_kinetic() const;
  double block_kinetic(int i) const;  // block i's kinetic energy, from its part's motion [J]
  double block_potential(int i) const;  // block i's potential energy [J]
  // The energy of the blocks locked to the held block [J] (energy() counts them, World::energy() does not).
  double hand_blocks_energy() const;
  // What a piece of time starts with, for the ledger (book_motion).
  struct PieceStart {
    core::Energy world;  // the dynamic bodies'
    double hand_blocks = 0;  // hand_blocks_energy()
  };
  PieceStart piece_start() const { return {world_.energy(), hand_blocks_energy()}; }
  void book_motion(const PieceStart& start);
  void check_unlocks();
  void emit(EventKind kind, int k, double energy, std::string detail = {});
  void advance_by(double h);  // advance() without the grips' forces and the adaptive walk
  std::string diverged(const core::Energy& e0, double h) const;
  // Why a step failed, for its message: the motion too violent for the step h (advising `usual`), unless the ladder
  // is so far from the origin that rounding alone keeps its hinges apart, which no smaller step can help.
  std::string too_violent(double h, const std::string& usual) const;
  // `start`: the world as it is now, when the caller has saved it already.
  void step_guarded(double h, int depth, const core::Snapshot* start = nullptr);
  void apply_grips(double h);
  void add_grip_forces(core::World& world, double h) const;
  double grips_until_ = 0, grips_h_ = 0;  // the grips' forces last applied: until when, and for what step

  LadderSpec spec_;
  core::World world_;
  std::vector<HingeInfo> hinges_;  // index k; hinge 0 is the hold / pin
  std::shared_ptr<Hand> hand_;
  int world_particle_ = -1;  // the pin's world particle when top == Pinned
  double s_detect_ = 0;      // s above which a hinge is in a forbidden quadrant
  std::vector<Event> events_;
  bool warned_ = false;   // a short-of-tolerance solve has been reported and not yet recovered from
  bool halving_ = false;  // steps are being redone in halves (reported once per episode)
  long rescued_solves_ = 0;
  bool locating_ = false;  // in locate(): its trial steps are single steps (see advance())
  // The watchdog redoes a failed step in halves, at most this deep (1/64 of the step), then gives up.
  static constexpr int kMaxHalvings = 6;
  // step_guarded()'s world before its step, one per depth of halving (0 to kMaxHalvings), reused: no allocation per
  // step. The outermost is also the start that advance_by() locates events from.
  std::array<core::Snapshot, kMaxHalvings + 1> before_;
  double mass_ = 0;  // [kg] of all the blocks, for diverged()'s floor
  // Block i's mass [kg]: ladder.masses' entry, or ladder.mass when the scene lists none.
  double block_mass(int i) const { return spec_.masses.empty() ? spec_.mass : spec_.masses[static_cast<size_t>(i)]; }
  double inertia_factor_ = 0;  // a block's moment of inertia about its centre over its mass [m^2]
  double step_h_ = 0;          // the step advance_by() is taking (contact_moments() steps a thousandth of it)
  double frame_h_ = 0;         // the step advance() is taking: sim.dt, of which step_h_ is a piece when adaptive
  core::World probe_;          // contact_moments()'s copy of the world for its trial step (reused buffers)
  std::vector<double> moments_;  // contact_moments()'s answer (reused)
  // contact_moments()'s moments of the folded pairs' face contacts about their other ends, where the pair would open
  // the other way (index k; 0 for a straight pair).
  std::vector<double> other_moments_;
  // Per hinge, when its contact was last let go (an impact or an unlock): a meeting at that same instant means that the
  // free motion turned the pair straight back in, so the contact must hold (meet_stop()).
  std::vector<double> released_at_;
  // Per hinge, when it last flip-flopped: a fold again within a step of that is a face contact (restructure()).
  std::vector<double> flipped_at_;
  // The energy ledger (losses()): the work the accepted steps of the piece under way put in, what was lost since the
  // last flip-flop (reported with the next one), and the total at the last flip-flop.
  double piece_work_ = 0, work_put_in_ = 0;
  Losses losses_, since_flip_;
  double lost_by_last_flip_ = 0;
  int flip_flops_ = 0;
  std::vector<Grip> grips_;  // sorted by block
  Vec2 unit_local(int i, int pair) const;
  // Per hinge k >= 1, for its present corner: sigma cross(u_a, u_b) and sigma u_a.u_b, so that measure() is two
  // products (set with the corner: construction and flip-flop).
  std::vector<std::array<double, 2>> measure_coef_;
  void set_measure_coef(int k);
  // The last step's closing any_violation(), reused as the next step's opening one while the positions and the
  // structure are those it measured (and no hinge was inside its forbidden half, where velocities count too).
  std::vector<double> s_cache_;
  std::uint64_t s_cache_version_ = 0, s_cache_structure_ = 0;
  bool s_cache_valid_ = false;
  // advance_by()'s measures at the start and the end of a step, kept so that a step neither allocates nor clears
  // them; the start takes the cache's values by a swap (which leaves the cache invalid) rather than a copy.
  std::vector<double> s_start_, s_end_;
  Grip& grip_of(int block);
  double nearest_turn(double angle, int block) const;
};

}  // namespace ladder::model
