// ladderd under network faults: a real server and the client library over real Cyclone DDS, across two network
// namespaces joined by a veth pair with random loss or a partition (a BPF classifier on each end's egress,
// tests/net/drop.c; this kernel has no netem), and on loopback for duplicate command ids and server restarts.
// The namespace tests need root; they skip, saying why, when not root or when the kernel refuses a namespace, a
// veth pair or the classifier (tests/daemon/netns.hpp).
#include "client.hpp"
#include "netns.hpp"
#include "process.hpp"
#include "transport/default_config.hpp"
#include "transport/dds.hpp"
#include "transport/topics.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <map>
#include <set>
#include <thread>

namespace ladder::test {
namespace {

using client::Client;
using client::Millis;
namespace cmd = client::cmd;
using Clock = std::chrono::steady_clock;

constexpr Millis kStart{15000};   // generous: CI runs two tests at once on two cores
constexpr Millis kAnswer{5000};
constexpr Millis kLossy{60000};   // one command's answer, or discovery, with 20 % loss each way
const std::string kLadderd = std::string(LADDER_BINARY_DIR) + "/server/ladderd";
const std::string kBpfDir = LADDER_BPF_DIR;  // drop20.o, drop100.o; empty when CMake found no clang

std::string test_name() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  return std::string(info->test_suite_name()) + "." + info->name();
}

double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

// The value at fraction q of the sorted values.
double percentile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())))];
}

std::string bpf_object(int percent) {
  if (kBpfDir.empty())
    throw std::runtime_error("the BPF classifier was not built: CMake found no clang (scripts/install-deps lists it)");
  return kBpfDir + "/drop" + std::to_string(percent) + ".o";
}

// Sets an environment variable for the object's life (Cyclone reads CYCLONEDDS_URI when a domain is created).
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const std::string& value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    setenv(name, value.c_str(), 1);
  }
  ~ScopedEnv() { old_ ? setenv(name_, old_->c_str(), 1) : unsetenv(name_); }

 private:
  const char* name_;
  std::optional<std::string> old_;
};

class NetFault : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string name = test_name();
    // The pid makes a rerun's server distinct from a killed one that discovery still lists (until its lease ends).
    sim_id_ = name.substr(name.size() > 40 ? name.size() - 40 : 0) + "-" + std::to_string(getpid());
    for (char& ch : sim_id_)
      if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '-';
    domain_ = 1 + static_cast<int>(std::hash<std::string>{}(name) % 230);
    log_ = std::string(LADDER_BINARY_DIR) + "/tests/" + name;
  }
  std::vector<std::string> ladderd_args() const {
    return {kLadderd, "--domain", std::to_string(domain_), "--sim-id", sim_id_, "--log-level", "debug"};
  }
  // ladderd in namespace a.
  Process start_server_in_a(const NetnsPair& net) const {
    return Process(net.run_in('a', NetnsPair::xml_a(), ladderd_args()), log_ + ".log");
  }
  // A client in namespace b: the calling thread stays there until `net` goes, and Cyclone's threads start from it.
  void client_in_b(NetnsPair& net, std::optional<Client>& c, const std::string& client_id) const {
    net.enter_b();
    ScopedEnv uri("CYCLONEDDS_URI", NetnsPair::xml_b());
    c.emplace(domain_, sim_id_, client_id);
  }

  // Cuts the link between ladderd and a client for `length`, then heals it (below).
  void partition_and_heal(Millis length);

  std::string sim_id_, log_;
  int domain_ = 0;
};

// ---------------------------------------------------------------------------------------------------------------
// 20 % random loss each way (from before discovery): 1000 commands, 10 in flight, each answered and applied once.

