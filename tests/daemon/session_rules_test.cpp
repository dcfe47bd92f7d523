// The session's command rules in-process, with typed commands (daemon/command.hpp) and no DDS: every refusal
// reason word for word, that a refusal changes nothing, pause and step, reset and load, and that a command's
// action reaches the ladder by the same path as the scene timeline's. The server tests (server_test.cpp) keep what
// needs a real ladderd: the wire, the loop's timing, the acks.
#include "classic_session.hpp"
#include "daemon/session.hpp"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>

namespace ladder::daemon {
namespace {

using core::Vec2;
namespace m = model;

struct Before {
  std::uint64_t hash, steps, pending;
  std::string settings;
  std::uint32_t generation;
  bool paused;
  std::size_t grips;
};
Before before(const Session& s) {
  return {s.state_hash(), s.sim().steps(), s.pending_steps(), scene::live_settings(s.sim().scene()),
          s.generation(), s.paused(), s.sim().ladder().grips().size()};
}

// Applies r and expects a refusal whose reason starts with `reason` (all of it when `whole`), and no change at all.
void refused(Session& s, const Request& r, const std::string& reason, bool whole = true) {
  const Before b = before(s);
  const Outcome o = s.apply(r);
  EXPECT_FALSE(o.accepted) << "accepted; expected: " << reason;
  if (whole)
    EXPECT_EQ(o.reason, reason);
  else
    EXPECT_EQ(o.reason.rfind(reason, 0), 0u) << o.reason;
  const Before a = before(s);
  EXPECT_EQ(a.hash, b.hash) << reason;
  EXPECT_EQ(a.steps, b.steps) << reason;
  EXPECT_EQ(a.pending, b.pending) << reason;
  EXPECT_EQ(a.settings, b.settings) << reason;
  EXPECT_EQ(a.generation, b.generation) << reason;
  EXPECT_EQ(a.paused, b.paused) << reason;
  EXPECT_EQ(a.grips, b.grips) << reason;
}

void accepted(Session& s, const Request& r) {
  const Outcome o = s.apply(r);
  EXPECT_TRUE(o.accepted) << o.reason;
  EXPECT_EQ(o.reason, "");
}

// As the server's loop runs a paused session: one ordered step at a time.
void run_pending(Session& s) {
  while (s.paused() && s.pending_steps() > 0) {
    s.take_pending_step();
    s.step();
  }
}

Request action(m::Action a) { return a; }

TEST(SessionRules, EveryLadderActionRefusalWordForWord) {
  auto s = classic();
  accepted(*s, Verb{Pause{}});
  refused(*s, action(m::Poke{99, {0.001, 0}, {}}), "no block 99 (blocks are 0..5)");
  refused(*s, action(m::Poke{-1, {0.001, 0}, {}}), "no block -1 (blocks are 0..5)");
  refused(*s, action(m::Poke{2, {kNan, 0}, {}}), "the impulse is nan, not a finite number");
  refused(*s, action(m::Poke{2, {1e6, 0}, {}}), "the impulse of 1e+06 N s is beyond the limit of 1 N s "
                                                  "(commands.max_impulse)");
  // Just over a limit: as many digits as it takes to tell the value from the limit (six made it "1 ... beyond 1").
  refused(*s, action(m::Poke{2, {1.0000001, 0}, {}}), "the impulse of 1.0000001 N s is beyond the limit of 1 N s "
                                                        "(commands.max_impulse)");
  refused(*s, action(m::Poke{2, {0.001, 0}, Vec2(kInf, 0)}), "the point is inf, not a finite number");
  refused(*s, action(m::Poke{2, {0.001, 0}, Vec2(5, 5)}), "the point is ", false);
  // Far away, a poke's point is beyond reach first (1e308: its offset from the block turned into the block's frame
  // was inf mm).
  refused(*s, action(m::Poke{2, {0.001, 0}, Vec2(1e308, 1e308)}),
          "the point is 1.4142135623730951e+308 m from the origin, beyond the reach of 10 m (commands.reach)");
  refused(*s, action(m::Poke{0, {0.001, 0}, {}}), "impulse: the block is held and does not move freely");
  refused(*s, action(m::Push{0, {1, 0}, {0, 0}, 0.1}), "push: the block is held and does not move freely");
  refused(*s, action(m::Push{2, {kInf, 0}, {0, 0}, 0.1}), "the force is inf, not a finite number");
  refused(*s, action(m::Push{2, {5000, 0}, {0, 0}, 0.1}), "the force of 5000 N is beyond the limit of 100 N "
                                                           "(commands.max_force)");
  refused(*s, action(m::Push{2, {1, 0}, {0, 0}, -1}), "the duration must be > 0 and at most 60 s "
                                                       "(commands.max_duration), not -1");
  refused(*s, action(m::Push{2, {1, 0}, {0, 0}, kNan}), "the duration is nan, not a finite number");
  refused(*s, action(m::Push{2, {1, 0}, {0.5, 0}, 0.1}), "the point is 500 mm across and 0 mm along block 2 from its "
                                                          "centre, outside the block (at most 6.5 mm across and 32 mm "
                                                          "along)");
  // Within the half-diagonal (32.65 mm) but beside the 13 mm thick block: outside it.
  refused(*s, action(m::Push{2, {1, 0}, {0.03, 0}, 0.1}), "the point is 30 mm across and 0 mm along block 2", false);
  accepted(*s, action(m::Push{2, {0.001, 0}, {0.0065, -0.032}, 0.1}));  // a corner
  // A poke's point is in the world: it is taken into the block's frame by the block's angle (block 2 hangs turned).
  const model::Ladder& l = s->sim().ladder();
  const core::Rot turn = core::Rot::of(l.block_angle(2));
  ASSERT_GT(std::abs(l.block_angle(2)), 0.1);
  refused(*s, action(m::Poke{2, {0.001, 0}, Vec2(l.block_centre(2) + turn * Vec2(0.03, 0))}),
          "the point is 30 mm across and ", false);
  accepted(*s, action(m::Poke{2, {0.001, 0}, Vec2(l.block_centre(2) + turn * Vec2(0.006, 0.031))}));
  refused(*s, action(m::Grab{0, {0, 0}, {}, {}, 0}), "block 0 is held by the hand; grab another block");
  refused(*s, action(m::Grab{9, {0, 0}, {}, {}, 0}), "no block 9 (blocks are 0..5)");
  refused(*s, action(m::Grab{3, {0, 0}, Vec2(1e9, 0), {}, 0}), "the target is 1e+09 m from the origin, beyond the "
                                                               "reach of 10 m (commands.reach)");
  refused(*s, action(m::Grab{3, {0, 0}, {}, {}, -1}),
          "the stiffness must be from 0 (the default) to 1e+06 N/m, not -1");
  refused(*s, action(m::Grab{3, {0, 0}, {}, 2000.0, 0}), "the angle must be from -1000 to 1000 rad, not 2000");
  refused(*s, action(m::Drag{3, {0, 0}, {}}), "nothing is grabbed; grab a block first");
  refused(*s, action(m::Release{3}), "nothing is grabbed; grab a block first");
  accepted(*s, action(m::Grab{4, {0, 0}, {}, {}, 0}));
  refused(*s, action(m::Drag{4, {0, -0.2}, kNan}), "the angle is nan, not a finite number");
  refused(*s, action(m::Drag{4, {0, 1e3}, {}}), "the target is 1000 m from the origin, beyond the reach of 10 m "
                                                "(commands.reach)");
  refused(*s, action(m::Release{2}), "block 2 is not grabbed");
  // A block that does not exist is named as such, grabbed or not (it was "block 9 is not grabbed").
  refused(*s, action(m::Release{9}), "no block 9 (blocks are 0..5)");
  refused(*s, action(m::Drag{-1, {0, 0}, {}}), "no block -1 (blocks are 0..5)");
  accepted(*s, action(m::Release{4}));
  refused(*s, action(m::Break{6}), "no hinge 6 (hinges are 0..5; hinge 0 is the top block's hold)");
  refused(*s, action(m::Join{3}), "hinge 3 is not broken");
  accepted(*s, action(m::Break{5}));
  refused(*s, action(m::Break{5}), "hinge 5 is already broken");
  accepted(*s, Verb{Step{300}});
  run_pending(*s);  // block 5 falls away
  refused(*s, action(m::Join{5}), "hinge 5: the corners are ", false);
  // Block 0 let go of by the hand may be grabbed; the hand takes it back only once the grip is released (before, a
  // join left the grip on the held block, and drags of it were accepted and did nothing).
  accepted(*s, action(m::Break{0}));
  accepted(*s, action(m::Grab{0, {0, 0}, {}, {}, 0}));
  refused(*s, action(m::Join{0}), "block 0 is grabbed; release it before the hand takes it back (join 0)");
  accepted(*s, action(m::Release{0}));
  accepted(*s, action(m::Join{0}));
  refused(*s, action(m::Grab{0, {0, 0}, {}, {}, 0}), "block 0 is held by the hand; grab another block");
  accepted(*s, action(m::Tip{}));
  refused(*s, action(m::Tip{}), "a tip is already in progress (it ends at t = ", false);
}

TEST(SessionRules, EverySessionVerbRefusalWordForWord) {
  auto s = classic();
  refused(*s, Verb{Resume{}}, "not paused");
  refused(*s, Verb{Step{5}}, "step works while paused: send pause first");
  accepted(*s, Verb{Pause{}});
  refused(*s, Verb{Pause{}}, "already paused");
  refused(*s, Verb{Step{0}}, "the step count must be 1 to 100000 (commands.max_step_count), not 0");
  refused(*s, Verb{Step{100001}}, "the step count must be 1 to 100000 (commands.max_step_count), not 100001");
  refused(*s, Verb{Set{"server.physics_rate=10"}},
          "server.physics_rate=10: server.physics_rate cannot change while the server runs; set it in ladderd.toml");
  refused(*s, Verb{Set{"server.publish_rate"}}, "server.publish_rate: expected key=value");
  refused(*s, Verb{Set{"server.speed=2"}},
          "server.speed=2: unknown key server.speed (server keys: server.real_time_factor, server.publish_rate)");
  refused(*s, Verb{Set{"ladder.blocks=3"}},
          "ladder.blocks=3: ladder.blocks cannot change while the ladder runs (live keys: sim.*, solver.*, damping.*, "
          "server.real_time_factor, server.publish_rate); set it in the scene file and load the scene again");
  refused(*s, Verb{Load{""}}, "load: give a scene name, e.g. classic");
  refused(*s, Verb{Load{"../../etc/passwd"}},
          "not permitted: scenes are loaded by name from the server's scene directory " + kScenes);
  refused(*s, Verb{Load{"no-such-scene"}},
          "no scene 'no-such-scene' in " + kScenes +
              " (available: classic, double-ripple, free-chain, long, tall, tall-double-ripple, toy-1889)");
  // A name as long as a command's text (1024 bytes): named by its first 80 characters and its length, so that the
  // reason and the list of scenes still fit the 512 bytes of an answer's reason.
  const std::string reason = "no scene '" + std::string(80, 'n') + "... (1024 characters)' in " + kScenes +
                             " (available: classic, double-ripple, free-chain, long, tall, tall-double-ripple, toy-1889)";
  ASSERT_LT(reason.size(), 512u);
  refused(*s, Verb{Load{std::string(1024, 'n')}}, reason);
  // A kind that names no command, as it may come from a client or a log.
  CommandFields unknown;
  unknown.kind = 14;
  const Before b = before(*s);
  const Outcome o = s->apply(unknown);
  EXPECT_FALSE(o.accepted);
  EXPECT_EQ(o.reason, "unknown command kind 14");
  EXPECT_EQ(s->state_hash(), b.hash);
}

// A scenes folder may hold a .toml that is no file (a pipe, which a read would wait on forever; a folder): `load`
// says it is not a regular file, and the list of what there is leaves it out. (Before: "no scene 'pipe' in ...
// (available: classic, folder, pipe)".)
TEST(SessionRules, ALoadOfAPipeOrAFolderSaysItIsNoRegularFile) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("ladder-scenes-" + std::to_string(getpid()));
  fs::create_directories(dir / "folder.toml");
  fs::copy_file(kScenes + "/classic.toml", dir / "classic.toml", fs::copy_options::overwrite_existing);
  ASSERT_EQ(mkfifo((dir / "pipe.toml").c_str(), 0600), 0);
  scene::Scene sc = scene::load_scene(kScenes + "/classic.toml");
  Session s(sc, dir.string(), Limits{}, Rates{});
  refused(s, Verb{Load{"pipe"}}, "'pipe.toml' in " + dir.string() + " is not a regular file (a scene is a .toml file)");
  refused(s, Verb{Load{"folder"}},
          "'folder.toml' in " + dir.string() + " is not a regular file (a scene is a .toml file)");
  refused(s, Verb{Load{"nothing"}}, "no scene 'nothing' in " + dir.string() + " (available: classic)");
  accepted(s, Verb{Load{"classic"}});
  fs::remove_all(dir);
}

// A scene whose rolling hinge the scene rules refuse (an end radius above half the thickness, NaN or negative, or a
// rolling hinge with an inset) is refused by `load` with the file's line, column and reason, and the ladder is left
// as it was.
TEST(SessionRules, ALoadOfABadRollingHingeSaysWhereAndChangesNothing) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("ladder-rolling-" + std::to_string(getpid()));
  fs::create_directories(dir);
  std::ifstream in(kScenes + "/classic.toml");
  std::stringstream classic;
  classic << in.rdbuf();
  const std::string text = classic.str();
  const std::size_t at = text.find("logic = true");
  ASSERT_NE(at, std::string::npos);
  const auto write = [&](const std::string& name, const std::string& lines) {
    std::ofstream(dir / (name + ".toml")) << text.substr(0, at) + lines + text.substr(at);
  };
  write("wide", "hinge = \"rolling\"\nend_radius = 0.02\n");
  write("nan", "hinge = \"rolling\"\nend_radius = nan\n");
  write("negative", "hinge = \"rolling\"\nend_radius = -0.004\n");
  write("inset", "hinge = \"rolling\"\nend_radius = 0.004\nhinge_inset = 0.1\n");
  const int line = 1 + static_cast<int>(std::count(text.begin(), text.begin() + static_cast<long>(at), '\n'));
  scene::Scene sc = scene::load_scene(kScenes + "/classic.toml");
  Session s(sc, dir.string(), Limits{}, Rates{});
  const auto starts_with = [&](const std::string& name, const std::string& where) {
    refused(s, Verb{Load{name}}, (dir / (name + ".toml")).string() + ":" + where, false);
  };
  starts_with("wide", std::to_string(line + 1) + ":14: ladder.end_radius must be at most half of ladder.thickness "
                      "(got 0.02 m with a thickness of 0.013 m)");
  starts_with("nan", std::to_string(line + 1) + ":14: ladder.end_radius must be finite (got nan)");
  starts_with("negative", std::to_string(line + 1) + ":14: ladder.end_radius must be >= 0 (got -0.004)");
  starts_with("inset", std::to_string(line + 2) + ":15: ladder.hinge_inset is for corner hinges; a rolling hinge's "
                       "pivot is set by ladder.end_radius");
  fs::remove_all(dir);
}

