// The fixture of the integration tests of ladderd: a real server process on a domain and sim id of the test's own,
// and the same client library ladderctl uses.
#pragma once

#include "naming.hpp"
#include "client.hpp"
#include "process.hpp"

#include <gtest/gtest.h>

#include <unistd.h>

#include <cctype>
#include <chrono>
#include <cstring>
#include <fstream>
#include <functional>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace ladder::test {

using client::Client;
using client::Millis;
namespace cmd = client::cmd;
using Clock = std::chrono::steady_clock;

inline constexpr Millis kStart{15000};  // generous: CI runs two tests at once on two cores
inline constexpr Millis kAnswer{5000};

class Server : public ::testing::Test {
 protected:
  void start(std::vector<std::string> extra = {}) {
    const std::string name = test_name();
    sim_id_ = sim_id_for(name);
    domain_ = domain_for(name);
    log_path_ = std::string(LADDER_BINARY_DIR) + "/tests/" + name + ".log";
    std::vector<std::string> args{std::string(LADDER_BINARY_DIR) + "/server/ladderd", "--domain",
                                  std::to_string(domain_), "--sim-id", sim_id_, "--log-level", "debug"};
    args.insert(args.end(), extra.begin(), extra.end());
    server_.emplace(args, log_path_);
    client_.emplace(domain_, sim_id_, "test");
    ASSERT_TRUE(client_->wait_for_server(kStart)) << "no ladderd on domain " << domain_ << "; its log:\n"
                                                  << server_->log();
  }

  Client& c() { return *client_; }

  // The arguments that start the server with a configuration file of this text.
  std::vector<std::string> with_config(const std::string& text) {
    const std::string config = std::string(LADDER_BINARY_DIR) + "/tests/" + test_name() + ".toml";
    std::ofstream(config) << text;
    return {"--config", config};
  }

  // Starts the server with commands.per_tick = 1 (and `extra`), sends a burst of 20 commands and checks that each is
  // accepted at a step of its own, in the order sent.
  void burst_with_one_command_per_tick(std::vector<std::string> extra = {});

  // Pauses and returns the paused state.
  client::State pause() {
    const client::Ack a = c().call(cmd::pause(), kAnswer);
    EXPECT_TRUE(a.accepted) << a.reason;
    auto s = c().wait_state([](const client::State& st) { return st.paused; }, kAnswer);
    EXPECT_TRUE(s.has_value());
    return s.value_or(client::State{});
  }

  // Sends c, expects a refusal whose reason contains `why`, and checks that the next state equals `before`.
  client::Ack expect_refusal(const ladder_msg_Command& command, const std::string& why) {
    const client::Ack a = c().call(command, kAnswer);
    EXPECT_FALSE(a.accepted) << "accepted, but expected a refusal containing '" << why << "'";
    EXPECT_NE(a.reason.find(why), std::string::npos) << "reason: " << a.reason;
    return a;
  }
  // The state after the command's turn (a refused command gets a fresh state too) must equal `before`.
  void expect_refused(const ladder_msg_Command& command, const std::string& why, const client::State& before) {
    const client::Ack a = expect_refusal(command, why);
    const auto after = c().wait_state([&](const client::State& st) { return st.commands_applied >= a.command_seq; },
                                      kAnswer);
    ASSERT_TRUE(after.has_value());
    EXPECT_EQ(after->step, before.step);
    EXPECT_EQ(after->sim_time, before.sim_time);
    EXPECT_EQ(after->generation, before.generation);
    ASSERT_EQ(after->blocks.size(), before.blocks.size());
    EXPECT_EQ(0, std::memcmp(after->blocks.data(), before.blocks.data(), before.blocks.size() * sizeof(client::Pose)))
        << "a refused command changed the blocks";
    ASSERT_EQ(after->hinges.size(), before.hinges.size());
    for (std::size_t k = 0; k < before.hinges.size(); ++k) {
      EXPECT_EQ(after->hinges[k].status, before.hinges[k].status) << "hinge " << k;
      EXPECT_EQ(after->hinges[k].corner, before.hinges[k].corner) << "hinge " << k;
    }
    EXPECT_EQ(after->grips.size(), before.grips.size());
  }

  // Returns the state that shows the command's effect.
  client::State expect_accepted(const ladder_msg_Command& command) {
    const client::Ack a = c().call(command, kAnswer);
    EXPECT_TRUE(a.accepted) << a.reason;
    const auto s = c().wait_state([&](const client::State& st) { return st.commands_applied >= a.command_seq; },
                                  kAnswer);
    EXPECT_TRUE(s.has_value()) << "no state after the command";
    return s.value_or(client::State{});
  }

  std::string sim_id_, log_path_;
  int domain_ = 0;
  std::optional<Process> server_;
  std::optional<Client> client_;
};

// A client made by hand, with a command writer only: its ack and event readers come when the test says.
struct BareSender {
  BareSender(int domain, std::string id)
      : sim_id(std::move(id)),
        participant(transport::make_participant(static_cast<dds_domainid_t>(domain))),
        topics(participant),
        command_w(participant, topics.command, transport::Profile::Command) {
    const auto deadline = Clock::now() + kAnswer;
    while (command_w.matched() == 0 && Clock::now() < deadline) std::this_thread::sleep_for(Millis(5));
  }
  void pause(std::uint64_t id) {
    ladder_msg_Command c = cmd::pause();
    transport::copy_text(c.sim_id, sim_id);
    transport::copy_text(c.client_id, "bare");
    c.command_id = id;
    command_w.write(c);
  }
  void add_readers(bool events = true) {
    ack_r.emplace(participant, topics.ack, transport::Profile::CommandAck);
    if (events) event_r.emplace(participant, topics.event, transport::Profile::Event);
  }
  // The ids of the acks that reach it within kAnswer, once one has.
  std::vector<std::uint64_t> acked() {
    std::vector<std::uint64_t> ids;
    const auto deadline = Clock::now() + kAnswer;
    while (ids.empty() && Clock::now() < deadline) {
      ack_r->take([&](const ladder_msg_CommandAck& a, const dds_sample_info_t&) {
        if (std::string(a.client_id) == "bare" && a.accepted) ids.push_back(a.command_id);
      });
      std::this_thread::sleep_for(Millis(5));
    }
    return ids;
  }

  std::string sim_id;
  transport::Entity participant;
  transport::Topics topics;
  transport::Writer<ladder_msg_Command> command_w;
  std::optional<transport::Reader<ladder_msg_CommandAck>> ack_r;
  std::optional<transport::Reader<ladder_msg_Event>> event_r;
};

}  // namespace ladder::test
