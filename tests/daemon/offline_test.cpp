// ladderd --offline as a user runs it: the real binary, real files, exit codes and error messages.
#include "process.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

const std::string kLadderd = std::string(LADDER_BINARY_DIR) + "/server/ladderd";
const std::string kScenes = std::string(LADDER_SOURCE_DIR) + "/config/scenes/";

using ladder::test::Result;

Result ladderd(const std::string& args) { return ladder::test::shell(kLadderd + " " + args); }

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

class Offline : public ::testing::Test {
 protected:
  void SetUp() override {
    dir = fs::temp_directory_path() /
          ("ladderd-test-" + std::to_string(::getpid()) + "-" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir);
  }
  void TearDown() override { fs::remove_all(dir); }
  std::string path(const std::string& name) const { return (dir / name).string(); }
  fs::path dir;
};

// The classic scene for 10 s: the events name hinges 1..5 flipping in order; the trajectory has its exact header and
// one row per block every 10 ms; the summary has every documented key with sane values, its energy lost by each kind
// of event the sum of those events' energies, and each flip-flop's line what was lost since the last one (or the
// start).
TEST_F(Offline, ClassicWritesEventsTrajectoryAndSummary) {
  const Result r = ladderd("--offline --quiet --scene " + kScenes + "classic.toml --duration 10 --events " +
                           path("ev.jsonl") + " --trajectory " + path("traj.csv") + " --summary " + path("sum.json"));
  ASSERT_EQ(r.code, 0) << r.output;
  std::map<int, double> first;
  std::map<std::string, double> removed;  // kind -> the sum of its events' energy_removed
  std::istringstream events(slurp(path("ev.jsonl")));
  for (std::string line; std::getline(events, line);) {
    const json e = json::parse(line);
    ASSERT_TRUE(e.contains("t") && e.contains("kind") && e.contains("hinge") && e.contains("energy_removed")) << line;
    removed[e["kind"]] += e["energy_removed"].get<double>();
    if (e["kind"] != "flip_flop") continue;
    EXPECT_EQ(e["detail"].get<std::string>().rfind("lost ", 0), 0u) << line;
    // The first flip-flop's loss is counted from the start, the others' from the flip-flop before.
    const char* since = first.empty() ? " J since the start: " : " J since the last flip-flop: ";
    EXPECT_NE(e["detail"].get<std::string>().find(since), std::string::npos) << line;
    if (!first.count(e["hinge"].get<int>())) first[e["hinge"]] = e["t"];
  }
  ASSERT_EQ(first.size(), 5u);
  for (int k = 2; k <= 5; ++k) EXPECT_GT(first[k], first[k - 1]);

  std::istringstream traj(slurp(path("traj.csv")));
  std::string line;
  std::getline(traj, line);
  EXPECT_EQ(line, "t,block,x,y,theta");
  int rows = 0;
  double last_t = -1;
  while (std::getline(traj, line)) {
    double t, x, y, th;
    int block;
    ASSERT_EQ(std::sscanf(line.c_str(), "%lf,%d,%lf,%lf,%lf", &t, &block, &x, &y, &th), 5) << line;
    EXPECT_EQ(block, rows % 6);
    EXPECT_NEAR(t, 0.01 * (rows / 6), 1e-9);
    EXPECT_TRUE(std::isfinite(x) && std::isfinite(y) && std::isfinite(th));
    last_t = t;
    ++rows;
  }
  EXPECT_EQ(rows, 1001 * 6);  // t = 0, 0.01, ..., 10
  EXPECT_NEAR(last_t, 10.0, 1e-9);

  const json s = json::parse(slurp(path("sum.json")));
  EXPECT_EQ(s["steps"], 10000);
  EXPECT_EQ(s["blocks"], 6);
  EXPECT_EQ(s["failed"], false);
  EXPECT_GT(s["wall_seconds"].get<double>(), 0);
  EXPECT_GT(s["block_steps_per_second"].get<double>(), 0);
  EXPECT_LT(s["max_hinge_error_m"].get<double>(), 1e-9);
  // The hand's tip does work on the ladder, at most lifting every block by one length: N m g L = 0.094 J.
  EXPECT_LT(std::abs(s["energy_final_J"].get<double>() - s["energy_initial_J"].get<double>()), 6 * 0.025 * 9.81 * 0.064);
  EXPECT_EQ(s["events"]["flip_flop"], 5);
  const json& lost = s["energy_lost_J"];
  double parts = 0;
  for (const char* kind : {"flip_flop", "impact", "lock", "join"}) {
    EXPECT_NEAR(lost[kind].get<double>(), removed[kind], 1e-15) << kind;
    parts += lost[kind].get<double>();
  }
  EXPECT_GT(lost["impact"].get<double>(), 0);
  EXPECT_GT(lost["motion"].get<double>(), 0);  // the drag
  EXPECT_NEAR(lost["total"].get<double>(), parts + lost["motion"].get<double>(), 1e-15);
  EXPECT_GT(s["energy_lost_per_flip_flop_J"].get<double>(), 0);
  EXPECT_LT(s["energy_lost_per_flip_flop_J"].get<double>(), lost["total"].get<double>() / 5 + 1e-15);
  // The ledger closes: the energy at the start, plus what the hand put in, less what was lost, is the energy at the
  // end (to rounding: the energies are sums of about 20 terms of 0.1 J). The tip puts in more than the whole rise.
  const double put_in = s["energy_put_in_J"].get<double>();
  EXPECT_GT(put_in, s["energy_final_J"].get<double>() - s["energy_initial_J"].get<double>());
  EXPECT_NEAR(s["energy_initial_J"].get<double>() + put_in - lost["total"].get<double>(),
              s["energy_final_J"].get<double>(), 1e-14);
  // What the run was: its file, no overrides, the settings in force.
  EXPECT_EQ(s["source"], kScenes + "classic.toml");
  EXPECT_TRUE(s["overrides"].empty());
  EXPECT_EQ(s["settings"]["sim.integrator"], "midpoint");
  EXPECT_EQ(s["settings"]["damping.linear"], "0.1");
}

