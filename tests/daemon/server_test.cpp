// ladderd as users meet it: a real server process, real Cyclone DDS on loopback, a unique domain and sim id per
// test, and the same client library ladderctl uses.
#include "server_fixture.hpp"

#include <gtest/gtest.h>

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <map>
#include <sstream>
#include <thread>
#include <utility>
#include <vector>

namespace ladder::test {
namespace {

// The built-in classic toy, tipped by a client: the ripple runs down hinge by hinge, as offline.
TEST_F(Server, TipMakesTheRippleRunDownEveryHinge) {
  start();
  const auto info = c().wait_scene_info(kAnswer);
  ASSERT_TRUE(info.has_value());
  ASSERT_EQ(info->blocks, 6u);
  const client::Ack ack = c().call(cmd::tip(), kAnswer);
  ASSERT_TRUE(ack.accepted) << ack.reason;
  std::map<int, double> first_flip;  // hinge -> time of its first flip-flop
  const auto deadline = Clock::now() + Millis(20000);
  while (first_flip.size() < 5 && Clock::now() < deadline) {
    const std::uint64_t seen = c().latest_state() ? c().latest_state()->seq : 0;
    c().wait_state([&](const client::State& st) { return st.seq > seen; }, Millis(200));
    for (const client::Event& e : c().take_events()) {
      if (e.kind == "flip_flop" && !first_flip.count(e.hinge)) first_flip[e.hinge] = e.t;
    }
  }
  ASSERT_EQ(first_flip.size(), 5u) << "the ripple stopped early";
  for (int k = 1; k <= 5; ++k) {
    ASSERT_TRUE(first_flip.count(k)) << "hinge " << k << " never flipped";
    EXPECT_GT(first_flip[k], ack.sim_time) << "hinge " << k << " flipped before the tip";
    if (k > 1) {
      EXPECT_GT(first_flip[k], first_flip[k - 1]) << "hinge " << k << " flipped before hinge " << k - 1;
    }
  }
}

// A client that joins late (the ladder paused, so nothing new is being published) still gets the scene and the
// latest state at once: both are transient-local.
TEST_F(Server, LateJoinerGetsSceneInfoAndStateWithinOneSecond) {
  start();
  const client::State paused = pause();
  const auto t0 = Clock::now();
  Client late(domain_, sim_id_, "late");
  const bool both = late.wait_for_server(Millis(1000));  // matched, with a SceneInfo and a State
  const double waited = std::chrono::duration<double>(Clock::now() - t0).count();
  const auto& info = late.scene_info();
  const auto& state = late.latest_state();
  ASSERT_TRUE(both) << "within 1 s: SceneInfo " << info.has_value() << ", State " << state.has_value();
  EXPECT_LT(waited, 1.0);
  EXPECT_EQ(info->blocks, 6u);
  EXPECT_DOUBLE_EQ(info->length, 0.064);
  ASSERT_EQ(info->masses.size(), 6u);
  EXPECT_DOUBLE_EQ(info->masses[0], 0.025);
  EXPECT_EQ(state->step, paused.step);
  EXPECT_EQ(state->blocks.size(), 6u);
}

TEST_F(Server, PauseThenStepTenAdvancesExactlyTenSteps) {
  start();
  const client::State p = pause();
  const auto info = c().wait_scene_info(kAnswer);
  ASSERT_TRUE(info.has_value());
  expect_accepted(cmd::step(10));
  const auto s = c().wait_state([&](const client::State& st) { return st.step >= p.step + 10; }, kAnswer);
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->step, p.step + 10);
  EXPECT_NEAR(s->sim_time, p.sim_time + 10 * info->dt, 1e-12);
  // Still paused: no further steps however long we wait.
  const auto later = c().wait_state([&](const client::State& st) { return st.step != p.step + 10; }, Millis(300));
  EXPECT_FALSE(later.has_value()) << "the ladder moved on while paused, to step " << later->step;
  expect_accepted(cmd::resume());
  EXPECT_TRUE(c().wait_state([&](const client::State& st) { return st.step > p.step + 20 && !st.paused; }, kAnswer));
}

TEST_F(Server, EveryCommandKindIsAcceptedWhenValid) {
  start();
  pause();
  expect_accepted(cmd::poke(3, 0.001, 0));
  expect_accepted(cmd::poke_at(2, 0, 0.001, 0.013, -0.15));  // 12 mm above block 2's centre (0.013, -0.162)
  expect_accepted(cmd::push(4, 0.01, 0, 0.05));
  expect_accepted(cmd::grab(5));
  expect_accepted(cmd::grab_to(3, 0.1, -0.2));
  expect_accepted(cmd::drag_pose(5, 0.15, -0.3, 0.5));
  expect_accepted(cmd::step(50));
  auto s = c().wait_state([](const client::State& st) { return st.grips.size() == 2; }, kAnswer);
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->grips[0].block, 3);
  EXPECT_EQ(s->grips[1].block, 5);
  EXPECT_DOUBLE_EQ(s->grips[1].target_x, 0.15);
  EXPECT_TRUE(s->grips[1].hold_angle);
  EXPECT_DOUBLE_EQ(s->grips[1].angle, 0.5);
  expect_accepted(cmd::release(3));
  expect_accepted(cmd::release(5));
  expect_accepted(cmd::break_hinge(5));
  expect_accepted(cmd::join_hinge(5));
  expect_accepted(cmd::set("damping.linear=0.5"));
  expect_accepted(cmd::set("sim.adaptive=true"));
  // A live setting shows in the SceneInfo published after it (late joiners and `ladderctl status` read it there).
  const auto live = c().wait_scene_info(kAnswer, [](const client::SceneInfo& i) {
    return i.options.find("sim.adaptive=true") != std::string::npos;
  });
  ASSERT_TRUE(live.has_value()) << "no SceneInfo with sim.adaptive=true";
  EXPECT_NE(live->options.find("damping.linear=0.5\n"), std::string::npos) << live->options;
  expect_accepted(cmd::set("server.real_time_factor=0.5"));
  const auto info = c().wait_scene_info(kAnswer);
  expect_accepted(cmd::tip());
  expect_accepted(cmd::reset());
  s = c().wait_state([](const client::State& st) { return st.step == 0; }, kAnswer);
  ASSERT_TRUE(s.has_value()) << "reset did not restart at step 0";
  expect_accepted(cmd::load("double-ripple"));
  const auto loaded = c().wait_state([](const client::State& st) { return st.blocks.size() == 16; }, kAnswer);
  ASSERT_TRUE(loaded.has_value()) << "the loaded scene's state never came";
  const auto li = c().wait_scene_info(kAnswer);
  ASSERT_TRUE(li.has_value());
  EXPECT_EQ(li->blocks, 16u);
  expect_accepted(cmd::resume());
  // Live settings last until the next load (docs/server.md): the loaded scene's own are back.
  EXPECT_NE(li->options.find("sim.adaptive=false\n"), std::string::npos) << li->options;
}

