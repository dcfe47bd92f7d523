// What ladderd does before serving: logging, the first scene, signal handling.
#pragma once

#include "daemon/config.hpp"
#include "scene/scene.hpp"

#include <atomic>
#include <string>
#include <vector>

namespace ladder::daemon {

// spdlog to standard error and, when config.log_file is set, to that file too. Throws std::runtime_error when the
// file cannot be opened.
void setup_logging(const DaemonConfig& config);

// The scene file named in the configuration, or the built-in classic toy at rest (its timeline removed), with
// the --set overrides. Throws scene::SceneError.
scene::Scene first_scene(const DaemonConfig& config, const std::vector<std::string>& overrides);

// SIGINT and SIGTERM set `stop` (and are logged by log_stop_reason once the server has stopped).
void catch_stop_signals(std::atomic<bool>& stop);
void log_stop_reason();

}  // namespace ladder::daemon