TEST_F(Offline, SetOverridesTheScene) {
  const Result r = ladderd("--offline --quiet --scene " + kScenes + "classic.toml --duration 0.05 --set ladder.blocks=3"
                           " --set sim.integrator=rk4 --trajectory " + path("traj.csv") + " --summary " + path("sum.json"));
  ASSERT_EQ(r.code, 0) << r.output;
  const json s = json::parse(slurp(path("sum.json")));
  EXPECT_EQ(s["blocks"], 3);
  EXPECT_EQ(s["logic"], true);
  EXPECT_EQ(s["integrator"], "rk4");
  EXPECT_EQ(s["steps"], 50);
  EXPECT_EQ(s["settings"]["sim.integrator"], "rk4");
  ASSERT_TRUE(s["overrides"].is_array());
  EXPECT_EQ(s["overrides"].back(), "sim.integrator=rk4");
  std::istringstream traj(slurp(path("traj.csv")));
  int rows = -1;
  for (std::string line; std::getline(traj, line);) ++rows;
  EXPECT_EQ(rows, 6 * 3);  // t = 0 .. 0.05 every 10 ms, three blocks
}

// Trajectory samples fall on exact multiples of 10 ms at any step: at dt = 1e-4 s a sampler comparing a running sum
// of the steps with k * 10 ms fell one step late after about 1 s; the time is counted in steps, so the sample of
// 1.23 s is written as 1.23 (to 17 digits) and there is one sample per 10 ms, no more, no fewer. The run's end
// time is exact too.
TEST_F(Offline, TrajectorySamplesFallOnExactMultiplesOfTenMilliseconds) {
  for (const char* dt : {"0.0001", "0.0003", "0.001"}) {
    const Result r = ladderd("--offline --quiet --scene " + kScenes + "free-chain.toml --duration 2 --set sim.dt=" + dt +
                             " --trajectory " + path("traj.csv") + " --summary " + path("sum.json"));
    ASSERT_EQ(r.code, 0) << r.output;
    std::istringstream traj(slurp(path("traj.csv")));
    std::string line;
    std::getline(traj, line);  // header
    int k = 0;
    const double step = std::stod(dt);
    const bool whole = std::abs(0.01 / step - std::round(0.01 / step)) < 1e-9;  // 10 ms is a whole number of steps
    for (int row = 0; std::getline(traj, line); ++row) {
      if (row % 2) continue;  // two blocks a sample
      const double t = std::stod(line.substr(0, line.find(',')));
      // The first step that reaches k * 10 ms: exactly k * 10 ms when 10 ms is a whole number of steps.
      const double expected = std::ceil(0.01 * k / step - 1e-6) * step;
      EXPECT_EQ(t, expected) << "dt " << dt << " sample " << k;
      if (whole) {
        EXPECT_NEAR(t, 0.01 * k, 1e-15 * (1 + t)) << "dt " << dt << " sample " << k;
      }
      ++k;
    }
    EXPECT_EQ(k, 201) << "dt " << dt;
    if (whole) {
      EXPECT_EQ(json::parse(slurp(path("sum.json")))["sim_time"].get<double>(), 2.0) << "dt " << dt;
    }
  }
}