// Refusals over the wire: the ack carries the reason and the published state stays as it was. One or two of each
// layer (the ladder, the server's limits, the scene's checks, the session's verbs); every reason, word for word,
// is checked in-process by session_rules_test.cpp.
TEST_F(Server, InvalidCommandsAreRefusedWithAReasonAndChangeNothing) {
  start();
  const client::State s = pause();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  expect_refused(cmd::poke(99, 0.001, 0), "no block 99", s);
  expect_refused(cmd::poke(2, nan, 0), "not a finite number", s);
  const client::State held = expect_accepted(cmd::grab(4));
  ASSERT_EQ(held.grips.size(), 1u);
  expect_refused(cmd::drag_pose(4, 0, -0.2, nan), "the angle is nan", held);
  expect_refused(cmd::release(2), "block 2 is not grabbed", held);
  expect_accepted(cmd::release(4));
  expect_refused(cmd::poke(2, 1e6, 0), "beyond the limit of 1 N s", s);
  expect_refused(cmd::poke_at(2, 0.001, 0, 5.0, 5.0), "outside the block", s);
  expect_refused(cmd::set("solver.tolerence=1e-9"), "solver.tolerance", s);  // did-you-mean
  expect_refused(cmd::set("ladder.blocks=3"), "cannot change while the ladder runs", s);
  expect_refused(cmd::set("sim.dt=-1"), "sim.dt", s);
  expect_refused(cmd::load("../../etc/passwd"), "not permitted", s);
  expect_refused(cmd::pause(), "already paused", s);
  // (A command kind outside the enum cannot be sent: Cyclone refuses to serialise it, and a receiver drops it.)

  // Break the bottom hinge, let block 5 fall away, and a join is refused with the distance.
  const client::State broken = expect_accepted(cmd::break_hinge(5));
  ASSERT_EQ(broken.hinges[5].status, ladder_msg_BROKEN);
  expect_refused(cmd::break_hinge(5), "already broken", broken);
  expect_accepted(cmd::step(300));
  const auto fallen = c().wait_state([&](const client::State& st) { return st.step == s.step + 300; }, kAnswer);
  ASSERT_TRUE(fallen.has_value());
  expect_refused(cmd::join_hinge(5), "more than the capture distance", *fallen);
  expect_refused(cmd::step(0), "step count", *fallen);
  expect_accepted(cmd::resume());
  expect_refusal(cmd::step(5), "while paused");
}

