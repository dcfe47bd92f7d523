// ladderd: the Jacob's ladder simulation server. By default it serves the ladder in real time over Cyclone DDS
// until SIGINT, SIGTERM or SIGHUP; with --offline it runs a scene as fast as possible with no network and exits.
#include "daemon/config.hpp"
#include "daemon/fatal.hpp"
#include "daemon/offline.hpp"
#include "daemon/server.hpp"
#include "daemon/startup.hpp"
#include "ladder/cli_error.hpp"
#include "transport/default_config.hpp"
#include "transport/dds.hpp"
#include "transport/domain_option.hpp"
#include "transport/version.hpp"

#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <charconv>
#include <memory>
#include <optional>
#include <iostream>
#include <string>

namespace {

// A number, or a whole one, in words when it is not ("--duration: 'ten' is not a number"; CLI11 said "Could not
// convert: --duration = ten"). Ranges are checked with the configuration's, which name the key.
CLI::Validator a_number(bool whole) {
  return CLI::Validator(
      [whole](std::string& text) -> std::string {
        const char* end = text.data() + text.size();
        bool read = false;
        if (whole) {
          long long n = 0;
          const auto r = std::from_chars(text.data(), end, n);
          read = r.ec == std::errc() && r.ptr == end;
        } else {
          double x = 0;
          const auto r = std::from_chars(text.data(), end, x);
          read = r.ec != std::errc::invalid_argument && r.ptr == end;  // (out of range: the range check says so)
        }
        return read && !text.empty() ? "" : "'" + text + "' is not a " + (whole ? "whole number" : "number");
      },
      "");  // (no words in --help: the type, INT or FLOAT, says it)
}

}  // namespace

