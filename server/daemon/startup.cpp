#include "daemon/startup.hpp"

#include "daemon/builtin_scene.hpp"

#include <spdlog/sinks/basic_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <csignal>
#include <memory>

namespace ladder::daemon {

namespace {
std::atomic<bool>* g_stop = nullptr;
volatile std::sig_atomic_t g_signal = 0;

extern "C" void on_signal(int sig) {
  g_signal = sig;
  if (g_stop) g_stop->store(true);  // lock-free atomic: async-signal-safe
}
}  // namespace

void setup_logging(const DaemonConfig& config) {
  std::vector<spdlog::sink_ptr> sinks{std::make_shared<spdlog::sinks::stderr_color_sink_mt>()};
  if (!config.log_file.empty()) {
    try {
      sinks.push_back(std::make_shared<spdlog::sinks::basic_file_sink_mt>(config.log_file));
    } catch (const spdlog::spdlog_ex& e) {
      throw std::runtime_error("cannot open the log file '" + config.log_file + "': " + e.what());
    }
  }
  auto logger = std::make_shared<spdlog::logger>("ladderd", sinks.begin(), sinks.end());
  spdlog::set_default_logger(logger);
  spdlog::set_level(spdlog::level::from_str(config.log_level));
  spdlog::set_pattern("%Y-%m-%d %H:%M:%S.%e %^[%l]%$ %v");
  spdlog::flush_on(spdlog::level::info);
}

scene::Scene first_scene(const DaemonConfig& config, const std::vector<std::string>& overrides) {
  if (!config.scene.empty()) return scene::load_scene(config.scene, overrides);
  scene::Scene s = scene::parse_scene(kBuiltinSceneToml, "built-in classic scene", overrides);
  s.timeline.clear();  // at rest: the user tips it
  s.name = "classic (at rest)";
  return s;
}

void catch_stop_signals(std::atomic<bool>& stop) {
  static_assert(std::atomic<bool>::is_always_lock_free);
  g_stop = &stop;
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

void log_stop_reason() {
  const int sig = g_signal;
  if (sig == SIGTERM) spdlog::info("stopped: SIGTERM received");
  else if (sig == SIGINT) spdlog::info("stopped: SIGINT received (Ctrl-C)");
  else spdlog::info("stopped");
}

}  // namespace ladder::daemon