// A burst within a client's commands.burst (here 2048, the most it may be) is taken whole: every command applied and
// answered once, the loop going on meanwhile, and the Stats accounting for each.
TEST_F(Server, ABurstWithinTheClientsBurstIsAllAppliedAndAnswered) {
  start(with_config("[commands]\nburst = 2048\nqueue = 2048\n"));
  const auto before = c().wait_stats([](const ladder_msg_Stats&) { return true; }, kStart);
  ASSERT_TRUE(before.has_value());
  constexpr int kBurst = 2000;
  std::vector<std::uint64_t> ids;
  for (int i = 0; i < kBurst; ++i) ids.push_back(c().send(cmd::set("damping.hinge=0")));
  int accepted = 0;
  for (std::uint64_t id : ids) {
    const auto a = c().wait_ack(id, Millis(30000));
    ASSERT_TRUE(a.has_value()) << "command " << id << " was never answered";
    EXPECT_TRUE(a->accepted) << a->reason;
    accepted += a->accepted ? 1 : 0;
  }
  EXPECT_EQ(accepted, kBurst);
  EXPECT_EQ(c().acks_received(), static_cast<std::size_t>(kBurst)) << "duplicate or extra acks";
  const auto after = c().wait_stats([&](const ladder_msg_Stats& st) { return st.commands_received >= kBurst; },
                                    Millis(10000));
  ASSERT_TRUE(after.has_value());
  EXPECT_GT(after->steps, before->steps) << "the loop stalled";  // (not how far: that would measure the machine)
  EXPECT_EQ(after->commands_accepted, static_cast<std::uint64_t>(kBurst));
  EXPECT_EQ(after->commands_rate_limited + after->commands_unanswered + after->commands_duplicate, 0u);
}

// commands.per_tick holds also for the commands the server applies between ticks, as they arrive: with a cap of 1,
// a burst is applied one command per step, in the order sent.
TEST_F(Server, PerTickCapHoldsBetweenTicks) { burst_with_one_command_per_tick(); }

// With --spin-us the physics thread busy-waits before each tick; commands that arrive then are applied as they come,
// one tick's worth at a time. Here it spins through half of each tick. Commands are sent one after another, each
// after a pause of 1 to 2 ms stepped by 0.37 ms, so that they arrive at scattered phases of the tick (sent straight
// after the last ack, they would all arrive in its first half): some arrive while it spins, and the debug log says
// where each was taken. On a loaded machine few land in the spin (with three busy loops on two cores, none of 40 in
// 5 runs of 60), so rounds of 40 go on until one has, 10 rounds at most.
TEST_F(Server, SpinningPhysicsThreadTakesCommandsAsTheyCome) {
  burst_with_one_command_per_tick({"--spin-us", "500"});
  EXPECT_NE(server_->log().find("busy-waits the last 500 us before each tick"), std::string::npos) << server_->log();
  bool spun = false;
  for (int round = 0; round < 10 && !spun; ++round) {
    for (int i = 0; i < 40; ++i) {
      std::this_thread::sleep_for(std::chrono::microseconds(1000 + (i * 370) % 1000));
      const client::Ack a = c().call(cmd::set("damping.hinge=0"), kAnswer);
      ASSERT_TRUE(a.accepted) << a.reason;
    }
    // A refusal is logged at info level, which flushes the debug lines before it.
    const std::string flush = "no.such.key" + std::to_string(round);
    EXPECT_FALSE(c().call(cmd::set(flush + "=1"), kAnswer).accepted);
    const auto deadline = Clock::now() + kAnswer;
    while (server_->log().find(flush) == std::string::npos && Clock::now() < deadline)
      std::this_thread::sleep_for(Millis(20));
    spun = server_->log().find(", while spinning before the tick") != std::string::npos;
  }
  EXPECT_TRUE(spun) << server_->log();
}

}  // namespace

void Server::burst_with_one_command_per_tick(std::vector<std::string> extra) {
  const std::vector<std::string> config = with_config("[commands]\nper_tick = 1\n");
  extra.insert(extra.end(), config.begin(), config.end());
  start(extra);
  constexpr int kBurst = 20;
  std::vector<std::uint64_t> ids;
  for (int i = 0; i < kBurst; ++i) ids.push_back(c().send(cmd::set("damping.hinge=0")));
  std::vector<std::uint64_t> steps;
  for (std::uint64_t id : ids) {
    const auto a = c().wait_ack(id, kAnswer);
    ASSERT_TRUE(a.has_value()) << "command " << id << " was never answered";
    ASSERT_TRUE(a->accepted) << a->reason;
    steps.push_back(a->step);
  }
  for (std::size_t i = 1; i < steps.size(); ++i)
    EXPECT_GT(steps[i], steps[i - 1]) << "commands " << i - 1 << " and " << i << " were applied at one step";
}

