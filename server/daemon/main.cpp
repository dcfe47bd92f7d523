// ladderd: the Jacob's ladder simulation server. This build runs the simulation offline (--offline); the
// real-time DDS server is the next piece of work (see README).
#include "daemon/offline.hpp"
#include "scene/scene.hpp"

#include <CLI/CLI.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <iostream>

int main(int argc, char** argv) {
  CLI::App app{"ladderd: the virtual Jacob's ladder simulation server"};
  ladder::daemon::OfflineOptions o;
  bool offline = false, quiet = false, keys = false;
  std::string level = "info";
  app.add_flag("--offline", offline, "run the scene as fast as possible with no network, then exit");
  app.add_option("--scene", o.scene, "scene file (TOML), e.g. config/scenes/classic.toml")->check(CLI::ExistingFile);
  app.add_option("--duration", o.duration, "simulated time to run [s] (offline)");
  app.add_option("--set", o.overrides, "override a scene key, KEY=VALUE (e.g. sim.dt=0.0005); repeatable");
  app.add_option("--events", o.events, "write events as JSON lines to FILE (offline)");
  app.add_option("--trajectory", o.trajectory, "write block centres and angles every 10 ms as CSV to FILE (offline)");
  app.add_option("--summary", o.summary, "write a JSON summary (steps, speed, hinge error, energy) to FILE (offline)");
  app.add_flag("--quiet", quiet, "no progress lines");
  app.add_option("--log-level", level, "trace, debug, info, warn, error or off")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "off"}));
  app.add_flag("--keys", keys, "list every scene key (usable with --set) and exit");
  app.set_version_flag("--version", "ladderd 0.1.0");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version exit 0; every bad command line exits 2, the code scripts get for any bad input.
    return app.exit(e) == 0 ? 0 : 2;
  }

  spdlog::set_default_logger(spdlog::stderr_color_mt("ladderd"));
  spdlog::set_level(spdlog::level::from_str(level));
  spdlog::set_pattern("%^[%l]%$ %v");
  if (keys) {
    std::cout << ladder::scene::keys_help();
    return 0;
  }
  if (!offline) {
    spdlog::error("this build of ladderd runs offline only: add --offline --scene FILE --duration S "
                  "(the real-time DDS server is not built yet)");
    return 2;
  }
  if (o.scene.empty() || o.duration <= 0) {
    spdlog::error("--offline needs --scene FILE and --duration S (seconds > 0); see --help");
    return 2;
  }
  o.progress = !quiet;
  return ladder::daemon::run_offline(o);
}
