#include "daemon/server.hpp"

#include "daemon/io.hpp"
#include "daemon/notify.hpp"
#include "daemon/outbox.hpp"
#include "daemon/physics.hpp"
#include "daemon/realtime.hpp"
#include "daemon/tick_log.hpp"
#include "transport/dds.hpp"
#include "transport/lcm_log.hpp"
#include "transport/topics.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <exception>
#include <memory>
#include <mutex>
#include <thread>
#include <utility>

namespace ladder::daemon {

namespace {

// Cyclone's own warnings and errors, in ladderd's log. A hostile writer can make Cyclone warn once per sample (one
// it cannot deserialize), so at most 10 lines a second go through; the rest are counted in the next line.
void cyclone_line(const char* message) {
  static std::mutex mutex;
  static transport::LineLimiter limiter(10, std::chrono::seconds(1));
  std::lock_guard lock(mutex);
  bool shown = false;
  const std::uint64_t hidden = limiter.admit(Clock::now(), shown);
  if (hidden > 0)  // (the first line of a new second is always shown)
    spdlog::warn("cyclone: {} (and {} more lines not shown)", transport::printable(message), hidden);
  else if (shown)
    spdlog::warn("cyclone: {}", transport::printable(message));  // (a line of Cyclone's may quote a peer's text)
}

// Another ladder that answers to this sim id on the domain (a live ladderd, or `ladderctl replay`): two publishers of
// one name would mix their states in every client, and both would take its commands. Its SceneInfo, which it keeps
// for late joiners, comes as soon as discovery has found it: looked for during `wait` (on loopback discovery takes
// a few milliseconds; a ladder that discovery has not found by then is not seen). "" when there is none, or when
// this participant may not read SceneInfo (DDS Security's server permissions do not grant it).
std::string sim_id_taken(const ServerConfig& config, std::chrono::milliseconds wait) {
  try {
    const transport::Entity participant = transport::make_participant(static_cast<dds_domainid_t>(config.domain));
    const transport::Entity topic = transport::make_topic(participant, &ladder_msg_SceneInfo_desc, "ladder/SceneInfo");
    const transport::Reader<ladder_msg_SceneInfo> reader(participant, topic, transport::Profile::SceneInfo);
    const Clock::time_point end = Clock::now() + wait;
    std::string found;
    while (found.empty() && Clock::now() < end) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      reader.take([&](const ladder_msg_SceneInfo& s, const dds_sample_info_t&) {
        if (transport::text_of(s.sim_id) != config.sim_id) return;
        found = s.replay ? std::string("a replay (ladderctl replay)")
                         : "a live ladderd, serving '" + transport::printable(transport::text_of(s.scene_name)) + "'";
      });
    }
    return found;
  } catch (const std::exception& e) {
    spdlog::debug("did not look for another ladder of sim id '{}': {}", config.sim_id, e.what());
    return {};
  }
}

}  // namespace

int run_server(const ServerConfig& config, const scene::Scene& scene, const std::atomic<bool>& stop) {
  return run_server(config, std::make_unique<Session>(scene, config.scenes_dir, config.limits, config.rates), stop);
}

int run_server(const ServerConfig& config, std::unique_ptr<Session> session, const std::atomic<bool>& stop) {
  const scene::Scene& scene = session->sim().scene();
  if (const std::string other = sim_id_taken(config, kSimIdCheck); !other.empty())
    throw SimIdTaken("sim id '" + config.sim_id + "' on DDS domain " + std::to_string(config.domain) +
                     " is already taken by " + other + "; stop it, or give this server another --sim-id");
  Shared shared(config);
  const Notifier notifier;
  shared.notifier = &notifier;
  if (notifier.enabled())
    spdlog::info("telling systemd when ready and stopping{}",
                 notifier.watchdog() ? ", and its watchdog every " +
                                           std::to_string(notifier.watchdog()->count() / 2000) + " ms"
                                     : std::string());
  std::unique_ptr<transport::LogWriter> log;
  if (!config.record.empty()) {
    try {
      log = std::make_unique<transport::LogWriter>(config.record);
    } catch (const std::runtime_error& e) {
      throw OutputError(e.what());
    }
    spdlog::info("recording the session to {}", transport::printable(config.record));
  }
  TickLog tick_log(config);
  if (tick_log) spdlog::info("writing one line per tick to {}", transport::printable(config.tick_log));
  // With a real-time priority this (the I/O) thread runs just below the physics thread, and so do DDS's threads,
  // which inherit it when Io starts them: a thread of the normal scheduler could otherwise hold the I/O side up while
  // the physics thread waits for the hand-off's lock.
  const bool realtime =
      config.realtime_priority > 0 && run_realtime("I/O", std::max(1, config.realtime_priority - 1));
  transport::route_cyclone_log(cyclone_line, "ladder/Command");
  Io io(shared, log.get(), tick_log);
  Physics physics(shared, std::move(session));
  spdlog::info("serving '{}' as sim id '{}' on DDS domain {}: {} blocks, {} Hz physics, {} Hz states, real-time "
               "factor {}",
               transport::printable(scene.name), config.sim_id, config.domain, scene.ladder.blocks,
               config.rates.physics, config.rates.publish, config.rates.real_time_factor);
  if (config.spin_us > 0) spdlog::info("the physics thread busy-waits the last {} us before each tick", config.spin_us);
  std::exception_ptr physics_error;
  std::thread physics_thread([&] {
    const bool physics_realtime = realtime && run_realtime("physics", config.realtime_priority);
    try {
      physics.run(stop, physics_realtime);
    } catch (...) {
      physics_error = std::current_exception();
      shared.physics_done = true;
    }
  });
  try {
    io.run();
  } catch (...) {
    {
      std::lock_guard lock(shared.inbox_mutex);  // a DDS failure on the I/O side: stop the physics thread (waking it)
      shared.abort = true;                       // before unwinding
    }
    shared.inbox_cv.notify_all();
    physics_thread.join();
    throw;
  }
  physics_thread.join();
  if (!tick_log.complete())
    spdlog::warn("the tick log {} is incomplete: writing to it failed", transport::printable(config.tick_log));
  if (log) {
    // (A session with no command never synced: a log on a full disk closed without a word.)
    const bool complete = log->sync(std::chrono::seconds(5));
    log.reset();  // writes what is queued, flushes, closes
    if (complete)
      spdlog::info("session log {} closed", transport::printable(config.record));
    else
      spdlog::warn("the session log {} is incomplete: writing to it failed or took over 5 s",
                   transport::printable(config.record));
  }
  if (physics_error) std::rethrow_exception(physics_error);
  return 0;
}

}  // namespace ladder::daemon
