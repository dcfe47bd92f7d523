// Session logs (ladderd --record): a real server records, then the log is re-simulated bit for bit, resumed
// after a kill -9, replayed over DDS, read by liblcm's own reader, and refused or read up to the damage when
// corrupt. Real processes, real Cyclone DDS on loopback, real LCM log files.
#include "client.hpp"
#include "daemon/resimulate.hpp"
#include "process.hpp"
#include "transport/lcm_decode.hpp"
#include "transport/lcm_log.hpp"

#include <gtest/gtest.h>

#include <cairo.h>
#include <lcm/lcm-cpp.hpp>

#include <algorithm>
#include <bit>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <cstring>
#include <functional>
#include <optional>
#include <random>
#include <thread>
#include <tuple>

namespace ladder::test {
namespace {

namespace fs = std::filesystem;
using client::Client;
using client::Millis;
namespace cmd = client::cmd;
using Clock = std::chrono::steady_clock;

const std::string kLadderd = std::string(LADDER_BINARY_DIR) + "/server/ladderd";
const std::string kLadderctl = std::string(LADDER_BINARY_DIR) + "/clients/ladderctl";
constexpr Millis kStart{15000}, kAnswer{5000};


class Record : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string name = ::testing::UnitTest::GetInstance()->current_test_info()->name();
    domain_ = 1 + static_cast<int>(std::hash<std::string>{}("rec-" + name) % 230);
    sim_id_ = "rec-" + name.substr(0, 40) + "-" + std::to_string(getpid());
    dir_ = fs::temp_directory_path() / ("ladder-record-" + std::to_string(getpid()) + "-" + name);
    fs::create_directories(dir_);
    log_ = (dir_ / "session.lcmlog").string();
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Starts a recording server and a client connected to it.
  void start(std::vector<std::string> extra = {}) {
    std::vector<std::string> args{kLadderd, "--domain", std::to_string(domain_), "--sim-id", sim_id_};
    args.insert(args.end(), extra.begin(), extra.end());
    server_.emplace(args, (dir_ / "ladderd.log").string());
    applied_ = 0;  // a new or resumed server numbers its commands afresh
    client_.emplace(domain_, sim_id_, "test");
    ASSERT_TRUE(client_->wait_for_server(kStart)) << server_->log();
  }
  void accepted(const ladder_msg_Command& c) {
    const client::Ack a = client_->call(c, kAnswer);
    EXPECT_TRUE(a.accepted) << a.reason;
    applied_ = std::max(applied_, a.command_seq);
  }
  // Waits until the sim time passes t in a state that shows every command acknowledged so far: after a reset, the
  // old scene's last state (long past t) does not count.
  void run_until(double t) {
    ASSERT_TRUE(client_->wait_state(
        [&](const client::State& s) { return s.commands_applied >= applied_ && s.sim_time > t; }, Millis(20000)));
  }
  int stop_server(int sig) {
    server_->signal(sig);
    const auto status = server_->wait_exit(Millis(5000));
    return status && WIFEXITED(*status) ? WEXITSTATUS(*status) : -1;
  }
  // After the server stopped: another, resumed from the log (under a sim id of its own), and its first state,
  // which is paused.
  std::optional<client::State> resume_from_log() {
    server_.reset();
    client_.reset();
    sim_id_ += "-resumed";
    start({"--resume", log_});
    return client_->wait_state([](const client::State& st) { return st.paused; }, kAnswer);
  }
  // Records a session of the built-in scene with these options, and draws it live and replayed (below).
  void replay_draws_what_the_live_server_drew(const std::vector<std::string>& scene);

  int domain_ = 0;
  std::uint64_t applied_ = 0;  // the last acknowledged command's command_seq
  std::string sim_id_, log_;
  fs::path dir_;
  std::optional<Process> server_;
  std::optional<Client> client_;
};

// The log `from` written again to `to`, each event through `bend`, which either writes it itself (changed, or not
// at all) and returns true, or returns false to have it copied as it is; `after` may add events at the end.
using Reader = transport::LogReader;
using Writer = transport::LogWriter;
using LogEvent = transport::LogReader::Event;
using Bend = std::function<bool(Reader&, const LogEvent&, Writer&)>;
void rewrite_log(const std::string& from, const std::string& to, const Bend& bend,
                 const std::function<void(Writer&)>& after = {}) {
  Reader in(from);
  Writer out(to);
  while (auto e = in.next())
    if (!bend(in, *e, out)) out.write_bytes(e->channel, e->utime, e->data, false);
  if (after) after(out);
}

// A classic session with a tip, a poke, a live setting, a pause with single steps and a reset: re-simulated from
// the log, every recorded state is identical to the last bit; a state changed by 1 ulp is caught and named.
TEST_F(Record, ClassicSessionResimulatesBitForBit) {
  start({"--record", log_});
  accepted(cmd::tip());
  run_until(0.6);
  accepted(cmd::poke(3, 0.002, 0));
  accepted(cmd::set("damping.angular=0.3"));
  run_until(1.4);
  accepted(cmd::pause());
  accepted(cmd::step(25));
  accepted(cmd::resume());
  run_until(2.0);
  accepted(cmd::reset());
  accepted(cmd::tip());
  run_until(0.5);
  ASSERT_EQ(stop_server(SIGTERM), 0) << server_->log();

  const daemon::SessionLog log = daemon::read_session_log(log_);
  EXPECT_TRUE(log.damage.empty()) << log.damage;
  EXPECT_EQ(log.commands.size(), 8u);
  EXPECT_GT(log.states.size(), 100u);
  EXPECT_GT(log.checkpoints.size(), 2u);
  EXPECT_EQ(log.scenes.size(), 3u);  // the start, the live setting and the reset
  const Result r = shell(kLadderd + " --offline --resimulate " + log_);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("identical to the last bit"), std::string::npos) << r.output;

  // The same log with one block's x changed by one ulp in one state: the re-run names that state and block.
  const std::string bent = (dir_ / "bent.lcmlog").string();
  double recorded = 0;
  std::int64_t bent_step = -1;
  std::size_t states = 0;
  rewrite_log(log_, bent, [&](Reader& in, const LogEvent& e, Writer& out) {
    if (e.channel != transport::kStateChannel || ++states != 50) return false;
    auto s = in.decode<ladderlcm::state_t>(e);
    recorded = s.x[4];
    s.x[4] = std::nextafter(s.x[4], 1.0);
    bent_step = s.step;
    out.write(transport::kStateChannel, e.utime, s, false);
    return true;
  });
  const Result b = shell(kLadderd + " --offline --resimulate " + bent);
  EXPECT_EQ(b.code, 1) << b.output;
  EXPECT_NE(b.output.find("step " + std::to_string(bent_step)), std::string::npos) << b.output;
  EXPECT_NE(b.output.find("block 4 x: recorded"), std::string::npos) << b.output;
  EXPECT_NE(recorded, 0);
}