// An event at a step's end carries that step's time as the states do, counted in steps: an unlock comes at the end
// of the step at which the loads pull the pair open, so its t is a whole number of steps exactly (the core's running
// sum of step lengths put the classic toy's first unlock at 1.1239999999999872 s; it is 1.124 s).
TEST_F(Offline, EventsAtAStepsEndCarryItsExactTime) {
  for (const char* dt : {"0.001", "0.0001"}) {
    const Result r = ladderd("--offline --quiet --scene " + kScenes + "classic.toml --duration 3 --set sim.dt=" + dt +
                             " --events " + path("ev.jsonl"));
    ASSERT_EQ(r.code, 0) << r.output;
    std::istringstream events(slurp(path("ev.jsonl")));
    const double step = std::stod(dt);
    int unlocks = 0;
    for (std::string line; std::getline(events, line);) {
      const json e = json::parse(line);
      if (e["kind"] != "unlock") continue;
      ++unlocks;
      const double t = e["t"].get<double>();
      EXPECT_EQ(t, std::round(t / step) * step) << "dt " << dt << ": " << line;
    }
    EXPECT_GT(unlocks, 0) << "dt " << dt;
  }
}

// Same scene, same settings: the same trajectory to the last digit (17 significant digits are written).
TEST_F(Offline, RunsAreBitForBitRepeatable) {
  for (const char* name : {"a.csv", "b.csv"}) {
    const Result r = ladderd("--offline --quiet --scene " + kScenes + "double-ripple.toml --duration 2 --trajectory " +
                             path(name));
    ASSERT_EQ(r.code, 0) << r.output;
  }
  EXPECT_EQ(slurp(path("a.csv")), slurp(path("b.csv")));
}

TEST_F(Offline, BadSceneIsRefusedWithItsPosition) {
  std::ofstream(path("bad.toml")) << "[ladder]\nblocks = 4\nmass = -1\n";
  const Result r = ladderd("--offline --scene " + path("bad.toml") + " --duration 1 --summary " + path("sum.json"));
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find(path("bad.toml") + ":3:8: ladder.mass must be >= 1e-06 and <= 1000000 (got -1)"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(path("sum.json")));  // nothing was run, nothing written
}

