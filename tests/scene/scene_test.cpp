#include "scene/scene.hpp"

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <variant>
#include <vector>

namespace ladder::scene {
namespace {

const std::string kSource = LADDER_SOURCE_DIR;

std::string scene_path(const std::string& name) { return kSource + "/config/scenes/" + name + ".toml"; }

// The message of the SceneError that parsing `text` (with `overrides`) throws, or "" when it does not throw.
std::string error_of(const std::string& text, const std::vector<std::string>& overrides = {}) {
  try {
    parse_scene(text, "<string>", overrides);
  } catch (const SceneError& e) {
    return e.what();
  }
  return "";
}

// Checks the message starts with `prefix` (the position) and contains every one of `parts`.
void expect_error(const std::string& text, const std::string& prefix, const std::vector<std::string>& parts,
                  const std::vector<std::string>& overrides = {}) {
  const std::string message = error_of(text, overrides);
  ASSERT_FALSE(message.empty()) << "no error for:\n" << text;
  EXPECT_EQ(message.substr(0, prefix.size()), prefix) << message;
  for (const std::string& p : parts) EXPECT_NE(message.find(p), std::string::npos) << "'" << p << "' not in: " << message;
}

// ------------------------------------------------------------------------------------------- shipped scenes

TEST(ShippedScenes, ClassicHasTheDocumentedValues) {
  const Scene s = load_scene(scene_path("classic"));
  EXPECT_EQ(s.source, scene_path("classic"));
  EXPECT_FALSE(s.name.empty());
  EXPECT_FALSE(s.description.empty());
  EXPECT_EQ(s.ladder.blocks, 6);
  EXPECT_DOUBLE_EQ(s.ladder.length, 0.064);
  EXPECT_DOUBLE_EQ(s.ladder.thickness, 0.013);
  EXPECT_DOUBLE_EQ(s.ladder.mass, 0.025);
  EXPECT_TRUE(s.ladder.masses.empty());
  EXPECT_EQ(s.ladder.top, model::Top::Held);
  EXPECT_EQ(s.ladder.start, model::Start::Hanging);
  EXPECT_TRUE(s.ladder.logic);
  EXPECT_DOUBLE_EQ(s.ladder.tip_duration, 0.4);
  EXPECT_DOUBLE_EQ(s.options.linear_damping, 0.1);
  EXPECT_DOUBLE_EQ(s.options.angular_damping, 0.1);
  EXPECT_DOUBLE_EQ(s.dt, 0.001);
  EXPECT_EQ(s.options.integrator, core::Integrator::Midpoint);
  EXPECT_EQ(s.options.solver, core::SolverKind::Newton);
  EXPECT_DOUBLE_EQ(s.options.tolerance, 1e-12);
  ASSERT_EQ(s.timeline.size(), 1u);
  EXPECT_TRUE(std::holds_alternative<model::Tip>(s.timeline[0].action));
  EXPECT_DOUBLE_EQ(s.timeline[0].t, 0.5);
  EXPECT_EQ(s.timeline[0].where.rfind(scene_path("classic") + ":", 0), 0u) << s.timeline[0].where;
}

TEST(ShippedScenes, DoubleRippleTipsTwice) {
  const Scene s = load_scene(scene_path("double-ripple"));
  EXPECT_EQ(s.ladder.blocks, 16);
  EXPECT_DOUBLE_EQ(s.ladder.length, 0.064);
  EXPECT_DOUBLE_EQ(s.ladder.thickness, 0.013);
  EXPECT_DOUBLE_EQ(s.ladder.mass, 0.025);
  EXPECT_DOUBLE_EQ(s.ladder.hinge_inset, 0.4);
  EXPECT_DOUBLE_EQ(s.options.linear_damping, 0.1);
  EXPECT_DOUBLE_EQ(s.options.angular_damping, 0.1);
  ASSERT_EQ(s.timeline.size(), 2u);
  EXPECT_TRUE(std::holds_alternative<model::Tip>(s.timeline[0].action));
  EXPECT_DOUBLE_EQ(s.timeline[0].t, 0.5);
  EXPECT_TRUE(std::holds_alternative<model::Tip>(s.timeline[1].action));
  EXPECT_DOUBLE_EQ(s.timeline[1].t, 0.9);
  // The tip back starts after the first tip has finished.
  EXPECT_GE(s.timeline[1].t, s.timeline[0].t + s.ladder.tip_duration);
}

TEST(ShippedScenes, LongHasAThousandBlocks) {
  const Scene s = load_scene(scene_path("long"));
  EXPECT_EQ(s.ladder.blocks, 1000);
  EXPECT_DOUBLE_EQ(s.ladder.length, 0.092);
  EXPECT_DOUBLE_EQ(s.ladder.thickness, 0.0025);
  EXPECT_DOUBLE_EQ(s.dt, 0.001);  // the midpoint integrator holds it at 1 ms (docs/benchmarks.md)
  EXPECT_EQ(s.ladder.hinge, model::HingeKind::Rolling);
  EXPECT_DOUBLE_EQ(s.ladder.end_radius, 0.001);
  EXPECT_DOUBLE_EQ(s.options.linear_damping, 0.1);
  EXPECT_DOUBLE_EQ(s.options.angular_damping, 0.1);
  ASSERT_EQ(s.timeline.size(), 1u);
  EXPECT_TRUE(std::holds_alternative<model::Tip>(s.timeline[0].action));
  EXPECT_DOUBLE_EQ(s.timeline[0].t, 0.5);
}

TEST(ShippedScenes, FreeChainIsTheComparisonSetup) {
  const Scene s = load_scene(scene_path("free-chain"));
  EXPECT_EQ(s.ladder.blocks, 2);
  EXPECT_DOUBLE_EQ(s.ladder.length, 0.06);
  EXPECT_DOUBLE_EQ(s.ladder.thickness, 0.01);
  EXPECT_DOUBLE_EQ(s.ladder.mass, 0.02);
  EXPECT_EQ(s.ladder.top, model::Top::Pinned);
  EXPECT_EQ(s.ladder.start, model::Start::Straight);
  EXPECT_FALSE(s.ladder.logic);
  EXPECT_DOUBLE_EQ(s.ladder.kick_omega, 5.0);
  EXPECT_DOUBLE_EQ(s.ladder.tilt, 0.0);
  EXPECT_DOUBLE_EQ(s.dt, 0.001);
  EXPECT_EQ(s.options.gravity, core::Vec2(0, -9.81));
  EXPECT_EQ(s.options.linear_damping, 0.0);
  EXPECT_EQ(s.options.angular_damping, 0.0);
  EXPECT_EQ(s.options.hinge_friction, 0.0);
  EXPECT_TRUE(s.timeline.empty());
}

// The geometry the free-chain description promises, as the model builds it.
TEST(ShippedScenes, FreeChainStartsAsDescribed) {
  const Scene s = load_scene(scene_path("free-chain"));
  const model::Ladder ladder(s.ladder, s.options);
  for (int i = 0; i < 2; ++i) {
    EXPECT_NEAR(ladder.block_centre(i).x(), 0.005, 1e-15) << i;
    EXPECT_NEAR(ladder.block_centre(i).y(), -0.03 - 0.06 * i, 1e-15) << i;
  }
  EXPECT_DOUBLE_EQ(ladder.world().part_omega(0), 0.0);
  EXPECT_DOUBLE_EQ(ladder.world().part_omega(1), 5.0);
}

TEST(ShippedScenes, EveryOneBuildsALadder) {
  for (const char* name : {"classic", "double-ripple", "long", "free-chain", "toy-1889", "tall", "tall-double-ripple"}) {
    SCOPED_TRACE(name);
    const Scene s = load_scene(scene_path(name));
    EXPECT_NO_THROW(model::Ladder(s.ladder, s.options));
  }
}

// ------------------------------------------------------------------------------------------- values

TEST(Values, EmptySceneKeepsTheDefaults) {
  const Scene s = parse_scene("", "<string>");
  const model::LadderSpec l;
  const core::Options o;
  EXPECT_EQ(s.source, "<string>");
  EXPECT_EQ(s.ladder.blocks, l.blocks);
  EXPECT_EQ(s.ladder.length, l.length);
  EXPECT_EQ(s.ladder.tip_duration, l.tip_duration);
  EXPECT_EQ(s.ladder.hinge_inset, l.hinge_inset);
  EXPECT_EQ(s.options.integrator, o.integrator);
  EXPECT_EQ(s.options.tolerance, o.tolerance);
  EXPECT_EQ(s.options.max_iterations, o.max_iterations);
  EXPECT_EQ(s.options.gravity, o.gravity);
  EXPECT_EQ(s.dt, 0.001);
  EXPECT_TRUE(s.timeline.empty());
}

// ladder.depth: only drawn (the viewer reads it from the SceneInfo's settings), checked like every length.
TEST(Values, DepthIsReadCheckedAndPublishedWithTheSettings) {
  EXPECT_EQ(parse_scene("", "<string>").depth, 0.045);
  const Scene s = parse_scene("[ladder]\ndepth = 0.03\n", "<string>");
  EXPECT_EQ(s.depth, 0.03);
  EXPECT_NE(live_settings(s).find("\nladder.depth=0.03\n"), std::string::npos) << live_settings(s);
  expect_error("[ladder]\ndepth = 0\n", "<string>:2:9: ", {"ladder.depth must be > 0 and <= 10 (got 0)"});
  expect_error("[ladder]\ndepth = 1e308\n", "<string>:2:9: ", {"ladder.depth must be > 0 and <= 10 (got 1e+308)"});
  expect_error("[ladder]\ncapture_distance = 1e300\n", "<string>:2:20: ",
               {"ladder.capture_distance must be >= 0 and <= 10 (got 1e+300)"});
}

TEST(Values, EveryKeyIsRead) {
  const Scene s = parse_scene(R"(
[scene]
name = "n"
description = "d"
[ladder]
masses = [1, 2.5, 3]
length = 2
thickness = 0.5
mass = 7
top = "free"
start = "straight"
logic = false
hinge_inset = 0.25
tip_duration = 1.5
unlock_threshold = 0
capture_distance = 0.01
[initial]
kick_omega = -2
tilt = 0.1
[sim]
dt = 1e-4
integrator = "rattle"
gravity = [1, -2]
[solver]
kind = "newton_linesearch"
tolerance = 1e-9
max_iterations = 50
[damping]
linear = 0.5
angular = 0.25
hinge = 0.0625
)",
                              "<string>");
  EXPECT_EQ(s.name, "n");
  EXPECT_EQ(s.description, "d");
  EXPECT_EQ(s.ladder.blocks, 3);  // from masses
  EXPECT_EQ(s.ladder.masses, (std::vector<double>{1, 2.5, 3}));
  EXPECT_EQ(s.ladder.length, 2.0);
  EXPECT_EQ(s.ladder.thickness, 0.5);
  EXPECT_EQ(s.ladder.mass, 7.0);
  EXPECT_EQ(s.ladder.top, model::Top::Free);
  EXPECT_EQ(s.ladder.start, model::Start::Straight);
  EXPECT_FALSE(s.ladder.logic);
  EXPECT_EQ(s.ladder.hinge_inset, 0.25);
  EXPECT_EQ(s.ladder.tip_duration, 1.5);
  EXPECT_EQ(s.ladder.unlock_threshold, 0.0);
  EXPECT_EQ(s.ladder.capture_distance, 0.01);
  EXPECT_EQ(s.ladder.kick_omega, -2.0);
  EXPECT_EQ(s.ladder.tilt, 0.1);
  EXPECT_EQ(s.dt, 1e-4);
  EXPECT_EQ(s.options.integrator, core::Integrator::Rattle);
  EXPECT_EQ(s.options.gravity, core::Vec2(1, -2));
  EXPECT_EQ(s.options.solver, core::SolverKind::NewtonLineSearch);
  EXPECT_EQ(s.options.tolerance, 1e-9);
  EXPECT_EQ(s.options.max_iterations, 50);
  EXPECT_EQ(s.options.linear_damping, 0.5);
  EXPECT_EQ(s.options.angular_damping, 0.25);
  EXPECT_EQ(s.options.hinge_friction, 0.0625);
}

TEST(Values, TimelineIsReadAndSortedStably) {
  const Scene s = parse_scene(R"([ladder]
blocks = 4
[[timeline]]
t = 2
command = "push"
block = 3
force = [0.5, 0]
duration = 0.25
at = [0, 0.01]
[[timeline]]
t = 1
command = "break"
hinge = 2
[[timeline]]
t = 1
command = "poke"
block = 1
impulse = [0, 1e-3]
[[timeline]]
t = 0.5
command = "join"
hinge = 0
)",
                              "<string>");
  ASSERT_EQ(s.timeline.size(), 4u);
  const auto& j = s.timeline[0];
  ASSERT_TRUE(std::holds_alternative<model::Join>(j.action));
  EXPECT_EQ(std::get<model::Join>(j.action).hinge, 0);
  EXPECT_EQ(j.where, "<string>:19:1");
  const auto& b = s.timeline[1];  // equal t: file order kept
  ASSERT_TRUE(std::holds_alternative<model::Break>(b.action));
  EXPECT_EQ(std::get<model::Break>(b.action).hinge, 2);
  EXPECT_EQ(b.where, "<string>:10:1");
  ASSERT_TRUE(std::holds_alternative<model::Poke>(s.timeline[2].action));
  const auto& p = std::get<model::Poke>(s.timeline[2].action);
  EXPECT_EQ(p.block, 1);
  EXPECT_EQ(p.impulse, core::Vec2(0, 1e-3));
  EXPECT_FALSE(p.at.has_value()) << "no `at`: the block's centre";
  const auto& u = s.timeline[3];
  EXPECT_EQ(u.t, 2.0);
  ASSERT_TRUE(std::holds_alternative<model::Push>(u.action));
  const auto& push = std::get<model::Push>(u.action);
  EXPECT_EQ(push.block, 3);
  EXPECT_EQ(push.force, core::Vec2(0.5, 0));
  EXPECT_EQ(push.duration, 0.25);
  EXPECT_EQ(push.at, core::Vec2(0, 0.01));
  EXPECT_EQ(u.where, "<string>:3:1");
}