// The same with rolling hinges and fully rounded ends (the classic toy with ladder.hinge = "rolling" and
// ladder.end_radius = thickness / 2): a tip, a poke, a live setting, a pause with single steps. The log's scene
// record carries the overrides, its states are the rolling ladder's (hanging straight, where corner hinges hang at
// +-atan(T / L) = +-0.2 rad) through a ripple that flips hinge 1, and the re-run from the log, which makes the scene
// again from the record's text and overrides, is identical to the last bit.
TEST_F(Record, RollingSessionResimulatesBitForBit) {
  const std::vector<std::string> rolling{"ladder.hinge=rolling", "ladder.end_radius=0.0065"};
  start({"--record", log_, "--set", rolling[0], "--set", rolling[1]});
  accepted(cmd::tip());
  run_until(0.6);
  accepted(cmd::poke(3, 0.002, 0));
  accepted(cmd::set("damping.angular=0.3"));
  run_until(1.4);
  accepted(cmd::pause());
  accepted(cmd::step(25));
  accepted(cmd::resume());
  run_until(2.5);
  ASSERT_EQ(stop_server(SIGTERM), 0) << server_->log();

  const daemon::SessionLog log = daemon::read_session_log(log_);
  EXPECT_TRUE(log.damage.empty()) << log.damage;
  ASSERT_EQ(log.scenes.size(), 2u);  // the start and the live setting
  for (const auto& sc : log.scenes) EXPECT_EQ(sc.overrides, rolling);
  EXPECT_EQ(log.commands.size(), 6u);
  ASSERT_GT(log.states.size(), 100u);
  EXPECT_GT(log.checkpoints.size(), 2u);
  const ladderlcm::state_t first = log.state(0), last = log.state(log.states.size() - 1);
  for (std::size_t i = 2; i < 6; ++i)
    EXPECT_LT(std::abs(first.theta[i]), 1e-3) << "block " << i << " does not hang straight";
  EXPECT_GE(last.flips[1], 1) << "no ripple";
  const Result r = shell(kLadderd + " --offline --resimulate " + log_);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("identical to the last bit"), std::string::npos) << r.output;
  std::printf("%s", r.output.c_str());
}

// A live setting is published (and logged) as a new SceneInfo only when it changes the settings: a value they
// already have sends none, and the session still re-simulates bit for bit.
TEST_F(Record, ALiveSettingThatChangesNothingSendsNoSceneInfo) {
  start({"--record", log_});
  accepted(cmd::set("damping.hinge=0"));    // the built-in scene has no hinge friction
  accepted(cmd::set("damping.linear=0.1"));  // its air drag already
  accepted(cmd::set("damping.angular=0.3"));  // a change (0.1 before)
  accepted(cmd::set("damping.angular=0.3"));  // the same again
  run_until(0.2);
  ASSERT_EQ(stop_server(SIGTERM), 0) << server_->log();
  const daemon::SessionLog log = daemon::read_session_log(log_);
  EXPECT_EQ(log.commands.size(), 4u);
  EXPECT_EQ(log.scenes.size(), 2u);  // the start and the one change
  const Result r = shell(kLadderd + " --offline --resimulate " + log_);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("identical to the last bit"), std::string::npos) << r.output;
}

// kill -9 in the middle: the log reads back up to its last complete event, re-simulates identically, and
// --resume serves from its last recorded state (past the last checkpoint; paused, at exactly that step and with
// exactly its coordinates), then runs on.
TEST_F(Record, AfterKillNineTheLogReadsBackAndResumes) {
  start({"--record", log_});
  accepted(cmd::tip());
  run_until(2.5);
  server_->signal(SIGKILL);
  server_->wait_exit(Millis(5000));

  const daemon::SessionLog log = daemon::read_session_log(log_);
  ASSERT_GE(log.checkpoints.size(), 2u);
  const auto newest = std::max_element(log.states.begin(), log.states.end(), [](const auto& a, const auto& b) {
    return a.step < b.step;
  });
  ASSERT_NE(newest, log.states.end());
  const ladderlcm::state_t last = log.state(static_cast<std::size_t>(newest - log.states.begin()));
  EXPECT_GT(last.step, log.checkpoints.back().step);  // the test shows something only if it ends past one
  const Result r = shell(kLadderd + " --offline --resimulate " + log_);
  EXPECT_EQ(r.code, 0) << r.output;

  const auto s = resume_from_log();
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->step, static_cast<std::uint64_t>(last.step));
  EXPECT_EQ(s->sim_time, last.sim_time);
  ASSERT_EQ(s->blocks.size(), last.x.size());
  for (std::size_t i = 0; i < s->blocks.size(); ++i) {
    EXPECT_EQ(s->blocks[i].x, last.x[i]) << "block " << i;
    EXPECT_EQ(s->blocks[i].theta, last.theta[i]) << "block " << i;
  }
  EXPECT_EQ(s->commands_applied, 1u);  // the tip, numbered on from the log
  EXPECT_NE(server_->log().find("resumed from"), std::string::npos) << server_->log();
  accepted(cmd::resume());
  EXPECT_TRUE(client_->wait_state([&](const client::State& st) { return st.step > s->step + 100; }, kAnswer));
}

// ladderctl replay publishes the recorded states as they were: a viewer sees SceneInfo flagged as a replay and
// states equal to the log's, bit for bit.
TEST_F(Record, ReplayRepublishesTheRecordedStates) {
  start({"--record", log_});
  accepted(cmd::tip());
  run_until(1.0);
  ASSERT_EQ(stop_server(SIGTERM), 0);
  const daemon::SessionLog log = daemon::read_session_log(log_);
  ASSERT_FALSE(log.states.empty());

  const std::string replay_id = sim_id_ + "-replay";
  Process player({kLadderctl, "replay", log_, "--speed", "0.5", "--from", "0.5", "--as", replay_id, "--domain",
                  std::to_string(domain_)},
                 (dir_ / "replay.log").string());
  Client viewer(domain_, replay_id, "viewer");
  ASSERT_TRUE(viewer.wait_for_server(kStart)) << player.log();
  EXPECT_TRUE(viewer.scene_info()->replay);
  EXPECT_EQ(viewer.scene_info()->blocks, 6u);
  const auto s = viewer.wait_state([](const client::State& st) { return st.sim_time > 0.8; }, Millis(20000));
  ASSERT_TRUE(s.has_value());
  EXPECT_GE(viewer.latest_state()->sim_time, 0.5);
  const auto found = std::find_if(log.states.begin(), log.states.end(),
                                  [&](const auto& r) { return r.step == static_cast<std::int64_t>(s->step); });
  ASSERT_NE(found, log.states.end());
  const ladderlcm::state_t recorded = log.state(static_cast<std::size_t>(found - log.states.begin()));
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(s->blocks[i].x, recorded.x[i]) << "block " << i;
    EXPECT_EQ(s->blocks[i].theta, recorded.theta[i]) << "block " << i;
  }
}