TEST_F(Offline, BadCommandLinesExitTwoWithAReason) {
  const std::string scene = " --scene " + kScenes + "classic.toml";
  struct Case { std::string args, words; };
  for (const Case& c : {Case{"--offline --duration 1 --scene /no/such.toml", "--scene /no/such.toml: no such file\n"},
                        Case{"--offline" + scene + " --duration ten", "--duration: 'ten' is not a number"},
                        Case{"--offline" + scene + " --duration 1 --duration 2 --duration 3",
                             "--duration is given 3 times; give it once\n"},
                        Case{scene + " --spin-us 1.5", "--spin-us: '1.5' is not a whole number"},
                        Case{"--offline" + scene, "--duration"},
                        Case{"--offline" + scene + " --duration 1e-10",
                             "--duration 1e-10 s is shorter than half a step (sim.dt = 0.001 s): no step would run"},
                        Case{"--offline" + scene + " --duration 1 --set ladder.blokcs=3", "did you mean 'ladder.blocks'"},
                        Case{"--offline" + scene + " --duration 1 --set sim.dt=nan", "sim.dt"},
                        Case{"--offline" + scene + " --duration 1 --summary /no/such/dir/s.json",
                             "cannot write the summary file '/no/such/dir/s.json': No such file or directory"},
                        Case{"--offline" + scene + " --duration 0",
                             "--duration must be a positive number of seconds (got 0)"},
                        Case{"--offline" + scene + " --duration -1",
                             "--duration must be a positive number of seconds (got -1)"},
                        Case{"--offline" + scene + " --duration 1 --set timeline.t=3",
                             "timeline.t: the timeline is a list of [[timeline]] entries, given in the scene "
                             "file only"},
                        Case{scene + " --domian 3", "ladderd: unknown option '--domian' (did you mean '--domain'?)\n"},
                        Case{scene + " --log-level foo", "log.level must be trace, debug, info, warn, error or off, "
                                                         "not 'foo' (given as --log-level foo)"},
                        Case{"--offline" + scene + " --duration 1 --events /dev/full",
                             "writing /dev/full failed (is the disk full?)"},
                        Case{"--offline" + scene + " --duration 1 --record " + path("s.lcmlog"),
                             "--record is for the live server, not --offline"},
                        Case{scene + " --duration 1", "--duration is for --offline runs"},
                        Case{"--offline --duration 1 --scene " + std::string(LADDER_SOURCE_DIR) + "/config",
                             "/config: a folder, not a scene file"},
                        Case{"--offline --duration 1 --scene /dev/null", "--scene /dev/null: not a regular file"},
                        Case{"--offline" + scene + " --duration 1 --frobnicate", "frobnicate"},
                        // Server mode: every check comes before DDS is touched.
                        Case{scene + " --rtf -1", "server.real_time_factor must be from 0"},
                        Case{scene + " --rate 0.5", "server.physics_rate must be from 1 to 100000 ticks a second "
                                                    "(given as --rate 0.5)"},
                        Case{scene + " --rate 100 --publish-rate 200", "server.publish_rate must be >= 1 and at most"},
                        Case{scene + " --sim-id 'a b'", "server.sim_id 'a b' may hold only"},
                        Case{scene + " --set ladder.blocks=0", "ladder.blocks"},
                        Case{scene + " --domain 232", "--domain: '232' is not a DDS domain id (0 to 231)"},
                        Case{scene + " --domain text", "--domain: 'text' is not a DDS domain id (0 to 231)"},
                        // The log turned off still leaves the reason a run did not start.
                        Case{"--offline" + scene + " --duration 1 --log-level off --set sim.dt=1",
                             "ladderd: --set sim.dt=1: sim.dt must be >= 1e-07 and <= 0.1 (got 1)"},
                        Case{scene + " --log-level off --security /no/such/dir",
                             "/no/such/dir: no such folder (scripts/make-pki DIR --server, --controller or --viewer"},
                        Case{scene + " --realtime-priority 100", "--realtime-priority"},
                        Case{scene + " --rate 500 --spin-us 5000",
                             "server.spin_us must be from 0 to half the tick period (1000 us at 500 Hz)"},
                        Case{scene + " --tick-log /no/such/dir/t.txt",
                             "cannot create the tick log '/no/such/dir/t.txt': No such file or directory"},
                        Case{scene + " --record /no/such/dir/s.lcmlog",
                             "cannot create the session log '/no/such/dir/s.lcmlog': No such file or directory"},
                        Case{scene + " --publish-rate 0.5",
                             "server.publish_rate must be >= 1 and at most server.physics_rate (0.5 states a second "
                             "against 1000 ticks a second) (given as --publish-rate 0.5)"},
                        // What the command line gave is quoted escaped, by CLI11's checks as by ours.
                        Case{"--config \"$(printf 'no\\033[2Jsuch')\"",
                             "--config: File does not exist: no\\x1b[2Jsuch"},
                        Case{scene + " --record \"$(printf '/no/such\\033[2J/s')\"",
                             "cannot create the session log '/no/such\\x1b[2J/s'"}}) {
    const Result r = ladderd(c.args);
    EXPECT_EQ(r.code, 2) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.words), std::string::npos) << c.args << "\n" << r.output;
    EXPECT_EQ(r.output.find('\x1b'), std::string::npos) << c.args << "\n" << r.output;
  }
}

