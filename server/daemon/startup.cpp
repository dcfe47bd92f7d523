#include "daemon/startup.hpp"

#include "daemon/builtin_scene.hpp"
#include "daemon/fatal.hpp"
#include "daemon/frames.hpp"
#include "daemon/resimulate.hpp"

#include <spdlog/sinks/basic_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <memory>

namespace ladder::daemon {

namespace {
std::atomic<bool>* g_stop = nullptr;
volatile std::sig_atomic_t g_signal = 0;

extern "C" void on_signal(int sig) {
  g_signal = sig;
  if (g_stop) g_stop->store(true);  // lock-free atomic: async-signal-safe
}

// Whether standard error is the journal's stream: systemd sets JOURNAL_STREAM to its device and inode.
bool to_journal() {
  const char* stream = std::getenv("JOURNAL_STREAM");
  struct stat st {};
  if (stream == nullptr || fstat(STDERR_FILENO, &st) != 0) return false;
  return std::string(stream) == std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino);
}
}  // namespace

void setup_logging(const DaemonConfig& config) {
  std::vector<spdlog::sink_ptr> sinks{std::make_shared<spdlog::sinks::stderr_color_sink_mt>()};
  if (!config.log_file.empty()) {
    // spdlog's file sink makes the missing folders on its way: a typo in the path would log to a new tree nobody
    // looks at. The folder must exist.
    namespace fs = std::filesystem;
    const fs::path parent = fs::path(config.log_file).parent_path();
    std::error_code ec;
    if (!parent.empty() && !fs::is_directory(parent, ec))
      throw std::runtime_error("cannot open the log file '" + config.log_file + "': its folder '" + parent.string() +
                               "' does not exist");
    try {
      sinks.push_back(std::make_shared<spdlog::sinks::basic_file_sink_mt>(config.log_file));
    } catch (const spdlog::spdlog_ex& e) {
      throw std::runtime_error("cannot open the log file '" + config.log_file + "': " + e.what());
    }
  }
  auto logger = std::make_shared<spdlog::logger>("ladderd", sinks.begin(), sinks.end());
  spdlog::set_default_logger(logger);
  spdlog::set_level(spdlog::level::from_str(config.log_level));
  // Under systemd the journal stamps each line itself: no second timestamp, no colour codes.
  spdlog::set_pattern(to_journal() ? "[%l] %v" : "%Y-%m-%d %H:%M:%S.%e %^[%l]%$ %v");
  spdlog::flush_on(spdlog::level::info);
}

std::string default_scenes_dir(const std::string& installed, const std::string& source_tree) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const fs::path beside = exe.parent_path().parent_path() / installed;
    if (fs::is_directory(beside, ec)) return beside.lexically_normal().string();
  }
  return source_tree;
}

std::string find_scene(const std::string& scene, const std::string& scenes_dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::is_regular_file(scene, ec)) return scene;
  const auto not_a_folder = [&] {
    if (fs::is_directory(scene, ec))
      throw std::runtime_error("--scene " + scene + ": a folder, not a scene file (a scene is a .toml file)");
    if (fs::exists(scene, ec))  // (/dev/null, a pipe: read once, or never ending)
      throw std::runtime_error("--scene " + scene + ": not a regular file (a scene is a .toml file)");
  };
  if (scene.find('/') != std::string::npos || scene.starts_with(".")) {
    not_a_folder();
    throw std::runtime_error("--scene " + scene + ": no such file");
  }
  const fs::path named = fs::path(scenes_dir) / (scene.ends_with(".toml") ? scene : scene + ".toml");
  if (fs::is_regular_file(named, ec)) return named.string();
  not_a_folder();
  const std::string available = scene_names(scenes_dir);
  throw std::runtime_error("--scene " + scene + ": no such file, and no scene of that name in " + scenes_dir +
                           " (" + (available.empty() ? "none there" : "there: " + available) + ")");
}

scene::Scene first_scene(const DaemonConfig& config, const std::vector<std::string>& overrides) {
  if (!config.scene.empty()) return scene::load_scene(config.scene, overrides);
  // At rest: the user tips it.
  scene::Scene s = scene::remake_scene(kBuiltinSceneToml, "built-in classic scene", overrides, true);
  s.name = "classic (at rest)";
  return s;
}

std::unique_ptr<Session> first_session(const DaemonConfig& config, const std::vector<std::string>& overrides) {
  const ServerConfig& s = config.server;
  return std::make_unique<Session>(first_scene(config, overrides), s.scenes_dir, s.limits, s.rates);
}

