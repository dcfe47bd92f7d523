// The server's command rules without a network: every command parameter and live setting has a range, a value
// outside it is refused with the key, the value and the range, and the refusal changes nothing. Values at the ends
// of the ranges are accepted and the simulation keeps stepping.
#include "classic_session.hpp"
#include "daemon/session.hpp"
#include "daemon/wire.hpp"
#include "transport/dds.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

namespace ladder::daemon {
namespace {

using core::Vec2;

ladder_msg_Command command(ladder_msg_CommandKind kind) {
  ladder_msg_Command c{};
  c.kind = kind;
  return c;
}
ladder_msg_Command set(const std::string& setting) {
  ladder_msg_Command c = command(ladder_msg_SET_PARAM);
  transport::copy_text(c.text, setting);
  return c;
}
ladder_msg_Command grab(int block, double stiffness = 0) {
  ladder_msg_Command c = command(ladder_msg_GRAB);
  c.block = block;
  c.e = stiffness;
  return c;
}
ladder_msg_Command grab_angle(int block, double angle) {
  ladder_msg_Command c = grab(block);
  c.has_angle = true;
  c.f = angle;
  return c;
}
ladder_msg_Command drag(int block, double x, double y, const double* angle = nullptr) {
  ladder_msg_Command c = command(ladder_msg_DRAG);
  c.block = block;
  c.a = x, c.b = y;
  c.has_angle = angle != nullptr;
  c.f = angle ? *angle : 0;
  return c;
}

// Everything a command could change: the dynamic state, the live settings, the rates, the generation, pausing.
struct Snapshot {
  std::uint64_t hash;
  std::string settings;
  Rates rates;
  std::uint32_t generation;
  bool paused;
};
Snapshot snapshot(const Session& s) {
  return {s.state_hash(), scene::live_settings(s.sim().scene()), s.rates(), s.generation(), s.paused()};
}

// Applies c, expects exactly `reason`, and that nothing changed.
void expect_refused(Session& s, const ladder_msg_Command& c, const std::string& reason) {
  const Snapshot before = snapshot(s);
  const Outcome o = s.apply(fields_of(c));
  EXPECT_FALSE(o.accepted) << "accepted; expected: " << reason;
  EXPECT_EQ(o.reason, reason);
  const Snapshot after = snapshot(s);
  EXPECT_EQ(after.hash, before.hash) << "the refusal changed the state: " << reason;
  EXPECT_EQ(after.settings, before.settings) << reason;
  EXPECT_EQ(after.rates.publish, before.rates.publish) << reason;
  EXPECT_EQ(after.rates.real_time_factor, before.rates.real_time_factor) << reason;
  EXPECT_EQ(after.generation, before.generation) << reason;
  EXPECT_EQ(after.paused, before.paused) << reason;
}

void expect_accepted(Session& s, const ladder_msg_Command& c) {
  const Outcome o = s.apply(fields_of(c));
  EXPECT_TRUE(o.accepted) << o.reason;
}

// Steps n times; the number of steps that failed.
int failures_in(Session& s, int n) {
  int failed = 0;
  for (int i = 0; i < n; ++i) {
    try {
      s.step();
    } catch (const std::runtime_error&) {
      ++failed;
      expect_accepted(s, command(ladder_msg_RESUME));
    }
  }
  return failed;
}

TEST(SessionRanges, GrabStiffnessIsFiniteNonNegativeAndCapped) {
  auto s = classic();
  expect_refused(*s, grab(3, kNan), "the stiffness is nan, not a finite number");
  expect_refused(*s, grab(3, kInf), "the stiffness is inf, not a finite number");
  expect_refused(*s, grab(3, -1), "the stiffness must be from 0 (the default) to 1e+06 N/m, not -1");
  expect_refused(*s, grab(3, 1e300), "the stiffness must be from 0 (the default) to 1e+06 N/m, not 1e+300");
  expect_accepted(*s, grab(3, 1e6));
}

// Today's main copied f into the grip even without has_angle: a NaN there was published as grips[0].angle.
TEST(SessionRanges, AGrabWithoutAnAngleIgnoresItsAngleField) {
  auto s = classic();
  ladder_msg_Command c = grab(3);
  c.f = kNan;
  expect_accepted(*s, c);
  ASSERT_EQ(s->sim().ladder().grips().size(), 1u);
  EXPECT_FALSE(s->sim().ladder().grips()[0].hold_angle);
  EXPECT_EQ(s->sim().ladder().grips()[0].angle, 0.0);
}

TEST(SessionRanges, GrabAndDragAnglesAreBoundedThenWrapped) {
  auto s = classic();
  expect_refused(*s, grab_angle(3, kNan), "the angle is nan, not a finite number");
  expect_refused(*s, grab_angle(3, 1e300), "the angle must be from -1000 to 1000 rad, not 1e+300");
  expect_refused(*s, grab_angle(3, -1000.5), "the angle must be from -1000 to 1000 rad, not -1000.5");
  expect_accepted(*s, grab(3));
  double a = 1e300;
  expect_refused(*s, drag(3, 0, -0.2, &a), "the angle must be from -1000 to 1000 rad, not 1e+300");
  a = -kInf;
  expect_refused(*s, drag(3, 0, -0.2, &a), "the angle is -inf, not a finite number");
  // Within half a turn of the block's angle: kept exactly; beyond: the nearest equivalent orientation.
  const double block = s->sim().ladder().block_angle(3);
  a = block + 0.5;
  expect_accepted(*s, drag(3, 0, -0.2, &a));
  EXPECT_EQ(s->sim().ladder().grips()[0].angle, block + 0.5);
  a = 999;
  expect_accepted(*s, drag(3, 0, -0.2, &a));
  const double held = s->sim().ladder().grips()[0].angle;
  EXPECT_LE(std::abs(held - block), M_PI + 1e-12);
  EXPECT_NEAR(std::remainder(held - 999, 2 * M_PI), 0, 1e-9) << held;
  // Still refused in the old order: a block that is not grabbed.
  expect_refused(*s, drag(4, 0, -0.2, &a), "block 4 is not grabbed");
}

// A refusal of a long setting names it by its start and length, so that the reason fits the answer's 512 characters
// (the setting itself, up to 1024, was echoed whole and the reason cut off).
TEST(SessionRanges, ALongSettingIsNamedByItsStartAndTheReasonFits) {
  auto s = classic();
  const std::string value(900, '[');
  const Outcome o = s->apply(fields_of(set("sim.dt=" + value)));
  EXPECT_FALSE(o.accepted);
  EXPECT_TRUE(o.reason.starts_with("sim.dt=" + std::string(73, '[') + "... (907 characters): ")) << o.reason;
  EXPECT_LT(o.reason.size(), 512u) << o.reason;
  EXPECT_NE(o.reason.find("sim.dt"), o.reason.rfind("sim.dt")) << "no reason after the name: " << o.reason;
  const Outcome server = s->apply(fields_of(set("server.publish_rate=" + std::string(900, '9'))));
  EXPECT_FALSE(server.accepted);
  EXPECT_TRUE(server.reason.ends_with("server.publish_rate must be a number from 1 Hz to the physics rate (1000 Hz)"))
      << server.reason;
  const Outcome key = s->apply(fields_of(set("server." + std::string(900, 'k') + "=1")));
  EXPECT_TRUE(key.reason.ends_with(" characters): unknown key (server keys: server.real_time_factor, "
                                   "server.publish_rate)"))
      << key.reason;
}

// A server key given without its table, or as ladderd's option names it, is named (the scene's keys offered 'sim.dt'
// for `set rtf 0.25`, and nothing for `set real_time_factor 0.25`).
TEST(SessionRanges, AServerKeyWithoutItsTableIsNamed) {
  auto s = classic();
  expect_refused(*s, set("rtf=0.25"), "rtf=0.25: unknown key 'rtf' (did you mean 'server.real_time_factor'?)");
  expect_refused(*s, set("real_time_factor=0.25"),
                 "real_time_factor=0.25: unknown key 'real_time_factor' (did you mean 'server.real_time_factor'?)");
  expect_refused(*s, set("publish_rate=30"), "publish_rate=30: unknown key 'publish_rate' (did you mean "
                                             "'server.publish_rate'?)");
  EXPECT_TRUE(s->apply(fields_of(set("server.real_time_factor=0.25"))).accepted);
}

TEST(SessionRanges, PublishRateIsAtLeastOneHertz) {
  auto s = classic();
  const std::string range = ": server.publish_rate must be a number from 1 Hz to the physics rate (1000 Hz)";
  expect_refused(*s, set("server.publish_rate=1e-300"), "server.publish_rate=1e-300" + range);
  expect_refused(*s, set("server.publish_rate=0.5"), "server.publish_rate=0.5" + range);
  expect_refused(*s, set("server.publish_rate=nan"), "server.publish_rate=nan" + range);
  expect_refused(*s, set("server.publish_rate=1001"), "server.publish_rate=1001" + range);
  expect_refused(*s, set("server.publish_rate=-0"), "server.publish_rate=-0" + range);
  expect_refused(*s, set("server.publish_rate=30\nv=2"), "server.publish_rate=30\nv=2" + range);
  expect_refused(*s, set("server.publish_rate=\"30\""), "server.publish_rate=\"30\"" + range);
  expect_accepted(*s, set("server.publish_rate=1"));
  EXPECT_EQ(s->rates().publish, 1);
  // Numbers as TOML writes them, as for the scene's keys: underscores, hexadecimal, exponents.
  expect_accepted(*s, set("server.publish_rate=1_0"));
  EXPECT_EQ(s->rates().publish, 10);
  expect_accepted(*s, set("server.publish_rate=0x20"));
  EXPECT_EQ(s->rates().publish, 32);
  expect_accepted(*s, set("server.publish_rate=2.5e1"));
  EXPECT_EQ(s->rates().publish, 25);
}

TEST(SessionRanges, RealTimeFactorIsZeroOrAtLeastOneHundredth) {
  auto s = classic();
  const std::string range = ": server.real_time_factor must be a number from 0.01 to 1000, or 0 (as fast as possible)";
  expect_refused(*s, set("server.real_time_factor=1e-300"), "server.real_time_factor=1e-300" + range);
  expect_refused(*s, set("server.real_time_factor=4.9e-324"), "server.real_time_factor=4.9e-324" + range);
  expect_refused(*s, set("server.real_time_factor=0.009"), "server.real_time_factor=0.009" + range);
  expect_refused(*s, set("server.real_time_factor=1e300"), "server.real_time_factor=1e300" + range);
  expect_refused(*s, set("server.real_time_factor=inf"), "server.real_time_factor=inf" + range);
  expect_accepted(*s, set("server.real_time_factor=0.01"));
  expect_accepted(*s, set("server.real_time_factor=-0"));  // -0 == 0: as fast as possible
  EXPECT_EQ(s->rates().real_time_factor, 0);
  expect_accepted(*s, set("server.real_time_factor=1000"));
}

TEST(SessionRanges, LiveSceneKeysNameTheKeyTheValueAndTheRange) {
  auto s = classic();
  expect_refused(*s, set("sim.gravity=[1e308,1e308]"),
                 "sim.gravity=[1e308,1e308]: sim.gravity must have |g| <= 1000 m/s^2, about 100 g (got [1e+308, "
                 "1e+308])");
  expect_refused(*s, set("sim.gravity=[0,-1001]"),
                 "sim.gravity=[0,-1001]: sim.gravity must have |g| <= 1000 m/s^2, about 100 g (got [0, -1001])");
  expect_refused(*s, set("sim.gravity=[nan,0]"), "sim.gravity=[nan,0]: sim.gravity[0] must be finite (got nan)");
  expect_refused(*s, set("damping.linear=1e6"),
                 "damping.linear=1e6: damping.linear must be >= 0 and <= 1000 (got 1000000)");
  expect_refused(*s, set("damping.angular=1e300"),
                 "damping.angular=1e300: damping.angular must be >= 0 and <= 1000 (got 1e+300)");
  expect_refused(*s, set("damping.hinge=1"), "damping.hinge=1: damping.hinge must be >= 0 and <= 0.1 (got 1)");
  expect_refused(*s, set("sim.dt=1e-300"), "sim.dt=1e-300: sim.dt must be >= 1e-07 and <= 0.1 (got 1e-300)");
  expect_refused(*s, set("sim.dt=5e-324"), "sim.dt=5e-324: sim.dt must be >= 1e-07 and <= 0.1 (got 5e-324)");
  expect_refused(*s, set("sim.substeps=100000"),
                 "sim.substeps=100000: sim.substeps must be >= 1 and <= 1000 (got 100000)");
  expect_refused(*s, set("solver.tolerance=0"),
                 "solver.tolerance=0: solver.tolerance must be >= 1e-15 and <= 1e-06 (got 0)");
  expect_refused(*s, set("solver.max_iterations=1000000000"),
                 "solver.max_iterations=1000000000: solver.max_iterations must be >= 1 and <= 1000 (got 1000000000)");
  expect_refused(*s, set("sim.error_tolerance=1e-300"),
                 "sim.error_tolerance=1e-300: sim.error_tolerance must be >= 1e-12 and <= 0.01 (got 1e-300)");
  // The sub-step against the step: whichever of the two was just set is named.
  expect_accepted(*s, set("sim.dt=1e-5"));
  expect_refused(*s, set("sim.substeps=1000"),
                 "sim.substeps=1000: sim.dt / sim.substeps must be >= 1e-07 s, the smallest time step (got 1e-05 / "
                 "1000 = 1e-08 s)");
  expect_accepted(*s, set("sim.substeps=100"));
  // The drag against the step: a live sim.dt under a strong drag is refused too.
  auto t = classic();
  expect_accepted(*t, set("damping.linear=100"));
  expect_refused(*t, set("sim.dt=0.05"),
                 "sim.dt=0.05: damping.linear must be <= 1 / (sim.dt / sim.substeps) = 20 /s, so that one step takes at "
                 "most a block's whole velocity (got 100 at sim.dt = 0.05 s, sim.substeps = 1)");
  expect_accepted(*t, set("sim.dt=0.01"));
  expect_refused(*t, set("damping.angular=101"),
                 "damping.angular=101: damping.angular must be <= 1 / (sim.dt / sim.substeps) = 100 /s, so that one "
                 "step takes at most a block's whole velocity (got 101 at sim.dt = 0.01 s, sim.substeps = 1)");
  expect_refused(*s, set("sim.dt=1e-6"),
                 "sim.dt=1e-6: sim.dt / sim.substeps must be >= 1e-07 s, the smallest time step (got 1e-06 / 100 = "
                 "1e-08 s)");
}

TEST(SessionRanges, CountsImpulsesForcesAndDurationsAreBounded) {
  auto s = classic();
  ladder_msg_Command poke = command(ladder_msg_POKE);
  poke.block = 2;
  poke.a = 1e300;
  expect_refused(*s, poke, "the impulse of 1e+300 N s is beyond the limit of 1 N s (commands.max_impulse)");
  poke.a = 4.9e-324, poke.b = kNan;
  expect_refused(*s, poke, "the impulse is nan, not a finite number");
  ladder_msg_Command push = command(ladder_msg_PUSH);
  push.block = 2;
  push.a = 1, push.e = 1e300;
  expect_refused(*s, push, "the duration must be > 0 and at most 60 s (commands.max_duration), not 1e+300");
  push.e = -0.0;
  expect_refused(*s, push, "the duration must be > 0 and at most 60 s (commands.max_duration), not -0");
  expect_accepted(*s, command(ladder_msg_PAUSE));
  ladder_msg_Command step = command(ladder_msg_STEP);
  step.count = 4'294'967'295u;
  expect_refused(*s, step, "the step count must be 1 to 100000 (commands.max_step_count), not 4294967295");
  ladder_msg_Command unknown = command(ladder_msg_TIP);
  const int kind = 99;  // as a hostile client may send it: outside the enum
  std::memcpy(&unknown.kind, &kind, sizeof kind);
  expect_refused(*s, unknown, "unknown command kind 99");
}

// The ends of every range are accepted and the tipped ladder then steps a second without a failure: an accepted
// value cannot make the simulation fail.
TEST(SessionRanges, TheEndsOfTheRangesStepWithoutFailing) {
  for (const char* setting : {"sim.gravity=[0,-1000]", "sim.gravity=[707,707]", "damping.linear=1000",
                              "damping.angular=1000", "damping.hinge=0.1", "sim.dt=0.1", "sim.dt=1e-7",
                              "solver.tolerance=1e-6", "solver.max_iterations=1"}) {
    SCOPED_TRACE(setting);
    auto s = classic();
    expect_accepted(*s, set(setting));
    expect_accepted(*s, command(ladder_msg_TIP));
    const int steps = std::string(setting) == "sim.dt=1e-7" ? 2000 : static_cast<int>(1.0 / s->sim().dt());
    EXPECT_EQ(failures_in(*s, steps), 0);
  }
  // The largest poke and the largest push, at a block's corner.
  for (const ladder_msg_CommandKind kind : {ladder_msg_POKE, ladder_msg_PUSH}) {
    SCOPED_TRACE(kind_name(kind));
    auto s = classic();
    ladder_msg_Command c = command(kind);
    c.block = 5;
    c.a = 0.6, c.b = 0.8;  // 1 N s, 100 N below
    if (kind == ladder_msg_PUSH) c.a *= 100, c.b *= 100, c.e = 60;
    c.has_point = true;
    const model::Ladder& l = s->sim().ladder();
    const Vec2 corner = l.corner(5, 1);
    const Vec2 local = l.world().part_rotation(5).inverse() * (corner - l.block_centre(5));
    c.c = kind == ladder_msg_POKE ? corner.x() : local.x();
    c.d = kind == ladder_msg_POKE ? corner.y() : local.y();
    expect_accepted(*s, c);
    EXPECT_EQ(failures_in(*s, 1000), 0);
  }
  // The strongest hand at the far end of its reach, turning a block by the largest angle.
  auto s = classic();
  ladder_msg_Command g = grab_angle(5, 1000);
  g.e = 1e6;
  expect_accepted(*s, g);
  const double a = -1000;
  expect_accepted(*s, drag(5, 0, -10, &a));
  EXPECT_EQ(failures_in(*s, 1000), 0);
}

// A step that fails pauses the session; a reset then starts the scene with its own settings, not the live ones.
TEST(SessionReset, AfterAFailedStepResetRestoresTheScenesSettings) {
  auto s = classic();
  const std::string own = scene::live_settings(s->sim().scene());
  expect_accepted(*s, set("damping.linear=0.5"));
  // Without a failure a reset keeps the live settings, and says nothing.
  Outcome o = s->apply(fields_of(command(ladder_msg_RESET)));
  EXPECT_TRUE(o.accepted);
  EXPECT_EQ(o.reason, "");
  EXPECT_NE(scene::live_settings(s->sim().scene()).find("damping.linear=0.5\n"), std::string::npos);
  // The final guard's path (a state found non-finite) marks the session failed as a failed step does.
  s->fail();
  EXPECT_TRUE(s->paused());
  EXPECT_TRUE(s->failed());
  o = s->apply(fields_of(command(ladder_msg_RESET)));
  EXPECT_TRUE(o.accepted);
  EXPECT_EQ(o.reason, "the last step failed: the scene restarted with its own settings (the live settings dropped), paused: resume runs it");
  EXPECT_EQ(scene::live_settings(s->sim().scene()), own);
  EXPECT_FALSE(s->failed());
  EXPECT_EQ(failures_in(*s, 100), 0);
}

// A real failed step: blocks so light that hinge friction at the top of its range is too stiff for SHAKE's step (the
// midpoint step takes the friction implicitly and holds there).
TEST(SessionReset, ARealStepFailureIsUndoneByAReset) {
  scene::Scene light =
      scene::parse_scene("[ladder]\nmass = 1e-5\n[sim]\nintegrator = \"symplectic_euler\"\n", "light.toml");
  Session s(light, kScenes, Limits{}, Rates{});
  expect_accepted(s, set("damping.hinge=0.1"));
  expect_accepted(s, command(ladder_msg_TIP));
  bool failed = false;
  for (int i = 0; i < 2000 && !failed; ++i) {
    try {
      s.step();
    } catch (const std::runtime_error&) {
      failed = true;
    }
  }
  if (!failed) GTEST_SKIP() << "no step failed with these settings: the reset path is covered by the test above";
  EXPECT_TRUE(s.paused());
  EXPECT_TRUE(s.failed());
  const Outcome o = s.apply(fields_of(command(ladder_msg_RESET)));
  EXPECT_EQ(o.reason, "the last step failed: the scene restarted with its own settings (the live settings dropped), paused: resume runs it");
  EXPECT_NE(scene::live_settings(s.sim().scene()).find("damping.hinge=0\n"), std::string::npos);
  expect_accepted(s, command(ladder_msg_RESUME));
  expect_accepted(s, command(ladder_msg_TIP));
  EXPECT_EQ(failures_in(s, 2000), 0);
}

}  // namespace
}  // namespace ladder::daemon