// A bad configuration file is refused with the position of the offending value, before anything starts.
TEST_F(Offline, BadConfigFileIsRefusedWithItsPosition) {
  struct Case { std::string text, words; };
  for (const Case& c : {Case{"[server]\nphysics_rate = -5\n", ":2:16: server.physics_rate must be from 1 to 100000"},
                        Case{"[server]\nrate = 5\n", ":2:1: unknown key 'server.rate'; the keys: server.sim_id, "},
                        Case{"[server]\nphyiscs_rate = 5\n",
                             ":2:1: unknown key 'server.phyiscs_rate' (did you mean 'server.physics_rate'?); the keys: "},
                        // A scene file given as the configuration: named so, at its first scene table.
                        Case{"# a scene\n[ladder]\nblocks = 6\n",
                             ":2:1: [ladder] is a table of a scene file, not of a configuration file (which has "
                             "[server], [commands] and [log]): give a scene with --scene FILE"},
                        Case{"[server]\ndomain = \"zero\"\n", ":2:10: server.domain must be an integer"},
                        Case{"[server]\ndomain = 232\n", ":2:10: server.domain must be from 0 to 231"},
                        Case{"[commands]\nqueue = 0\n", ":2:9: commands.queue must be from 1 to 1000000"},
                        Case{"[commands]\nreader_wait = -1\n", ":2:15: commands.reader_wait must be from 0"},
                        Case{"[commands]\nrate = 0\n", ":2:8: commands.rate must be > 0 and at most 1000000"},
                        Case{"[commands]\nburst = 4096\n", ":2:9: commands.burst must be from 1 to 2048"},
                        Case{"[log]\nlevel = \"loud\"\n", ":2:9: log.level must be trace"},
                        Case{"[server]\nrealtime_priority = 100\n", ":2:21: server.realtime_priority must be from 0 to 99"},
                        Case{"[server]\nspin_us = 600\n", ":2:11: server.spin_us must be from 0 to half the tick period (500 us"},
                        Case{"[server]\nphysics_rate = 30\npublish_rate = 60\n",
                             "ladderd.toml:3:16: server.publish_rate must be >= 1 and at most server.physics_rate (60 "
                             "states a second against 30 ticks a second)"},
                        Case{"[server]\nstats_rate = 1e-300\n", ":2:14: server.stats_rate must be from 0.01 to 100"},
                        Case{"[server]\nscenes_dir = \"no-such-folder\"\n",
                             ":2:14: server.scenes_dir must be a folder of scenes: '"},
                        Case{"[server]\nscene = \"nothing-here\"\n",
                             ":2:9: server.scene nothing-here: no such file, and no scene of that name in "},
                        Case{"[server\n", ":1:8: "},
                        // A NUL ends a path for the system: the log went to another file.
                        Case{"[log]\nfile = \"out\\u0000.txt\"\n", ":2:8: log.file must not hold a NUL character (U+0000)"},
                        // What the file says is quoted escaped: an escape sequence, a newline, a bidi override.
                        Case{"[server]\n\"\\u001b[2J\\nfake\" = 1\n", ":2:1: unknown key 'server.\\x1b[2J\\x0afake'; the keys: "},
                        Case{"[server]\nsim_id = \"a\\u202eb\"\n",
                             ":2:10: server.sim_id 'a\\xe2\\x80\\xaeb' may hold only letters, digits, '-', '_' and '.'"}}) {
    std::ofstream(path("ladderd.toml")) << c.text;
    const Result r = ladderd("--config " + path("ladderd.toml"));
    EXPECT_EQ(r.code, 2) << c.text << "\n" << r.output;
    EXPECT_NE(r.output.find(c.words), std::string::npos) << c.text << "\n" << r.output;
    EXPECT_EQ(r.output.find("\nfake"), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("\u202e"), std::string::npos) << r.output;
  }
}