int main(int argc, char** argv) {
  using namespace ladder;
  CLI::App app{"ladderd: the virtual Jacob's ladder simulation server (real time over DDS, or --offline)"};
  daemon::OfflineOptions o;
  daemon::DaemonConfig c;
  c.server.scenes_dir = daemon::default_scenes_dir(LADDER_INSTALLED_SCENES, LADDER_SCENES_DIR);
  std::string config_file, resimulate, resume;
  std::optional<transport::Identity> identity;  // --security: outlives every participant (made in run_server)
  bool offline = false, quiet = false, keys = false;
  app.add_option("--config", config_file, "configuration file (TOML), e.g. config/ladderd.toml")
      ->check(CLI::ExistingFile);
  app.add_option("--scene", o.scene,
                 "scene file (TOML), or the name of one in the scenes folder (e.g. double-ripple); default: the "
                 "built-in classic toy at rest (required with --offline, but for --resimulate)");
  app.add_option("--set", o.overrides, "override a scene key, KEY=VALUE (e.g. sim.dt=0.0005); repeatable");
  auto* domain = app.add_option("--domain", c.server.domain, "DDS domain id (0-231)")
                     ->check(transport::domain_check())
                     ->capture_default_str();
  auto* sim_id = app.add_option("--sim-id", c.server.sim_id,
                                "this ladder's id, to share a domain with others (refused if one there has it)");
  auto* rate =
      app.add_option("--rate", c.server.rates.physics, "physics ticks per second of wall time")
          ->check(a_number(false))
          ->capture_default_str();
  auto* publish = app.add_option("--publish-rate", c.server.rates.publish,
                                 "states published per second (default 60, or the physics rate when that is lower)")
                     ->check(a_number(false));
  auto* rtf = app.add_option("--rtf", c.server.rates.real_time_factor,
                             "real-time factor: sim seconds per wall second, 0 = as fast as possible")
                  ->check(a_number(false))
                  ->capture_default_str();
  auto* realtime = app.add_option("--realtime-priority", c.server.realtime_priority,
                                  "run the physics thread at SCHED_FIFO priority 1-99 (needs CAP_SYS_NICE); 0 = off")
                       ->check(a_number(true))
                       ->check(CLI::Range(0, 99).description(""));
  auto* spin = app.add_option("--spin-us", c.server.spin_us,
                              "busy-wait the last US microseconds before each tick instead of sleeping: ticks start on "
                              "time, for that much CPU; 0 = off")
                   ->check(a_number(true));
  auto* level = app.add_option("--log-level", c.log_level, "trace, debug, info, warn, error or off (default info)");
  auto* log_file = app.add_option("--log-file", c.log_file, "also log to FILE");
  auto* security = app.add_option("--security", c.security,
                                  "DDS Security: this server's identity folder DIR/NAME of scripts/make-pki "
                                  "(docs/security.md); default: none");
  app.add_option("--record", c.server.record, "write the session to an LCM event log FILE (docs/recording.md)");
  app.add_option("--tick-log", c.server.tick_log,
                 "write one line per tick of the real-time loop to FILE: start, lateness, step time, commands");
  app.add_option("--resume", resume,
                 "go on live, paused, from where a session log FILE ends (it is re-run to its end and checked on the "
                 "way; docs/recording.md)")
      ->check(CLI::ExistingFile);
  app.add_flag("--offline", offline, "run the scene as fast as possible with no network, then exit");
  app.add_option("--resimulate", resimulate,
                 "with --offline: re-run a session log FILE and compare every recorded state bit for bit")
      ->check(CLI::ExistingFile);
  auto* duration = app.add_option("--duration", o.duration,
                                  "simulated time to run [s] (required with --offline, but for --resimulate)")
                       ->check(a_number(false));
  app.add_option("--events", o.events, "write events as JSON lines to FILE (offline)");
  app.add_option("--trajectory", o.trajectory, "write block centres and angles every 10 ms as CSV to FILE (offline)");
  app.add_option("--summary", o.summary, "write a JSON summary (steps, speed, hinge error, energy) to FILE (offline)");
  app.add_flag("--quiet", quiet, "no progress lines (offline)");
  app.add_flag("--keys", keys, "list every scene key (those --set takes, then the timeline's fields) and exit");
  app.set_version_flag("--version", std::string("ladderd ") + kVersion);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version exit 0; every bad command line exits 2, the code scripts get for any bad input. An
    // unknown option is named with the nearest one; what is quoted of the command line is made printable.
    return report_parse_error(app, e, "ladderd");
  }
  if (keys) {
    std::cout << scene::keys_help();
    return 0;
  }

  try {
    // The file first, then the command line over it.
    const daemon::DaemonConfig cli = c;
    if (!config_file.empty()) daemon::load_config(config_file, c);
    if (domain->count()) c.server.domain = cli.server.domain;
    if (sim_id->count()) c.server.sim_id = cli.server.sim_id;
    if (rate->count()) c.server.rates.physics = cli.server.rates.physics;
    if (publish->count()) {
      c.server.rates.publish = cli.server.rates.publish;
      c.publish_rate_given = true;
    }
    c.default_publish_rate();
    if (rtf->count()) c.server.rates.real_time_factor = cli.server.rates.real_time_factor;
    if (realtime->count()) c.server.realtime_priority = cli.server.realtime_priority;
    if (spin->count()) c.server.spin_us = cli.server.spin_us;
    if (level->count()) c.log_level = cli.log_level;
    if (log_file->count()) c.log_file = cli.log_file;
    if (!o.scene.empty()) c.scene = daemon::find_scene(o.scene, c.server.scenes_dir);
    if (security->count()) c.security = cli.security;
    daemon::check_config(c);
    // Checked before DDS starts: a bad identity folder is named with what is wrong with it, not Cyclone's refusal.
    if (!c.security.empty()) identity = daemon::server_identity(c.security);
    daemon::setup_logging(c);
  } catch (const std::exception& e) {
    // A value checked under its configuration key also names the option it came from, when it came from one.
    std::string why = e.what(), given;
    for (const auto& [key, option] :
         {std::pair{"server.physics_rate", rate}, {"server.publish_rate", publish}, {"server.real_time_factor", rtf},
          {"server.spin_us", spin}, {"server.sim_id", sim_id}, {"log.level", level}})
      if (option->count() && why.find(key) != std::string::npos)
        given += (given.empty() ? "" : " and ") + option->get_name() + " " + option->as<std::string>();
    if (!given.empty()) why += " (given as " + given + ")";
    std::cerr << "ladderd: " << printable(why, false) << "\n";  // (it may quote a key or a value of the file)
    return 2;
  }

  if (!offline) {  // the offline run's outputs, which a live server would silently ignore
    for (const auto& [given, option] :
         {std::pair{o.duration != 0, "--duration"}, {!o.events.empty(), "--events"},
          {!o.trajectory.empty(), "--trajectory"}, {!o.summary.empty(), "--summary"}})
      if (given) {
        return daemon::exit_with(
            2, std::string(option) + " is for --offline runs; a live server runs until it is stopped (add --offline)");
      }
  }
  if (offline && !resimulate.empty()) return daemon::run_resimulation(resimulate, !quiet);
  if (!resimulate.empty()) {
    return daemon::exit_with(2, "--resimulate runs offline: add --offline");
  }
  if (offline) {
    // The live server's outputs: an offline run has its own (--events, --trajectory, --summary).
    for (const auto& [given, option] : {std::pair{!c.server.record.empty(), "--record"},
                                        {!c.server.tick_log.empty(), "--tick-log"}, {!resume.empty(), "--resume"}})
      if (given) {
        return daemon::exit_with(2, std::string(option) +
                                        " is for the live server, not --offline (an offline run writes --events, "
                                        "--trajectory and --summary)");
      }
    if (c.scene.empty() || !duration->count()) {
      return daemon::exit_with(2, "--offline needs --scene FILE and --duration S (seconds > 0); see --help");
    }  // (a --duration of 0 or less is refused by run_offline, with the figure given)
    o.scene = c.scene;
    o.progress = !quiet;
    return daemon::run_offline(o);
  }

  std::unique_ptr<daemon::Session> session;
  try {
    session = resume.empty() ? daemon::first_session(c, o.overrides) : daemon::resumed_session(resume, c);
  } catch (const std::exception& e) {
    return daemon::exit_with(2, e.what());
  }
  static std::atomic<bool> stop{false};
  daemon::catch_stop_signals(stop);
  transport::use_default_config(transport::kDefaultCycloneConfig);
  if (identity) {
    transport::set_default_identity(&*identity);
    spdlog::info("DDS Security on: the server '{}' ({}), certificate valid until {}", identity->name,
                 identity->subject, identity->not_after);
  }
  try {
    const int rc = daemon::run_server(c.server, std::move(session), stop);
    daemon::log_stop_reason();
    return rc;
  } catch (const daemon::OutputError& e) {
    return daemon::exit_with(2, e.what());
  } catch (const std::exception& e) {
    return daemon::exit_with(1, e.what());
  }
}
