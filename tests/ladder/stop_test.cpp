// The straight stop as a one-sided contact (docs/model.md section 5): a meeting is a perfectly inelastic impact that
// stays as a lock only while the loads press the pair into the stop, and a lock lets go at the step its contact's
// moment turns to pulling. Against closed forms on held and free pairs, then on the classic scene; and the energy
// ledger that the flip-flops and the offline summary report.
#include "scene/simulation.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <string>
#include <vector>

namespace ladder {
namespace {

using model::EventKind;

scene::Scene shipped(const std::string& name, const std::vector<std::string>& overrides = {}) {
  return scene::load_scene(std::string(LADDER_SOURCE_DIR) + "/config/scenes/" + name, overrides);
}

// The classic block (64 x 13 mm, 25 g) and its corner hinges: W = T.
constexpr double kL = 0.064, kT = 0.013, kM = 0.025, kG = 9.81;

// The classic toy cut to two blocks, the top one held still, with no drag and no timeline: block 1 swings about
// hinge 1 (its top-right corner) and can meet the straight stop only by turning clockwise.
scene::Scene held_pair(const std::vector<std::string>& more = {}) {
  std::vector<std::string> o{"ladder.blocks=2", "damping.linear=0", "damping.angular=0"};
  o.insert(o.end(), more.begin(), more.end());
  scene::Scene sc = shipped("classic.toml", o);
  sc.timeline.clear();
  return sc;
}

// A held pair kicked clockwise from rest hanging (its diagonal vertical) swings up to straight and meets the stop. The
// held block does not move, so the perfectly inelastic meeting stops block 1: it removes all of the relative turn's
// energy, 1/2 I_P w^2 at the meeting, which by energy conservation is the kick's 1/2 I_P w0^2 less the rise of block
// 1's centre from d = sqrt(L^2 + W^2) / 2 below the hinge to L / 2 below it; I_P = m (L^2 + T^2) / 12 + m d^2. At
// straight, gravity's moment about the hinge, m g W / 2, turns the block back into the allowed half: the contact
// would have to pull, so the meeting is one impact and the pair swings open at once (no lock, no unlock).
// Measured: the energy agrees to 1.2e-14 J of 1.6e-3 J (the midpoint step keeps energy to its solve's tolerance, and
// the meeting is located to s <= 2 tolerance / L, a 1e-11 rad turn).
TEST(Stop, HeldPairMeetingIsOneImpactThatRemovesTheTurnsEnergy) {
  const double w0 = 10;  // [rad/s] clockwise
  scene::Simulation sim(held_pair({"initial.kick_omega=-" + std::to_string(w0)}));
  const double d = std::sqrt(kL * kL + kT * kT) / 2;
  const double inertia = kM * (kL * kL + kT * kT) / 12 + kM * d * d;
  const double expected = 0.5 * inertia * w0 * w0 - kM * kG * (d - kL / 2);
  std::vector<model::Event> events;
  double s_after = 0, t_impact = -1;
  while (sim.time() < 0.1) {
    sim.step();
    for (const model::Event& e : sim.take_events()) events.push_back(e);
    if (t_impact < 0 && !events.empty()) t_impact = events[0].t;
    if (t_impact >= 0) {
      // Opening: s falls below zero and keeps falling for the 20 ms watched after the impact.
      const double s = sim.ladder().hinge_measure(1);
      if (sim.time() > t_impact + 1e-3) {
        EXPECT_LT(s, s_after) << "t = " << sim.time();
      }
      s_after = s;
      if (sim.time() > t_impact + 0.02) break;
    }
  }
  ASSERT_EQ(events.size(), 1u) << "first: " << (events.empty() ? "none" : model::to_string(events[0].kind));
  EXPECT_EQ(events[0].kind, EventKind::Impact);
  EXPECT_EQ(events[0].hinge, 1);
  EXPECT_NEAR(events[0].energy_removed, expected, 1e-9 * expected);
  EXPECT_EQ(sim.ladder().hinges()[1].status, model::HingeStatus::Hinged);
  EXPECT_LT(s_after, -1e-6);
}

// A free pair in no gravity, straight, block 1 kicked into the forbidden half: it meets the stop at once. The meeting
// keeps linear and angular momentum, so it removes exactly the kinetic energy above that of one rigid 2L x T
// rectangle with the same momentum P and angular momentum L_c about its centre of mass: KE0 - P^2 / 2M - L_c^2 / 2I_c
// with I_c = 2 m (L^2 + T^2) / 12 + 2 m (L / 2)^2 (L_c is constant: the centre moves uniformly). Turning as one body
// at W = L_c / I_c, block 1 would need the centripetal force m W^2 L / 2 from the hinge at its corner, whose moment
// about its centre, m W^2 L T / 4, the contact would have to cancel by pulling (5.2e-4 N m at W = 10 rad/s, as
// measured, 52 times ladder.unlock_threshold): so it is an impact, and the blocks turn apart.
TEST(Stop, FreePairMeetingRemovesTheRelativeTurnsEnergyAndKeepsMomentum) {
  const double w0 = -20;  // [rad/s] clockwise: into the forbidden half
  scene::Simulation sim(held_pair({"ladder.top=free", "ladder.start=straight", "sim.gravity=[0, 0]",
                                   "initial.kick_omega=" + std::to_string(w0)}));
  const core::World& w = sim.ladder().world();
  const std::vector<int> both{0, 1};
  const core::Vec2 p0 = w.linear_momentum(both);
  const double l0 = w.angular_momentum(both, core::Vec2::Zero()), ke0 = w.kinetic_energy();
  const core::Vec2 xc = 0.5 * (sim.ladder().block_centre(0) + sim.ladder().block_centre(1));
  const double mass = 2 * kM, ic = 2 * kM * (kL * kL + kT * kT) / 12 + 2 * kM * (kL / 2) * (kL / 2);
  const double lc = l0 - mass * core::cross(xc, p0 / mass);
  const double expected = ke0 - p0.squaredNorm() / (2 * mass) - lc * lc / (2 * ic);
  sim.step();
  const std::vector<model::Event> events = sim.take_events();
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].kind, EventKind::Impact);
  EXPECT_EQ(events[0].hinge, 1);
  EXPECT_EQ(events[0].t, 0.0);
  EXPECT_NEAR(events[0].energy_removed, expected, 1e-12 * ke0);
  EXPECT_GT(kM * (lc / ic) * (lc / ic) * kL * kT / 4, 10 * sim.ladder().spec().unlock_threshold);
  EXPECT_NEAR((w.linear_momentum(both) - p0).norm(), 0.0, 1e-15);
  EXPECT_NEAR(w.angular_momentum(both, core::Vec2::Zero()), l0, 1e-15);
  EXPECT_LT(sim.ladder().hinge_measure(1), 0);  // turned apart over the step
}

