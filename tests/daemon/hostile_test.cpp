// A hostile client against a real ladderd over real Cyclone DDS on loopback: every command kind with every field
// set to NaN, infinities, 1e300, -0, denormals and out-of-range indices and counts, and every live key with extreme
// values. Meanwhile a second participant reads every State, Stats, Event and SceneInfo the server publishes and
// checks every number in them. Afterwards the server must still publish at its rate and the ladder still move.
#include "naming.hpp"
#include "client.hpp"
#include "process.hpp"
#include "transport/dds.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <thread>
#include <limits>
#include <string>
#include <vector>

namespace ladder::test {
namespace {

using client::Client;
using client::Millis;
namespace cmd = client::cmd;
using Clock = std::chrono::steady_clock;

constexpr Millis kStart{15000};  // generous: CI runs two tests at once on two cores
constexpr Millis kAnswer{10000};

// Reads everything the server publishes, on a participant of its own, and counts every number that is not finite.
class Scanner {
 public:
  explicit Scanner(int domain)
      : participant_(transport::make_participant(static_cast<dds_domainid_t>(domain))),
        topics_(participant_),
        state_(participant_, topics_.state, transport::Profile::State),
        scene_(participant_, topics_.scene_info, transport::Profile::SceneInfo),
        event_(participant_, topics_.event, transport::Profile::Event),
        stats_(participant_, topics_.stats, transport::Profile::Stats) {}

  void scan() {
    state_.take([&](const ladder_msg_State& s, const dds_sample_info_t&) {
      ++states;
      last_seq = s.seq, last_step = s.step, last_time = s.sim_time, paused = s.paused;
      check(s.sim_time, "State.sim_time");
      check(s.energy, "State.energy");
      for (std::uint32_t i = 0; i < s.poses._length; ++i) check(s.poses._buffer[i], "State.poses");
      for (std::uint32_t i = 0; i < s.grips._length; ++i) {
        const ladder_msg_Grip& g = s.grips._buffer[i];
        check(g.target_x, "State.grips.target_x");
        check(g.target_y, "State.grips.target_y");
        check(g.angle, "State.grips.angle");
      }
    });
    scene_.take([&](const ladder_msg_SceneInfo& s, const dds_sample_info_t&) {
      ++scenes;
      for (double v : {s.length, s.thickness, s.hinge_inset, s.dt, s.physics_rate, s.publish_rate, s.real_time_factor})
        check(v, "SceneInfo");
      for (std::uint32_t i = 0; i < s.masses._length; ++i) check(s.masses._buffer[i], "SceneInfo.masses");
    });
    event_.take([&](const ladder_msg_Event& e, const dds_sample_info_t&) {
      ++events;
      check(e.t, "Event.t");
      check(e.energy_removed, "Event.energy_removed");
      if (std::string(e.kind) == "solver_failure") failures.push_back(e.detail);
    });
    stats_.take([&](const ladder_msg_Stats& s, const dds_sample_info_t&) {
      ++stats;
      for (double v : {s.sim_time, s.window, s.step_p50_us, s.step_p99_us, s.step_max_us, s.late_p50_us, s.late_p99_us,
                       s.late_max_us, s.real_time_factor, s.solver_residual, s.energy, s.max_hinge_error})
        check(v, "Stats");
    });
  }

  std::uint64_t states = 0, scenes = 0, events = 0, stats = 0, non_finite = 0;
  std::string first_bad;
  std::vector<std::string> failures;  // solver_failure details
  std::uint64_t last_seq = 0, last_step = 0;
  double last_time = 0;
  bool paused = false;

 private:
  void check(double v, const char* where) {
    if (std::isfinite(v)) return;
    if (non_finite++ == 0) first_bad = std::string(where) + " = " + std::to_string(v);
  }