namespace {

TEST_F(Server, SigtermStopsWithinOneSecondAndSaysWhy) {
  start();
  const auto t0 = Clock::now();
  server_->signal(SIGTERM);
  const auto status = server_->wait_exit(Millis(1000));
  ASSERT_TRUE(status.has_value()) << "still running 1 s after SIGTERM";
  EXPECT_LT(std::chrono::duration<double>(Clock::now() - t0).count(), 1.0);
  ASSERT_TRUE(WIFEXITED(*status));
  EXPECT_EQ(WEXITSTATUS(*status), 0);
  EXPECT_NE(server_->log().find("SIGTERM"), std::string::npos) << server_->log();
}

// Clients that stopped answering (suspended watchers of events and of Stats, the server's reliable writers holding
// samples they have not acknowledged) hold a stopping server at most the shipped configuration's WriterLingerDuration
// a writer, 100 ms: with Cyclone's default of 1 s it stopped 2 s after SIGTERM. A watcher ended by SIGTERM (`timeout`,
// `kill`) leaves as Ctrl-C makes it, exit 0 and its participant deleted: killed by the signal, it left its readers
// behind.
TEST_F(Server, SuspendedWatchersDoNotHoldTheServerAtItsStop) {
  start();
  const std::string ctl = std::string(LADDER_BINARY_DIR) + "/clients/ladderctl";
  const std::vector<std::string> where{ctl, "--domain", std::to_string(domain_), "--sim-id", sim_id_, "watch"};
  const auto watcher = [&](const std::string& what) {
    std::vector<std::string> args = where;
    args.push_back(what);
    return std::make_unique<Process>(args, log_path_ + "." + what);
  };
  const auto shows = [](const Process& p, const std::string& words) {
    const auto deadline = Clock::now() + kStart;
    while (p.log().find(words) == std::string::npos && Clock::now() < deadline)
      std::this_thread::sleep_for(Millis(20));
    return p.log().find(words) != std::string::npos;
  };
  const auto events = watcher("events"), stats = watcher("stats"), ended = watcher("stats");
  ASSERT_TRUE(shows(*events, "events of sim id")) << events->log();
  ASSERT_TRUE(shows(*stats, "real-time")) << stats->log();
  ASSERT_TRUE(shows(*ended, "real-time")) << ended->log();
  ended->signal(SIGTERM);
  const auto ended_status = ended->wait_exit(Millis(5000));
  ASSERT_TRUE(ended_status.has_value()) << ended->log();
  EXPECT_TRUE(WIFEXITED(*ended_status) && WEXITSTATUS(*ended_status) == 0) << *ended_status;
  expect_accepted(cmd::tip());  // its flip-flops come after the watchers are suspended
  events->signal(SIGSTOP);
  stats->signal(SIGSTOP);
  std::this_thread::sleep_for(Millis(1500));  // events and Stats written to them meanwhile, never acknowledged
  const auto t0 = Clock::now();
  server_->signal(SIGTERM);
  const auto status = server_->wait_exit(Millis(5000));
  const double took = std::chrono::duration<double>(Clock::now() - t0).count();
  ASSERT_TRUE(status.has_value()) << "still running 5 s after SIGTERM";
  EXPECT_LT(took, 1.0) << server_->log();
  EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 0);
  events->signal(SIGCONT);
  stats->signal(SIGCONT);
}

// The real-time factor of the first Stats after a reset counts the new scene's time from its start, t = 0: it was
// the time run since the last Stats, negative across the reset, so it read exactly 0 for a second after every reset
// or load (in the window, the terminal, `ladderctl list`). Asserted only above 0: the machine may be slow.
TEST_F(Server, TheRealTimeFactorAfterAResetCountsTheNewScenesTime) {
  start();
  ASSERT_TRUE(c().wait_state([](const client::State& st) { return st.sim_time > 1.5; }, kStart));
  const client::Ack reset = c().call(cmd::reset(), kAnswer);
  ASSERT_TRUE(reset.accepted) << reset.reason;
  const auto after = c().wait_stats([](const ladder_msg_Stats& st) { return st.sim_time < 1.0; }, kStart);
  ASSERT_TRUE(after.has_value());
  EXPECT_GT(after->real_time_factor, 0) << "sim time " << after->sim_time << ", window " << after->window;
}

// A second ladderd started with the sim id a running one serves on the same domain (`scripts/run` run again in another
// terminal) refuses to start, naming the other, and publishes nothing: the two had served side by side, and every
// client saw their states mixed (sim time 41 s, then 12 s) and both took its commands. The first one serves on.
TEST_F(Server, ASecondServerOfTheSameSimIdRefusesToStartAndTheFirstServesOn) {
  start();
  const std::string log = std::string(LADDER_BINARY_DIR) + "/tests/" + test_name() + ".second.log";
  Process second({std::string(LADDER_BINARY_DIR) + "/server/ladderd", "--domain", std::to_string(domain_),
                  "--sim-id", sim_id_},
                 log);
  const auto status = second.wait_exit(kStart);
  ASSERT_TRUE(status.has_value()) << "the second server is still running; its log:\n" << second.log();
  ASSERT_TRUE(WIFEXITED(*status));
  EXPECT_EQ(WEXITSTATUS(*status), 2);
  EXPECT_NE(second.log().find("sim id '" + sim_id_ + "' on DDS domain " + std::to_string(domain_) +
                              " is already taken by a live ladderd, serving '"),
            std::string::npos)
      << second.log();
  EXPECT_EQ(second.log().find("] serving"), std::string::npos) << second.log();  // it never served
  const client::Ack a = c().call(cmd::pause(), kAnswer);
  EXPECT_TRUE(a.accepted) << a.reason;
  // Another sim id on the same domain is not taken.
  Process other({std::string(LADDER_BINARY_DIR) + "/server/ladderd", "--domain", std::to_string(domain_),
                 "--sim-id", sim_id_ + "-other"},
                std::string(LADDER_BINARY_DIR) + "/tests/" + test_name() + ".other.log");
  Client oc(domain_, sim_id_ + "-other", "test-other");
  EXPECT_TRUE(oc.wait_for_server(kStart)) << other.log();
}