TEST_F(NetFault, ThousandCommandsUnderTwentyPercentLossAreEachAppliedOnce) {
  NetnsPair net;
  if (const auto why = net.create()) GTEST_SKIP() << *why;
  if (const auto why = net.set_loss(bpf_object(20)))
    GTEST_SKIP() << "the kernel refused the BPF classifier: " << *why;
  Process server = start_server_in_a(net);
  const auto t_connect = Clock::now();
  std::optional<Client> c;
  client_in_b(net, c, "lossy");
  ASSERT_TRUE(c->wait_for_server(kLossy)) << "no ladderd across the lossy link; its log:\n" << server.log();
  const double connect_ms = ms_since(t_connect);
  const std::uint64_t base = c->latest_state()->commands_applied;

  // Distinct values, so that the last one applied shows in the live settings. kWindow commands in flight, as a
  // client that does not wait for each answer: a lost packet then holds up the answers behind it too (DDS delivers a
  // writer's samples in order), which the latencies include. Acks arrive in order, so waiting for the oldest times
  // each one as it comes.
  constexpr int kCommands = 1000;
  constexpr std::size_t kWindow = 10;  // 1: each command alone (docs/network.md has both figures)
  std::vector<double> latency_ms;
  std::set<std::uint64_t> seqs;
  std::deque<std::pair<std::uint64_t, Clock::time_point>> in_flight;  // command id, when sent
  const auto t_run = Clock::now();
  for (int sent = 0; sent < kCommands || !in_flight.empty();) {
    while (sent < kCommands && in_flight.size() < kWindow) {
      char text[64];
      std::snprintf(text, sizeof text, "damping.linear=%.3f", 0.001 * ++sent);
      in_flight.emplace_back(c->send(cmd::set(text)), Clock::now());
    }
    const auto [id, t0] = in_flight.front();
    in_flight.pop_front();
    const auto ack = c->wait_ack(id, kLossy);
    ASSERT_TRUE(ack.has_value()) << "command " << id << " unanswered after " << kLossy.count()
                                 << " ms; server log:\n" << server.log();
    latency_ms.push_back(ms_since(t0));
    ASSERT_TRUE(ack->accepted) << "command " << id << ": " << ack->reason;
    EXPECT_TRUE(seqs.insert(ack->command_seq).second) << "command_seq " << ack->command_seq << " given twice";
  }
  const double run_s = ms_since(t_run) / 1000;

  // Applied once each: the server gave them the places base+1 .. base+1000 in its order, and a last command comes
  // right after them. Acks of one writer arrive in order, so an ack written twice would have come before its ack.
  EXPECT_EQ(seqs.size(), static_cast<std::size_t>(kCommands));
  EXPECT_EQ(*seqs.begin(), base + 1);
  EXPECT_EQ(*seqs.rbegin(), base + kCommands);
  const client::Ack last = c->call(cmd::set("damping.linear=1"), kLossy);  // the value it has: no SceneInfo
  EXPECT_TRUE(last.accepted) << last.reason;
  EXPECT_EQ(last.command_seq, base + kCommands + 1) << "a command was applied more than once";
  EXPECT_EQ(c->acks_received(), static_cast<std::size_t>(kCommands + 1)) << "an ack came twice";
  const auto st = c->wait_state([&](const client::State& s) { return s.commands_applied >= last.command_seq; },
                                kLossy);
  ASSERT_TRUE(st.has_value());
  EXPECT_EQ(st->commands_applied, base + kCommands + 1);
  const auto info = c->wait_scene_info(kLossy, [](const client::SceneInfo& s) {
    return s.options.find("damping.linear=1\n") != std::string::npos;
  });
  EXPECT_TRUE(info.has_value()) << "the last value sent is not the live one: " << c->scene_info()->options;
  // The server's own totals (Stats, once a second) say the same.
  const auto stats = c->wait_stats([&](const ladder_msg_Stats& s) { return s.commands_received >= kCommands + 1; },
                                   kLossy);
  ASSERT_TRUE(stats.has_value());
  EXPECT_EQ(stats->commands_received, static_cast<std::uint64_t>(kCommands + 1));
  EXPECT_EQ(stats->commands_accepted, static_cast<std::uint64_t>(kCommands + 1));
  EXPECT_EQ(stats->commands_duplicate, 0u) << "DDS delivered a command twice";

  // The loss was real: each end's classifier dropped about a fifth of what it saw.
  for (char side : {'a', 'b'}) {
    const NetnsPair::Egress e = net.egress(side);
    const double loss =
        100.0 * static_cast<double>(e.dropped) / static_cast<double>(std::max<std::uint64_t>(1, e.packets));
    std::printf("[ figures  ] egress of side %c: %llu packets, %llu dropped (%.1f %%)\n", side,
                static_cast<unsigned long long>(e.packets), static_cast<unsigned long long>(e.dropped), loss);
    EXPECT_GT(e.packets, 1000u);
    EXPECT_GT(loss, 10.0);
    EXPECT_LT(loss, 30.0);
  }
  std::printf("[ figures  ] 20 %% loss each way: connected in %.0f ms; %d commands, %zu in flight, in %.1f s; ack "
              "latency p50 %.2f ms, p99 %.1f ms, max %.1f ms\n",
              connect_ms, kCommands, kWindow, run_s, percentile(latency_ms, 0.5), percentile(latency_ms, 0.99),
              *std::max_element(latency_ms.begin(), latency_ms.end()));
}