// A held pair pressed into the stop: a sideways push at block 1's centre (its moment about the hinge, F L / 2, three
// times gravity's m g W / 2 the other way) swings it to straight, and there the push keeps pressing: the meeting is
// a lock. The push ends at t = 0.3 s, a step boundary; from then on only gravity acts, which pulls the pair open, so
// the contact's moment changes sign at that instant and the lock lets go there: the unlock's time is 0.3 s, not a step
// later. In between the pair stays straight (hinge measure at the lock's, s <= s_det / 2). (Measured: the lock at
// 0.056 s, pressed with 3.19e-3 N m = F L / 2 - m g W / 2 for the block at rest; the unlock pulled with m g W / 2.)
TEST(Stop, PressedPairStaysLockedAndLetsGoTheStepThePushEnds) {
  scene::Simulation sim(held_pair());
  const double force = 3 * kM * kG * kT / kL, t_end = 0.3;
  sim.ladder().push(1, core::Vec2::Zero(), core::Vec2(-force, 0), t_end);
  std::vector<model::Event> events;
  while (sim.time() < 0.5) {
    sim.step();
    for (const model::Event& e : sim.take_events()) events.push_back(e);
    if (!events.empty() && events.back().kind == EventKind::Lock && sim.time() < t_end - 1e-9) {
      EXPECT_LE(sim.ladder().hinge_measure(1), 1e-10) << "t = " << sim.time();
    }
  }
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].kind, EventKind::Lock);
  EXPECT_LT(events[0].t, 0.2);
  EXPECT_GT(events[0].energy_removed, 0);
  EXPECT_EQ(events[1].kind, EventKind::Unlock);
  EXPECT_NEAR(events[1].t, t_end, 1e-9);
  EXPECT_EQ(sim.ladder().hinges()[1].status, model::HingeStatus::Hinged);
  EXPECT_LT(sim.ladder().hinge_measure(1), -1e-3);  // swung open
}