TEST(Values, InlineTimelineTablesWork) {
  const Scene s = parse_scene("timeline = [{ t = 0.5, command = \"tip\" }]\n", "<string>");
  ASSERT_EQ(s.timeline.size(), 1u);
  EXPECT_EQ(s.timeline[0].where, "<string>:1:13");
}

TEST(Values, IntegersAreAcceptedAsNumbers) {
  const Scene s = parse_scene("[sim]\ngravity = [0, -10]\n[ladder]\nlength = 1\n", "<string>");
  EXPECT_EQ(s.options.gravity, core::Vec2(0, -10));
  EXPECT_EQ(s.ladder.length, 1.0);
}

// ------------------------------------------------------------------------------------------- errors

TEST(Errors, SyntaxErrorReportsTomlsPosition) {
  expect_error("[ladder]\nblocks = = 3\n", "<string>:2:10: ", {"could not determine value type"});
  expect_error("[sim]\ndt = 0.001\n[sim]\n", "<string>:3:1: ", {"sim"});
}

TEST(Errors, UnknownKeySuggestsTheNearestOne) {
  expect_error("[ladder]\nblocks = 6\nblokcs = 6\n", "<string>:3:1: ",
               {"unknown key 'ladder.blokcs'", "(did you mean 'ladder.blocks'?)"});
  expect_error("[sim]\n  integrater = \"rk4\"\n", "<string>:2:3: ", {"(did you mean 'sim.integrator'?)"});
}