// A command to a replay is not sent into the void (a replay answers none): ladderctl says what the sim id is.
TEST_F(Record, ACommandToAReplaySaysItIsOne) {
  start({"--record", log_});
  run_until(0.3);
  ASSERT_EQ(stop_server(SIGTERM), 0);
  const std::string replay_id = sim_id_ + "-replay";
  Process player({kLadderctl, "replay", log_, "--speed", "0.02", "--as", replay_id, "--domain",
                  std::to_string(domain_)},
                 (dir_ / "replay.log").string());
  Client viewer(domain_, replay_id, "viewer");
  ASSERT_TRUE(viewer.wait_for_server(kStart)) << player.log();
  const Result r = shell(kLadderctl + " tip --domain " + std::to_string(domain_) + " --sim-id " + replay_id +
                         " --timeout 10");
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("'" + replay_id + "' on DDS domain " + std::to_string(domain_) +
                          " is a replay of a recorded session (ladderctl replay), which takes no commands"),
            std::string::npos)
      << r.output;
  // The terminal view says so too, instead of how to tip it from another terminal.
  const Result view = shell(std::string(LADDER_BINARY_DIR) + "/clients/ladder-view --ascii --frames 1 --domain " +
                            std::to_string(domain_) + " --sim-id " + replay_id + " --timeout 10 < /dev/null");
  EXPECT_EQ(view.code, 0) << view.output;
  EXPECT_NE(view.output.find("a replay of a recorded session (ladderctl replay): it takes no commands"),
            std::string::npos)
      << view.output;
  EXPECT_EQ(view.output.find("from another terminal"), std::string::npos) << view.output;
}

// A replay may not take the sim id of a ladder that is on the domain: a live server's clients would get the replay's
// states, and their commands would go to a replay, which takes none.
TEST_F(Record, AReplayRefusesTheSimIdOfALiveLadder) {
  start({"--record", log_});
  run_until(0.3);
  ASSERT_EQ(stop_server(SIGTERM), 0);
  start();  // a live server again, of the same sim id
  const Result r = shell(kLadderctl + " replay " + log_ + " --as " + sim_id_ + " --domain " + std::to_string(domain_));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("'" + sim_id_ + "' on DDS domain " + std::to_string(domain_) +
                          " is already served by a live ladderd"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("replaying "), std::string::npos) << r.output;
}

// A log is untrusted input: a state whose hinge status is none the message can carry (7) is skipped and counted,
// and the replay goes on and ends normally.
TEST_F(Record, ReplaySkipsAStateWithAnUnknownHingeStatus) {
  start({"--record", log_});
  run_until(0.3);
  ASSERT_EQ(stop_server(SIGTERM), 0);
  const std::string bent = (dir_ / "bent.lcmlog").string();
  std::size_t states = 0;
  rewrite_log(log_, bent, [&](Reader& in, const LogEvent& e, Writer& out) {
    if (e.channel != transport::kStateChannel || ++states != 5) return false;
    auto s = in.decode<ladderlcm::state_t>(e);
    s.status[2] = 7;
    out.write(transport::kStateChannel, e.utime, s, false);
    return true;
  });
  ASSERT_GT(states, 5u);
  const Result r = shell(kLadderctl + " replay " + bent + " --speed 0 --as " + sim_id_ + "-replay --domain " +
                         std::to_string(domain_));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("skipped 1 state(s) with a hinge status other than 0, 1 or 2"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("replayed " + std::to_string(states - 1) + " states"), std::string::npos) << r.output;
}

// The same across a reset: the resumed server stands in the reset's generation, with the settings made after it.
TEST_F(Record, ResumeAfterKillNineGoesOnInTheGenerationOfTheLastReset) {
  start({"--record", log_});
  accepted(cmd::tip());
  run_until(0.3);
  accepted(cmd::reset());
  for (const char* v : {"0.11", "0.12", "0.13"}) accepted(cmd::set(std::string("damping.linear=") + v));
  server_->signal(SIGKILL);
  server_->wait_exit(Millis(5000));
  const std::uint64_t last_acked = applied_;
  ASSERT_EQ(last_acked, 5u);

  const auto s = resume_from_log();
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->generation, 1u);
  EXPECT_EQ(s->commands_applied, last_acked);
  const auto info = client_->wait_scene_info(kAnswer);
  ASSERT_TRUE(info.has_value());
  EXPECT_NE(info->options.find("damping.linear=0.13\n"), std::string::npos) << info->options;
  EXPECT_NE(server_->log().find("(generation 1, step "), std::string::npos) << server_->log();
}

// Every acknowledged command is in the log file by the time its ack arrives: read back at each ack, the file holds
// that command's record (the ack waits for the record to be written and flushed). Prints the command-to-ack
// latency with and without --record, for docs/recording.md.
TEST_F(Record, EveryAckArrivesAfterItsCommandIsInTheFile) {
  const auto latencies = [&](bool check_file) {
    std::vector<double> ms;
    for (int i = 0; i < 200; ++i) {
      const auto t0 = Clock::now();
      const client::Ack a = client_->call(cmd::set(i % 2 ? "damping.angular=0.2" : "damping.angular=0.3"), kAnswer);
      ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      EXPECT_TRUE(a.accepted) << a.reason;
      if (!check_file) continue;
      transport::LogReader in(log_);  // as a crash would leave it: up to the last complete event
      bool found = false;
      while (auto e = in.next())
        if (e->channel == transport::kCommandChannel)
          found = found || in.decode<ladderlcm::command_t>(*e).command_seq == static_cast<std::int64_t>(a.command_seq);
      EXPECT_TRUE(found) << "command " << a.command_seq << " acknowledged before it was in the log";
    }
    std::sort(ms.begin(), ms.end());
    return std::pair{ms[ms.size() / 2], ms[ms.size() * 99 / 100]};
  };
  start();
  const auto [p50, p99] = latencies(false);
  ASSERT_EQ(stop_server(SIGTERM), 0);
  start({"--record", log_});
  const auto [rec_p50, rec_p99] = latencies(true);
  ASSERT_EQ(stop_server(SIGTERM), 0);
  std::printf("command-to-ack over 200 commands: without --record p50 %.3f ms, p99 %.3f ms; with --record (the ack "
              "waits for the flush) p50 %.3f ms, p99 %.3f ms\n", p50, p99, rec_p50, rec_p99);
}

// A forged event time (2^40 us, 12.7 days, ahead) cannot stall a replay: a pause of more than 10 s in the
// recording is played as 10 s, and said. (The old replay waited for the forged time: killed after 20 s.)
TEST_F(Record, AForgedTimestampCannotStallAReplay) {
  start({"--record", log_});
  run_until(0.3);
  ASSERT_EQ(stop_server(SIGTERM), 0);
  const std::string bent = (dir_ / "late.lcmlog").string();
  std::size_t states = 0;
  rewrite_log(log_, bent, [&](Reader&, const LogEvent& e, Writer& out) {
    if (e.channel != transport::kStateChannel || ++states != 3) return false;
    out.write_bytes(e.channel, e.utime + (std::int64_t{1} << 40), e.data, false);
    return true;
  });
  ASSERT_GT(states, 3u);
  // --speed 10: the 10 s pause takes 1 s.
  const Result r = shell("timeout -s KILL 20 " + kLadderctl + " replay " + bent + " --speed 10 --as " + sim_id_ +
                         "-replay --domain " + std::to_string(domain_));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("1 pause(s) longer than 10 s in the recording played as 10 s"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("replayed " + std::to_string(states) + " states"), std::string::npos) << r.output;
}