// ---------------------------------------------------------------------------------------------------------------
// A partition (every packet dropped both ways) that heals: the same client gets its answers and states again. 5 s
// is within the DDS lease (10 s): nothing is forgotten, and the command sent during the cut is delivered after it.
// 15 s is beyond it: each side drops the other and finds it again after the heal, and the command written during
// the cut may be lost; the client sends it again with the same id, and it is applied once all the same.

void NetFault::partition_and_heal(Millis length) {
  const bool beyond_lease = length > Millis(10000);
  NetnsPair net;
  if (const auto why = net.create()) GTEST_SKIP() << *why;
  Process server = start_server_in_a(net);
  std::optional<Client> c;
  client_in_b(net, c, "partitioned");
  ASSERT_TRUE(c->wait_for_server(kStart)) << "no ladderd across the link; its log:\n" << server.log();
  const client::Ack before = c->call(cmd::set("damping.linear=0.1"), kAnswer);
  ASSERT_TRUE(before.accepted) << before.reason;

  if (const auto why = net.set_loss(bpf_object(100)))
    GTEST_SKIP() << "the kernel refused the BPF classifier: " << *why;
  const auto t_cut = Clock::now();
  const ladder_msg_Command during_cmd = cmd::set("damping.linear=0.2");
  const std::uint64_t during = c->send(during_cmd);
  const auto idle = [&](Millis t) { c->wait_state([](const client::State&) { return false; }, t); };
  // After a second nothing is in flight any more; from then on nothing may cross.
  idle(Millis(1000));
  const std::uint64_t seq_cut = c->latest_state()->seq;
  idle(std::chrono::duration_cast<Millis>(t_cut + length - Clock::now()));
  EXPECT_EQ(c->latest_state()->seq, seq_cut) << "a state crossed the partition";
  EXPECT_FALSE(c->wait_ack(during, Millis(0)).has_value()) << "an ack crossed the partition";

  const auto t_heal = Clock::now();  // states flow as soon as side a's classifier is gone, before b's is
  net.clear_loss();
  const auto st = c->wait_state([&](const client::State& s) { return s.seq > seq_cut; }, kLossy);
  ASSERT_TRUE(st.has_value()) << "no state in " << kLossy.count() << " ms after the heal; server log:\n"
                              << server.log();
  const double state_ms = ms_since(t_heal);
  ASSERT_TRUE(c->wait_for_server(kLossy)) << "the client does not take the server for connected again";
  std::optional<client::Ack> during_ack = c->wait_ack(during, beyond_lease ? Millis(2000) : kLossy);
  const bool resent = beyond_lease && !during_ack;
  if (resent) {
    c->resend(during_cmd, during);
    during_ack = c->wait_ack(during, kLossy);
  }
  ASSERT_TRUE(during_ack.has_value()) << "the command sent during the partition was never answered";
  const double during_ms = ms_since(t_heal);
  EXPECT_TRUE(during_ack->accepted) << during_ack->reason;
  EXPECT_EQ(during_ack->command_seq, before.command_seq + 1);
  const auto t_after = Clock::now();
  const client::Ack after = c->call(cmd::set("damping.linear=0.3"), kLossy);
  const double after_ms = ms_since(t_after);
  EXPECT_TRUE(after.accepted) << after.reason;
  EXPECT_EQ(after.command_seq, before.command_seq + 2) << "the command sent during the partition was applied twice";
  if (!beyond_lease) {
    EXPECT_EQ(c->acks_received(), 3u);  // beyond the lease the lost command's original ack may come as well
  }
  EXPECT_FALSE(server.wait_exit(Millis(0)).has_value()) << "ladderd stopped:\n" << server.log();
  std::printf("[ figures  ] after a %.0f s partition: first state %.0f ms after the heal; the command sent during it "
              "%s at %.0f ms; a new command answered in %.1f ms\n",
              1e-3 * static_cast<double>(length.count()), state_ms, resent ? "lost, sent again and answered"
                                                                            : "answered",
              during_ms, after_ms);
}

TEST_F(NetFault, ClientResumesAfterAFiveSecondPartition) { partition_and_heal(Millis(5000)); }

TEST_F(NetFault, ClientResumesAfterAPartitionLongerThanTheLease) { partition_and_heal(Millis(15000)); }

// ---------------------------------------------------------------------------------------------------------------
// Duplicate command ids (a client that sends a command again after its ack was lost, or twice by mistake): one
// application, the original ack repeated. Loopback; a raw DDS writer, since the client library numbers commands.