// The first number in an event's detail after `key`; details print 3 significant digits, within kDigits of the value.
constexpr double kDigits = 5e-3;
double number_after(const std::string& detail, const std::string& key) {
  const size_t at = detail.find(key);
  return at == std::string::npos ? std::nan("") : std::stod(detail.substr(at + key.size()));
}

// A pair pressed face to face. Without gravity, block 1 of a held pair is kicked counter-clockwise and folds up
// against block 0 (a flip-flop: the hinge moves to the far ends, block 1 stops); a push at its centre straight into
// block 0's face, F from the start, then closes it again about the new hinge at once. Flipping back would close it
// about the old one just as fast (before: 9100 flip-flops in 0.3 s, nanoseconds apart). Instead the faces' contact
// locks, its moments about both ends F L / 2 (the push's lever, block 1 at rest). A pull F at block 1's hinged
// corner, away from block 0, then opens the pair about the other end (F L less the push's F L / 2): the lock lets go
// after the first step pulled, and the hinge moves back to the ends it left (an unlock and a flip-flop, nothing to
// land).
TEST(Stop, PairPressedFaceToFaceLocksAndOpensAboutTheEndPulled) {
  scene::Simulation sim(held_pair({"sim.gravity=[0, 0]", "initial.kick_omega=20"}));
  model::Ladder& l = sim.ladder();
  const double force = 0.05;  // [N]
  l.push(1, core::Vec2::Zero(), core::Vec2(-force, 0), 10);
  const int first_corner = l.hinges()[1].corner;
  std::vector<model::Event> events;
  while (sim.time() < 0.3) {
    sim.step();
    for (const model::Event& e : sim.take_events()) events.push_back(e);
  }
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].kind, EventKind::FlipFlop);
  EXPECT_EQ(events[1].kind, EventKind::Lock);
  EXPECT_LT(events[1].t - events[0].t, 1e-6) << "closed again at once";
  EXPECT_NEAR(number_after(events[1].detail, "pressed with "), force * kL / 2, kDigits * force * kL / 2);
  EXPECT_NEAR(number_after(events[1].detail, " N m at the hinge and "), force * kL / 2, kDigits * force * kL / 2);
  EXPECT_NE(l.hinges()[1].corner, first_corner);
  EXPECT_EQ(l.hinges()[1].status, model::HingeStatus::Locked);
  // The pull acts at block 1's hinged corner, in its frame.
  core::Vec2 centre;
  double angle = 0;
  l.block_pose(1, centre, angle);
  const core::Vec2 end = core::Rot::of(angle).inverse() * (l.corner(1, l.hinges()[1].corner) - centre);
  const double t_pull = sim.time();
  l.push(1, end, core::Vec2(force, 0), 10);  // away from block 0's face, beside the push at the centre
  events.clear();
  while (sim.time() < t_pull + 0.05) {
    sim.step();
    for (const model::Event& e : sim.take_events()) events.push_back(e);
  }
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].kind, EventKind::Unlock);
  EXPECT_NE(events[0].detail.find("other ends"), std::string::npos) << events[0].detail;
  EXPECT_NEAR(events[0].t, t_pull + sim.scene().dt, 1e-9);  // judged after the first step pulled
  EXPECT_NEAR(number_after(events[0].detail, "other ends with "), force * kL / 2, kDigits * force * kL / 2);
  EXPECT_EQ(events[1].kind, EventKind::FlipFlop);
  EXPECT_EQ(events[1].energy_removed, 0);
  EXPECT_EQ(l.hinges()[1].corner, first_corner);
  EXPECT_EQ(l.hinges()[1].status, model::HingeStatus::Hinged);
  EXPECT_LT(l.hinge_measure(1), -1e-3);  // swung open about the old ends
}

