// What ladderd does before serving: logging, the first scene, signal handling.
#pragma once

#include "daemon/config.hpp"
#include "daemon/session.hpp"
#include "scene/scene.hpp"

#include <atomic>
#include <memory>
#include <string>
#include <vector>

namespace ladder::daemon {

// spdlog to standard error and, when config.log_file is set, to that file too. Throws std::runtime_error when the
// file cannot be opened.
void setup_logging(const DaemonConfig& config);

// The scene file named in the configuration, or the built-in classic toy at rest (its timeline removed), with
// the --set overrides. Throws scene::SceneError.
// Where `load NAME` and `--scene NAME` look: PREFIX/`installed` when this ladderd runs from PREFIX/bin and that
// folder is there (an installed ladderd, run from anywhere), else `source_tree` (a build tree).
std::string default_scenes_dir(const std::string& installed, const std::string& source_tree);
// --scene's file: the path itself if it is a file, else the scene of that name in scenes_dir; throws naming both
// and listing the scenes there.
std::string find_scene(const std::string& scene, const std::string& scenes_dir);
scene::Scene first_scene(const DaemonConfig& config, const std::vector<std::string>& overrides);
std::unique_ptr<Session> first_session(const DaemonConfig& config, const std::vector<std::string>& overrides);

// A session re-run from a log up to its last checkpoint (exactly the state recorded there), paused, to serve from.
// Throws std::runtime_error when the log cannot be read or does not re-run identically.
std::unique_ptr<Session> resumed_session(const std::string& log, const DaemonConfig& config);

// ladderd --offline --resimulate LOG: exit 0 identical, 1 a difference (named), 2 an unreadable log.
int run_resimulation(const std::string& log, bool progress);

// SIGINT and SIGTERM set `stop` (and are logged by log_stop_reason once the server has stopped).
void catch_stop_signals(std::atomic<bool>& stop);
void log_stop_reason();

}  // namespace ladder::daemon