TEST(SessionRules, PausedTheSessionRunsExactlyTheOrderedSteps) {
  auto s = classic();
  accepted(*s, Verb{Pause{}});
  const std::uint64_t at = s->sim().steps();
  accepted(*s, Verb{Step{10}});
  accepted(*s, Verb{Step{5}});  // they add up
  EXPECT_EQ(s->pending_steps(), 15u);
  run_pending(*s);
  EXPECT_EQ(s->sim().steps(), at + 15);
  EXPECT_DOUBLE_EQ(s->sim().time(), 15 * s->sim().dt()) << "15 steps of dt from t = 0";
  accepted(*s, Verb{Step{7}});
  accepted(*s, Verb{Resume{}});  // resuming drops the steps not yet taken
  EXPECT_FALSE(s->paused());
  EXPECT_EQ(s->pending_steps(), 0u);
}

TEST(SessionRules, ResetKeepsTheLiveSettingsAndLoadDropsThem) {
  auto s = classic();
  const std::uint64_t start = s->state_hash();
  accepted(*s, Verb{Set{"damping.linear=0.5"}});
  accepted(*s, action(m::Poke{3, {0.001, 0}, {}}));
  for (int i = 0; i < 20; ++i) s->step();
  accepted(*s, Verb{Reset{}});
  EXPECT_EQ(s->generation(), 1u) << "a reset starts generation 1 (the scene's first is 0)";
  EXPECT_EQ(s->sim().steps(), 0u);
  EXPECT_EQ(s->state_hash(), start) << "back to the scene's first state";
  EXPECT_NE(scene::live_settings(s->sim().scene()).find("damping.linear=0.5\n"), std::string::npos);
  accepted(*s, Verb{Load{"double-ripple"}});
  EXPECT_EQ(s->generation(), 2u);
  EXPECT_EQ(s->sim().ladder().blocks(), 16);
  EXPECT_EQ(scene::live_settings(s->sim().scene()).find("damping.linear=0.5\n"), std::string::npos);
}

