// What ladderd's two threads share: the inbox of commands for the physics thread, the outbox of what it hands the
// I/O thread to publish and record (besides the latest state, which goes through a Latest buffer), and counters.
// The physics thread only ever holds the locks for a swap or a push.
#pragma once

#include "daemon/config.hpp"
#include "daemon/handoff.hpp"
#include "daemon/intake.hpp"
#include "daemon/notify.hpp"
#include "daemon/session.hpp"
#include "ladder.h"  // generated from msgs/ladder.idl
#include "transport/dds.hpp"
#include "transport/version.hpp"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <cstring>
#include <mutex>
#include <string>
#include <vector>

namespace ladder::daemon {

using Clock = std::chrono::steady_clock;
inline double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// What SceneInfo, the session log and the tick log say made them.
inline const std::string kServerVersion = std::string("ladderd ") + ladder::kVersion;

// An event of the simulation (or a refused timeline command, or a failed step), for Event and the log.
struct EventOut {
  double t = 0;
  std::string kind, detail;
  int hinge = 0;
  double energy_removed = 0;
};
// A scene as started, or its live settings and rates changed: for SceneInfo and the log.
struct SceneOut {
  std::uint32_t generation = 0;
  std::string name, description, top, options;
  std::string text, source;              // what the scene was made from, for the log
  std::vector<std::string> overrides;
  bool timeline_dropped = false;
  int blocks = 0;
  double length = 0, thickness = 0, inset = 0, dt = 0;
  std::vector<double> masses;
  Rates rates;
};
// A command as the simulation took it, for the log.
struct CommandOut {
  ladder_msg_Command command;
  std::uint32_t generation = 0;
  std::uint64_t step = 0, seq = 0;
  bool accepted = false;
  std::string reason;
};
// A hash of the complete dynamic state, for the log (a re-run compares it).
struct CheckpointOut {
  std::uint32_t generation = 0;
  std::uint64_t step = 0, commands_applied = 0, hash = 0;
  double t = 0;
};
// One tick of the real-time loop, for the tick log (ladderd --tick-log). Times on the steady clock, in ns.
struct TickRecord {
  std::uint64_t tick = 0;
  std::int64_t start_ns = 0, late_ns = 0, step_ns = 0;
  std::uint32_t steps = 0, commands = 0;
  bool published = false;
};
// An answer of the physics thread, for the sender whose record keeps it (to answer a repeated command again).
struct AckOut {
  ladder_msg_CommandAck ack;
  SenderKey sender = 0;
};
struct Outbox {
  std::vector<AckOut> acks;
  std::vector<CommandOut> commands;       // only when recording
  std::vector<CheckpointOut> checkpoints;  // only when recording
  std::vector<CheckpointOut> failures;     // only when recording: where a step failed (the session paused)
  std::vector<CheckpointOut> non_finite;   // the same: where the state was found non-finite (the session paused)
  std::vector<EventOut> events;
  std::vector<ladder_msg_Stats> stats;
  std::vector<SceneOut> scenes;
  std::vector<TickRecord> ticks;  // only with a tick log

  // Empties every list and keeps their capacity (the two threads swap one Outbox to and fro).
  void clear() {
    acks.clear(), commands.clear(), checkpoints.clear(), failures.clear(), non_finite.clear();
    events.clear(), stats.clear(), scenes.clear(), ticks.clear();
  }
};

// Shared between the two threads.
struct Shared {
  explicit Shared(const ServerConfig& c) : config(c) {}
  const ServerConfig& config;
  std::mutex inbox_mutex;
  std::condition_variable inbox_cv;  // a command came: wakes the physics thread between ticks
  Inbox inbox;
  std::mutex outbox_mutex;
  Outbox outbox;
  Latest<StateFrame> state;
  std::atomic<std::uint64_t> received{0}, rate_limited{0}, duplicates{0}, unanswered{0}, states_published{0},
      states_dropped{0}, events_published{0}, write_failures{0};
  std::atomic<bool> physics_done{false};
  std::atomic<bool> abort{false};  // the I/O thread failed: the physics thread stops too
  const transport::Waiter* waiter = nullptr;  // to wake the I/O thread
  const Notifier* notifier = nullptr;          // systemd's, when it started us
  std::atomic<Clock::rep> io_alive{0};         // when the I/O thread last went round its loop
};

// The answer to command c: addressed to its client, with the outcome; the caller adds when it took effect.
inline ladder_msg_CommandAck ack_for(const ladder_msg_Command& c, const Outcome& r) {
  ladder_msg_CommandAck a{};
  std::memcpy(a.sim_id, c.sim_id, sizeof a.sim_id);
  std::memcpy(a.client_id, c.client_id, sizeof a.client_id);
  a.command_id = c.command_id;
  a.accepted = r.accepted;
  // A reason may quote a client's text (a scene name, a setting): made printable here too, for clients of any make
  // that print it as it comes. A backslash is kept, so that our clients' own printable() does not double it.
  transport::copy_text(a.reason, printable(r.reason, false));
  return a;
}

}  // namespace ladder::daemon