// A pair pressed into its stop by a hand: the grip's force counts when the lock is judged after a step, as it does at
// the meeting. (The grip's force of a step runs out at its end, and the lock was judged without it: let go after each
// step and met again in the next, a lock and an unlock every step.) Block 1 of a held pair, grabbed at its centre
// and pulled past straight, locks and stays locked while held (before: 965 events in 0.5 s); released, gravity pulls
// it open.
TEST(Stop, PairHeldIntoItsStopByAGripStaysLocked) {
  scene::Simulation sim(held_pair());
  model::Ladder& l = sim.ladder();
  const core::Vec2 hinge = l.corner(1, l.hinges()[1].corner);
  // Turned clockwise about the hinge from hanging (diagonal vertical) through straight and 0.2 rad beyond.
  const core::Rot turn = core::Rot::of(-(std::atan(kT / kL) + 0.2));
  l.grab({.block = 1, .target = hinge + turn * (l.block_centre(1) - hinge)});
  std::vector<model::Event> events;
  while (sim.time() < 0.5) {
    sim.step();
    for (const model::Event& e : sim.take_events()) events.push_back(e);
  }
  // The grip brings it in fast, its damper pulling back: the first meeting may be an impact. Then one lock, for good.
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back().kind, EventKind::Lock);
  EXPECT_LT(events.back().t, 0.1);
  EXPECT_LE(events.size(), 2u);
  EXPECT_EQ(l.hinges()[1].status, model::HingeStatus::Locked);
  const double t_release = sim.time();
  l.release(1);
  sim.step();
  const std::vector<model::Event> after = sim.take_events();
  ASSERT_EQ(after.size(), 1u);
  EXPECT_EQ(after[0].kind, EventKind::Unlock);
  EXPECT_NEAR(after[0].t, t_release + sim.scene().dt, 1e-9);  // judged after the first step without the hand
  // Only gravity acts then, its moment m g W / 2 about the hinge (block 1 at rest, held straight below block 0).
  EXPECT_NEAR(number_after(after[0].detail, "pulled open with "), kM * kG * kT / 2, kDigits * kM * kG * kT / 2);
}

// A ladder let go at the top and held by one block below (two commands any client may send: break hinge 0, grab a
// block where it is): the blocks above fall and fold onto each other, pressed face to face. Before, the pairs
// flip-flopped back and forth nanoseconds apart, up to the 64 events a step allows (double-ripple.toml, block 3:
// 8 160 events in 3 s, 67 in one step; tall.toml, block 10: 8 809 and 74), each such step 100 times slower. Now no
// step has more than a few events, no hinge flip-flops three times within a microsecond, and the faces' contacts
// are met as contacts: face-to-face locks, and (on the rolling ladder) folds pulled open at the hinge they have.
TEST(Stop, ALadderLetGoAndHeldByOneBlockMakesNoEventStorm) {
  struct Case {
    const char* scene;
    int block;
    size_t most;  // events in a step, at most (measured 3 and 12)
    bool opens_at_the_hinge;
  };
  for (const Case& c : {Case{"double-ripple.toml", 3, 6, false}, Case{"tall.toml", 10, 20, true}}) {
    scene::Scene sc = shipped(c.scene);
    sc.timeline.clear();
    scene::Simulation sim(sc);
    model::Ladder& l = sim.ladder();
    l.break_hinge(0);
    l.grab({.block = c.block, .target = l.block_centre(c.block)});
    size_t most = 0;
    int face_locks = 0, opened_at_the_hinge = 0, warnings = 0;
    std::map<int, std::array<double, 2>> last_flips;  // each hinge's last two flip-flops
    while (sim.time() < 3) {
      sim.step();
      const std::vector<model::Event> events = sim.take_events();
      most = std::max(most, events.size());
      for (const model::Event& e : events) {
        face_locks += e.kind == EventKind::Lock && e.detail.find("face to face") != std::string::npos;
        opened_at_the_hinge += e.kind == EventKind::Impact && e.detail.find("face to face") != std::string::npos;
        warnings += e.kind == EventKind::SolverWarning;
        if (e.kind != EventKind::FlipFlop) continue;
        // Over and back at once happens (the fold, then the other end pulled open: the first flip-flop was a bounce);
        // a third within a microsecond would be the storm.
        std::array<double, 2>& t = last_flips.try_emplace(e.hinge, std::array<double, 2>{-1, -1}).first->second;
        EXPECT_GT(e.t - t[0], 1e-6) << c.scene << " hinge " << e.hinge << ": three flip-flops at t = " << e.t;
        t = {t[1], e.t};
      }
    }
    EXPECT_LE(most, c.most) << c.scene;
    EXPECT_EQ(warnings, 0) << c.scene;
    EXPECT_GE(face_locks, 1) << c.scene;
    if (c.opens_at_the_hinge) {
      EXPECT_GE(opened_at_the_hinge, 1) << c.scene;
    }
  }
}