// A hang-up (a closed terminal or SSH session) stops the server as cleanly as SIGTERM: exit 0, the reason logged.
// (It used to end it at once, without its last lines.)
TEST_F(Server, SighupStopsCleanlyAndSaysWhy) {
  start();
  server_->signal(SIGHUP);
  const auto status = server_->wait_exit(kAnswer);
  ASSERT_TRUE(status.has_value()) << "still running after SIGHUP";
  ASSERT_TRUE(WIFEXITED(*status)) << "ended by a signal: " << WTERMSIG(*status);
  EXPECT_EQ(WEXITSTATUS(*status), 0);
  EXPECT_NE(server_->log().find("stopped: SIGHUP received (the terminal hung up)"), std::string::npos)
      << server_->log();
}

// A datagram socket of the test's own, standing in for systemd's: what ladderd sends to $NOTIFY_SOCKET.
class NotifySocket {
 public:
  explicit NotifySocket(std::string path) : path_(std::move(path)) {
    unlink(path_.c_str());
    fd_ = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    std::strncpy(a.sun_path, path_.c_str(), sizeof a.sun_path - 1);
    bound_ = bind(fd_, reinterpret_cast<const sockaddr*>(&a), sizeof a) == 0;
  }
  ~NotifySocket() {
    close(fd_);
    unlink(path_.c_str());
  }
  bool bound() const { return bound_; }
  // The next message, or nothing within the timeout.
  std::optional<std::string> next(Millis timeout) {
    pollfd p{fd_, POLLIN, 0};
    if (poll(&p, 1, static_cast<int>(timeout.count())) <= 0) return std::nullopt;
    char buf[512];
    const ssize_t n = recv(fd_, buf, sizeof buf, 0);
    return n >= 0 ? std::optional<std::string>(std::string(buf, static_cast<std::size_t>(n))) : std::nullopt;
  }
  // The messages that come within `span` that equal `what`.
  int count(const std::string& what, Millis span) {
    int n = 0;
    const auto until = Clock::now() + span;
    while (Clock::now() < until)
      if (const auto m = next(std::chrono::duration_cast<Millis>(until - Clock::now()) + Millis(1)); m && *m == what)
        ++n;
    return n;
  }

 private:
  std::string path_;
  int fd_ = -1;
  bool bound_ = false;
};

// Under systemd (Type=notify, WatchdogSec=): READY=1 once the first State is on the wire, WATCHDOG=1 twice per
// watchdog interval (here 200 ms) while the loop runs and none while the process is stopped, STOPPING=1 on SIGTERM.
TEST_F(Server, TellsSystemdWhenReadyKeepsItsWatchdogAndSaysWhenStopping) {
  const std::string path = std::string(LADDER_BINARY_DIR) + "/tests/notify-" + std::to_string(getpid()) + ".sock";
  NotifySocket sock(path);
  ASSERT_TRUE(sock.bound());
  setenv("NOTIFY_SOCKET", path.c_str(), 1);
  setenv("WATCHDOG_USEC", "200000", 1);
  start();
  unsetenv("NOTIFY_SOCKET");
  unsetenv("WATCHDOG_USEC");
  std::optional<std::string> first;
  while ((first = sock.next(kAnswer)) && *first == "WATCHDOG=1") {
  }
  ASSERT_TRUE(first.has_value()) << "no READY=1";
  EXPECT_EQ(first->rfind("READY=1\nSTATUS=serving sim id '" + sim_id_ + "'", 0), 0u) << *first;
  EXPECT_GE(sock.count("WATCHDOG=1", Millis(1000)), 5) << "every 100 ms";
  server_->signal(SIGSTOP);
  std::this_thread::sleep_for(Millis(100));
  sock.count("WATCHDOG=1", Millis(50));  // those sent before the stop
  EXPECT_EQ(sock.count("WATCHDOG=1", Millis(1000)), 0) << "a stopped server still told the watchdog all was well";
  server_->signal(SIGCONT);
  EXPECT_GE(sock.count("WATCHDOG=1", Millis(1000)), 1) << "not after SIGCONT";
  server_->signal(SIGTERM);
  std::optional<std::string> m;
  while ((m = sock.next(kAnswer)) && *m == "WATCHDOG=1") {
  }
  ASSERT_TRUE(m.has_value()) << "no STOPPING=1";
  EXPECT_EQ(*m, "STOPPING=1");
  EXPECT_TRUE(server_->wait_exit(kAnswer).has_value());
}