// The recording host's clock stepped back (an hour, as an NTP correction can) between two states: the replay is
// paced from there on as before the step. (The old replay took every event after it as lying before the latest one
// and played the rest of the log at once: 2.5 s of recording in no time.)
TEST_F(Record, AReplayKeepsItsPaceAfterTheRecordedClockStepsBack) {
  start({"--record", log_});
  run_until(2.5);
  ASSERT_EQ(stop_server(SIGTERM), 0);
  const std::string bent = (dir_ / "stepped.lcmlog").string();
  std::size_t states = 0;
  std::int64_t stepped_at = 0, last = 0;
  rewrite_log(log_, bent, [&](Reader&, const LogEvent& e, Writer& out) {
    constexpr std::int64_t kHour = 3'600'000'000;  // [us]
    if (e.channel == transport::kStateChannel && ++states == 3) stepped_at = e.utime;
    last = e.utime;
    if (stepped_at == 0) return false;
    out.write_bytes(e.channel, e.utime - kHour, e.data, false);
    return true;
  });
  const double after = 1e-6 * static_cast<double>(last - stepped_at);  // [s] of recording after the step
  ASSERT_GT(after, 2.0);
  const auto t0 = std::chrono::steady_clock::now();
  const Result r = shell("timeout -s KILL 30 " + kLadderctl + " replay " + bent + " --as " + sim_id_ +
                         "-replay --domain " + std::to_string(domain_));
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("the recorded times went back by more than 10 s 1 time(s)"), std::string::npos) << r.output;
  EXPECT_GE(took, 0.95 * after) << r.output;  // (a lower bound: a slow machine only adds to it)
}

// A recorded session replayed to a real ladder-view draws the same picture as the live server did at the same
// sim time (pixel for pixel below the heading line, which names the sim id).
TEST_F(Record, ReplayDrawsWhatTheLiveServerDrew) { replay_draws_what_the_live_server_drew({}); }

// The same for a scene whose blocks the viewer draws from SceneInfo's options, which a scene record has no field
// for: rolling hinges with fully rounded ends, and a depth of 30 mm. The replay makes the scene again from the
// record's text and overrides to publish them. (Before it did, the replay's blocks were square and 45 mm deep.)
TEST_F(Record, ReplayOfARollingSessionDrawsWhatTheLiveServerDrew) {
  replay_draws_what_the_live_server_drew(
      {"--set", "ladder.hinge=rolling", "--set", "ladder.end_radius=0.0065", "--set", "ladder.depth=0.03"});
}

// A scene record whose text does not make a scene in this build (here: not TOML at all): the replay says so, plays
// the session anyway (drawn at the default depth, with square corners) and ends normally.
TEST_F(Record, ReplayOfASceneThatDoesNotBuildHereSaysSoAndPlays) {
  start({"--record", log_});
  run_until(0.3);
  ASSERT_EQ(stop_server(SIGTERM), 0);
  const std::string bent = (dir_ / "bent.lcmlog").string();
  std::size_t states = 0;
  rewrite_log(log_, bent, [&](Reader& in, const LogEvent& e, Writer& out) {
    states += e.channel == transport::kStateChannel;
    if (e.channel != transport::kSceneChannel) return false;
    auto sc = in.decode<ladderlcm::scene_t>(e);
    sc.toml = "not = = toml";
    out.write(transport::kSceneChannel, e.utime, sc, false);
    return true;
  });
  const Result r = shell(kLadderctl + " replay " + bent + " --speed 0 --as " + sim_id_ + "-replay --domain " +
                         std::to_string(domain_));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("the scene of generation 0 does not build here ("), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("replayed " + std::to_string(states) + " states"), std::string::npos) << r.output;
}

void Record::replay_draws_what_the_live_server_drew(const std::vector<std::string>& scene) {
  const std::string viewer = std::string(LADDER_BINARY_DIR) + "/clients/ladder-view";
  std::vector<std::string> args{"--record", log_};
  args.insert(args.end(), scene.begin(), scene.end());
  start(args);
  accepted(cmd::tip());
  run_until(1.2);
  accepted(cmd::pause());
  const auto paused = client_->wait_state([](const client::State& st) { return st.paused; }, kAnswer);
  ASSERT_TRUE(paused.has_value());
  char at[32];
  std::snprintf(at, sizeof at, "%.17g", paused->sim_time);  // reads back as the same double
  const std::string camera = " --size 400x600 --view 0.01,-0.2,1200 --at " + std::string(at);
  const std::string live_png = (dir_ / "live.png").string(), replay_png = (dir_ / "replay.png").string();
  const Result live = shell(viewer + " --domain " + std::to_string(domain_) + " --sim-id " + sim_id_ +
                            " --timeout 30 --png " + live_png + camera);
  ASSERT_EQ(live.code, 0) << live.output;
  ASSERT_EQ(stop_server(SIGTERM), 0);

  // The viewer waits for the replay; the replay runs as fast as it can and ends on the paused state.
  const std::string replay_id = sim_id_ + "-r";
  const std::string view_cmd = viewer + " --domain " + std::to_string(domain_) + " --sim-id " + replay_id +
                               " --timeout 30 --png " + replay_png + camera;
  Process player({"/bin/sh", "-c",
                  "sleep 1; exec " + kLadderctl + " replay " + log_ + " --speed 4 --as " + replay_id +
                      " --domain " + std::to_string(domain_)},
                 (dir_ / "replay.log").string());
  const Result rep = shell(view_cmd);
  ASSERT_EQ(rep.code, 0) << rep.output << player.log();

  cairo_surface_t* a = cairo_image_surface_create_from_png(live_png.c_str());
  cairo_surface_t* b = cairo_image_surface_create_from_png(replay_png.c_str());
  ASSERT_EQ(cairo_surface_status(a), CAIRO_STATUS_SUCCESS);
  ASSERT_EQ(cairo_surface_status(b), CAIRO_STATUS_SUCCESS);
  ASSERT_EQ(cairo_image_surface_get_width(a), cairo_image_surface_get_width(b));
  ASSERT_EQ(cairo_image_surface_get_height(a), cairo_image_surface_get_height(b));
  const int w = cairo_image_surface_get_width(a), h = cairo_image_surface_get_height(a);
  const int stride = cairo_image_surface_get_stride(a);
  const unsigned char *pa = cairo_image_surface_get_data(a), *pb = cairo_image_surface_get_data(b);
  int differing = 0, drawn = 0;
  for (int y = 50; y < h; ++y)  // below the heading box
    for (int x = 0; x < w; ++x) {
      const auto* qa = pa + y * stride + 4 * x;
      const auto* qb = pb + y * stride + 4 * x;
      if (std::memcmp(qa, qb, 4) != 0) ++differing;
      if (std::memcmp(qa, pa + 60 * stride, 4) != 0) ++drawn;  // not the background of row 60, column 0
    }
  cairo_surface_destroy(a);
  cairo_surface_destroy(b);
  EXPECT_EQ(differing, 0);
  EXPECT_GT(drawn, 1000) << "the pictures show nothing, so their equality proves nothing";
}