TEST(Errors, UnknownKeyWithNothingNearHasNoHint) {
  const std::string m = error_of("[damping]\nwobble = 1\n");
  EXPECT_EQ(m, "<string>:2:1: unknown key 'damping.wobble'");
}

TEST(Errors, UnknownTableSuggestsTheNearestOne) {
  expect_error("\n[ladr]\nblocks = 6\n", "<string>:2:2: ", {"unknown table 'ladr'", "(did you mean 'ladder'?)"});
  expect_error("blocks = 6\n", "<string>:1:1: ", {"unknown key 'blocks'", "(did you mean 'ladder.blocks'?)"});
}

TEST(Errors, TheFirstUnknownKeyInTheFileIsReported) {
  // toml++ keeps keys sorted; the report must follow the file.
  expect_error("[ladder]\nzzz = 1\naaa = 2\n", "<string>:2:1: ", {"ladder.zzz"});
}

TEST(Errors, KnownTableThatIsNotATable) {
  expect_error("sim = 3\n", "<string>:1:7: ", {"sim must be a table, not an integer"});
  expect_error("[timeline]\nt = 1\n", "<string>:1:1: ", {"timeline must be an array of tables"});
}

TEST(Errors, WrongType) {
  expect_error("[ladder]\nblocks = \"six\"\n", "<string>:2:10: ", {"ladder.blocks must be an integer, not a string"});
  expect_error("[ladder]\nlength = true\n", "<string>:2:10: ", {"ladder.length must be a number, not a boolean"});
  expect_error("[ladder]\nlogic = 1\n", "<string>:2:9: ", {"ladder.logic must be a boolean"});
  expect_error("[scene]\nname = 3\n", "<string>:2:8: ", {"scene.name must be a string, not an integer"});
  expect_error("[ladder]\ntop = 1\n", "<string>:2:7: ", {"ladder.top must be a string"});
}

TEST(Errors, IntegerKeysRefuseFloats) {
  expect_error("[ladder]\nblocks = 6.0\n", "<string>:2:10: ",
               {"ladder.blocks must be an integer, not a floating-point number"});
  expect_error("[solver]\nmax_iterations = 1.5\n", "<string>:2:18: ", {"solver.max_iterations must be an integer"});
}

