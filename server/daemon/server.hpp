// ladderd's real-time server: a physics thread that owns the session and keeps time, and an I/O thread that
// takes commands from DDS and publishes what the physics thread hands it. The physics thread never touches DDS,
// so a slow subscriber or a burst of commands cannot delay a step.
#pragma once

#include "daemon/session.hpp"

#include <atomic>
#include <cstddef>
#include <memory>
#include <stdexcept>
#include <string>

namespace ladder::daemon {

struct ServerConfig {
  std::string sim_id = "ladder";
  int domain = 0;
  std::string scenes_dir;         // where load_scene looks
  Rates rates;
  double stats_rate = 1.0;        // Stats per wall second
  Limits limits;
  // Per sender (one client's command writer): commands waiting for the physics thread, beyond which they are
  // refused; and a token bucket of `rate` commands a second, `burst` at once. A sender over its rate is refused,
  // at most `rate` refusals a second as well; the commands beyond those go unanswered, counted and logged
  // (docs/server.md, "Intake"). `burst` stays at most half transport::kAckDepth, so that a client's answers and
  // refusals all fit in the ack writer's history.
  std::size_t queue = 1000;
  double rate = 1000;
  double burst = 1000;
  std::size_t per_tick = 100;     // commands applied per tick at most, taken from the senders in turn
  // [s] the longest a new client's commands wait for this server to find its ack and event readers (an answer
  // written before then would reach no one); 0 = not at all.
  double reader_wait = 2.0;
  std::string record;             // LCM session log to write; empty = none
  double checkpoint_every = 1.0;  // [s of sim time] between checkpoints in the log
  // SCHED_FIFO priority of the physics thread, 1 to 99; 0 = the normal scheduler. Needs CAP_SYS_NICE (or root): when
  // refused, the server logs a warning and runs with normal scheduling.
  int realtime_priority = 0;
  // The physics thread busy-waits the last spin_us microseconds before each tick's deadline instead of sleeping
  // through them, so that a tick starts on time rather than when the timer wakes the thread (tens of microseconds
  // late); it costs that much CPU per tick. 0 = sleep all the way.
  int spin_us = 0;
  // Writes one line per tick of the real-time loop (when it started, how late, its steps, commands and publish) to
  // this file; empty = none. The I/O thread writes it (docs/server.md, "The tick log").
  std::string tick_log;
};

// An output file (--record, --tick-log) cannot be created: bad input, before anything starts.
class OutputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Runs until `stop` becomes true (a signal handler sets it). Returns the process exit code. Throws
// transport::DdsError when DDS cannot be set up.
int run_server(const ServerConfig& config, const scene::Scene& scene, const std::atomic<bool>& stop);
// The same, going on from a session made elsewhere (ladderd --resume); it takes the config's rules.
int run_server(const ServerConfig& config, std::unique_ptr<Session> session, const std::atomic<bool>& stop);

}  // namespace ladder::daemon