// The logs are standard LCM event logs: liblcm's reader sees the same events, and lcm-logplayer plays them.
TEST_F(Record, LogsReadWithLiblcmAndPlayInLcmLogplayer) {
  start({"--record", log_});
  accepted(cmd::tip());
  run_until(0.5);
  ASSERT_EQ(stop_server(SIGTERM), 0);
  transport::LogReader ours(log_);
  std::size_t n_ours = 0;
  while (ours.next()) ++n_ours;
  lcm::LogFile theirs(log_, "r");
  ASSERT_TRUE(theirs.good());
  std::size_t n_theirs = 0, states = 0;
  while (const lcm::LogEvent* e = theirs.readNextEvent()) {
    ++n_theirs;
    if (e->channel == transport::kStateChannel) {
      ladderlcm::state_t s;
      ASSERT_GE(s.decode(e->data, 0, e->datalen), 0);
      ++states;
    }
  }
  EXPECT_EQ(n_theirs, n_ours);
  EXPECT_GT(states, 10u);
  // memq:// keeps the played messages in the process: no network. -s 50: fifty times as fast.
  const Result r = shell("timeout 20 lcm-logplayer --lcm-url=memq:// -s 50 " + log_);
  EXPECT_EQ(r.code, 0) << r.output;
}

// Damaged logs: cut at many places, or with bytes overwritten, a log is read up to the damage with a clear
// message (exit 0 or 1 from the re-run of what is left), or refused (exit 2); never a crash.
TEST_F(Record, CorruptOrTruncatedLogsAreRefusedOrReadUpToTheDamage) {
  start({"--record", log_});
  accepted(cmd::tip());
  run_until(0.4);
  ASSERT_EQ(stop_server(SIGTERM), 0);
  std::ifstream in(log_, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(bytes.size(), 1000u);
  std::mt19937 rng(42);
  const std::string bad = (dir_ / "bad.lcmlog").string();
  int refused = 0, read_to_damage = 0;
  for (int trial = 0; trial < 24; ++trial) {
    std::string damaged = bytes;
    if (trial % 2 == 0) {
      damaged.resize(std::uniform_int_distribution<std::size_t>(0, bytes.size() - 1)(rng));
    } else {
      for (int k = 0; k < 8; ++k)
        damaged[std::uniform_int_distribution<std::size_t>(0, bytes.size() - 1)(rng)] =
            static_cast<char>(rng() & 0xFF);
    }
    std::ofstream(bad, std::ios::binary | std::ios::trunc) << damaged;
    const Result r = shell(kLadderd + " --offline --resimulate " + bad);
    ASSERT_TRUE(r.code == 0 || r.code == 1 || r.code == 2) << "trial " << trial << ": exit " << r.code << "\n"
                                                          << r.output;
    if (r.code == 2) {
      // Refused with an error naming the file: not an LCM log, an event that does not decode, a scene text that
      // no longer parses, no scene record.
      ++refused;
      EXPECT_NE(r.output.find("[error]"), std::string::npos) << r.output;
      EXPECT_NE(r.output.find(bad), std::string::npos) << r.output;
      continue;
    }
    if (r.code == 1) {  // a difference, or damage in the middle of the log (the events after it not re-run)
      EXPECT_TRUE(r.output.find("differs: ") != std::string::npos ||
                  r.output.find("the log is damaged in the middle") != std::string::npos)
          << r.output;
    }
    if (r.output.find("complete events") != std::string::npos) ++read_to_damage;  // "... after N complete events"
  }
  EXPECT_GT(refused, 0);
  EXPECT_GT(read_to_damage, 0);
}

// The log with the first event on `channel` changed by `bend` (its encoded bytes, fingerprint included); returns
// the event's number.
std::uint64_t bend_first(const std::string& from, const std::string& to, const char* channel,
                         const std::function<void(std::vector<std::uint8_t>&)>& bend) {
  std::uint64_t bent = 0;
  rewrite_log(from, to, [&](Reader&, const LogEvent& e, Writer& out) {
    if (bent || e.channel != channel) return false;
    std::vector<std::uint8_t> data = e.data;
    bend(data);
    bent = e.number;
    out.write_bytes(e.channel, e.utime, std::move(data), false);
    return true;
  });
  return bent;
}
void put_big_endian(std::vector<std::uint8_t>& data, std::size_t at, std::uint64_t v, int bytes) {
  for (int i = bytes - 1; i >= 0; --i, v >>= 8) data.at(at + static_cast<std::size_t>(i)) = v & 0xFF;
}
// Where fields lie in an encoded state_t (after the 8-byte fingerprint: utime 8, generation 4, seq 8, step 8,
// sim_time 8, paused 1, commands_applied 8, energy 8, num_blocks 4), command_t and checkpoint_t (utime 8,
// generation 4, step 8).
constexpr std::size_t kStateStep = 28, kStateNumBlocks = 61, kCommandStep = 20, kCheckpointStep = 20;

// The three hostile logs of issue 18 (a state with num_blocks = 2^28 + 1, a state whose payload after its
// fingerprint is all 0x7f, a state with step 2^62): resimulate, replay and resume each refuse it (exit 2) within
// 5 s, naming the event and what is wrong. On the old reader the first overflowed a heap buffer in all three, the
// second hung the re-run and crashed the replay, the third made the re-run run forever.
TEST_F(Record, HostileLogsAreRefusedByEveryReaderWithinFiveSeconds) {
  start({"--record", log_});
  accepted(cmd::tip());
  run_until(0.3);
  ASSERT_EQ(stop_server(SIGTERM), 0) << server_->log();
  struct Case {
    const char* name;
    std::function<void(std::vector<std::uint8_t>&)> bend;
    std::string why;
  };
  const std::vector<Case> cases{
      {"blocks", [](auto& d) { put_big_endian(d, kStateNumBlocks, (1u << 28) + 1, 4); },
       "num_blocks = 268435457 is more than 1000000 (the most blocks a scene may have)"},
      {"7f", [](auto& d) { std::fill(d.begin() + 8, d.end(), 0x7f); }, "paused = 127 is not a boolean (0 or 1)"},
      {"step", [](auto& d) { put_big_endian(d, kStateStep, std::uint64_t{1} << 62, 8); },
       "step = 4611686018427387904 is beyond 100000000000000"},
  };
  for (const Case& c : cases) {
    const std::string bad = (dir_ / (std::string(c.name) + ".lcmlog")).string();
    const std::uint64_t event = bend_first(log_, bad, transport::kStateChannel, c.bend);
    ASSERT_GT(event, 0u);
    const std::string where = "event " + std::to_string(event) + " (LADDER_STATE at byte ";
    const std::string d = std::to_string(domain_);
    const std::vector<std::pair<const char*, std::string>> readers{
        {"resimulate", kLadderd + " --offline --resimulate " + bad},
        {"replay", kLadderctl + " replay " + bad + " --as " + sim_id_ + "-replay --domain " + d},
        {"resume", kLadderd + " --resume " + bad + " --domain " + d + " --sim-id " + sim_id_ + "-resumed"}};
    for (const auto& [name, reader] : readers) {
      const auto t0 = Clock::now();
      const Result r = shell("timeout -s KILL 5 " + reader);  // 137 if it hangs
      const double took = std::chrono::duration<double>(Clock::now() - t0).count();
      EXPECT_EQ(r.code, 2) << c.name << ": " << reader << "\n" << r.output;
      EXPECT_NE(r.output.find(bad + ": " + where), std::string::npos) << c.name << ": " << reader << "\n"
                                                                       << r.output;
      EXPECT_NE(r.output.find(c.why), std::string::npos) << c.name << ": " << reader << "\n" << r.output;
      const std::size_t line = std::min(r.output.find(bad + ": "), r.output.size());
      std::printf("%s log, %s: exit %d in %.2f s: %s\n", c.name, name, r.code, took,
                  r.output.substr(line, r.output.find('\n', line) - line).c_str());
    }
  }
  // A command or a checkpoint at step 2^62: refused too (the re-run would step toward it forever).
  for (const auto& [channel, at] : {std::pair{transport::kCommandChannel, kCommandStep},
                                    std::pair{transport::kCheckpointChannel, kCheckpointStep}}) {
    const std::string bad = (dir_ / "far.lcmlog").string();
    const std::uint64_t event =
        bend_first(log_, bad, channel, [at = at](auto& d) { put_big_endian(d, at, std::uint64_t{1} << 62, 8); });
    const Result r = shell("timeout -s KILL 5 " + kLadderd + " --offline --resimulate " + bad);
    EXPECT_EQ(r.code, 2) << channel << "\n" << r.output;
    EXPECT_NE(r.output.find("event " + std::to_string(event) + " (" + channel), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("step = 4611686018427387904 is beyond"), std::string::npos) << r.output;
  }
}

// A state whose step fits the step bound but not its time, or lies far past the last checkpoint: refused, so a
// re-run never steps toward a place no run of the server reaches.
TEST_F(Record, AStateBeyondWhatItsTimeAndCheckpointsAllowIsRefused) {
  start({"--record", log_});
  run_until(0.3);
  ASSERT_EQ(stop_server(SIGTERM), 0) << server_->log();
  const std::string bad = (dir_ / "far.lcmlog").string();
  const std::uint64_t event = bend_first(log_, bad, transport::kStateChannel, [](auto& d) {
    put_big_endian(d, kStateStep, 1'000'000'000, 8);
  });
  Result r = shell("timeout -s KILL 5 " + kLadderd + " --offline --resimulate " + bad);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("event " + std::to_string(event) + " (LADDER_STATE"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("steps of dt = 0.001 .. 0.001 s take 1e+06 .. 1e+06 s"), std::string::npos) << r.output;

  // Its time made to agree (1e6 s at dt = 1 ms): now it is a million seconds past the checkpoint at step 0.
  bend_first(log_, bad, transport::kStateChannel, [](auto& d) {
    put_big_endian(d, kStateStep, 1'000'000'000, 8);
    put_big_endian(d, kStateStep + 8, std::bit_cast<std::uint64_t>(1e6), 8);
  });
  r = shell("timeout -s KILL 5 " + kLadderd + " --offline --resimulate " + bad);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("1000000000 steps after the checkpoint before it (step 0)"), std::string::npos)
      << r.output;
}

// kill -9 right after the last of 30 acknowledged commands (live settings and pokes, half of them before the
// checkpoint at 1 s and half after): --resume applies every one of them. The commands logged after the last
// checkpoint are replayed at their recorded steps, the resumed server numbers on from the log, and the live setting
// is the last one set. (The old --resume stopped at the last checkpoint, and lost every command after it.)
TEST_F(Record, ResumeAfterKillNineKeepsEveryAcknowledgedCommand) {
  start({"--record", log_});
  accepted(cmd::tip());
  std::uint64_t last_acked = 0;
  std::string last_setting;
  for (int i = 1; i <= 30; ++i) {
    ladder_msg_Command c = cmd::poke(1 + i % 4, 0.0002 * (i % 2 ? 1 : -1), 0);
    if (i % 3 != 0) {
      char text[40];
      std::snprintf(text, sizeof text, "damping.linear=0.%02d", i);
      c = cmd::set(text);
      last_setting = std::string(text) + "\n";
    }
    const client::Ack a = client_->call(c, kAnswer);
    ASSERT_TRUE(a.accepted) << a.reason;
    last_acked = applied_ = std::max(last_acked, a.command_seq);
    if (i == 15) run_until(1.05);  // half of them before the checkpoint at 1 s, half after
  }
  server_->signal(SIGKILL);  // at once: no time for a 50 ms batch of the log writer
  server_->wait_exit(Millis(5000));
  ASSERT_EQ(last_acked, 31u);
  ASSERT_EQ(last_setting, "damping.linear=0.29\n");

  // Every acknowledged command is in the log, in order.
  const daemon::SessionLog log = daemon::read_session_log(log_);
  ASSERT_FALSE(log.commands.empty());
  EXPECT_EQ(log.commands.size(), 31u);
  EXPECT_EQ(log.commands.back().command_seq, 31);
  const std::int64_t at_checkpoint = log.checkpoints.back().commands_applied;
  ASSERT_GE(log.checkpoints.size(), 2u);
  const auto after = std::count_if(log.commands.begin(), log.commands.end(),
                                   [&](const ladderlcm::command_t& c) { return c.command_seq > at_checkpoint; });

  EXPECT_GT(after, 0);
  EXPECT_LT(after, 31);
  const auto s = resume_from_log();
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->commands_applied, last_acked);
  const auto info = client_->wait_scene_info(kAnswer);
  ASSERT_TRUE(info.has_value());
  EXPECT_NE(info->options.find(last_setting), std::string::npos) << info->options;
  EXPECT_NE(server_->log().find("after replaying " + std::to_string(after) + " commands past the last checkpoint"),
            std::string::npos)
      << server_->log();
  const std::string out = server_->log();
  const std::size_t line = out.find("resumed from");
  if (line != std::string::npos) std::printf("%s\n", out.substr(line, out.find('\n', line) - line).c_str());
  // The next command goes on from the log's numbering.
  const client::Ack a = client_->call(cmd::resume(), kAnswer);
  EXPECT_TRUE(a.accepted) << a.reason;
  EXPECT_EQ(a.command_seq, last_acked + 1);
}

// One tick may take thousands of steps (here 10 s of sim time: 100 ticks a second at a real-time factor of 1000):
// the server still writes a checkpoint every simulated second, before the step that passes it, so the log's
// checkpoints lie at most a second and a step apart and the log re-runs. (Before, it took at most one a tick: its
// checkpoints lay 10 s apart, and both readers refused the log, whose steps lay too far past a checkpoint.)
TEST_F(Record, ALogRecordedAtAThousandTimesRealTimeHasACheckpointEverySecondAndReRuns) {
  start({"--record", log_, "--rate", "100", "--rtf", "1000"});
  run_until(30);
  ASSERT_EQ(stop_server(SIGTERM), 0) << server_->log();
  const daemon::SessionLog log = daemon::read_session_log(log_);
  ASSERT_GE(log.checkpoints.size(), 30u);
  for (std::size_t i = 1; i < log.checkpoints.size(); ++i)
    EXPECT_LE(log.checkpoints[i].sim_time - log.checkpoints[i - 1].sim_time, 1.0 + 0.001 + 1e-9) << "checkpoint " << i;
  const Result r = shell(kLadderd + " --offline --resimulate " + log_);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("identical to the last bit"), std::string::npos) << r.output;
}