// --tick-log: one line per tick of the real-time loop. Its deadlines lie exactly one period apart (a tick more than
// one period late starts the schedule afresh from itself); its steps add up to the server's step count, with none
// between the pause and the `step 10` but those ten; its commands are the two the test sent.
TEST_F(Server, TickLogAccountsForEveryTickStepAndCommand) {
  const std::string path = std::string(LADDER_BINARY_DIR) + "/tests/" + test_name() + ".ticks";
  start({"--rate", "200", "--tick-log", path});
  ASSERT_TRUE(c().wait_state([](const client::State& st) { return st.step >= 20; }, kAnswer));
  const client::State p = pause();
  expect_accepted(cmd::step(10));
  const auto s = c().wait_state([&](const client::State& st) { return st.step >= p.step + 10; }, kAnswer);
  ASSERT_TRUE(s.has_value());
  std::this_thread::sleep_for(Millis(100));  // some ticks while paused
  server_->signal(SIGTERM);
  const auto status = server_->wait_exit(Millis(5000));
  ASSERT_TRUE(status && WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << server_->log();

  struct Tick {
    long long tick, start, late, step_ns, steps, commands, published;
  };
  std::vector<Tick> ticks;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream f(line);
    Tick t{};
    ASSERT_TRUE(f >> t.tick >> t.start >> t.late >> t.step_ns >> t.steps >> t.commands >> t.published) << line;
    ticks.push_back(t);
  }
  ASSERT_GE(ticks.size(), 20U);
  constexpr long long kPeriod = 5'000'000;  // [ns] at 200 Hz
  long long steps = 0, commands = 0, steps_from_pause = 0, published = 0;
  bool paused = false;
  for (std::size_t i = 0; i < ticks.size(); ++i) {
    const Tick& t = ticks[i];
    ASSERT_EQ(t.tick, static_cast<long long>(i + 1)) << "a tick is missing from the log";
    EXPECT_GE(t.late, 0) << "tick " << t.tick;
    EXPECT_EQ(t.steps == 0, t.step_ns == 0) << "tick " << t.tick;
    if (i > 0) {
      const Tick& prev = ticks[i - 1];
      const long long prev_deadline = prev.late > kPeriod ? prev.start : prev.start - prev.late;
      EXPECT_EQ(t.start - t.late - prev_deadline, kPeriod) << "tick " << t.tick;
    }
    paused = paused || t.commands > 0;  // the first command, the pause, is applied before its tick's steps
    steps += t.steps;
    commands += t.commands;
    published += t.published;
    if (paused) steps_from_pause += t.steps;
  }
  EXPECT_EQ(steps, static_cast<long long>(s->step));
  EXPECT_EQ(steps_from_pause, 10);
  EXPECT_EQ(commands, 2);
  EXPECT_GT(published, 0);  // at least the states after the pause and the step
  std::filesystem::remove(path);
}

// The scheduling policy (41st field of /proc/PID/task/TID/stat; 1 = SCHED_FIFO) and real-time priority (40th) of each
// thread of a process. The second field, the thread's name, is in parentheses and may hold spaces.
std::vector<std::pair<int, int>> thread_policies(pid_t pid) {
  std::vector<std::pair<int, int>> out;
  for (const auto& task : std::filesystem::directory_iterator("/proc/" + std::to_string(pid) + "/task")) {
    std::ifstream in(task.path() / "stat");
    std::string line;
    std::getline(in, line);
    std::istringstream rest(line.substr(line.rfind(')') + 2));  // from field 3 on
    std::vector<std::string> f(std::istream_iterator<std::string>{rest}, {});
    if (f.size() >= 39) out.emplace_back(std::stoi(f[38]), std::stoi(f[37]));  // fields 41 and 40
  }
  return out;
}

// --realtime-priority 30: the physics thread runs under SCHED_FIFO at 30, and the I/O thread with DDS's threads just
// below, at 29; or, where the system refuses (no CAP_SYS_NICE), the log says why and every thread keeps the normal
// scheduler. The ladder is served either way.
TEST_F(Server, RealtimePriorityPutsThePhysicsThreadUnderSchedFifo) {
  start({"--realtime-priority", "30"});
  ASSERT_TRUE(c().wait_state([](const client::State& st) { return st.step > 0; }, kAnswer));
  const auto threads = thread_policies(server_->pid());
  const auto count = [&](int policy, int priority) {
    return std::count(threads.begin(), threads.end(), std::pair{policy, priority});
  };
  if (server_->log().find("physics thread at SCHED_FIFO priority 30") != std::string::npos) {
    EXPECT_NE(server_->log().find("I/O thread at SCHED_FIFO priority 29"), std::string::npos) << server_->log();
    EXPECT_EQ(count(1, 30), 1) << "exactly one thread, the physics thread, at 30";
    EXPECT_GE(count(1, 29), 2) << "the I/O thread and DDS's threads at 29";
  } else {
    EXPECT_NE(server_->log().find("could not run the I/O thread at SCHED_FIFO priority 29"), std::string::npos)
        << server_->log();
    EXPECT_NE(server_->log().find("CAP_SYS_NICE"), std::string::npos) << server_->log();
    EXPECT_EQ(count(1, 30) + count(1, 29), 0);
  }
}

