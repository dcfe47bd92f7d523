// ladderd's real-time server: a physics thread that owns the session and keeps time, and an I/O thread that
// takes commands from DDS and publishes what the physics thread hands it. The physics thread never touches DDS,
// so a slow subscriber or a burst of commands cannot delay a step.
#pragma once

#include "daemon/config.hpp"
#include "daemon/session.hpp"

#include <atomic>
#include <chrono>
#include <memory>
#include <stdexcept>
#include <string>

namespace ladder::daemon {

// An output file (--record, --tick-log) cannot be created: bad input, before anything starts.
class OutputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
// Another ladder already answers to the sim id on the domain (run_server looks for kSimIdCheck first): bad input,
// before anything is published.
class SimIdTaken : public OutputError {
 public:
  using OutputError::OutputError;
};
inline constexpr std::chrono::milliseconds kSimIdCheck{500};

// Runs until `stop` becomes true (a signal handler sets it). Returns the process exit code. Throws
// transport::DdsError when DDS cannot be set up.
int run_server(const ServerConfig& config, const scene::Scene& scene, const std::atomic<bool>& stop);
// The same, going on from a session made elsewhere (ladderd --resume); it takes the config's rules.
int run_server(const ServerConfig& config, std::unique_ptr<Session> session, const std::atomic<bool>& stop);

}  // namespace ladder::daemon