TEST(Errors, OutOfRange) {
  expect_error("[ladder]\nmass = -1\n", "<string>:2:8: ", {"ladder.mass must be >= 1e-06 and <= 1000000 (got -1)"});
  expect_error("[ladder]\nlength = 0.0\n", "<string>:2:10: ", {"ladder.length must be >= 0.001 and <= 10 (got 0)"});
  // Values that used to be accepted and then broke the first step (1e-300 kg: a non-finite state), spun the solve to
  // its iteration limit on every step (a tolerance rounding cannot reach), or turned by rounding noise (1e300 rad).
  expect_error("[ladder]\nmass = 1e-300\n", "<string>:2:8: ",
               {"ladder.mass must be >= 1e-06 and <= 1000000 (got 1e-300)"});
  expect_error("[ladder]\nmasses = [0.025, 1e300]\nblocks = 2\n", "<string>:2:", {"ladder.masses", "(got 1e+300)"});
  expect_error("[ladder]\ntip_duration = 1e-300\n", "<string>:2:16: ",
               {"ladder.tip_duration must be >= 0.001 (got 1e-300)"});
  expect_error("[initial]\ntilt = 1e300\n", "<string>:2:8: ",
               {"initial.tilt must be >= -6.283185307179586 and <= 6.283185307179586 (got 1e+300)"});
  expect_error("[solver]\ntolerance = 5e-324\n", "<string>:2:13: ",
               {"solver.tolerance must be >= 1e-15 and <= 1e-06 (got 5e-324)"});
  expect_error("[ladder]\nhinge_inset = 0.5\n", "<string>:2:15: ",
               {"ladder.hinge_inset must be >= 0 and < 0.5 (got 0.5)"});
  expect_error("[sim]\ndt = 0.2\n", "<string>:2:6: ", {"sim.dt must be >= 1e-07 and <= 0.1 (got 0.2)"});
  expect_error("[solver]\nmax_iterations = 1001\n", "<string>:2:18: ", {"solver.max_iterations", "(got 1001)"});
  expect_error("[damping]\nhinge = -0.5\n", "<string>:2:9: ", {"damping.hinge must be >= 0 and <= 0.1 (got -0.5)"});
}

// The live settings' bounds hold in a file too, with the value's position: an accepted value cannot fail the step.
TEST(Errors, LiveSettingsBoundsInAFile) {
  EXPECT_EQ(error_of("[sim]\ngravity = [0, -2000]\n"),
            "<string>:2:11: sim.gravity must have |g| <= 1000 m/s^2, about 100 g (got [0, -2000])");
  EXPECT_EQ(error_of("[sim]\ngravity = [1e308, 1e308]\n"),
            "<string>:2:11: sim.gravity must have |g| <= 1000 m/s^2, about 100 g (got [1e+308, 1e+308])");
  EXPECT_EQ(error_of("[damping]\nlinear = 1e6\n"),
            "<string>:2:10: damping.linear must be >= 0 and <= 1000 (got 1000000)");
  EXPECT_EQ(error_of("[damping]\nangular = 1001\n"),
            "<string>:2:11: damping.angular must be >= 0 and <= 1000 (got 1001)");
  EXPECT_EQ(error_of("[damping]\nhinge = 0.5\n"), "<string>:2:9: damping.hinge must be >= 0 and <= 0.1 (got 0.5)");
  // The sub-step: the file's substeps, or the --set that made it too small.
  EXPECT_EQ(error_of("[sim]\ndt = 1e-6\nsubsteps = 100\n"),
            "<string>:3:12: sim.dt / sim.substeps must be >= 1e-07 s, the smallest time step (got 1e-06 / 100 = "
            "1e-08 s)");
  EXPECT_EQ(error_of("[sim]\nsubsteps = 100\n", {"sim.dt=1e-6"}),
            "--set sim.dt=1e-6: sim.dt / sim.substeps must be >= 1e-07 s, the smallest time step (got 1e-06 / 100 = "
            "1e-08 s)");
  EXPECT_EQ(error_of("[sim]\ndt = 2e-7\n", {"sim.accuracy=accurate"}),
            "--set sim.accuracy=accurate: sim.dt / sim.substeps must be >= 1e-07 s, the smallest time step (got "
            "2e-07 / 4 = 5e-08 s)");
  EXPECT_EQ(error_of("[initial]\nkick_omega = 1e300\n"),
            "<string>:2:14: initial.kick_omega must be >= -1000 and <= 1000 (got 1e+300)");
  EXPECT_EQ(error_of("[sim]\ndt = 1e-4\nsubsteps = 1000\n"), "");  // 1e-7 exactly, up to rounding
  EXPECT_EQ(error_of("[sim]\ngravity = [0, -1000]\n[damping]\nlinear = 1000\nangular = 1000\nhinge = 0.1\n"), "");
}

// An empty scene file would silently be the defaults: almost always the wrong file, or one cut short.
TEST(Errors, EmptySceneFileIsRefused) {
  const std::string path = testing::TempDir() + "scene_test_empty.toml";
  for (const char* text : {"", "\n  \n", "# only a comment\n"}) {
    std::ofstream(path, std::ios::trunc) << text;
    try {
      load_scene(path);
      ADD_FAILURE() << "no error for '" << text << "'";
    } catch (const SceneError& e) {
      EXPECT_EQ(std::string(e.what()), path + ":1:1: the scene file is empty; a scene needs at least one table, e.g. "
                                              "[ladder] with blocks = 6 (docs/scenes.md lists every key)");
    }
  }
  std::ofstream(path, std::ios::trunc) << "[ladder]\n";  // a table, even empty, says what the file is
  EXPECT_EQ(load_scene(path).ladder.blocks, 6);
  std::remove(path.c_str());
}