// A log holds at most 64 KiB of a reason and no NUL in a text (docs/recording.md): the server wrote a longer reason
// whole (a `load` refused for a key of 70 000 characters quotes it), and both readers then refused the whole log. It
// is recorded cut, ending in "...", and the log re-runs. A scene whose name holds a NUL, which made a scene record
// that no reader took, is refused where it is read.
TEST_F(Record, AReasonLongerThanALogHoldsIsRecordedCutAndTheLogReRuns) {
  const fs::path scenes = dir_ / "scenes";
  fs::create_directories(scenes);
  std::ofstream(scenes / "long-key.toml") << "[ladder]\n" << std::string(70'000, 'k') << " = 1\n";
  std::ofstream(scenes / "nul-name.toml") << "[scene]\nname = \"a\\u0000b\"\n";
  std::ofstream(dir_ / "ladderd.toml") << "[server]\nscenes_dir = \"" << scenes.string() << "\"\n";
  start({"--record", log_, "--config", (dir_ / "ladderd.toml").string()});
  const client::Ack long_key = client_->call(cmd::load("long-key"), kAnswer);
  EXPECT_FALSE(long_key.accepted);
  EXPECT_NE(long_key.reason.find("unknown key"), std::string::npos) << long_key.reason;
  const client::Ack nul = client_->call(cmd::load("nul-name"), kAnswer);
  EXPECT_FALSE(nul.accepted);
  EXPECT_NE(nul.reason.find("nul-name.toml:2:8: scene.name must not hold a NUL character (U+0000)"), std::string::npos)
      << nul.reason;
  applied_ = nul.command_seq;
  run_until(0.1);
  ASSERT_EQ(stop_server(SIGTERM), 0) << server_->log();
  const daemon::SessionLog log = daemon::read_session_log(log_);
  ASSERT_EQ(log.commands.size(), 2u);
  EXPECT_EQ(log.commands[0].reason.size(), transport::kLogMaxText);
  EXPECT_TRUE(log.commands[0].reason.ends_with("kkk...")) << log.commands[0].reason.substr(0, 200);
  const Result r = shell(kLadderd + " --offline --resimulate " + log_);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("identical to the last bit"), std::string::npos) << r.output;
}