// Two ladders on one domain: each client sees only its own.
TEST_F(Server, TwoSimIdsShareADomainWithoutMixing) {
  start();
  const std::string other_id = sim_id_ + "-other";
  Process other({std::string(LADDER_BINARY_DIR) + "/server/ladderd", "--domain", std::to_string(domain_),
                 "--sim-id", other_id, "--scene", std::string(LADDER_SOURCE_DIR) + "/config/scenes/double-ripple.toml"},
                log_path_ + ".other");
  Client oc(domain_, other_id, "other");
  ASSERT_TRUE(oc.wait_for_server(kStart)) << other.log();
  EXPECT_EQ(oc.scene_info()->blocks, 16u);
  EXPECT_TRUE(oc.wait_state([](const client::State& st) { return st.blocks.size() == 16; }, kAnswer));
  const client::Ack a = oc.call(cmd::pause(), kAnswer);
  EXPECT_TRUE(a.accepted) << a.reason;
  // Ours still runs with 6 blocks, unpaused.
  const auto mine = c().wait_state([](const client::State&) { return true; }, kAnswer);
  ASSERT_TRUE(mine.has_value());
  EXPECT_EQ(mine->blocks.size(), 6u);
  EXPECT_FALSE(mine->paused);
  EXPECT_EQ(c().scene_info()->blocks, 6u);
}

// In a domain that another server shares, a client is ready only when it has found the command reader, ack writer
// and event writer of the server that publishes its sim id's states. Discovery can bring a server's writers before
// its readers; a client that had only matched the other server's reader (what `matched() > 0` counted) lost its first
// command (this test's CI failure, TwoSimIdsShareADomainWithoutMixing). The late server is played by a participant
// of the test's own, which creates its readers and writers in that order on purpose: a real one creates them too
// quickly for the race to be produced at will.
TEST_F(Server, AClientIsReadyOnlyWhenItsOwnServerTakesCommands) {
  start();
  const std::string id = "late-" + std::to_string(getpid());
  Client late(domain_, id, "test");
  const transport::Entity participant = transport::make_participant(static_cast<dds_domainid_t>(domain_));
  const transport::Topics topics(participant);
  const transport::Writer<ladder_msg_SceneInfo> scene_w(participant, topics.scene_info, transport::Profile::SceneInfo);
  const transport::Writer<ladder_msg_State> state_w(participant, topics.state, transport::Profile::State);
  ladder_msg_SceneInfo si{};
  transport::copy_text(si.sim_id, id);
  si.blocks = 1;
  scene_w.write(si);
  ladder_msg_State st{};
  transport::copy_text(st.sim_id, id);
  st.seq = 1;
  const std::vector<double> poses{0.0, 0.0, 0.0};
  const std::vector<std::uint8_t> corner{0};
  const std::vector<ladder_msg_HingeStatus> status{ladder_msg_HINGED};
  const std::vector<std::uint32_t> flips{0};
  transport::lend_blocks(st, poses, corner, status, flips);
  state_w.write(st);
  // The client sees the late server's SceneInfo and State, and ladderd's command reader: not ready.
  EXPECT_TRUE(late.wait_state([](const client::State& s) { return s.seq == 1; }, kAnswer));
  EXPECT_FALSE(late.wait_for_server(Millis(1500))) << "ready with only another server's command reader";
  const transport::Reader<ladder_msg_Command> command_r(participant, topics.command, transport::Profile::Command);
  const transport::Writer<ladder_msg_CommandAck> ack_w(participant, topics.ack, transport::Profile::CommandAck);
  const transport::Writer<ladder_msg_Event> event_w(participant, topics.event, transport::Profile::Event);
  ASSERT_TRUE(late.wait_for_server(kAnswer));
  // and its first command reaches the late server.
  const std::uint64_t sent = late.send(cmd::pause());
  std::vector<std::uint64_t> received;
  const auto deadline = Clock::now() + kAnswer;
  while (received.empty() && Clock::now() < deadline) {
    command_r.take([&](const ladder_msg_Command& m, const dds_sample_info_t&) {
      if (std::string(m.sim_id) == id) received.push_back(m.command_id);
    });
    std::this_thread::sleep_for(Millis(10));
  }
  EXPECT_EQ(received, std::vector<std::uint64_t>{sent});
}