// The shipped configuration is valid (it only restates the defaults): checked without starting the server.
TEST_F(Offline, ShippedConfigIsValid) {
  const Result r = ladderd("--config " + std::string(LADDER_SOURCE_DIR) + "/config/ladderd.toml --rtf -1");
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(r.output.find("ladderd.toml"), std::string::npos) << r.output;  // refused for --rtf, not the file
  EXPECT_NE(r.output.find("server.real_time_factor"), std::string::npos) << r.output;
  // server.scene names a shipped scene as --scene does (it was taken as a file beside the configuration file).
  std::ofstream(path("named.toml")) << "[server]\nscene = \"double-ripple\"\n";
  const Result named = ladderd("--config " + path("named.toml") + " --rtf -1");
  EXPECT_EQ(named.code, 2);
  EXPECT_EQ(named.output.find("server.scene"), std::string::npos) << named.output;
  EXPECT_NE(named.output.find("server.real_time_factor"), std::string::npos) << named.output;
}

// A physics rate below the default 60 states a second lowers the publish rate to it when that is not given (before,
// `ladderd --rate 30` was refused for the publish rate nobody had named); one given above it is still refused.
TEST_F(Offline, APhysicsRateBelowSixtyHertzPublishesAtIt) {
  const std::string domain = std::to_string(1 + getpid() % 230), id = "rate30-" + std::to_string(getpid());
  ladder::test::Process server({kLadderd, "--rate", "30", "--domain", domain, "--sim-id", id}, path("server.log"));
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (server.log().find("serving") == std::string::npos && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_NE(server.log().find(" 30 Hz physics, 30 Hz states"), std::string::npos) << server.log();
  server.signal(SIGTERM);
  EXPECT_TRUE(server.wait_exit(std::chrono::seconds(10)).has_value()) << server.log();
  // The same from a configuration file (which checked the default publish rate against its physics rate, and
  // refused it); and a --rate over the file's lower one publishes at the default 60 again.
  std::ofstream(path("ladderd.toml")) << "[server]\nphysics_rate = 30\n";
  for (const auto& [rate, said] : {std::pair{"", " 30 Hz physics, 30 Hz states"},
                                   {"1000", " 1000 Hz physics, 60 Hz states"}}) {
    std::vector<std::string> args{kLadderd, "--config", path("ladderd.toml"), "--domain", domain, "--sim-id", id};
    if (*rate) args.insert(args.end(), {"--rate", rate});
    ladder::test::Process from_file(args, path(std::string("file") + rate + ".log"));
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (from_file.log().find("serving") == std::string::npos && from_file.log().find("rror") == std::string::npos &&
           std::chrono::steady_clock::now() < until)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    EXPECT_NE(from_file.log().find(said), std::string::npos) << from_file.log();
    from_file.signal(SIGTERM);
    EXPECT_TRUE(from_file.wait_exit(std::chrono::seconds(10)).has_value()) << from_file.log();
  }
  const Result r = ladderd("--rate 30 --publish-rate 60 --domain " + domain);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("server.publish_rate must be >= 1 and at most server.physics_rate (60 states a second "
                          "against 30 ticks a second) (given as --rate 30 and --publish-rate 60)"),
            std::string::npos)
      << r.output;
}