// The blocks' energy [J]: kinetic plus gravity, summed by block, the held top block left out (the hand moves it), so
// that a block locked to the hand still counts (Ladder::energy() counts moving bodies only).
double blocks_energy(const scene::Simulation& sim) {
  const model::Ladder& l = sim.ladder();
  double e = 0;
  for (int i = l.held() ? 1 : 0; i < l.blocks(); ++i) {
    const double w = l.world().part_omega(i);
    e += 0.5 * kM * l.world().part_velocity(i).squaredNorm() + 0.5 * kM * (kL * kL + kT * kT) / 12 * w * w -
         kM * sim.scene().options.gravity.dot(l.block_centre(i));
  }
  return e;
}

// classic.toml over 10 s, as shipped: every meeting with a stop is one event. The ripple is the paper's (hinges 1 to 5
// in order). No lock is let go within two steps of its meeting (before, 25 of the 32 locks were let go at the end
// of the step they were made in, their contact pulling from the start); the shortest lock now holds 2.6 ms (three
// steps), and at dt = 0.1 ms the same lock holds 2.0 ms (Classic.EventsConvergeAsTheStepShrinks): it is pressed, not a
// chatter. After an impact the pair is open at the end of the next step (s < 0); a locked pair stays straight; no
// hinge has two events at one instant; no event adds energy.
TEST(Stop, ClassicMeetingsAreOneEventEach) {
  scene::Simulation sim(shipped("classic.toml"));
  const double dt = sim.dt(), s_det = 2 * sim.scene().options.tolerance / kL;
  std::map<int, double> locked_at, last;  // hinge -> its lock's time; its last event's
  std::map<int, int> opening;             // hinge -> steps left before its impact must show the pair open
  std::map<EventKind, int> count;
  std::vector<int> flips;
  std::vector<double> short_locks;  // the locks let go within 5 ms with no event between
  int previous_hinge = -1;
  while (sim.time() < 10) {
    sim.step();
    for (const model::Event& e : sim.take_events()) {
      ++count[e.kind];
      EXPECT_GE(e.energy_removed, -1e-12) << model::to_string(e.kind) << " at " << e.t;
      if (last.count(e.hinge)) {
        EXPECT_GT(e.t, last[e.hinge]) << "hinge " << e.hinge << ": two events at " << e.t;
      }
      last[e.hinge] = e.t;
      opening.erase(e.hinge);
      if (e.kind == EventKind::FlipFlop) flips.push_back(e.hinge);
      if (e.kind == EventKind::Impact) opening[e.hinge] = 2;  // this step's end, then the next one's
      if (e.kind == EventKind::Lock) locked_at[e.hinge] = e.t;
      if (e.kind == EventKind::Unlock) {
        ASSERT_TRUE(locked_at.count(e.hinge));
        EXPECT_GT(e.t - locked_at[e.hinge], 2 * dt) << "hinge " << e.hinge << " locked at " << locked_at[e.hinge];
        if (e.t - locked_at[e.hinge] < 5e-3 && previous_hinge == e.hinge) short_locks.push_back(locked_at[e.hinge]);
      }
      previous_hinge = e.hinge;
    }
    for (auto it = opening.begin(); it != opening.end();) {
      if (--it->second > 0) {
        ++it;
        continue;
      }
      EXPECT_LT(sim.ladder().hinge_measure(it->first), 0) << "hinge " << it->first << " at " << sim.time();
      it = opening.erase(it);
    }
    for (int k = 1; k < sim.ladder().blocks(); ++k) {
      if (sim.ladder().hinges()[k].status == model::HingeStatus::Locked) {
        EXPECT_LE(std::abs(sim.ladder().hinge_measure(k)), s_det) << "hinge " << k << " at " << sim.time();
      }
    }
  }
  EXPECT_EQ(flips, (std::vector<int>{1, 2, 3, 4, 5}));
  EXPECT_GT(count[EventKind::Lock], 0);
  EXPECT_GT(count[EventKind::Impact], count[EventKind::Lock]);
  EXPECT_EQ(count[EventKind::Unlock], count[EventKind::Lock]);
  EXPECT_EQ(count[EventKind::SolverWarning], 0);
  // Issue 17 asks for no lock and unlock of one hinge less than 5 ms apart with nothing between. The classic scene
  // has two, both at hinge 5, both pressed (0.58 and 0.16 mN m) and converging with dt (docs/model.md section 5):
  // the toy's presses, kept. Pinned here, so that a new one fails.
  ASSERT_EQ(short_locks.size(), 2u);
  EXPECT_NEAR(short_locks[0], 1.126, 2e-3);
  EXPECT_NEAR(short_locks[1], 2.462, 2e-3);
}

