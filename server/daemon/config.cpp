#include "daemon/config.hpp"

#include "daemon/startup.hpp"
#include "ladder/sim_id.hpp"
#include "ladder/spelling.hpp"
#include "scene/scene.hpp"
#include "transport/dds.hpp"

#include <toml++/toml.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <functional>
#include <string_view>
#include <algorithm>

namespace ladder::daemon {

namespace {

namespace fs = std::filesystem;

std::string where(const std::string& file, const toml::source_region& r) {
  return file + ":" + std::to_string(r.begin.line) + ":" + std::to_string(r.begin.column);
}

// One key of the file: its name, and how to read a node into the config (throws std::invalid_argument with why).
struct Key {
  std::string_view name;  // "table.key"
  std::function<void(const toml::node&, DaemonConfig&, const fs::path& dir)> read;
};

double number(const toml::node& n) {
  if (const auto* i = n.as_integer()) return static_cast<double>(i->get());
  if (const auto* f = n.as_floating_point()) return f->get();
  throw std::invalid_argument("must be a number");
}

long long integer(const toml::node& n, long long lo, long long hi) {
  const auto* i = n.as_integer();
  if (!i) throw std::invalid_argument("must be an integer");
  if (i->get() < lo || i->get() > hi)
    throw std::invalid_argument("must be from " + std::to_string(lo) + " to " + std::to_string(hi));
  return i->get();
}

std::string text(const toml::node& n) {
  const auto* s = n.as_string();
  if (!s) throw std::invalid_argument("must be a string");
  // (A path or a name with a NUL in it ends there for the system: the log went to another file.)
  if (s->get().find('\0') != std::string::npos) throw std::invalid_argument("must not hold a NUL character (U+0000)");
  return s->get();
}

std::string path_in(const toml::node& n, const fs::path& dir) {
  const std::string t = text(n);
  return t.empty() || fs::path(t).is_absolute() ? t : (dir / t).lexically_normal().string();
}

template <class F>
Key number_key(std::string_view name, F set) {
  return {name, [set](const toml::node& n, DaemonConfig& c, const fs::path&) { set(c, number(n)); }};
}
template <class F>
Key integer_key(std::string_view name, long long lo, long long hi, F set) {
  return {name, [=](const toml::node& n, DaemonConfig& c, const fs::path&) { set(c, integer(n, lo, hi)); }};
}

const std::vector<Key>& keys() {
  static const std::vector<Key> k{
      {"server.sim_id", [](const toml::node& n, DaemonConfig& c, const fs::path&) { c.server.sim_id = text(n); }},
      integer_key("server.domain", 0, transport::kMaxDomain, [](DaemonConfig& c, long long v) { c.server.domain = static_cast<int>(v); }),
      {"server.scene", [](const toml::node& n, DaemonConfig& c, const fs::path& d) { c.scene = path_in(n, d); }},
      {"server.scenes_dir",
       [](const toml::node& n, DaemonConfig& c, const fs::path& d) {
         // Checked now: a `load` would otherwise fail much later, naming a folder nobody meant.
         const std::string dir = path_in(n, d);
         std::error_code ec;
         if (!fs::is_directory(dir, ec))
           throw std::invalid_argument("must be a folder of scenes: '" + dir + "' is not one");
         c.server.scenes_dir = dir;
       }},
      number_key("server.physics_rate", [](DaemonConfig& c, double v) { c.server.rates.physics = v; }),
      number_key("server.publish_rate",
                 [](DaemonConfig& c, double v) {
                   c.server.rates.publish = v;
                   c.publish_rate_given = true;
                 }),
      number_key("server.stats_rate", [](DaemonConfig& c, double v) { c.server.stats_rate = v; }),
      number_key("server.real_time_factor", [](DaemonConfig& c, double v) { c.server.rates.real_time_factor = v; }),
      integer_key("server.realtime_priority", 0, 99,
                  [](DaemonConfig& c, long long v) { c.server.realtime_priority = static_cast<int>(v); }),
      integer_key("server.spin_us", 0, 1'000'000,
                  [](DaemonConfig& c, long long v) { c.server.spin_us = static_cast<int>(v); }),
      integer_key("commands.queue", 1, 1'000'000,
                  [](DaemonConfig& c, long long v) { c.server.queue = static_cast<std::size_t>(v); }),
      integer_key("commands.per_tick", 1, 100'000,
                  [](DaemonConfig& c, long long v) { c.server.per_tick = static_cast<std::size_t>(v); }),
      number_key("commands.reader_wait", [](DaemonConfig& c, double v) { c.server.reader_wait = v; }),
      number_key("commands.rate", [](DaemonConfig& c, double v) { c.server.rate = v; }),
      integer_key("commands.burst", 1, transport::kAckDepth / 2,
                  [](DaemonConfig& c, long long v) { c.server.burst = static_cast<double>(v); }),
      number_key("commands.max_impulse", [](DaemonConfig& c, double v) { c.server.limits.max_impulse = v; }),
      number_key("commands.max_force", [](DaemonConfig& c, double v) { c.server.limits.max_force = v; }),
      number_key("commands.max_duration", [](DaemonConfig& c, double v) { c.server.limits.max_duration = v; }),
      number_key("commands.reach", [](DaemonConfig& c, double v) { c.server.limits.reach = v; }),
      integer_key("commands.max_step_count", 1, kWidestLimits.max_step_count,
                  [](DaemonConfig& c, long long v) { c.server.limits.max_step_count = static_cast<std::uint32_t>(v); }),
      {"server.security",
       [](const toml::node& n, DaemonConfig& c, const fs::path& d) {
         c.security = path_in(n, d);
         try {
           if (!c.security.empty()) server_identity(c.security);
         } catch (const ConfigError& e) {
           throw std::invalid_argument(e.what());  // positioned at the value by load_config
         }
       }},
      {"log.level", [](const toml::node& n, DaemonConfig& c, const fs::path&) { c.log_level = text(n); }},
      {"log.file", [](const toml::node& n, DaemonConfig& c, const fs::path& d) { c.log_file = path_in(n, d); }},
  };
  return k;
}

void positive(double v, double hi, const char* key, const char* bound = nullptr) {
  if (!(v > 0 && v <= hi))
    throw ConfigError(std::string(key) + " must be > 0 and at most " +
                          (bound ? std::string(bound) : std::to_string(static_cast<long long>(hi))),
                      key);
}

}  // namespace

void check_config(const DaemonConfig& c) {
  const ServerConfig& s = c.server;
  if (const std::string why = sim_id_problem(s.sim_id); !why.empty()) {
    const bool quoted = !s.sim_id.empty() && s.sim_id.size() <= kMaxSimId;  // (its characters are what is wrong)
    throw ConfigError("server.sim_id " + (quoted ? "'" + s.sim_id + "' " : std::string()) + why, "server.sim_id");
  }
  // At least 1 Hz: a state goes out at least once a second and at most once a tick (0.5 Hz was refused as a
  // publish rate below 1, blaming a rate the user had not given).
  if (!(s.rates.physics >= kMinPublishRate && s.rates.physics <= 100'000))
    throw ConfigError("server.physics_rate must be from 1 to 100000 ticks a second", "server.physics_rate");
  // The same bounds as `set` (session.hpp): below them the server would stop publishing or freeze the simulation.
  if (!(s.rates.publish >= kMinPublishRate && s.rates.publish <= s.rates.physics))
    throw ConfigError("server.publish_rate must be >= 1 and at most server.physics_rate (" +
                          scene::format_number(s.rates.publish) + " states a second against " +
                          scene::format_number(s.rates.physics) + " ticks a second)",
                      "server.publish_rate");
  // (Below 0.01 Hz the next Stats would be hours away: 1e-300 Hz published none, as the publish rate once did.)
  if (!(s.stats_rate >= kMinStatsRate && s.stats_rate <= 100))
    throw ConfigError(
        "server.stats_rate must be from " + scene::format_number(kMinStatsRate) + " to 100 Stats a second",
        "server.stats_rate");
  const double rtf = s.rates.real_time_factor;
  if (!(rtf == 0 || (rtf >= kMinRealTimeFactor && rtf <= kMaxRealTimeFactor)))
    throw ConfigError("server.real_time_factor must be from 0.01 to 1000, or 0 (as fast as possible)",
                      "server.real_time_factor");
  if (!(s.realtime_priority >= 0 && s.realtime_priority <= 99))
    throw ConfigError("server.realtime_priority must be from 0 (normal scheduling) to 99", "server.realtime_priority");
  // At most half the tick: under SCHED_FIFO the spinning physics thread keeps the I/O thread (one priority lower)
  // off its core, and on one core off the machine.
  if (!(s.spin_us >= 0 && s.spin_us <= 500'000 / s.rates.physics))
    throw ConfigError("server.spin_us must be from 0 to half the tick period (" +
                          std::to_string(static_cast<long long>(500'000 / s.rates.physics)) + " us at " +
                          std::to_string(static_cast<long long>(s.rates.physics)) + " Hz)",
                      "server.spin_us");
  if (!(s.reader_wait >= 0 && s.reader_wait <= 3600))
    throw ConfigError("commands.reader_wait must be from 0 (do not wait) to 3600 s", "commands.reader_wait");
  positive(s.rate, 1e6, "commands.rate");
  positive(s.limits.max_impulse, kWidestLimits.max_impulse, "commands.max_impulse");
  positive(s.limits.max_force, kWidestLimits.max_force, "commands.max_force");
  positive(s.limits.max_duration, kWidestLimits.max_duration, "commands.max_duration");
  positive(s.limits.reach, kWidestLimits.reach, "commands.reach");
  static constexpr std::array levels{"trace", "debug", "info", "warn", "error", "off"};
  if (std::find(levels.begin(), levels.end(), c.log_level) == levels.end())
    throw ConfigError("log.level must be trace, debug, info, warn, error or off, not '" + c.log_level + "'", "log.level");
}

transport::Identity server_identity(const std::string& dir) {
  try {
    transport::Identity id = transport::load_identity(dir);
    transport::require_role(id, {transport::Role::Server}, "ladderd");
    return id;
  } catch (const transport::SecurityError& e) {
    throw ConfigError(std::string("security: ") + e.what(), "server.security");
  }
}

void load_config(const std::string& path, DaemonConfig& config) {
  toml::table root;
  try {
    root = toml::parse_file(path);
  } catch (const toml::parse_error& e) {
    if (e.source().begin.line == 0) throw ConfigError(path + ": cannot read the configuration file");
    throw ConfigError(where(path, e.source()) + ": " + std::string(e.description()));
  }
  const fs::path dir = fs::path(path).parent_path();
  DaemonConfig c = config;
  for (auto&& [table_name, table_node] : root) {
    if (scene::is_scene_table(table_name.str()))
      throw ConfigError(where(path, table_node.source()) + ": [" + std::string(table_name.str()) +
                        "] is a table of a scene file, not of a configuration file (which has [server], [commands] "
                        "and [log]): give a scene with --scene FILE, or as server.scene in the configuration");
    const auto* table = table_node.as_table();
    if (!table)
      throw ConfigError(where(path, table_node.source()) + ": '" + std::string(table_name.str()) +
                        "' must be a table: [server], [commands] or [log]");
    for (auto&& [key, node] : *table) {
      const std::string name = std::string(table_name.str()) + "." + std::string(key.str());
      const auto it = std::find_if(keys().begin(), keys().end(), [&](const Key& k) { return k.name == name; });
      if (it == keys().end()) {
        std::vector<std::string> names;
        std::string known;
        for (const Key& k : keys()) {
          names.emplace_back(k.name);
          known += (known.empty() ? "" : ", ") + names.back();
        }
        const std::string best = nearest(name, names);
        throw ConfigError(where(path, key.source()) + ": unknown key '" + name + "'" +
                          (best.empty() ? "" : " (did you mean '" + best + "'?)") + "; the keys: " + known);
      }
      try {
        it->read(node, c, dir);
      } catch (const std::invalid_argument& e) {
        throw ConfigError(where(path, node.source()) + ": " + name + " " + e.what(), name);
      }
    }
  }
  // server.scene as --scene takes it: a file (beside the configuration file), else the name of one in the scenes
  // folder ("double-ripple"); which, is known once the whole file (server.scenes_dir) has been read.
  if (const toml::node* n = root.at_path("server.scene").node(); n && !c.scene.empty()) {
    std::error_code ec;
    const std::string given(text(*n));
    if (!fs::is_regular_file(c.scene, ec)) {
      try {
        c.scene = find_scene(given.find('/') == std::string::npos ? given : c.scene, c.server.scenes_dir);
      } catch (const std::exception& e) {
        std::string why = e.what();
        if (why.starts_with("--scene ")) why = why.substr(8);
        throw ConfigError(where(path, n->source()) + ": server.scene " + why, "server.scene");
      }
    }
  }
  c.default_publish_rate();  // the file's physics rate may be below it
  try {
    check_config(c);
  } catch (const ConfigError& e) {
    const toml::node* n = root.at_path(e.key()).node();
    if (!n) throw ConfigError(path + ": " + e.what(), e.key());  // a default is at fault: no position to give
    throw ConfigError(where(path, n->source()) + ": " + e.what(), e.key());
  }
  config = c;
}

}  // namespace ladder::daemon