// A session log that cannot be written (a full disk: /dev/full) is said to be incomplete when the server stops, even
// in a session with no command (whose log was never synced, and was said to be "closed").
TEST_F(Offline, ASessionLogThatCouldNotBeWrittenIsSaidToBeIncomplete) {
  const std::string domain = std::to_string(1 + (getpid() + 7) % 230);
  ladder::test::Process server({kLadderd, "--record", "/dev/full", "--domain", domain, "--sim-id",
                                "full-" + std::to_string(getpid())},
                               path("server.log"));
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (server.log().find("serving") == std::string::npos && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // states written meanwhile
  server.signal(SIGTERM);
  ASSERT_TRUE(server.wait_exit(std::chrono::seconds(20)).has_value()) << server.log();
  EXPECT_NE(server.log().find("the session log /dev/full is incomplete: writing to it failed"), std::string::npos)
      << server.log();
  EXPECT_EQ(server.log().find("session log /dev/full closed"), std::string::npos) << server.log();
}

// A scene's name reaches the terminal escaped (ladder/printable.hpp): an escape sequence in it would drive the
// terminal, a newline would start a forged log line, a right-to-left override would make it read as another name.
TEST_F(Offline, ASceneNameIsLoggedWithItsControlsEscaped) {
  std::ofstream(path("esc.toml")) << "[scene]\nname = \"red\\u001b[31m\\nfake line\\u202e!\"\n[ladder]\nblocks = 3\n";
  const Result r = ladderd("--offline --scene " + path("esc.toml") + " --duration 0.01");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("scene 'red\\x1b[31m\\x0afake line\\xe2\\x80\\xae!'"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find('\x1b'), std::string::npos);
  EXPECT_EQ(r.output.find("\nfake line"), std::string::npos);
}

// A scene's name taken from its file's name need not be UTF-8, nor its path, and JSON has no way to write such
// bytes: the run wrote its refused timeline command's place into the events and the name into the summary, and ended
// in an uncaught exception (exit 134). They are written as U+FFFD, and both files parse.
TEST_F(Offline, AFileNameThatIsNotUtf8IsWrittenToTheJsonFilesAsAReplacement) {
  const std::string scene = path("bad\xff.toml");
  std::ofstream(scene) << "[ladder]\nblocks = 3\n[[timeline]]\nt = 0.01\ncommand = \"poke\"\nblock = 2\n"
                          "impulse = [0.001, 0]\nat = [0.5, 0]\n";  // off block 2: refused when it comes
  const Result r = ladderd("--offline --quiet --scene '" + scene + "' --duration 0.05 --events " + path("ev.jsonl") +
                           " --summary " + path("sum.json"));
  ASSERT_EQ(r.code, 0) << r.output;
  const json e = json::parse(slurp(path("ev.jsonl")));
  EXPECT_EQ(e["kind"], "command_refused");
  EXPECT_EQ(e["where"], path("bad\xef\xbf\xbd.toml") + ":3:1");
  const json s = json::parse(slurp(path("sum.json")));
  EXPECT_EQ(s["scene"], "bad\xef\xbf\xbd");
  EXPECT_EQ(s["events"]["command_refused"], 1);
}

TEST_F(Offline, KeysListsEverySceneKey) {
  const Result r = ladderd("--keys");
  EXPECT_EQ(r.code, 0);
  for (const char* key : {"ladder.blocks", "sim.dt", "sim.integrator", "solver.kind", "solver.tolerance",
                          "solver.max_iterations", "ladder.flip_impact"})
    EXPECT_NE(r.output.find(key), std::string::npos) << key;
}

// A run that cannot be carried out (a 2000-block column that is too stiff for SHAKE at 1/64 of a 0.05 s step; the
// midpoint step's rescued solves carry it) exits 3, says why, and still leaves a summary that says it failed.
TEST_F(Offline, AFailedRunExitsThreeAndSaysSo) {
  const Result r = ladderd("--offline --quiet --scene " + kScenes + "free-chain.toml --duration 1 --set ladder.blocks=2000"
                           " --set sim.integrator=symplectic_euler --set sim.dt=0.05 --set solver.max_iterations=3"
                           " --summary " + path("sum.json"));
  ASSERT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("smaller sim.dt"), std::string::npos) << r.output;
  // With the log off, the reason still comes, alone.
  const Result quiet = ladderd("--offline --quiet --log-level off --scene " + kScenes + "free-chain.toml --duration 1"
                               " --set ladder.blocks=2000 --set sim.integrator=symplectic_euler --set sim.dt=0.05"
                               " --set solver.max_iterations=3");
  ASSERT_EQ(quiet.code, 3) << quiet.output;
  EXPECT_EQ(quiet.output.rfind("ladderd: the simulation failed at t = ", 0), 0u) << quiet.output;
  EXPECT_EQ(std::count(quiet.output.begin(), quiet.output.end(), '\n'), 1) << quiet.output;
  const json s = json::parse(slurp(path("sum.json")));
  EXPECT_EQ(s["failed"], true);
  EXPECT_NE(s["error"].get<std::string>().find("1/64"), std::string::npos);
}

}  // namespace