TEST(Errors, ZeroBlocks) {
  expect_error("# comment\n[ladder]\nblocks = 0\n", "<string>:3:10: ", {"ladder.blocks must be >= 1", "(got 0)"});
  expect_error("[ladder]\nblocks = 1000001\n", "<string>:2:10: ", {"<= 1000000", "(got 1000001)"});
}

TEST(Errors, NonFiniteNumbersAreRefused) {
  expect_error("[ladder]\nlength = nan\n", "<string>:2:10: ", {"ladder.length must be finite (got nan)"});
  expect_error("[initial]\ntilt = -inf\n", "<string>:2:8: ", {"initial.tilt must be finite (got -inf)"});
  expect_error("[sim]\ngravity = [0, inf]\n", "<string>:2:15: ", {"sim.gravity[1] must be finite (got inf)"});
}

// A text is sent over DDS and recorded in LCM as a C string, which ends at a NUL: a name with one reached the clients
// cut short and made the session log unreadable, and a name of 70 000 bytes was recorded but refused by the log's
// readers (64 KiB). Refused where they are read, with their place.
TEST(Errors, ATextWithANulOrANameTooLongIsRefused) {
  expect_error("[scene]\nname = \"a\\u0000b\"\n", "<string>:2:8: ", {"scene.name must not hold a NUL character (U+0000)"});
  expect_error("[sim]\nintegrator = \"midpoint\\u0000\"\n", "<string>:2:14: ",
               {"sim.integrator must not hold a NUL character"});
  const std::string longest(1024, 'n');
  EXPECT_EQ(error_of("[scene]\nname = \"" + longest + "\"\n"), "");
  expect_error("[scene]\nname = \"" + longest + "n\"\n", "<string>:2:8: ",
               {"scene.name must be at most 1024 bytes long (got 1025)"});
  expect_error("[ladder]\nblocks = 3\n", "--set scene.name=", {"scene.name must be at most 1024 bytes long (got 1025)"},
               {"scene.name=" + longest + "n"});
  EXPECT_EQ(error_of("[ladder]\nblocks = 3\n", std::vector<std::string>(10'000, "sim.dt=0.001")), "");
  EXPECT_EQ(error_of("[ladder]\nblocks = 3\n", std::vector<std::string>(10'001, "sim.dt=0.001")),
            "at most 10000 --set overrides (got 10001)");
}

TEST(Errors, NegativeMass) {
  expect_error("[ladder]\nmasses = [0.1, -0.2, 0.3]\n", "<string>:2:16: ",
               {"ladder.masses[1] must be >= 1e-06 and <= 1000000 (got -0.2)"});
}

TEST(Errors, MassesOfTheWrongLength) {
  expect_error("[ladder]\nblocks = 3\nmasses = [1, 2]\n", "<string>:3:10: ",
               {"ladder.masses has 2 entries but ladder.blocks is 3"});
  expect_error("[ladder]\nmasses = []\n", "<string>:2:10: ", {"ladder.masses must not be empty"});
}

TEST(Errors, UnknownEnumNames) {
  expect_error("[sim]\nintegrator = \"rk5\"\n", "<string>:2:14: ", {"sim.integrator", "unknown integrator 'rk5'"});
  expect_error("[solver]\nkind = \"gauss\"\n", "<string>:2:8: ", {"solver.kind", "unknown solver 'gauss'"});
  expect_error("[ladder]\ntop = \"hold\"\n", "<string>:2:7: ",
               {"ladder.top must be held, pinned or free (got 'hold')", "did you mean 'held'"});
}

TEST(Errors, GravityNeedsTwoNumbers) {
  expect_error("[sim]\ngravity = [0, -9.81, 0]\n", "<string>:2:11: ", {"sim.gravity must have exactly 2 elements"});
  expect_error("[sim]\ngravity = -9.81\n", "<string>:2:11: ", {"sim.gravity must be an array of 2 numbers"});
  expect_error("[sim]\ngravity = [0, \"down\"]\n", "<string>:2:15: ", {"sim.gravity[1] must be a number, not a string"});
}

TEST(Errors, TimelineCommandMissingAField) {
  expect_error("[[timeline]]\nt = 1\ncommand = \"poke\"\nblock = 2\n", "<string>:1:1: ",
               {"timeline[0]: command 'poke' needs 'impulse'"});
  expect_error("[[timeline]]\nt = 1\ncommand = \"break\"\n", "<string>:1:1: ", {"needs 'hinge'"});
  expect_error("\n[[timeline]]\ncommand = \"tip\"\n", "<string>:2:1: ", {"timeline[0] needs a time t"});
  expect_error("[[timeline]]\nt = 1\n[[timeline]]\nt = 2\n", "<string>:1:1: ", {"timeline[0] needs a command"});
}

TEST(Errors, TimelineBlockOutOfRange) {
  expect_error("[ladder]\nblocks = 6\n[[timeline]]\nt = 1\ncommand = \"poke\"\nblock = 6\nimpulse = [0, 1]\n",
               "<string>:6:9: ", {"timeline[0].block must be >= 0 and < 6 (got 6)"});
  expect_error("[[timeline]]\nt = 1\ncommand = \"join\"\nhinge = -1\n", "<string>:4:9: ", {"timeline[0].hinge"});
}

TEST(Errors, TimelineFieldsThatDoNotBelong) {
  expect_error("[[timeline]]\nt = 1\ncommand = \"tip\"\nblock = 0\n", "<string>:4:1: ",
               {"timeline[0].block does not apply to command 'tip'"});
  expect_error("[[timeline]]\nt = 1\ncommand = \"tip\"\nblok = 0\n", "<string>:4:1: ",
               {"unknown key 'timeline.blok'", "(did you mean 'timeline.block'?)"});
}

TEST(Errors, TimelineValues) {
  expect_error("[[timeline]]\nt = -1\ncommand = \"tip\"\n", "<string>:2:5: ", {"timeline[0].t must be >= 0 (got -1)"});
  expect_error("[[timeline]]\nt = 1\ncommand = \"jump\"\n", "<string>:3:11: ", {"timeline[0].command must be tip"});
  expect_error("[[timeline]]\nt = 0\ncommand = \"push\"\nblock = 1\nforce = [1, 0]\nduration = 0\n", "<string>:6:12: ",
               {"timeline[0].duration must be > 0 and <= 60 (got 0)"});
  // Held to the server's default command limits where the file gives them: a scene a server loads cannot script a
  // poke the server would refuse a client (1e300 N s made a non-finite state, and the server stopped publishing).
  expect_error("[[timeline]]\nt = 0\ncommand = \"poke\"\nblock = 1\nimpulse = [1e300, 0]\n", "<string>:5:11: ",
               {"timeline[0].impulse must be at most 1 N s in size (got 1e+300 N s)"});
  expect_error("[[timeline]]\nt = 0\ncommand = \"poke\"\nblock = 1\nimpulse = [0.1, 0]\nat = [5, 9]\n",
               "<string>:6:6: ", {"timeline[0].at must be at most 10 m from the origin (got 10.295630140987 m)"});
  expect_error("[[timeline]]\nt = 0\ncommand = \"push\"\nblock = 1\nforce = [0, 101]\nduration = 1\n",
               "<string>:5:9: ", {"timeline[0].force must be at most 100 N in size (got 101 N)"});
  expect_error("[[timeline]]\nt = 0\ncommand = \"push\"\nblock = 1\nforce = [0, 1]\nduration = 1e9\n",
               "<string>:6:12: ", {"timeline[0].duration must be > 0 and <= 60 (got 1000000000)"});
  expect_error("[[timeline]]\nt = 0\ncommand = \"poke\"\nblock = 1\nimpulse = [1, 0]\nat = [1]\n", "<string>:6:6: ",
               {"timeline[0].at must have exactly 2 elements"});
  expect_error("timeline = [1]\n", "<string>:1:13: ", {"timeline[0] must be a table, not an integer"});
}

TEST(Errors, FileThatCannotBeOpened) {
  const std::string path = kSource + "/config/scenes/no-such-scene.toml";
  try {
    load_scene(path);
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_EQ(std::string(e.what()), path + ": cannot open scene file (No such file or directory)");
  }
  try {
    load_scene(kSource + "/config/scenes");
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("cannot open scene file (it is a directory)"), std::string::npos);
  }
  // Larger than a session log holds a scene's text (it would be recorded, and the log then refused): a sparse file.
  const std::filesystem::path big =
      std::filesystem::temp_directory_path() / ("big-" + std::to_string(getpid()) + ".toml");
  std::ofstream(big) << "[ladder]\nblocks = 3\n";
  std::filesystem::resize_file(big, (64u << 20) + 1);
  try {
    load_scene(big.string());
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_EQ(std::string(e.what()), big.string() + ": cannot open scene file (it is larger than 64 MiB)");
  }
  std::filesystem::remove(big);
}

TEST(Errors, FileErrorsNameTheFile) {
  const std::string path = testing::TempDir() + "scene_test_bad.toml";
  std::ofstream(path) << "[ladder]\nmass = -1\n";
  try {
    load_scene(path);
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_EQ(std::string(e.what()), path + ":2:8: ladder.mass must be >= 1e-06 and <= 1000000 (got -1)");
  }
  std::remove(path.c_str());
}

TEST(Errors, OverrideErrorsNameTheOverride) {
  try {
    load_scene(scene_path("classic"), {"ladder.mass=-1"});
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_EQ(std::string(e.what()), "--set ladder.mass=-1: ladder.mass must be >= 1e-06 and <= 1000000 (got -1)");
  }
}

// ------------------------------------------------------------------------------------------- overrides

TEST(Overrides, ChangeValues) {
  const Scene s = load_scene(scene_path("classic"),
                             {"sim.dt=0.0005", "sim.integrator=rk4", "ladder.blocks=100", "sim.gravity=[0, 9.81]",
                              "ladder.top=\"pinned\"", "damping.hinge = 0.01", "scene.name=bare words"});
  EXPECT_EQ(s.dt, 0.0005);
  EXPECT_EQ(s.options.integrator, core::Integrator::RK4);
  EXPECT_EQ(s.ladder.blocks, 100);
  EXPECT_EQ(s.options.gravity, core::Vec2(0, 9.81));
  EXPECT_EQ(s.ladder.top, model::Top::Pinned);
  EXPECT_EQ(s.options.hinge_friction, 0.01);
  EXPECT_EQ(s.name, "bare words");
  EXPECT_EQ(s.ladder.length, 0.064);  // untouched
}

TEST(Overrides, CreateAMissingTable) {
  const Scene s = parse_scene("", "<string>", {"solver.max_iterations=7"});
  EXPECT_EQ(s.options.max_iterations, 7);
}

// A step given on the command line that makes the file's drag too strong is blamed, not the file's other step keys
// (it named the file's sim.accuracy, the last of them given there).
TEST(Overrides, AStepThatMakesTheFilesDragTooStrongIsBlamed) {
  const std::string text = "[sim]\ndt = 0.001\nsubsteps = 1\naccuracy = \"balanced\"\n[damping]\nlinear = 600\n";
  EXPECT_EQ(error_of(text, {"sim.dt=0.002"}),
            "--set sim.dt=0.002: damping.linear must be <= 1 / (sim.dt / sim.substeps) = 500 /s, so that one step "
            "takes at most a block's whole velocity (got 600 at sim.dt = 0.002 s, sim.substeps = 1)");
  // All of them in the file: the drag itself.
  std::string slow = text;
  slow.replace(slow.find("0.001"), 5, "0.002");
  const std::string own = error_of(slow);
  EXPECT_EQ(own.substr(0, own.find(" must")), "<string>:6:10: damping.linear") << own;
}

TEST(Overrides, TheLastOneWins) {
  const Scene s = parse_scene("", "<string>", {"sim.dt=0.002", "sim.dt=0.003"});
  EXPECT_EQ(s.dt, 0.003);
}

TEST(Overrides, AreValidatedLikeFileValues) {
  EXPECT_EQ(error_of("", {"sim.dt=1"}), "--set sim.dt=1: sim.dt must be >= 1e-07 and <= 0.1 (got 1)");
  EXPECT_EQ(error_of("", {"ladder.blocks=many"}), "--set ladder.blocks=many: ladder.blocks must be an integer, not a string");
  // A number past TOML's 64-bit integers is a number that is out of range, not "a string".
  EXPECT_EQ(error_of("", {"damping.linear=99999999999999999999"}),
            "--set damping.linear=99999999999999999999: damping.linear must be >= 0 and <= 1000 (got 1e+20)");
  EXPECT_EQ(error_of("", {"ladder.blocks=99999999999999999999"}),
            "--set ladder.blocks=99999999999999999999: ladder.blocks must be >= 1 and <= 1000000 (got 1e+20)");
  EXPECT_EQ(error_of("", {"damping.linear=1e400"}), "--set damping.linear=1e400: damping.linear must be finite (got inf)");
  EXPECT_EQ(error_of("", {"ladder.blocks=6.0"}), "--set ladder.blocks=6.0: ladder.blocks must be an integer, not a floating-point number");
  EXPECT_EQ(error_of("", {"ladder.blocks=0"}), "--set ladder.blocks=0: ladder.blocks must be >= 1 and <= 1000000 (got 0)");
  EXPECT_EQ(error_of("", {"ladder.length=nan"}), "--set ladder.length=nan: ladder.length must be finite (got nan)");
  // An array that is not TOML is named as such, with TOML's reason and where in the value it is, not "a string".
  EXPECT_EQ(error_of("", {"sim.gravity=[0, x]"}),
            "--set sim.gravity=[0, x]: sim.gravity: not a valid TOML array (near character 5): Error while parsing "
            "value: could not determine value type");
  EXPECT_EQ(error_of("", {"sim.gravity=[1e400, 0]"}),
            "--set sim.gravity=[1e400, 0]: sim.gravity: not a valid TOML array (near character 7): Error while parsing "
            "floating-point: '1e400' could not be interpreted as a value");
  EXPECT_EQ(error_of("", {"sim.gravity={x = 1}"}), "--set sim.gravity={x = 1}: sim.gravity must be an array of 2 "
                                                     "numbers, not a table");
  expect_error("", "--set sim.integrator=rk5: ", {"unknown integrator 'rk5'"}, {"sim.integrator=rk5"});
}

TEST(Overrides, AnErrorInTheFileIsStillReportedAtItsLine) {
  expect_error("[sim]\ndt = 5\n", "<string>:2:6: ", {"sim.dt"}, {"ladder.blocks=3"});
}

TEST(Overrides, UnknownKeySuggestsTheNearestOne) {
  EXPECT_EQ(error_of("", {"sim.dtt=0.001"}), "--set sim.dtt=0.001: unknown key 'sim.dtt' (did you mean 'sim.dt'?)");
  EXPECT_EQ(error_of("", {"blocks=5"}), "--set blocks=5: unknown key 'blocks' (did you mean 'ladder.blocks'?)");
  expect_error("", "--set timeline.t=1: ",
               {"timeline.t: the timeline is a list of [[timeline]] entries, given in the scene file only"},
               {"timeline.t=1"});
  expect_error("", "--set sim.dt: ", {"expected KEY=VALUE"}, {"sim.dt"});
}

TEST(Overrides, BlocksMustMatchTheFilesMasses) {
  const std::string file = "[ladder]\nmasses = [1, 2, 3]\n";
  EXPECT_EQ(error_of(file, {"ladder.blocks=4"}),
            "--set ladder.blocks=4: ladder.masses has 3 entries but ladder.blocks is 4");
  EXPECT_EQ(parse_scene(file, "<string>", {"ladder.blocks=3"}).ladder.blocks, 3);
  // Overriding both together is fine.
  const Scene s = parse_scene(file, "<string>", {"ladder.blocks=2", "ladder.masses=[5, 6]"});
  EXPECT_EQ(s.ladder.masses, (std::vector<double>{5, 6}));
}

TEST(Overrides, BlocksBoundTheTimeline) {
  const std::string file = "[[timeline]]\nt = 1\ncommand = \"break\"\nhinge = 5\n";
  EXPECT_NO_THROW(parse_scene(file, "<string>"));  // default 6 blocks
  expect_error(file, "<string>:4:9: ", {"timeline[0].hinge must be >= 0 and < 5 (got 5)"}, {"ladder.blocks=5"});
}

// ------------------------------------------------------------------------------------------- help and docs

std::vector<std::string> help_keys() {
  std::vector<std::string> keys;
  std::istringstream in(keys_help());
  std::string line;
  while (std::getline(in, line))
    if (line.starts_with("  ")) keys.push_back(line.substr(2, line.find(' ', 2) - 2));
  return keys;
}

TEST(Help, OneLinePerKey) {
  const auto keys = help_keys();
  EXPECT_EQ(keys.size(), 43u);
  EXPECT_EQ(keys.front(), "scene.name");
  const std::string help = keys_help();
  EXPECT_NE(help.find("ladder.blocks"), std::string::npos);
  EXPECT_NE(help.find("(>= 1 and <= 1000000)"), std::string::npos);
  EXPECT_NE(help.find("euler|symplectic_euler|rattle|rk4|projection|reduced"), std::string::npos);
  EXPECT_NE(help.find("fast|balanced|accurate"), std::string::npos);
  // The timeline's fields come last, under a heading of their own: --set does not take them.
  const size_t fields = help.find("The fields of a [[timeline]] entry, in a scene file only (not with --set):");
  ASSERT_NE(fields, std::string::npos);
  EXPECT_EQ(help.find("timeline."), help.find("  timeline.t ", fields) + 2);
  EXPECT_EQ(keys.back(), "timeline.duration");
}

TEST(Help, EveryIntegratorAndSolverItListsIsAccepted) {
  for (const char* i : {"euler", "symplectic_euler", "rattle", "rk4", "projection", "reduced"})
    EXPECT_NO_THROW(parse_scene("", "<string>", {std::string("sim.integrator=") + i})) << i;
  for (const char* k : {"newton", "newton_linesearch"})
    EXPECT_NO_THROW(parse_scene("", "<string>", {std::string("solver.kind=") + k})) << k;
}

TEST(Help, EveryKeyIsDocumented) {
  std::ifstream in(kSource + "/docs/scenes.md");
  ASSERT_TRUE(in) << "docs/scenes.md";
  std::stringstream doc;
  doc << in.rdbuf();
  for (const std::string& key : help_keys()) {
    const std::string leaf = key.substr(key.find('.') + 1);
    EXPECT_NE(doc.str().find("`" + leaf + "`"), std::string::npos) << key;
  }
}

}  // namespace
}  // namespace ladder::scene

TEST(Values, FlipImpactChoice) {
  EXPECT_EQ(ladder::scene::parse_scene("", "<string>").ladder.flip_impact, ladder::model::FlipImpact::Face);
  const auto s = ladder::scene::parse_scene("[ladder]\nflip_impact = \"corner\"\n", "<string>");
  EXPECT_EQ(s.ladder.flip_impact, ladder::model::FlipImpact::Corner);
  try {
    ladder::scene::parse_scene("[ladder]\nflip_impact = \"edge\"\n", "<string>");
    FAIL() << "accepted an unknown flip_impact";
  } catch (const ladder::scene::SceneError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("<string>:2:15:", 0), 0u) << e.what();
  }
}

namespace ladder::scene {
namespace {

// The rolling hinge's keys: read, published with the settings for the viewer, and refused at the key that is wrong
// (the radius against the thickness, a radius without a rolling hinge, an inset with one).
TEST(Values, RollingHingeKeys) {
  const Scene corner = parse_scene("", "<string>");
  EXPECT_EQ(corner.ladder.hinge, model::HingeKind::Corner);
  EXPECT_EQ(corner.ladder.end_radius, 0.0);
  const Scene s = parse_scene("[ladder]\nthickness = 0.01\nhinge = \"rolling\"\nend_radius = 0.005\n", "<string>");
  EXPECT_EQ(s.ladder.hinge, model::HingeKind::Rolling);
  EXPECT_EQ(s.ladder.end_radius, 0.005);
  EXPECT_NE(live_settings(s).find("\nladder.hinge=rolling\nladder.end_radius=0.005\n"), std::string::npos)
      << live_settings(s);
  expect_error("[ladder]\nthickness = 0.01\nhinge = \"rolling\"\nend_radius = 0.006\n", "<string>:4:14: ",
               {"ladder.end_radius must be at most half of ladder.thickness (got 0.006 m with a thickness of 0.01 m)"});
  expect_error("[ladder]\nend_radius = 0.001\n", "<string>:2:14: ", {"ladder.end_radius needs ladder.hinge = \"rolling\""});
  expect_error("[ladder]\nthickness = 0.01\nhinge = \"rolling\"\nend_radius = -0.001\n", "<string>:4:14: ",
               {"ladder.end_radius must be", "(got -0.001)"});
  expect_error("[ladder]\nthickness = 0.01\nhinge = \"rolling\"\nend_radius = nan\n", "<string>:4:14: ",
               {"ladder.end_radius must be finite (got nan)"});
  // A radius too small to place the hinge (the engine found the two arc centres at one point at 1e-300).
  expect_error("[ladder]\nthickness = 0.01\nhinge = \"rolling\"\nend_radius = 1e-300\n", "<string>:4:14: ",
               {"ladder.end_radius must be 0 (the corner hinge) or at least 1e-6 of ladder.thickness (got 1e-300 m"});
  EXPECT_EQ(parse_scene("[ladder]\nthickness = 0.01\nhinge = \"rolling\"\nend_radius = 1e-8\n", "<string>")
                .ladder.end_radius, 1e-8);  // the smallest radius allowed there
  expect_error("[ladder]\nhinge = \"rolling\"\nhinge_inset = 0.2\n", "<string>:3:15: ",
               {"ladder.hinge_inset is for corner hinges"});
  expect_error("[ladder]\nhinge = \"pivot\"\n", "<string>:2:9: ", {"ladder.hinge must be", "corner", "rolling"});
  // A key given on the command line that leaves a key of the file in conflict is blamed, and the message says where
  // the file's key is: a thickness that leaves the radius too large, a corner hinge with the file's radius, a rolling
  // hinge with the file's inset. Given both in the file or both on the command line, the first key is blamed.
  expect_error("[ladder]\nhinge = \"rolling\"\nend_radius = 0.006\n", "--set ladder.thickness=0.01: ",
               {"at most half of ladder.thickness (got 0.006 m with a thickness of 0.01 m) (ladder.end_radius is "
                "given at <string>:3:14)"},
               {"ladder.thickness=0.01"});
  expect_error("[ladder]\nhinge = \"rolling\"\nend_radius = 0.004\n", "--set ladder.hinge=corner: ",
               {"ladder.end_radius needs ladder.hinge = \"rolling\"", "ladder.end_radius must be 0)",
                "(ladder.end_radius is given at <string>:3:14)"},
               {"ladder.hinge=corner"});
  expect_error("[ladder]\nhinge_inset = 0.2\n", "--set ladder.hinge=rolling: ",
               {"ladder.hinge_inset is for corner hinges", "(ladder.hinge_inset is given at <string>:2:15)"},
               {"ladder.hinge=rolling"});
  expect_error("[ladder]\nend_radius = 0.004\n", "--set ladder.end_radius=0.005: ",
               {"ladder.end_radius needs ladder.hinge = \"rolling\""},
               {"ladder.end_radius=0.005", "ladder.hinge=corner"});
  const std::string both = error_of("[ladder]\nhinge = \"corner\"\nend_radius = 0.004\n", {});
  EXPECT_EQ(both.find(" is given at "), std::string::npos) << both;
}

}  // namespace
}  // namespace ladder::scene