// One path to the ladder: a poke and a push sent as commands leave the very state (every bit of it) that the same
// poke and push in the scene's timeline leave.
TEST(SessionRules, ACommandAndTheTimelineReachTheLadderAlike) {
  scene::Scene scripted = scene::load_scene(kScenes + "/classic.toml");
  scripted.timeline = {{0, m::Poke{3, {0.002, 0}, {}}, "test:1:1"},
                       {0, m::Push{4, {0.5, 0}, {0, 0.01}, 0.05}, "test:2:1"}};
  Session timeline(scripted, kScenes, Limits{}, Rates{});
  scene::Scene plain = scripted;
  plain.timeline.clear();
  Session commands(plain, kScenes, Limits{}, Rates{});
  accepted(commands, action(m::Poke{3, {0.002, 0}, {}}));
  accepted(commands, action(m::Push{4, {0.5, 0}, {0, 0.01}, 0.05}));
  for (int i = 0; i < 200; ++i) timeline.step(), commands.step();
  EXPECT_EQ(timeline.state_hash(), commands.state_hash());
  EXPECT_NE(timeline.state_hash(), Session(plain, kScenes, Limits{}, Rates{}).state_hash());
}

// The typed command is what the wire's fields say, field by field, and no field a kind does not read.
TEST(SessionRules, TheFieldsOfEachKindMakeItsTypedCommand) {
  CommandFields f;
  f.kind = kind::kGrab;
  f.block = 2;
  f.a = 0.1, f.b = -0.2, f.c = 0.001, f.d = 0.002, f.e = 50, f.f = kNan;
  f.has_point = true;
  f.has_target = true;
  const auto grab = std::get<m::Grab>(std::get<m::Action>(request_of(f)));
  EXPECT_EQ(grab.block, 2);
  EXPECT_EQ(grab.local, Vec2(0.001, 0.002));
  EXPECT_EQ(grab.target, Vec2(0.1, -0.2));
  EXPECT_FALSE(grab.angle.has_value()) << "f is read only with has_angle";
  EXPECT_EQ(grab.stiffness, 50);
  f.kind = kind::kPoke;
  f.has_point = false;
  EXPECT_FALSE(std::get<m::Poke>(std::get<m::Action>(request_of(f))).at.has_value());
  f.kind = kind::kSet;
  f.text = "sim.dt=0.002";
  EXPECT_EQ(std::get<Set>(std::get<Verb>(request_of(f))).setting, "sim.dt=0.002");
  for (std::int32_t k = 0; k <= kind::kLast; ++k) {
    f.kind = k;
    EXPECT_NO_THROW(request_of(f)) << kind_name(k);
  }
  f.kind = -1;
  EXPECT_THROW(request_of(f), std::invalid_argument);
  EXPECT_STREQ(kind_name(-1), "unknown");
  EXPECT_STREQ(kind_name(kind::kBreak), "break");
}

}  // namespace
}  // namespace ladder::daemon