// A step that fails pauses the session, and a reset then restarts the scene with its own settings (the live ones
// made it fail). The log says where the step failed, so the re-run takes that step too, fails alike and goes on as
// the session did: the reset restores the scene's settings and the resume is accepted; --resume serves the last
// state. Without the failure's record the re-run refuses the resume ("not paused"), as both readers did before.
TEST_F(Record, AFailedStepAndTheResetAfterItReRunAndResume) {
  start({"--record", log_});
  accepted(cmd::set("sim.integrator=euler"));
  accepted(cmd::set("sim.dt=0.1"));
  accepted(cmd::set("sim.gravity=[1000,0]"));
  ASSERT_TRUE(client_->wait_state(
      [&](const client::State& s) { return s.commands_applied >= applied_ && s.paused; }, Millis(20000)))
      << server_->log();
  const client::Ack reset = client_->call(cmd::reset(), kAnswer);
  ASSERT_TRUE(reset.accepted) << reset.reason;
  EXPECT_NE(reset.reason.find("the scene restarted with its own settings"), std::string::npos) << reset.reason;
  applied_ = reset.command_seq;
  accepted(cmd::resume());
  run_until(0.5);
  ASSERT_EQ(stop_server(SIGTERM), 0) << server_->log();

  const daemon::SessionLog log = daemon::read_session_log(log_);
  ASSERT_EQ(log.failures.size(), 1u);
  EXPECT_TRUE(log.failures[0].step);
  EXPECT_EQ(log.failures[0].at.generation, 0);
  EXPECT_EQ(log.failures[0].at.commands_applied, 3);
  Result r = shell(kLadderd + " --offline --resimulate " + log_);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("(5 commands; 1 failed step failed alike)"), std::string::npos) << r.output;

  const std::string without = (dir_ / "without.lcmlog").string();
  rewrite_log(log_, without, [](Reader&, const LogEvent& e, Writer&) {
    return e.channel == transport::kFailureChannel;  // (left out)
  });
  r = shell(kLadderd + " --offline --resimulate " + without);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("command 5 (resume), accepted live, is refused in the re-run: not paused"), std::string::npos)
      << r.output;

  const auto last = std::max_element(log.states.begin(), log.states.end(), [](const auto& a, const auto& b) {
    return std::tie(a.generation, a.step) < std::tie(b.generation, b.step);
  });
  ASSERT_NE(last, log.states.end());
  const auto s = resume_from_log();
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->sim_time, last->sim_time);
  EXPECT_EQ(s->commands_applied, 5u);
}

// A re-run holds the logged commands to the widest limits a configuration allows (ladderd.toml [commands]): a
// poke of 1e300 N s written into a log as accepted, which no ladderd accepts, is refused by --resume, naming the
// command and the limit. (Before, the re-run applied it: the resumed state held an infinite energy, so the server
// published no State, and no client could find it, not even to reset it.)
TEST_F(Record, AResumedLogIsHeldToTheWidestLimitsAConfigurationAllows) {
  start({"--record", log_});
  accepted(cmd::poke(3, 0.002, 0));
  run_until(0.3);
  ASSERT_EQ(stop_server(SIGTERM), 0) << server_->log();
  const std::string bad = (dir_ / "poke.lcmlog").string();
  rewrite_log(log_, bad, [](Reader& in, const LogEvent& e, Writer& out) {
    if (e.channel != transport::kCommandChannel) return false;
    auto c = in.decode<ladderlcm::command_t>(e);
    c.a = 1e300;
    out.write(transport::kCommandChannel, e.utime, c, false);
    return true;
  });
  const Result r = shell("timeout -s KILL 20 " + kLadderd + " --domain " + std::to_string(domain_) + " --sim-id " +
                         sim_id_ + "-bad --resume " + bad);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(bad + ": command 1 (poke), accepted live, is refused in the re-run: the impulse of 1e+300 "
                                "N s is beyond the limit of 1e+06 N s (commands.max_impulse)"),
            std::string::npos)
      << r.output;
}