class DuplicateSender {
 public:
  DuplicateSender(int domain, const std::string& sim_id)
      : sim_id_(sim_id),
        participant_((transport::use_default_config(transport::kDefaultCycloneConfig),
                      transport::make_participant(static_cast<dds_domainid_t>(domain)))),
        topics_(participant_),
        command_w_(participant_, topics_.command, transport::Profile::Command),
        ack_r_(participant_, topics_.ack, transport::Profile::CommandAck),
        event_r_(participant_, topics_.event, transport::Profile::Event) {}

  // The server's command reader and ack writer found (it holds our commands until it finds our readers).
  bool wait_matched(Millis timeout) {
    return until([&] { return command_w_.matched() > 0 && ack_r_.matched() > 0 && event_r_.matched() > 0; }, timeout);
  }
  void send(const std::string& client_id, std::uint64_t command_id, ladder_msg_Command c) {
    transport::copy_text(c.sim_id, sim_id_);
    transport::copy_text(c.client_id, client_id);
    c.command_id = command_id;
    command_w_.write(c);
  }
  // The acks of (client_id, command_id) once there are at least n.
  std::vector<client::Ack> acks(const std::string& client_id, std::uint64_t command_id, std::size_t n,
                                Millis timeout) {
    until([&] { return acks_[{client_id, command_id}].size() >= n; }, timeout);
    return acks_[{client_id, command_id}];
  }
  std::size_t total() {
    poll();
    std::size_t n = 0;
    for (const auto& [key, list] : acks_) n += list.size();
    return n;
  }

 private:
  void poll() {
    ack_r_.take([&](const ladder_msg_CommandAck& a, const dds_sample_info_t&) {
      if (transport::text_of(a.sim_id) != sim_id_) return;
      acks_[{transport::text_of(a.client_id), a.command_id}].push_back(
          {a.command_id, a.accepted, transport::text_of(a.reason), a.sim_time, a.step, a.command_seq});
    });
    event_r_.take([](const ladder_msg_Event&, const dds_sample_info_t&) {});
  }
  bool until(const std::function<bool()>& done, Millis timeout) {
    const auto deadline = Clock::now() + timeout;
    for (poll(); !done(); poll()) {
      if (Clock::now() > deadline) return false;
      std::this_thread::sleep_for(Millis(2));
    }
    return true;
  }

  std::string sim_id_;
  transport::Entity participant_;
  transport::Topics topics_;
  transport::Writer<ladder_msg_Command> command_w_;
  transport::Reader<ladder_msg_CommandAck> ack_r_;
  transport::Reader<ladder_msg_Event> event_r_;
  std::map<std::pair<std::string, std::uint64_t>, std::vector<client::Ack>> acks_;
};

void expect_same_ack(const client::Ack& repeat, const client::Ack& original) {
  EXPECT_EQ(repeat.accepted, original.accepted);
  EXPECT_EQ(repeat.reason, original.reason);
  EXPECT_EQ(repeat.step, original.step);
  EXPECT_EQ(repeat.sim_time, original.sim_time);
  EXPECT_EQ(repeat.command_seq, original.command_seq) << "the repeated command was applied again";
}

