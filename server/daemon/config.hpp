// ladderd's configuration file (config/ladderd.toml): every key optional, checked with file:line:column errors.
#pragma once

#include "daemon/limits.hpp"
#include "transport/security.hpp"

#include <algorithm>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <utility>

namespace ladder::daemon {

// The real-time server's settings (ladderd.toml [server] and [commands], and the command line).
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
  // [s] the longest a new client's commands wait for this server to find its ack reader (an answer written before
  // then would reach no one; its event reader is waited for 0.1 s more at most, Io::check); 0 = not at all.
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

struct DaemonConfig {
  ServerConfig server;
  std::string scene;  // scene file; empty = the built-in classic toy at rest
  std::string log_level = "info";
  std::string log_file;  // empty = standard error only
  std::string security;  // DDS Security: the server's identity folder (scripts/make-pki); empty = none
  // Whether server.publish_rate was named (in the file or on the command line). When it was not, the default of 60
  // states a second is lowered to the physics rate if that is lower (`ladderd --rate 30` publishes 30 a second).
  bool publish_rate_given = false;
  // That rule, applied after the file and after the command line, each of which may set the physics rate.
  void default_publish_rate() {
    if (!publish_rate_given) server.rates.publish = std::min(Rates{}.publish, server.rates.physics);
  }
};

class ConfigError : public std::runtime_error {
 public:
  explicit ConfigError(const std::string& what, std::string key = {}) : std::runtime_error(what), key_(std::move(key)) {}
  const std::string& key() const { return key_; }  // the offending key, when one is to blame

 private:
  std::string key_;
};

// Reads `path` over the defaults in `config`. Relative paths in the file are taken from the file's folder.
// Throws ConfigError "FILE:LINE:COLUMN: message" (or "FILE: cannot open ...").
void load_config(const std::string& path, DaemonConfig& config);

// The checks a value gets whether it comes from the file or the command line: ConfigError("KEY ...why", KEY).
void check_config(const DaemonConfig& config);

// The checked server identity of the folder `dir` (server.security, --security); throws ConfigError with what is wrong.
transport::Identity server_identity(const std::string& dir);

}  // namespace ladder::daemon