// A lock is made while the stop's moment pulls by less than ladder.unlock_threshold (docs/model.md section 5), so it
// may be made under a slight pull. Its words say which: "pressed with M N m" with M >= 0, or "pulled open with only M
// N m (within ladder.unlock_threshold, T N m)" with 0 < M <= T, never a press of a negative moment. toy-1889.toml makes
// one of the second kind at hinge 2 near 2.75 s (measured: 9.76e-6 N m).
TEST(Stop, ALockMadeUnderASlightPullSaysSo) {
  scene::Simulation sim(shipped("toy-1889.toml"));
  const double threshold = sim.ladder().spec().unlock_threshold;
  int pressed = 0, pulled = 0;
  while (sim.time() < 3) {
    sim.step();
    for (const model::Event& e : sim.take_events()) {
      if (e.kind != EventKind::Lock) continue;
      EXPECT_EQ(e.detail.find("pressed with -"), std::string::npos) << e.detail;
      if (e.detail.rfind("pressed with ", 0) == 0) {
        EXPECT_GE(number_after(e.detail, "pressed with "), 0) << e.detail;
        ++pressed;
      } else {
        ASSERT_EQ(e.detail.rfind("pulled open with only ", 0), 0u) << e.detail;
        const double m = number_after(e.detail, "pulled open with only ");
        EXPECT_GT(m, 0) << e.detail;
        EXPECT_LE(m, threshold) << e.detail;
        EXPECT_NE(e.detail.find(" N m (within ladder.unlock_threshold, 1e-05 N m)"), std::string::npos) << e.detail;
        EXPECT_EQ(e.hinge, 2);
        EXPECT_NEAR(e.t, 2.7535, 0.01);
        ++pulled;
      }
    }
  }
  EXPECT_GT(pressed, 0);
  EXPECT_EQ(pulled, 1);
}

// An event's velocity fix is a projection in the mass metric onto the motions the new structure allows: with every
// block free or held still, it can only take kinetic energy out. While the hand turns the top block, the allowed
// motions keep the hand's, and the impulse that keeps them does work on the blocks, so a meeting can give the blocks
// energy (a negative energy_removed; the ledger counts it where it happens). double-ripple.toml over 10 s, two tips:
// no event adds more than rounding while the hand is still, and some add energy while it turns (measured: 4 events,
// all inside the tips, down to -1.1e-4 J, against the largest removal 0.049 J).
TEST(Stop, OnlyAMovingHandLetsAnEventAddEnergy) {
  scene::Simulation sim(shipped("double-ripple.toml"));
  const model::Ladder& l = sim.ladder();
  const auto hand_moves = [&] {
    return l.world().part_omega(0) != 0 || l.world().part_velocity(0).squaredNorm() != 0;
  };
  int still = 0, turning = 0, gained_while_turning = 0;
  while (sim.time() < 10) {
    const bool moved_at_start = hand_moves();
    sim.step();
    const bool moving = moved_at_start || hand_moves();
    for (const model::Event& e : sim.take_events()) {
      ++(moving ? turning : still);
      if (moving) {
        gained_while_turning += e.energy_removed < -1e-8;
      } else {
        EXPECT_GE(e.energy_removed, -1e-15) << model::to_string(e.kind) << " at " << e.t << ", hinge " << e.hinge;
      }
    }
  }
  EXPECT_GT(still, 100);
  EXPECT_GT(turning, 10);
  EXPECT_GE(gained_while_turning, 1);
}