TEST_F(NetFault, ADuplicateCommandIdIsAnsweredWithTheOriginalAckAndNotAppliedAgain) {
  Process server(ladderd_args(), log_ + ".log");
  Client watcher(domain_, sim_id_, "watcher");
  ASSERT_TRUE(watcher.wait_for_server(kStart)) << "no ladderd; its log:\n" << server.log();
  DuplicateSender s(domain_, sim_id_);
  ASSERT_TRUE(s.wait_matched(kStart));
  const std::string me = "resender";

  // Sent again after its ack: the same ack, and the next command takes the very next place.
  s.send(me, 1, cmd::set("damping.linear=0.25"));
  const std::vector<client::Ack> first = s.acks(me, 1, 1, kAnswer);
  ASSERT_EQ(first.size(), 1u);
  ASSERT_TRUE(first[0].accepted) << first[0].reason;
  s.send(me, 1, cmd::set("damping.linear=0.25"));
  const std::vector<client::Ack> again = s.acks(me, 1, 2, kAnswer);
  ASSERT_EQ(again.size(), 2u) << "the repeated command got no answer";
  expect_same_ack(again[1], first[0]);
  s.send(me, 2, cmd::set("damping.linear=0.5"));
  const std::vector<client::Ack> next = s.acks(me, 2, 1, kAnswer);
  ASSERT_EQ(next.size(), 1u);
  EXPECT_EQ(next[0].command_seq, first[0].command_seq + 1) << "the repeated command was applied again";

  // Sent twice at once: the second copy arrives while the first is pending, and shares its answer (one ack), or
  // after it, and gets that answer again (two equal acks). Either way one application.
  s.send(me, 3, cmd::poke(5, 0.001, 0));
  s.send(me, 3, cmd::poke(5, 0.001, 0));
  const std::vector<client::Ack> copy = s.acks(me, 3, 1, kAnswer);
  ASSERT_GE(copy.size(), 1u) << "neither copy was answered";
  EXPECT_TRUE(copy[0].accepted) << copy[0].reason;
  EXPECT_EQ(copy[0].command_seq, next[0].command_seq + 1);

  // The same command id from another client is another command.
  s.send("another", 1, cmd::set("damping.linear=0.75"));
  const std::vector<client::Ack> other = s.acks("another", 1, 1, kAnswer);
  ASSERT_EQ(other.size(), 1u);
  EXPECT_TRUE(other[0].accepted) << other[0].reason;
  EXPECT_EQ(other[0].command_seq, copy[0].command_seq + 1) << "one of the two copies was applied too";

  // Every answer is in (acks of one writer arrive in order): the copies' answers are one or two, the same.
  const std::vector<client::Ack> copies = s.acks(me, 3, 1, Millis(0));
  ASSERT_LE(copies.size(), 2u) << "more answers than copies";
  if (copies.size() == 2) expect_same_ack(copies[1], copies[0]);
  EXPECT_EQ(s.total(), 4 + copies.size());
  const auto st = watcher.wait_state([&](const client::State& x) { return x.commands_applied >= other[0].command_seq; },
                                     kAnswer);
  ASSERT_TRUE(st.has_value());
  EXPECT_EQ(st->commands_applied, other[0].command_seq) << "more commands applied than sent once";
  // The server's own count: 6 received, 4 applied, 2 repeats.
  const auto stats = watcher.wait_stats([](const ladder_msg_Stats& x) { return x.commands_received >= 6; }, kStart);
  ASSERT_TRUE(stats.has_value());
  EXPECT_EQ(stats->commands_received, 6u);
  EXPECT_EQ(stats->commands_accepted, 4u);
  EXPECT_EQ(stats->commands_duplicate, 2u);
}

// ---------------------------------------------------------------------------------------------------------------
// The server restarted under a running client (loopback): after SIGTERM or SIGKILL a new ladderd with the same
// domain and sim id starts, and the same Client object gets its states and answers.

void restart_under_a_client(const std::vector<std::string>& args, const std::string& log, int sig) {
  std::optional<Process> server;
  server.emplace(args, log + "-1.log");
  Client c(std::stoi(args[2]), args[4], "long-running");
  ASSERT_TRUE(c.wait_for_server(kStart)) << "no ladderd; its log:\n" << server->log();
  // The first server ends paused, so that the next unpaused state can only be the new server's.
  const client::Ack paused = c.call(cmd::pause(), kAnswer);
  ASSERT_TRUE(paused.accepted) << paused.reason;
  ASSERT_TRUE(c.wait_state([](const client::State& s) { return s.paused; }, kAnswer).has_value());
  server->signal(sig);
  const auto status = server->wait_exit(kStart);
  ASSERT_TRUE(status.has_value()) << "ladderd did not stop";
  if (sig == SIGTERM) {
    EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << server->log();
  }

  const auto t_start = Clock::now();
  server.emplace(args, log + "-2.log");
  const auto st = c.wait_state([](const client::State& s) { return !s.paused; }, kLossy);
  ASSERT_TRUE(st.has_value()) << "no state from the new server; its log:\n" << server->log();
  const double state_ms = ms_since(t_start);
  ASSERT_TRUE(c.wait_for_server(kLossy)) << "the client does not take the new server for connected";
  const client::Ack ack = c.call(cmd::set("damping.linear=0.5"), kAnswer);
  const double ack_ms = ms_since(t_start);
  EXPECT_TRUE(ack.accepted) << ack.reason;
  EXPECT_EQ(ack.command_seq, 1u) << "not the new server's first command";
  EXPECT_EQ(c.acks_received(), 2u);
  std::printf("[ figures  ] after %s: the new server's first state %.0f ms after its start, a command answered at "
              "%.0f ms\n",
              sig == SIGTERM ? "SIGTERM" : "SIGKILL", state_ms, ack_ms);
}

TEST_F(NetFault, AClientFindsTheServerAgainAfterSigterm) {
  restart_under_a_client(ladderd_args(), log_, SIGTERM);
}

TEST_F(NetFault, AClientFindsTheServerAgainAfterSigkill) {
  restart_under_a_client(ladderd_args(), log_, SIGKILL);
}

}  // namespace
}  // namespace ladder::test