std::unique_ptr<Session> resumed_session(const std::string& path, const DaemonConfig& config) {
  if (!config.server.record.empty())
    throw std::runtime_error("--record with --resume is not supported: a new log would start mid-session; "
                             "resume without --record, or record a new session");
  const SessionLog log = read_session_log(path);
  // A cut-off end is what a killed server leaves, and its last command acknowledged is before it; events after
  // damage in the middle would be dropped by a resume from before it (commands acknowledged among them, perhaps).
  if (log.damage_after > 0)
    throw std::runtime_error(path + ": " + log.damage + "; a resume from before the damage would drop them: repair "
                             "the log, or resume from a copy cut at the damage if what follows may be lost");
  if (!log.damage.empty())
    spdlog::warn("{}: {}; resuming from what came before", printable(path), printable(log.damage));
  if (log.checkpoints.empty()) throw std::runtime_error(path + ": no checkpoint to resume from");
  // To the end of what was recorded: the last checkpoint, the states after it (checked), and every command after
  // it, so that each command the killed server acknowledged (logged before its ack went out) is applied again.
  std::unique_ptr<Session> session;
  Resimulation r;
  try {
    r = resimulate(log, session, Until::kLastCommand);
  } catch (const std::runtime_error& e) {  // a command the re-run refuses, a scene it lacks
    throw std::runtime_error(path + ": " + e.what());
  }
  if (!r.identical) throw std::runtime_error(path + ": the re-run differs from the log: " + r.difference);
  // A server publishes no State that holds a non-finite number, and a client finds a server by its State: one
  // resumed in such a state could be reached by nobody, not even to reset it.
  if (const std::string bad = non_finite_in(*session); !bad.empty())
    throw std::runtime_error(path + ": the session ends in a state that holds a non-finite number (" + bad +
                             "), which no server can publish; start the scene anew");
  session->pause();
  // The step commands still owed where the log ends go on, but at most one step command's worth of this server's
  // (commands.max_step_count): the re-run took them within the widest limits any server allows (1e9 steps), and a
  // resumed server runs them flat out, as a live step command.
  if (const std::uint64_t most = config.server.limits.max_step_count; session->pending_steps() > most) {
    spdlog::warn("{}: {} ordered steps were still to be taken where the log ends; this server takes at most {} "
                 "(commands.max_step_count), and drops the rest",
                 printable(path), session->pending_steps(), most);
    session->limit_pending_steps(most);
  }
  session->sim().take_events();  // they happened before; the log has them
  session->sim().take_refusals();
  const std::uint64_t refused = std::min(r.refused, r.last_command_seq);
  session->set_taken_before({r.last_command_seq - refused, refused});
  spdlog::info("resumed from {} at t = {:.6f} s (generation {}, step {}, {} commands taken) after replaying {} "
               "commands past the last checkpoint; {} states and {} checkpoints checked on the way; paused",
               printable(path), session->sim().time(), session->generation(), session->sim().steps(), r.last_command_seq,
               r.commands_after_checkpoint, r.states, r.checkpoints);
  return session;
}

int run_resimulation(const std::string& path, bool progress) {
  SessionLog log;
  try {
    log = read_session_log(path);
  } catch (const std::exception& e) {
    return exit_with(2, e.what());
  }
  if (!log.damage.empty())
    spdlog::warn("{}: {}; re-running what came before", printable(path), printable(log.damage));
  spdlog::info("{}: {} scene(s), {} commands, {} states, {} checkpoints, {} events{}", printable(path),
               log.scenes.size(), log.commands.size(), log.states.size(), log.checkpoints.size(), log.events,
               log.failures.empty() ? std::string() : fmt::format(", {} failures", log.failures.size()));
  std::unique_ptr<Session> session;
  Resimulation r;
  try {
    // To the last command, as --resume goes: a command after the last state that the re-run refuses (or cannot
    // reach) is a log that --resume refuses, and so a difference here too.
    r = resimulate(log, session, Until::kLastCommand, [&](std::uint64_t steps, std::uint64_t states) {
      if (progress) spdlog::info("... {} steps, {} states identical so far", steps, states);
    });
  } catch (const std::exception& e) {
    return exit_with(2, path + ": " + e.what());
  }
  if (!r.identical) {
    return exit_with(1, fmt::format("differs: {} ({} states and {} checkpoints identical before it)", r.difference,
                                    r.states, r.checkpoints));
  }
  if (log.damage_after > 0)
    return exit_with(1, fmt::format("{} states and {} checkpoints identical up to the damage, but the log is damaged "
                                    "in the middle: what follows it was not re-run ({})",
                                    r.states, r.checkpoints, printable(log.damage)));
  spdlog::info("identical to the last bit: {} states and {} checkpoints compared over {} steps ({} commands{}), up "
               "to t = {:.6f} s",
               r.states, r.checkpoints, r.steps, r.commands,
               r.failures ? fmt::format("; {} failed step{} failed alike", r.failures, r.failures == 1 ? "" : "s")
                          : std::string(),
               r.sim_time);
  return 0;
}

void catch_stop_signals(std::atomic<bool>& stop) {
  static_assert(std::atomic<bool>::is_always_lock_free);
  g_stop = &stop;
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  // A hang-up (the terminal or SSH session that started the server closed) stops it as cleanly as SIGTERM, with
  // its last log lines and the session log closed, instead of the default's sudden death.
  sigaction(SIGHUP, &sa, nullptr);
  // A closed pipe on standard error (ladderd 2>&1 | head) makes a write fail with EPIPE instead of killing it.
  signal(SIGPIPE, SIG_IGN);
}

void log_stop_reason() {
  const int sig = g_signal;
  if (sig == SIGTERM) spdlog::info("stopped: SIGTERM received");
  else if (sig == SIGINT) spdlog::info("stopped: SIGINT received (Ctrl-C)");
  else if (sig == SIGHUP) spdlog::info("stopped: SIGHUP received (the terminal hung up)");
  else spdlog::info("stopped");
}

}  // namespace ladder::daemon
