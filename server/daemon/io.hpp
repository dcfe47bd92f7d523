// ladderd's I/O thread: DDS in and out. It takes the commands from ladder/Command, holds a new sender's until this
// server can answer it (its sender guard), refuses what a sender may not send (intake.hpp), queues the rest for the
// physics thread, and writes what the physics thread hands over: SceneInfo, State, CommandAck, Event, Stats, the
// session log and the tick log.
#pragma once

#include "daemon/outbox.hpp"
#include "daemon/recorder.hpp"
#include "daemon/tick_log.hpp"
#include "transport/dds.hpp"
#include "transport/lcm_log.hpp"
#include "transport/topics.hpp"

#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

namespace ladder::daemon {

class Io {
 public:
  Io(Shared& shared, transport::LogWriter* log, TickLog& tick_log)
      : sh_(shared),
        log_(log),
        tick_log_(tick_log),
        participant_(transport::make_participant(static_cast<dds_domainid_t>(shared.config.domain))),
        topics_(participant_),
        scene_w_(participant_, topics_.scene_info, transport::Profile::SceneInfo),
        state_w_(participant_, topics_.state, transport::Profile::State),
        ack_w_(participant_, topics_.ack, transport::Profile::CommandAck),
        event_w_(participant_, topics_.event, transport::Profile::Event),
        stats_w_(participant_, topics_.stats, transport::Profile::Stats),
        command_r_(participant_, topics_.command, transport::Profile::Command),
        waiter_(participant_) {
    waiter_.attach(command_r_.entity());
    sh_.waiter = &waiter_;
    if (log_) recorder_.emplace(*log_, shared.config.sim_id);
  }

  // Until the physics thread has finished and everything it handed over is written.
  void run();

 private:
  // A client: the DDS participant of one or more command writers (one client process; every writer it makes shares
  // its limits, so that a process cannot multiply them by making writers). Whether this server can answer it yet
  // (its ack and event writers have found a reader in that participant), and its commands meanwhile. Also what it may
  // send (its rate), what it sent lately (repeats are answered, not applied) and what this server could not answer
  // it, for the log.
  struct Sender {
    Sender(SenderKey k, const ServerConfig& c, Clock::time_point now)
        : key(k), first_seen(now), commands(c.rate, c.burst, now), refusals(c.rate, c.burst, now), next_report(now) {}
    SenderKey key;                          // its commands' Incoming::sender
    std::string client;                     // the client id of its first command, for the log
    std::optional<dds_guid_t> participant;  // none: the writer had left when its first command was read
    Clock::time_point first_seen, next_check;
    std::optional<Clock::time_point> ack_reader_found;  // when this server's ack writer found its reader
    bool ready = false;
    std::deque<Incoming> held;  // in the order they came
    Bucket commands, refusals;  // commands.rate and commands.burst, each
    RecentCommands recent;
    std::uint64_t rate_limited = 0, unanswered = 0;  // since the last report
    Clock::time_point next_report;
  };

  void take_commands();
  void admit(Sender& s, const ladder_msg_Command& c, Clock::time_point now, std::vector<Incoming>& ready);
  Sender& sender(dds_instance_handle_t writer, const ladder_msg_Command& c, Clock::time_point now);
  void check(Sender& s, Clock::time_point now);
  void release_answerable(std::vector<Incoming>& ready);
  void queue_for_physics(std::vector<Incoming>& ready);
  void refuse_for_rate(const Incoming& in, const std::string& reason);
  void report(Sender& s, Clock::time_point now);
  void forget_departed_senders();
  void refuse_leftovers();
  void write_outbox();
  void write_scene(const SceneOut& s);
  void write_state();
  void refuse(const ladder_msg_Command& c, const std::string& reason);
  void answer(const ladder_msg_Command& c, const Answer& a);
  void remember(const AckOut& a);
  // Counts a failed write (a write that Cyclone could not take: it does not end the server) and logs it, once a
  // topic at first and then at most every 10 s.
  void written(dds_return_t rc, const char* topic);

  Shared& sh_;
  transport::LogWriter* log_;  // null when not recording
  std::optional<Recorder> recorder_;  // the same
  TickLog& tick_log_;
  transport::Entity participant_;  // first: destroyed last
  transport::Topics topics_;
  transport::Writer<ladder_msg_SceneInfo> scene_w_;
  transport::Writer<ladder_msg_State> state_w_;
  transport::Writer<ladder_msg_CommandAck> ack_w_;
  transport::Writer<ladder_msg_Event> event_w_;
  transport::Writer<ladder_msg_Stats> stats_w_;
  transport::Reader<ladder_msg_Command> command_r_;
  transport::Waiter waiter_;
  std::uint64_t state_seq_ = 0, event_seq_ = 0;
  std::uint32_t generation_ = 0;
  // The latest SceneInfo is written again every kSceneRepeat while nothing changes it. A reader's history is shared
  // by every writer of the sim id (transport/dds.hpp, Side): a client whose one transient-local copy was pushed out
  // by another participant's SceneInfos (a forger's, without DDS Security) has the server's again within a second.
  static constexpr auto kSceneRepeat = std::chrono::seconds(1);
  std::optional<SceneOut> scene_;
  Clock::time_point scene_written_{};
  Outbox out_;
  std::unordered_map<SenderKey, Sender> senders_;
  std::unordered_map<dds_instance_handle_t, SenderKey> writer_sender_;  // each command writer's client
  std::map<std::array<std::uint8_t, 16>, SenderKey> participant_sender_;  // each client participant's, by GUID
  SenderKey next_sender_ = 1;
  std::vector<SenderKey> waiting_;  // the senders not ready yet
  std::size_t forget_above_ = 256;  // writers known before those that have left (and their clients) are forgotten
  Clock::time_point next_forget_{};  // and once a second
  // Commands held for clients whose readers are not found yet, all clients together: at most kHeldQueues times
  // commands.queue (16 000 by default, about 19 MB), so that many participants that never read cannot each fill a
  // queue (a client's own is commands.queue).
  static constexpr std::size_t kHeldQueues = 16;
  std::size_t held_ = 0;
  LogBudget slow_readers_log_{1, Clock::now()};  // "its ack reader not found": one line a second
  std::unordered_map<std::string, Clock::time_point> write_failure_logged_;  // by topic
};

}  // namespace ladder::daemon