// The server side of the same race: a client's command can arrive before the server has discovered the client's
// ack and event readers, and an ack written then would reach no one. The server holds a sender's commands until its
// ack and event writers match a reader in the sender's participant (commands.reader_wait at most, 60 s here, so
// that neither a slow machine nor a server that never finds the readers can pass for the other). The client here
// creates its readers 100 ms after sending, a delay that discovery alone produces only by chance.
TEST_F(Server, ACommandWaitsUntilItsSenderCanHearTheAnswer) {
  start(with_config("[commands]\nreader_wait = 60\n"));
  BareSender bare(domain_, sim_id_);
  ASSERT_EQ(bare.command_w.matched(), 1u);
  bare.pause(7);
  std::this_thread::sleep_for(Millis(100));
  // Not applied yet: a state that left the server after the 100 ms still runs.
  const std::uint64_t seq = c().wait_state([](const client::State&) { return true; }, kAnswer)->seq;
  const auto later = c().wait_state([&](const client::State& st) { return st.seq > seq; }, kAnswer);
  ASSERT_TRUE(later && !later->paused) << "the pause was applied before its sender could hear the answer";
  bare.add_readers();
  EXPECT_EQ(bare.acked(), std::vector<std::uint64_t>{7});
  EXPECT_TRUE(c().wait_state([](const client::State& st) { return st.paused; }, kAnswer));
}

// A sender that never makes the readers waits no longer than commands.reader_wait (0.5 s here): its command is
// then taken, and the log says why.
TEST_F(Server, ACommandOfASenderWithoutReadersIsTakenAfterTheReaderWait) {
  start(with_config("[commands]\nreader_wait = 0.5\n"));
  BareSender bare(domain_, sim_id_);
  ASSERT_EQ(bare.command_w.matched(), 1u);
  const auto sent = Clock::now();
  bare.pause(1);
  ASSERT_TRUE(c().wait_state([](const client::State& st) { return st.paused; }, kAnswer));
  EXPECT_GE(Clock::now() - sent, Millis(500)) << "taken before the 0.5 s were over";
  EXPECT_NE(server_->log().find("client 'bare': its ack reader not found in 0.5 s"), std::string::npos)
      << server_->log();
}

// A client of its own making that reads the answers but not the events (docs/server.md, "Your own client"): its
// commands wait for its ack reader, then 0.1 s for an event reader that does not come, not commands.reader_wait
// (60 s here; it was 2 s by default, for every first command of such a client).
TEST_F(Server, ASenderThatReadsAcksButNoEventsIsAnsweredWithoutTheReaderWait) {
  start(with_config("[commands]\nreader_wait = 60\n"));
  BareSender bare(domain_, sim_id_);
  bare.add_readers(/*events=*/false);
  ASSERT_EQ(bare.command_w.matched(), 1u);
  bare.pause(3);
  EXPECT_EQ(bare.acked(), std::vector<std::uint64_t>{3});
  const auto deadline = Clock::now() + kAnswer;  // (the log line is written before the command is passed on)
  while (server_->log().find("client 'bare': no event reader ") == std::string::npos && Clock::now() < deadline)
    std::this_thread::sleep_for(Millis(20));
  EXPECT_NE(server_->log().find("client 'bare': no event reader "), std::string::npos) << server_->log();
}

// A client drops a State whose sequences disagree (a broken or hostile publisher: five numbers for two poses),
// counts it, and takes the next good one.
TEST(ClientLibrary, DropsAStateWhoseSequencesDisagree) {
  const int domain = domain_for(test_name());
  const std::string id = "hostile-" + std::to_string(getpid());
  Client c(domain, id, "test");
  const transport::Entity participant = transport::make_participant(static_cast<dds_domainid_t>(domain));
  const transport::Topics topics(participant);
  const transport::Writer<ladder_msg_State> w(participant, topics.state, transport::Profile::State);
  const std::vector<double> poses{0.1, 0.2, 0.3, 0.4, 0.5, 0.6}, short_poses{0.1, 0.2, 0.3, 0.4, 0.5};
  const std::vector<std::uint8_t> corner{0, 1};
  const std::vector<ladder_msg_HingeStatus> status{ladder_msg_HINGED, ladder_msg_LOCKED};
  const std::vector<std::uint32_t> flips{0, 3};
  const auto publish = [&](std::uint64_t seq, const std::vector<double>& p) {
    ladder_msg_State m{};
    transport::copy_text(m.sim_id, id);
    m.seq = seq;
    transport::lend_blocks(m, p, corner, status, flips);
    w.write(m);
  };
  publish(1, short_poses);
  const auto deadline = Clock::now() + kAnswer;
  while (c.states_malformed() == 0 && Clock::now() < deadline)
    c.wait_state([](const client::State&) { return true; }, Millis(20));
  EXPECT_EQ(c.states_malformed(), 1u);
  EXPECT_FALSE(c.latest_state().has_value()) << "the malformed state was taken";
  publish(2, poses);
  const auto s = c.wait_state([](const client::State& st) { return st.seq == 2; }, kAnswer);
  ASSERT_TRUE(s.has_value());
  ASSERT_EQ(s->blocks.size(), 2u);
  EXPECT_EQ(s->blocks[1].y, 0.5);
  EXPECT_EQ(s->blocks[1].theta, 0.6);
  EXPECT_EQ(s->hinges[1].corner, 1);
  EXPECT_EQ(s->hinges[1].status, ladder_msg_LOCKED);
  EXPECT_EQ(s->hinges[1].flips, 3u);
  EXPECT_EQ(c.states_malformed(), 1u);
}

}  // namespace
}  // namespace ladder::test