// A log is held to what its scene does, not only to what its records say (four findings of a hostile-log probe).
TEST_F(Record, AForgedLogIsHeldToWhatItsSceneSteps) {
  const std::string d = std::to_string(domain_);
  // 3 (first: its own recording, which ends paused). The step command made 1e9 steps (the most the widest limits
  // allow), of which the run took 5: a resumed server owes the rest, but takes at most its own
  // commands.max_step_count (100 000 by default). (Before: it ran them all flat out, "paused", for hours.)
  start({"--record", log_});
  run_until(0.1);
  accepted(cmd::pause());
  accepted(cmd::step(5));
  ASSERT_TRUE(client_->wait_state([&](const client::State& s) { return s.commands_applied >= applied_; }, kAnswer));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // (the 5 steps taken, their state logged)
  ASSERT_EQ(stop_server(SIGTERM), 0) << server_->log();
  const std::string many = (dir_ / "many-steps.lcmlog").string();
  rewrite_log(log_, many, [](Reader& in, const LogEvent& e, Writer& out) {
    if (e.channel != transport::kCommandChannel) return false;
    auto c = in.decode<ladderlcm::command_t>(e);
    if (c.kind == ladder_msg_STEP) c.count = 1'000'000'000;
    out.write(transport::kCommandChannel, e.utime, c, false);
    return true;
  });
  Result r = shell("timeout -s KILL 20 " + kLadderd + " --offline --resimulate " + many);
  EXPECT_EQ(r.code, 0) << r.output;  // (the re-run matches the log: it takes the steps the log shows)
  r = shell("timeout --preserve-status -s INT 3 " + kLadderd + " --resume " + many + " --domain " + d +
            " --sim-id " + sim_id_ + "-many");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("999999995 ordered steps were still to be taken where the log ends; this server takes at "
                          "most 100000 (commands.max_step_count), and drops the rest"),
            std::string::npos)
      << r.output;

  start({"--record", log_});
  accepted(cmd::tip());
  run_until(0.3);
  ASSERT_EQ(stop_server(SIGTERM), 0) << server_->log();

  // 1. Its scene record says dt = 1e-7 s (and its states' steps agree): the checks take the step bound from that dt
  // (2e7 steps a checkpoint), while the scene the text makes steps 1 ms. The re-run stops at once, saying so.
  // (Before: it stepped 1 ms steps toward step 3e6 and more, an hour of CPU for a 1000-block scene.)
  const std::string tiny = (dir_ / "tiny-dt.lcmlog").string();
  rewrite_log(log_, tiny, [](Reader& in, const LogEvent& e, Writer& out) {
    if (e.channel == transport::kSceneChannel) {
      auto sc = in.decode<ladderlcm::scene_t>(e);
      sc.dt = 1e-7;
      out.write(transport::kSceneChannel, e.utime, sc, false);
    } else if (e.channel == transport::kStateChannel) {
      auto st = in.decode<ladderlcm::state_t>(e);
      st.step = std::llround(st.sim_time / 1e-7);
      out.write(transport::kStateChannel, e.utime, st, false);
    } else if (e.channel == transport::kCommandChannel) {
      auto c = in.decode<ladderlcm::command_t>(e);
      c.step = std::llround(static_cast<double>(c.step) * 1e-3 / 1e-7);
      out.write(transport::kCommandChannel, e.utime, c, false);
    } else {
      return false;
    }
    return true;
  });
  r = shell("timeout -s KILL 20 " + kLadderd + " --offline --resimulate " + tiny);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("the scene records of generation 0 say dt = 1e-07 .. 1e-07 s, but its scene steps 0.001 s"),
            std::string::npos)
      << r.output;

  // 2. One event in the middle damaged (its sync word), intact events after it: --resume refuses to go back to
  // before it, which would drop what follows (acknowledged commands perhaps); --resimulate says the rest was not
  // re-run. (Before: resumed from before the damage, and "identical", with exit 0.)
  std::ifstream file(log_, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  std::size_t middle = bytes.find("\xED\xA1\xDA\x01", bytes.size() / 2);
  ASSERT_NE(middle, std::string::npos);
  bytes[middle] = 'X';
  const std::string damaged = (dir_ / "damaged.lcmlog").string();
  std::ofstream(damaged, std::ios::binary | std::ios::trunc) << bytes;
  r = shell("timeout -s KILL 20 " + kLadderd + " --offline --resimulate " + damaged);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("no sync word where an event should start at byte " + std::to_string(middle)),
            std::string::npos) << r.output;
  EXPECT_NE(r.output.find("the log is damaged in the middle, not cut off"), std::string::npos) << r.output;
  r = shell("timeout -s KILL 20 " + kLadderd + " --resume " + damaged + " --domain " + d + " --sim-id " + sim_id_ +
            "-damaged");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("a resume from before the damage would drop them"), std::string::npos) << r.output;

  // 4. A command after the last state that the re-run refuses (a poke of block 99 of 6): --resume refuses the log,
  // and so does --resimulate now. (Before: "identical", exit 0, as it stopped at the last state.)
  const std::string late = (dir_ / "late-poke.lcmlog").string();
  std::optional<ladderlcm::command_t> last;
  std::int64_t last_step = 0;
  rewrite_log(
      log_, late,
      [&](Reader& in, const LogEvent& e, Writer&) {
        if (e.channel == transport::kCommandChannel) last = in.decode<ladderlcm::command_t>(e);
        if (e.channel == transport::kStateChannel) last_step = in.decode<ladderlcm::state_t>(e).step;
        return false;
      },
      [&](Writer& out) {
        if (!last) return;
        ladderlcm::command_t poke = *last;
        poke.command_seq = last->command_seq + 1;
        poke.command_id = last->command_id + 1;
        poke.kind = ladder_msg_POKE;
        poke.block = 99;
        poke.a = 0.001;
        poke.step = last_step + 1;
        poke.accepted = true;
        poke.reason = "";
        out.write(transport::kCommandChannel, last->utime, poke, false);
      });
  ASSERT_TRUE(last.has_value());
  r = shell("timeout -s KILL 20 " + kLadderd + " --offline --resimulate " + late);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("(poke), accepted live, is refused in the re-run"), std::string::npos) << r.output;

  // 5. A scene text in the log that makes no scene is the log's fault, not the file it was recorded from: the error
  // says which record holds it. (Before: only "<the scene file>:1:7: ...", a file that is fine.)
  const std::string text = (dir_ / "bad-text.lcmlog").string();
  rewrite_log(log_, text, [](Reader& in, const LogEvent& e, Writer& out) {
    if (e.channel != transport::kSceneChannel) return false;
    auto sc = in.decode<ladderlcm::scene_t>(e);
    sc.toml = "not = = toml";
    out.write(transport::kSceneChannel, e.utime, sc, false);
    return true;
  });
  r = shell("timeout -s KILL 20 " + kLadderd + " --offline --resimulate " + text);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("the scene record of generation 0 holds a scene text (recorded from "), std::string::npos)
      << r.output;
}

}  // namespace
}  // namespace ladder::test