  transport::Entity participant_;
  transport::Topics topics_;
  transport::Reader<ladder_msg_State> state_;
  transport::Reader<ladder_msg_SceneInfo> scene_;
  transport::Reader<ladder_msg_Event> event_;
  transport::Reader<ladder_msg_Stats> stats_;
};

// The hostile command set.
std::vector<ladder_msg_Command> hostile_commands() {
  constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const std::vector<double> bad{kNan, -kNan, kInf, -kInf, 1e300, -1e300, -0.0,
                                std::numeric_limits<double>::denorm_min(), std::numeric_limits<double>::max(),
                                std::numeric_limits<double>::min() / 4};
  std::vector<ladder_msg_Command> out;
  out.push_back(cmd::grab(3));  // so that drags find a grip
  // Every field of every kind (the kinds without numbers must ignore them), with and without the has_* flags.
  for (int k = ladder_msg_TIP; k <= ladder_msg_LOAD_SCENE; ++k) {
    const auto kind = static_cast<ladder_msg_CommandKind>(k);
    for (int field = 0; field < 6; ++field) {
      for (const double v : bad) {
        for (const bool flags : {false, true}) {
          ladder_msg_Command c = cmd::make(kind);
          c.block = c.hinge = 3;
          c.count = 10;
          c.a = 0.001, c.b = 0, c.c = 0, c.d = 0, c.e = 0.01, c.f = 0.1;
          c.has_point = c.has_target = c.has_angle = flags;
          double* fields[] = {&c.a, &c.b, &c.c, &c.d, &c.e, &c.f};
          *fields[field] = v;
          out.push_back(c);
        }
      }
    }
  }
  // Every kind with out-of-range blocks, hinges and counts.
  out.push_back(cmd::pause());
  for (int kind = ladder_msg_TIP; kind <= ladder_msg_RESET; ++kind) {
    for (const std::int32_t index : {-1, INT_MIN, INT_MAX, 6, 1'000'000}) {
      ladder_msg_Command c = cmd::make(static_cast<ladder_msg_CommandKind>(kind));
      c.block = c.hinge = index;
      c.a = 0.001, c.e = 0.01;
      out.push_back(c);
    }
    for (const std::uint32_t count : {0u, UINT32_MAX, 100'001u, 100'000u}) {
      ladder_msg_Command c = cmd::make(static_cast<ladder_msg_CommandKind>(kind));
      c.count = count;
      out.push_back(c);
    }
  }
  // A huge count that is accepted: the steps run while paused, a tick's worth at a time.
  out.push_back(cmd::pause());
  out.push_back(cmd::step(100'000));
  // Every live key with extreme values.
  for (const char* key : {"sim.dt", "sim.substeps", "sim.accuracy", "sim.integrator", "sim.stabilization",
                          "sim.adaptive", "sim.error_tolerance", "sim.gravity", "solver.kind", "solver.tolerance",
                          "solver.max_iterations", "damping.linear", "damping.angular", "damping.hinge",
                          "server.real_time_factor", "server.publish_rate", "server.physics_rate"}) {
    for (const char* value : {"nan", "inf", "-inf", "1e300", "-1e300", "1e-300", "-0", "4.9e-324", "0", "1e308",
                              "-1", "[1e308,1e308]", "[nan,0]", "[0,-1e300]", "abc", "", "99999999999999999999"})
      out.push_back(cmd::set(std::string(key) + "=" + value));
  }
  out.push_back(cmd::set("sim.gravity"));
  for (const char* name : {"", "..", "../../etc/passwd", "/etc/passwd", "nan", "classic\n"})
    out.push_back(cmd::load(name));
  out.push_back(cmd::load(std::string(1000, 'x')));
  out.push_back(cmd::reset());
  return out;
}

class Hostile : public ::testing::Test {
 protected:
  void start(const std::vector<std::string>& extra = {}) {
    const std::string name = test_name();
    sim_id_ = sim_id_for(name);
    domain_ = domain_for(name);
    log_path_ = std::string(LADDER_BINARY_DIR) + "/tests/" + name + ".log";
    std::vector<std::string> args{std::string(LADDER_BINARY_DIR) + "/server/ladderd", "--domain",
                                  std::to_string(domain_), "--sim-id", sim_id_};
    args.insert(args.end(), extra.begin(), extra.end());
    server_.emplace(args, log_path_);
    client_.emplace(domain_, sim_id_, "hostile");  // first: it sets the project's DDS configuration
    scanner_.emplace(domain_);
    ASSERT_TRUE(client_->wait_for_server(kStart)) << "no ladderd on domain " << domain_ << "; its log:\n"
                                                  << server_->log();
  }

  // Scans until `done` or the deadline; false at the deadline.
  template <class F>
  bool scan_until(F done, Millis timeout) {
    const auto deadline = Clock::now() + timeout;
    while (!done()) {
      if (Clock::now() > deadline) return false;
      client_->poll();
      scanner_->scan();
      std::this_thread::sleep_for(Millis(2));
    }
    return true;
  }

  std::string sim_id_, log_path_;
  int domain_ = 0;
  std::optional<Process> server_;
  std::optional<Scanner> scanner_;
  std::optional<Client> client_;
};

TEST_F(Hostile, NoHostileCommandMakesTheServerPublishANonFiniteNumberOrStop) {
  start();
  Client& c = *client_;
  Scanner& s = *scanner_;
  ASSERT_TRUE(c.call(cmd::tip(), kAnswer).accepted);  // a moving ladder: flip-flops, events
  const std::vector<ladder_msg_Command> commands = hostile_commands();
  std::size_t accepted = 0, refused = 0, resent = 0;
  // In batches of 50, each answered before the next and at most 500 a second: this tests the values, not the
  // intake's limits (a command refused for rate is sent again, after a pause).
  for (std::size_t first = 0; first < commands.size(); first += 50) {
    const auto batch_start = Clock::now();
    std::vector<std::pair<std::size_t, std::uint64_t>> ids;
    for (std::size_t i = first; i < std::min(commands.size(), first + 50); ++i) ids.push_back({i, c.send(commands[i])});
    for (std::size_t k = 0; k < ids.size(); ++k) {
      std::optional<client::Ack> ack;
      ASSERT_TRUE(scan_until([&] { return (ack = c.wait_ack(ids[k].second, Millis(0))).has_value(); }, kAnswer))
          << "no answer to command " << ids[k].second << "; the server's log:\n" << server_->log();
      if (ack->reason.find("rate limit") != std::string::npos) {
        ASSERT_LT(++resent, 1000u) << "refused for rate again and again: " << ack->reason;
        scan_until([] { return false; }, Millis(100));
        ids.push_back({ids[k].first, c.send(commands[ids[k].first])});
        continue;
      }
      (ack->accepted ? accepted : refused)++;
    }
    scan_until([&] { return Clock::now() - batch_start >= Millis(100); }, Millis(200));
  }
  EXPECT_EQ(accepted + refused, commands.size());
  std::printf("%zu hostile commands: %zu accepted, %zu refused (%zu sent again after a rate limit)\n", commands.size(),
              accepted, refused, resent);
  EXPECT_GT(refused, commands.size() / 2);

  // A legitimate user then runs it in real time again (the hostile set ran it as fast as possible for a while).
  ASSERT_TRUE(c.call(cmd::set("server.real_time_factor=1"), kAnswer).accepted);
  const client::Ack resume = c.call(cmd::resume(), kAnswer);
  ASSERT_TRUE(resume.accepted || resume.reason == "not paused") << resume.reason;
  const client::Ack tip = c.call(cmd::tip(), kAnswer);  // events to scan: the ripple's flip-flops
  EXPECT_TRUE(tip.accepted) << tip.reason;
  // (not an ASSERT: on a server that stopped publishing, the checks below still say what else went wrong)
  EXPECT_TRUE(scan_until([&] { return s.states > 0 && !s.paused; }, kAnswer)) << "no running state";

  // Publication goes on at the set rate (60 Hz; at least 10 Hz asked, for a slow machine), and the ladder moves.
  const std::uint64_t seq0 = s.last_seq, step0 = s.last_step;
  const double t0 = s.last_time;
  const auto wall0 = Clock::now();
  scan_until([] { return false; }, Millis(3000));
  const double wall = std::chrono::duration<double>(Clock::now() - wall0).count();
  const double rate = static_cast<double>(s.last_seq - seq0) / wall;
  std::printf("after the hostile set: %.1f states/s, %llu steps and %.3f s of sim time in %.2f s\n", rate,
              static_cast<unsigned long long>(s.last_step - step0), s.last_time - t0, wall);
  EXPECT_GE(rate, 10.0) << "the server stopped publishing (or nearly)";
  EXPECT_GT(s.last_step, step0 + 100) << "the simulation does not advance";
  EXPECT_GT(s.last_time, t0 + 0.1);

  EXPECT_EQ(s.non_finite, 0u) << "first: " << s.first_bad;
  EXPECT_TRUE(s.failures.empty()) << s.failures.size() << " solver failures, the first: " << s.failures.front();
  EXPECT_GT(s.states, 100u);
  EXPECT_GT(s.scenes, 0u);
  EXPECT_GT(s.events, 0u);
  EXPECT_GT(s.stats, 0u);
  std::printf("scanned %llu States, %llu SceneInfos, %llu Events, %llu Stats\n",
              static_cast<unsigned long long>(s.states), static_cast<unsigned long long>(s.scenes),
              static_cast<unsigned long long>(s.events), static_cast<unsigned long long>(s.stats));
  server_->signal(SIGTERM);
  const auto status = server_->wait_exit(Millis(10000));
  ASSERT_TRUE(status.has_value()) << "ladderd did not stop";
  EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << server_->log();
}

// A client's text reaches the server's log escaped: a newline in a scene's name would otherwise start a line of the
// client's making (here a forged "[error] step failed", which anyone grepping the log would take for the server's).
// What the server logs of a peer's text and what the clients show of it (transport::printable): valid UTF-8 kept,
// and every control character (C0, DEL, C1), every byte that is not valid UTF-8 (a stray continuation byte, a
// truncated sequence, an overlong form, a surrogate, past U+10FFFF) and the backslash escaped, so that the result is
// valid UTF-8 with no control character and cannot be confused with an escape.
TEST(Printable, KeepsValidUtf8AndEscapesControlsAndEveryOtherByte) {
  using transport::printable;
  EXPECT_EQ(printable("plain text 1.5 m"), "plain text 1.5 m");
  EXPECT_EQ(printable("caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80"), "caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80");
  EXPECT_EQ(printable("a\nb\x1b[2J\x7f"), "a\\x0ab\\x1b[2J\\x7f");
  EXPECT_EQ(printable("back\\slash"), "back\\\\slash");
  EXPECT_EQ(printable("\xc2\x9b"), "\\xc2\\x9b");                  // U+009B, a C1 control (CSI)
  EXPECT_EQ(printable("\x80"), "\\x80");                          // a continuation byte alone
  EXPECT_EQ(printable("\xe2\x82"), "\\xe2\\x82");                  // cut short
  EXPECT_EQ(printable("\xc0\xaf"), "\\xc0\\xaf");                  // overlong '/'
  EXPECT_EQ(printable("\xe0\x80\xaf"), "\\xe0\\x80\\xaf");          // overlong, three bytes
  EXPECT_EQ(printable("\xed\xa0\x80"), "\\xed\\xa0\\x80");          // a surrogate
  EXPECT_EQ(printable("\xf4\x90\x80\x80"), "\\xf4\\x90\\x80\\x80");  // past U+10FFFF
  EXPECT_EQ(printable("\xff\xfe\xc3("), "\\xff\\xfe\\xc3(");
  EXPECT_EQ(printable(std::string("a\0b", 3)), "a\\x00b");
  // The bidirectional controls, which make a terminal show text in another order ("abc" + U+202E + "fdp.exe" reads
  // as "abcexe.pdf"), and not their neighbours.
  EXPECT_EQ(printable("abc\xe2\x80\xae" "fdp.exe"), "abc\\xe2\\x80\\xae" "fdp.exe");  // U+202E
  EXPECT_EQ(printable("\xe2\x81\xa6x\xe2\x81\xa9"), "\\xe2\\x81\\xa6x\\xe2\\x81\\xa9");  // U+2066, U+2069
  EXPECT_EQ(printable("\xe2\x80\x8f\xd8\x9c"), "\\xe2\\x80\\x8f\\xd8\\x9c");          // U+200F, U+061C
  EXPECT_EQ(printable("\xe2\x80\xa9\xe2\x80\xaf"), "\xe2\x80\xa9\xe2\x80\xaf");      // U+2029, U+202F: kept
}

// A text cut to a bounded field (a DDS message's char[N], a log's text) is cut at a character's start: a reason that
// quoted a Cyrillic scene name and was cut inside a letter reached every client with a \xd0 at its end.
TEST(Printable, TextCutToAFieldEndsOnAWholeCharacter) {
  EXPECT_EQ(cut_text("short", 8), "short");
  EXPECT_EQ(cut_text("exactly8", 8), "exactly8");
  EXPECT_EQ(cut_text("nine char", 8), "nine ...");
  const std::string zh = "\xd0\x96";  // 'Ж', 2 bytes
  EXPECT_EQ(cut_text("a" + zh + zh + zh + zh, 8), "a" + zh + zh + "...");  // 5 bytes, then "...": 8
  EXPECT_EQ(cut_text(zh + zh + zh + zh + zh, 8), zh + zh + "...");         // 5 would end inside a letter: 4
  EXPECT_EQ(cut_text("\xf0\x9f\x98\x80\xf0\x9f\x98\x80", 7), "\xf0\x9f\x98\x80...");
  EXPECT_EQ(cut_text("\xf0\x9f\x98\x80\xf0\x9f\x98\x80", 6), "...");                  // no whole character fits
  EXPECT_EQ(cut_text("four", 3), "...");
  EXPECT_EQ(cut_text("four", 0), "");
  char field[8];
  transport::copy_text(field, "a\xd0\x96\xd0\x96\xd0\x96");  // 7 bytes: fits with its NUL
  EXPECT_EQ(transport::text_of(field), "a\xd0\x96\xd0\x96\xd0\x96");
  transport::copy_text(field, "abc" + zh + zh + zh);  // 9 bytes: the old cut kept 'abc' and half a letter
  EXPECT_EQ(transport::text_of(field), "abc...");
  EXPECT_EQ(transport::printable(transport::text_of(field)), transport::text_of(field));
}

TEST_F(Hostile, AClientsTextCannotForgeALogLine) {
  start();
  const std::string forged = "2026-12-05 09:00:00.000 [error] step failed, simulation paused: FORGED";
  const client::Ack a = client_->call(cmd::load("x\n" + forged), kAnswer);
  EXPECT_FALSE(a.accepted);
  // The client gets its own text back, made printable as every peer's text is (transport::printable).
  EXPECT_EQ(a.reason.rfind("no scene 'x\\x0a" + forged + "' in ", 0), 0u) << a.reason;
  const auto deadline = Clock::now() + kAnswer;
  while (server_->log().find("load (command") == std::string::npos && Clock::now() < deadline)
    std::this_thread::sleep_for(Millis(20));
  const std::string log = server_->log();
  EXPECT_NE(log.find("refused: no scene 'x\\x0a" + forged + "' in "), std::string::npos) << log;
  EXPECT_EQ(log.find("\n" + forged), std::string::npos) << log;
}

// A stop does not wait for the end of a long step: it comes between two of the step's sub-steps. (A step of 1000
// sub-steps of a 20 000-block ladder takes seconds; with a solver tolerance that rounding cannot reach, which the
// scene's ranges now refuse, a step of the 1000-block `long` took minutes, and so did SIGTERM.)
TEST_F(Hostile, AStopCutsALongStepBetweenItsSubSteps) {
  start({"--set", "ladder.blocks=20000", "--set", "sim.substeps=1000"});
  ASSERT_TRUE(client_->wait_state([](const client::State&) { return true; }, kAnswer)) << server_->log();
  std::this_thread::sleep_for(Millis(500));  // well inside the first step (each takes seconds)
  server_->signal(SIGTERM);
  const auto status = server_->wait_exit(Millis(60000));
  ASSERT_TRUE(status.has_value()) << "ladderd did not stop";
  EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << server_->log();
  const std::string log = server_->log();
  const std::size_t at = log.find(" interrupted after ");
  ASSERT_NE(at, std::string::npos) << log;
  int taken = 0, of = 0;
  ASSERT_EQ(std::sscanf(log.c_str() + at, " interrupted after %d of its %d sub-steps", &taken, &of), 2) << log;
  EXPECT_EQ(of, 1000);
  EXPECT_GE(taken, 1);
  EXPECT_LT(taken, 1000);
  EXPECT_NE(log.find("stopped: SIGTERM received"), std::string::npos) << log;
}

// A step longer than two ticks of sim time (sim.dt = 0.05 s against 1 ms ticks) still comes due: the loop's backlog
// cap of two ticks kept it from ever stepping (set sim.dt=0.05 froze the simulation).
TEST_F(Hostile, ACoarseStepStillRunsInRealTime) {
  start();
  Client& c = *client_;
  ASSERT_TRUE(c.call(cmd::set("sim.dt=0.05"), kAnswer).accepted);
  const auto s0 = c.wait_state([](const client::State&) { return true; }, kAnswer);
  ASSERT_TRUE(s0.has_value());
  const auto t0 = Clock::now();
  const auto later = c.wait_state([&](const client::State& st) { return st.sim_time >= s0->sim_time + 0.5; },
                                  Millis(20000));
  ASSERT_TRUE(later.has_value()) << "the simulation did not advance 0.5 s in 20 s";
  std::printf("0.5 s of sim time in 0.05 s steps took %.2f s of wall time\n",
              std::chrono::duration<double>(Clock::now() - t0).count());
  EXPECT_FALSE(later->paused);
}

// Settings that are each within range can still fail a step together (SHAKE's 0.1 s step under 1000 m/s^2
// sideways; the default midpoint step holds there): the server pauses, and a reset then restarts the scene with its
// own settings instead of failing again.
TEST_F(Hostile, AResetAfterAFailedStepRestoresTheScenesSettings) {
  start();
  Client& c = *client_;
  Scanner& s = *scanner_;
  const auto own = c.wait_scene_info(kAnswer);
  ASSERT_TRUE(own.has_value());
  ASSERT_TRUE(c.call(cmd::set("sim.integrator=symplectic_euler"), kAnswer).accepted);
  ASSERT_TRUE(c.call(cmd::set("sim.dt=0.1"), kAnswer).accepted);
  ASSERT_TRUE(c.call(cmd::set("sim.gravity=[1000,0]"), kAnswer).accepted);
  ASSERT_TRUE(scan_until([&] { return !s.failures.empty(); }, Millis(30000))) << "no step failed";
  ASSERT_TRUE(c.wait_state([](const client::State& st) { return st.paused; }, kAnswer)) << "not paused";
  // Failing again at once would be the old reset (the live settings kept).
  const client::Ack reset = c.call(cmd::reset(), kAnswer);
  EXPECT_TRUE(reset.accepted);
  EXPECT_EQ(reset.reason,
            "the last step failed: the scene restarted with its own settings (the live settings dropped), paused: "
            "resume runs it");
  const auto restored = c.wait_scene_info(kAnswer, [&](const client::SceneInfo& i) {
    return i.generation > own->generation;
  });
  ASSERT_TRUE(restored.has_value());
  EXPECT_EQ(restored->options, own->options);
  EXPECT_EQ(restored->dt, own->dt);
  const std::size_t failures = s.failures.size();
  ASSERT_TRUE(c.call(cmd::resume(), kAnswer).accepted);
  ASSERT_TRUE(c.call(cmd::tip(), kAnswer).accepted);
  const auto moved = c.wait_state([](const client::State& st) { return !st.paused && st.step > 1000; }, Millis(30000));
  EXPECT_TRUE(moved.has_value()) << "the restarted scene did not run 1000 steps";
  scan_until([] { return false; }, Millis(200));
  EXPECT_EQ(s.failures.size(), failures) << "it failed again: " << s.failures.back();
  EXPECT_EQ(s.non_finite, 0u) << "first: " << s.first_bad;
  // A reset without a failure keeps the live settings, as before.
  ASSERT_TRUE(c.call(cmd::set("damping.linear=0.5"), kAnswer).accepted);
  const client::Ack plain = c.call(cmd::reset(), kAnswer);
  EXPECT_TRUE(plain.accepted);
  EXPECT_EQ(plain.reason, "");
  const auto kept = c.wait_scene_info(kAnswer, [&](const client::SceneInfo& i) {
    return i.generation > restored->generation;
  });
  ASSERT_TRUE(kept.has_value());
  EXPECT_NE(kept->options.find("damping.linear=0.5\n"), std::string::npos) << kept->options;
}

// Careless start-up input is refused before anything starts, with exit 2 and a message naming it: an empty scene
// file (it would silently be the defaults) and a log file in a folder that does not exist (spdlog made the folders).
TEST(HostileStart, AnEmptySceneAndALogFileInAMissingFolderExitTwoNamingThem) {
  const std::string dir = std::string(LADDER_BINARY_DIR) + "/tests/" + test_name();
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string empty = dir + "/empty.toml";
  std::ofstream(empty) << "# nothing but a comment\n";
  // `timeout`: a ladderd that takes the input would serve until it is stopped.
  const std::string ladderd = "timeout 20 " + std::string(LADDER_BINARY_DIR) + "/server/ladderd --domain " +
                              std::to_string(domain_for(test_name())) + " ";
  Result r = shell(ladderd + "--scene " + empty);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(empty + ":1:1: the scene file is empty; a scene needs at least one table"),
            std::string::npos)
      << r.output;
  const std::string log = dir + "/no-such-folder/ladderd.log";
  r = shell(ladderd + "--log-file " + log);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("ladderd: cannot open the log file '" + log + "': its folder '" + dir +
                          "/no-such-folder' does not exist"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir + "/no-such-folder")) << "the folder was made";
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace ladder::test