// The energy ledger (Ladder::losses()) closes. On the classic scene from 1 s (the hand still after its tip) to 10 s,
// the blocks' energy falls by exactly what the ledger adds up (measured: to 6e-17 J of 0.03 J). With the midpoint
// step, whose energy change is the work put in less what the drag takes, to its solve's tolerance, the motion's share
// never falls from one step to the next, through the hand's tip too (the ledger takes out the hand's work, 0.09 J
// over the 0.4 s tip), and over the whole run it is the drag's work.
TEST(Stop, TheEnergyLedgerCloses) {
  scene::Simulation sim(shipped("classic.toml"));
  const model::Ladder& l = sim.ladder();
  const core::Options& o = sim.scene().options;
  // The drag's power [W]: the sum over the blocks of c m |v|^2 + c_a I w^2.
  const auto drag_power = [&] {
    double p = 0;
    for (int i = 1; i < l.blocks(); ++i) {
      const double w = l.world().part_omega(i);
      p += o.linear_damping * kM * l.world().part_velocity(i).squaredNorm() +
           o.angular_damping * kM * (kL * kL + kT * kT) / 12 * w * w;
    }
    return p;
  };
  double motion = 0, e1 = 0, lost1 = 0, worst = 0, drag = 0, power = drag_power(), worst_ledger = 0;
  int ledger_steps = 0;
  while (sim.time() < 10) {
    sim.step();
    const double next = drag_power();
    drag += 0.5 * sim.dt() * (power + next);
    power = next;
    // The ledger, step by step through the tip (the hand's work) and the ripple: E(t + h) - E(t) - work +
    // dissipated, where the motion's loss is E(t) + work - E(t + h) and the midpoint step reports what the damping
    // dissipated. (Steps cut at an event are pieces, each its own world step: left out.)
    if (sim.take_events().empty()) {
      worst_ledger = std::max(worst_ledger, std::abs(l.losses().motion - motion - l.world().last_step().dissipated));
      ++ledger_steps;
    }
    worst = std::min(worst, l.losses().motion - motion);
    motion = l.losses().motion;
    if (std::abs(sim.time() - 1.0) < 0.5 * sim.dt()) {
      e1 = blocks_energy(sim);
      lost1 = l.losses().total();
    }
  }
  // A step's energy error is up to the weight of the ladder times the hinge tolerance, N m g 1e-12 m = 1.5e-12 J
  // (measured: the motion's share fell by 1.4e-12 J at most in one step, at rest before the tip).
  EXPECT_GE(worst, -10 * 6 * kM * kG * sim.scene().options.tolerance);
  EXPECT_GT(ledger_steps, 9900);
  EXPECT_LT(worst_ledger, 1e-9);  // [J], the bound (measured: printed)
  std::printf("the ledger over %d steps: worst |dE - work + dissipated| %.3g J\n", ledger_steps, worst_ledger);
  EXPECT_NEAR(e1 - blocks_energy(sim), l.losses().total() - lost1, 1e-12);
  // With the midpoint step the motion's share is the drag's work, which the trapezoid rule over the blocks' speeds at
  // the steps' ends finds closely (measured: 1.7e-4 of 6.4e-3 J apart; counting the work of the event location's
  // discarded trial steps made it 3.4 %).
  EXPECT_NEAR(l.losses().motion, drag, 1e-3 * drag);
  EXPECT_EQ(l.flip_flops(), 5);
  EXPECT_GT(l.lost_by_last_flip(), 0);
  EXPECT_LE(l.lost_by_last_flip(), l.losses().total());
}

}  // namespace
}  // namespace ladder
