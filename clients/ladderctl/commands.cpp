#include "commands.hpp"
#include "transport/dds.hpp"
#include "transport/domain_option.hpp"
#include "transport/version.hpp"

#include "cli_checks.hpp"
#include "ladder/cli_error.hpp"
#include "list.hpp"
#include "replay.hpp"
#include "scene/scene.hpp"
#include "session_plot.hpp"
#include "stop_signals.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <functional>
#include <iostream>
#include <optional>
#include <sstream>
#include <type_traits>

namespace ladder::ctl {

namespace {

using client::Client;
using client::Millis;
namespace cmd = client::cmd;

std::atomic<bool> g_interrupted{false};
extern "C" void on_interrupt(int) { g_interrupted = true; }

// "X,Y" or "X,Y,THETA" -> numbers; CLI11 reports the ValidationError with the option's name.
std::vector<double> numbers(const std::string& text, std::size_t min, std::size_t max, const std::string& what) {
  std::vector<double> out;
  std::stringstream in(text);
  std::string part;
  while (std::getline(in, part, ',')) {
    // A number too small for a double (1e-400) is 0 or nearly, not an error (std::stod threw); one too large is.
    double v = 0;
    bool underflow = false;
    if (!client::read_number(part, v, underflow) || !std::isfinite(v))
      throw CLI::ValidationError(what, "'" + text + "' is not a list of finite numbers like 0.01,0");
    out.push_back(v);
  }
  if (out.size() < min || out.size() > max)
    throw CLI::ValidationError(what, "'" + text + "' needs " +
                                         (min == max ? std::to_string(min) : std::to_string(min) + " or " +
                                                                                 std::to_string(max)) +
                                         " numbers separated by commas");
  return out;
}

std::string format_ack(const client::Ack& a) {
  char buf[96];
  if (a.accepted) {
    std::snprintf(buf, sizeof buf, "accepted at t = %.3f s (step %llu)", a.sim_time,
                  static_cast<unsigned long long>(a.step));
    return a.reason.empty() ? std::string(buf) : std::string(buf) + ": " + a.reason;  // a note (e.g. from reset)
  }
  return "refused: " + a.reason;
}

// --timeout as the messages write it, e.g. "3".
std::string timeout_text(const Connection& c) {
  char t[32];
  std::snprintf(t, sizeof t, "%g", c.timeout);
  return t;
}


Millis timeout_of(const Connection& c) { return Millis(static_cast<long>(c.timeout * 1000)); }

// The identity of --security, checked (a controller's or a viewer's) before DDS sees it; kept for the process.
const transport::Identity* identity_for(const Connection& c) {
  static std::optional<transport::Identity> id;
  if (c.security.empty()) return nullptr;
  if (!id || id->dir != c.security) {
    transport::Identity loaded = transport::load_identity(c.security);
    transport::require_role(loaded, {transport::Role::Controller, transport::Role::Viewer}, "ladderctl");
    id = std::move(loaded);
  }
  return &*id;
}

// Makes the client (once); kAccepted, or the exit code of what went wrong (printed).
int make_client(const Connection& c, std::unique_ptr<Client>& client) {
  if (client) return kAccepted;
  try {
    client = std::make_unique<Client>(c.domain, c.sim_id, std::string{}, identity_for(c));
  } catch (const transport::SecurityError& e) {
    std::cerr << "ladderctl: security: " << e.what() << "\n";
    return kUsage;
  } catch (const transport::DdsError& e) {
    std::cerr << "ladderctl: " << e.what() << "\n";
    return kUsage;
  }
  return kAccepted;
}

// Waits for the server (once); nullptr when it did not answer.
Client* connect(Connection& c, std::unique_ptr<Client>& client) {
  if (!client->scene_info() && !client->wait_for_server(timeout_of(c))) {
    std::cerr << "ladderctl: " << client->no_server(c.timeout) << "\n";
    return nullptr;
  }
  return client.get();
}

int send(Client& client, const Connection& c, const ladder_msg_Command& command) {
  if (client.scene_info() && client.scene_info()->replay) {  // it would never answer
    std::cerr << "ladderctl: '" << c.sim_id << "' on DDS domain " << c.domain
              << " is a replay of a recorded session (ladderctl replay), which takes no commands; give the sim id "
                 "of a running ladderd (ladderctl list)\n";
    return kNoServer;
  }
  if (!client.may_command()) {
    std::cerr << "ladderctl: " << client.denied() << "\n";
    return kDenied;
  }
  const std::uint64_t id = client.send(command);
  const auto ack = client.wait_ack(id, timeout_of(c));
  if (!ack) {
    // The server was found (connect()): it is there, but did not answer this one.
    std::cerr << "ladderctl: no answer from ladderd '" << c.sim_id << "' on DDS domain " << c.domain
              << " to the command within " << timeout_text(c)
              << " s: it may be limiting this client's commands (its Stats count them: commands_rate_limited, "
                 "commands_unanswered), or it stopped, or the network lost them\n";
    return kNoServer;
  }
  std::cout << format_ack(*ack) << "\n";
  return ack->accepted ? kAccepted : kRefused;
}

std::string hinge_text(const client::Hinge& h) {
  return h.status == ladder_msg_BROKEN ? "broken" : h.status == ladder_msg_LOCKED ? "locked" : "hinged";
}

// One JSON object, field by field: a number that is not finite is null (JSON has no NaN), a text is escaped.
class Json {
 public:
  Json& raw(const char* key, const std::string& value) {
    out_ += (out_.size() > 1 ? ",\"" : "\"") + std::string(key) + "\":" + value;
    return *this;
  }
  // Without a format, the shortest text that reads back as the same double (a sim time to the last bit).
  Json& field(const char* key, double v, const char* format = nullptr) {
    if (!std::isfinite(v)) return raw(key, "null");
    char buf[64];
    if (format == nullptr) return raw(key, std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr));
    std::snprintf(buf, sizeof buf, format, v);
    return raw(key, buf);
  }
  template <class I, std::enable_if_t<std::is_integral_v<I>, int> = 0>
  Json& field(const char* key, I v) {
    return raw(key, std::to_string(v));
  }
  Json& field(const char* key, const std::string& text) {
    std::string q = "\"";
    for (const char ch : text) {
      const auto c = static_cast<unsigned char>(ch);
      if (c == '"' || c == '\\') {
        q += '\\';
        q += ch;
      } else if (c < 0x20) {
        char buf[8];
        std::snprintf(buf, sizeof buf, "\\u%04x", c);
        q += buf;
      } else {
        q += ch;
      }
    }
    return raw(key, q + "\"");
  }
  std::string done() const { return out_ + "}"; }

 private:
  std::string out_ = "{";
};

void print_event(const client::Event& e, bool json) {
  if (json) {
    Json j;
    j.field("seq", e.seq).field("t", e.t).field("kind", e.kind).field("hinge", e.hinge);
    j.field("energy_removed", e.energy_removed).field("detail", e.detail);
    std::printf("%s\n", j.done().c_str());
  } else {
    std::printf("t = %9s s  %-15s hinge %-3d energy removed %.3g J%s%s\n", client::fixed(e.t, 4).c_str(),
                e.kind.c_str(), e.hinge, e.energy_removed, e.detail.empty() ? "" : "  ", e.detail.c_str());
  }
}

// A new generation of the scene (a reset or a load), in the event stream: in JSON, an object whose kind is "scene".
void print_scene_start(const client::SceneInfo& info, bool json) {
  if (json) {
    Json j;
    j.field("kind", std::string("scene")).field("generation", info.generation);
    j.field("scene", info.scene_name).field("blocks", info.blocks);
    std::printf("%s\n", j.done().c_str());
  } else {
    std::printf("--- the scene starts again (generation %u, a reset or a load): '%s', %u blocks; t counts from 0 ---\n",
                info.generation, info.scene_name.c_str(), info.blocks);
  }
}

void print_stats(const ladder_msg_Stats& s, bool json) {
  if (json) {
    Json j;
    j.field("sim_time", s.sim_time).field("steps", s.steps).field("real_time_factor", s.real_time_factor, "%.4g");
    j.field("step_p50_us", s.step_p50_us, "%.4g").field("step_p99_us", s.step_p99_us, "%.4g");
    j.field("step_max_us", s.step_max_us, "%.4g").field("late_p50_us", s.late_p50_us, "%.4g");
    j.field("late_p99_us", s.late_p99_us, "%.4g").field("late_max_us", s.late_max_us, "%.4g");
    j.field("missed_deadlines", s.missed_deadlines).field("solver_iterations", s.solver_iterations);
    j.field("solver_residual", s.solver_residual, "%.3g").field("energy", s.energy);
    j.field("max_hinge_error", s.max_hinge_error, "%.3g").field("commands_received", s.commands_received);
    j.field("commands_accepted", s.commands_accepted).field("commands_refused", s.commands_refused);
    j.field("commands_rate_limited", s.commands_rate_limited).field("commands_unanswered", s.commands_unanswered);
    j.field("commands_duplicate", s.commands_duplicate).field("commands_undecodable", s.commands_undecodable);
    j.field("write_failures", s.write_failures).field("states_published", s.states_published);
    std::printf("%s\n", j.done().c_str());
  } else {
    std::printf("t = %.3f s  real-time factor %.3f  step p50 %.1f us p99 %.1f us  tick late p99 %.0f us  missed in "
                "all %llu  hinge error %.2g m  energy %.6f J  commands %llu (%llu refused, %llu rate-limited, %llu "
                "unanswered)\n",
                s.sim_time, s.real_time_factor, s.step_p50_us, s.step_p99_us, s.late_p99_us,
                static_cast<unsigned long long>(s.missed_deadlines), s.max_hinge_error, s.energy,
                static_cast<unsigned long long>(s.commands_received),
                static_cast<unsigned long long>(s.commands_refused),
                static_cast<unsigned long long>(s.commands_rate_limited),
                static_cast<unsigned long long>(s.commands_unanswered));
  }
}

void print_state(const client::State& s, bool json) {
  if (json) {
    std::string blocks, hinges;
    char buf[128];
    for (const auto& b : s.blocks) {
      std::snprintf(buf, sizeof buf, "%s[%.9g,%.9g,%.9g]", blocks.empty() ? "" : ",", b.x, b.y, b.theta);
      blocks += buf;
    }
    for (const auto& h : s.hinges)
      hinges += (hinges.empty() ? "\"" : ",\"") + hinge_text(h) + "\"";
    Json j;  // (the poses are finite: the client takes no State with a pose that is not)
    j.field("seq", s.seq).field("step", s.step).field("t", s.sim_time).raw("paused", s.paused ? "true" : "false");
    j.field("energy", s.energy).raw("blocks", "[" + blocks + "]").raw("hinges", "[" + hinges + "]");
    std::printf("%s\n", j.done().c_str());
    return;
  }
  std::string flips;
  for (std::size_t k = 1; k < s.hinges.size() && k <= 16; ++k)
    flips += (flips.empty() ? "" : " ") + std::to_string(s.hinges[k].flips);
  std::printf("t = %9s s  step %-8llu %s energy %s J  flips per hinge: %s%s\n", client::fixed(s.sim_time, 4).c_str(),
              static_cast<unsigned long long>(s.step), s.paused ? "paused " : "", client::fixed(s.energy, 6).c_str(),
              flips.c_str(), s.hinges.size() > 17 ? " ..." : "");
}

// The event kinds ladderd publishes: the ladder's (server/ladder/ladder.cpp, to_string(EventKind)) and the server's
// own (server/daemon/physics.cpp: a stopped simulation, a scene's timed command refused).
const std::vector<std::string> kEventKinds{"flip_flop", "impact",         "lock",           "unlock",
                                           "break",     "join",           "solver_warning", "solver_failure",
                                           "command_refused"};

// --kinds flip_flop,lock -> the kinds; every one must be a kind ladderd publishes.
std::vector<std::string> event_kinds(const std::string& text) {
  std::vector<std::string> kinds;
  std::stringstream in(text);
  for (std::string k; std::getline(in, k, ',');) {
    if (std::find(kEventKinds.begin(), kEventKinds.end(), k) == kEventKinds.end()) {
      std::string all;
      for (const std::string& e : kEventKinds) all += (all.empty() ? "" : ", ") + e;
      throw CLI::ValidationError("--kinds", "'" + k + "' is not an event kind (" + all + ")");
    }
    kinds.push_back(k);
  }
  return kinds;
}

struct WatchOptions {
  std::string what;
  bool json = false;
  double rate = 10;
  std::vector<std::string> kinds;  // events: only these (empty = all)
};

int watch(Client& client, const Connection& c, const WatchOptions& w) {
  const bool json = w.json;
  const std::string& what = w.what;
  const double rate = w.rate;
  if (what == "events" && !json) {
    std::string kinds;
    for (const std::string& k : w.kinds) kinds += (kinds.empty() ? "" : ", ") + k;
    if (!kinds.empty()) kinds = " (only " + kinds + ")";
    std::printf("events of sim id '%s' on DDS domain %d%s as they happen; hinge k joins blocks k-1 and k "
                "(Ctrl-C stops):\n",
                c.sim_id.c_str(), c.domain, kinds.c_str());
    std::fflush(stdout);
  }
  g_interrupted = false;
  const client::StopSignals stop(on_interrupt);
  std::uint64_t seen_state = 0;
  const auto min_gap = std::chrono::duration<double>(rate > 0 ? 1.0 / rate : 0);
  auto last_print = std::chrono::steady_clock::now() - std::chrono::hours(1);
  std::uint64_t last_event = 0;  // the last event's seq (the server numbers every event it publishes, from 1)
  const auto missed = [](std::uint64_t from, std::uint64_t to, const char* when) {
    std::fflush(stdout);
    std::fprintf(stderr, "ladderctl: %llu event%s missed %s (numbers %llu to %llu): this client did not read them in "
                         "time\n",
                 static_cast<unsigned long long>(to - from + 1), to == from ? "" : "s", when,
                 static_cast<unsigned long long>(from), static_cast<unsigned long long>(to));
  };
  // The server's count of published events, from its Stats (once a second): events lost at the end of a burst are
  // followed by no event that would show the gap. A count above the last event seen is taken as lost when a second
  // Stats, a second later, still shows it (events reach a reader in milliseconds; Stats and events are written by
  // different threads, so one Stats may count an event still on its way).
  // Before its first event the watcher counts from the second Stats it gets: events published before its reader met
  // the server's writer are not kept for it, and are not its loss (the first Stats may come before that meeting).
  std::uint64_t stats_seen = client.stats_received(), pending = 0;
  int stats_before_count = 0;
  bool counted = false;  // last_event holds a number: an event's, or a Stats count
  // The scene's generation: a reset or a load starts a new one, whose clock starts again at 0. Marked with a line of
  // its own (the events do not carry the generation; the marker comes before the events taken in the same poll).
  std::optional<std::uint32_t> generation;
  while (!g_interrupted) {
    if (what == "events") {
      client.wait_state([](const client::State&) { return false; }, Millis(100));
      if (const auto& info = client.scene_info()) {
        if (generation && *generation != info->generation) print_scene_start(*info, json);
        generation = info->generation;
      }
      for (const client::Event& e : client.take_events()) {
        // A gap in the numbers: events this client's reader lost (it keeps the last 64, and a client stopped with
        // Ctrl-Z or too slow to read lets the rest go). Said on standard error, so that --json's lines stay clean;
        // a lower number is a restarted server, which counts afresh.
        if (counted && e.seq > last_event + 1) missed(last_event + 1, e.seq - 1, "before this one");
        last_event = e.seq;
        counted = true;
        if (w.kinds.empty() || std::find(w.kinds.begin(), w.kinds.end(), e.kind) != w.kinds.end())
          print_event(e, json);
      }
      if (client.stats_received() != stats_seen && client.latest_stats()) {
        stats_seen = client.stats_received();
        const std::uint64_t published = client.latest_stats()->events_published;
        if (!counted) {
          if (++stats_before_count >= 2) last_event = published, counted = true;
        } else {
          if (pending > last_event && published >= pending) {
            missed(last_event + 1, pending, "since the last one");
            last_event = pending;
          }
          // (none unseen when published <= last_event: a Stats may be older than the last event, and a restart shows
          // in the events)
          pending = published > last_event ? published : 0;
        }
      }
    } else if (what == "stats") {
      // Every new sample (once a second), paused or not: a paused server's step count stays where it is.
      const auto s = client.wait_stats([](const ladder_msg_Stats&) { return true; }, Millis(200));
      if (s) print_stats(*s, json);
    } else {
      const auto s = client.wait_state([&](const client::State& st) { return st.seq > seen_state; }, Millis(200));
      if (s && std::chrono::steady_clock::now() - last_print >= min_gap) {
        seen_state = s->seq;
        last_print = std::chrono::steady_clock::now();
        print_state(*s, json);
      }
    }
    std::fflush(stdout);
  }
  return kAccepted;
}

int status(Client& client, const Connection& c) {
  const auto& info = client.scene_info();
  const auto& state = client.latest_state();
  const auto stats = client.wait_stats([](const ladder_msg_Stats&) { return true; }, Millis(1500));
  if (!info || !state) {
    std::cerr << "ladderctl: " << client.no_server(c.timeout) << "\n";
    return kNoServer;
  }
  std::printf("server %s, sim id '%s' on DDS domain %d\n", info->server_version.c_str(), c.sim_id.c_str(), c.domain);
  std::printf("scene '%s': %u blocks of %.4g x %.4g mm, top block %s\n", info->scene_name.c_str(), info->blocks,
              info->length * 1e3, info->thickness * 1e3, info->top.c_str());
  std::printf("sim time %s s, step %llu, %s, energy %s J\n", client::fixed(state->sim_time, 3).c_str(),
              static_cast<unsigned long long>(state->step), state->paused ? "paused" : "running",
              client::fixed(state->energy, 6).c_str());
  if (info->replay)
    std::printf("a replay of a recorded session (ladderctl replay): it takes no commands\n");
  else
    std::printf("rates: physics %g Hz, states %g Hz, real-time factor set to %g\n", info->physics_rate,
                info->publish_rate, info->real_time_factor);
  if (stats) {
    std::printf("measured over the last %.1f s: real-time factor %.3f, step p50 %.1f us p99 %.1f us max %.1f us,\n"
                "  tick lateness p50 %.0f us p99 %.0f us max %.0f us\n"
                "since the start: %llu tick%s missed (started more than a period late); since the scene was loaded: "
                "largest hinge error %.2g m\n",
                stats->window, stats->real_time_factor, stats->step_p50_us, stats->step_p99_us, stats->step_max_us,
                stats->late_p50_us, stats->late_p99_us, stats->late_max_us,
                static_cast<unsigned long long>(stats->missed_deadlines), stats->missed_deadlines == 1 ? "" : "s",
                stats->max_hinge_error);
    std::printf("commands: %llu received, %llu accepted, %llu refused, %llu rate-limited, %llu unanswered (a "
                "client over its rate), %llu repeated ids, %llu undecodable; %llu failed writes\n",
                static_cast<unsigned long long>(stats->commands_received),
                static_cast<unsigned long long>(stats->commands_accepted),
                static_cast<unsigned long long>(stats->commands_refused),
                static_cast<unsigned long long>(stats->commands_rate_limited),
                static_cast<unsigned long long>(stats->commands_unanswered),
                static_cast<unsigned long long>(stats->commands_duplicate),
                static_cast<unsigned long long>(stats->commands_undecodable),
                static_cast<unsigned long long>(stats->write_failures));
  }
  // SceneInfo's options also carry what the viewer draws from and cannot change live (ladder.depth, ladder.hinge,
  // ladder.end_radius): listed apart, so that none of them looks like something `set` takes.
  std::string live, fixed;
  std::istringstream lines(info->options);
  for (std::string line; std::getline(lines, line);)
    (scene::is_live_key(line.substr(0, line.find('='))) ? live : fixed) += "  " + line + "\n";
  std::printf("live settings (set KEY VALUE):\n%s", live.c_str());
  if (!fixed.empty()) std::printf("fixed for this scene (load it again to change them):\n%s", fixed.c_str());
  return kAccepted;
}

// What the parsed subcommand does once connected.
using Action = std::function<int(Client&, const Connection&)>;
// What a subcommand that needs no server (replay) does.
using Standalone = std::function<int(const Connection&)>;

struct Values {
  int index = 0;
  std::uint32_t count = 1;
  std::string impulse = "0.005,0", at, force, to, pose, key, value, scene, kinds;
  double duration = 0, stiffness = 0;
  WatchOptions watch;
  ReplayOptions replay;
  PlotOptions plot;
  std::string plot_size;
};

void add_connection(CLI::App& app, Connection& c) {
  app.add_option("--domain", c.domain, "DDS domain id of the server, 0-231 (default 0)")
      ->check(ladder::transport::domain_check());
  app.add_option("--sim-id", c.sim_id, "the server's sim id (default 'ladder')")->check(ladder::client::sim_id_check());
  // (At most a million seconds: 1e10 overflowed the clock's nanoseconds and timed out at once.)
  app.add_option("--timeout", c.timeout, "seconds to wait for the server and for each answer (default 3)")
      ->check(ladder::client::positive(1e6));
  app.add_option("--security", c.security,
                 "DDS Security: this client's identity folder DIR/NAME of scripts/make-pki (docs/security.md)");
}

// Declares every subcommand; the chosen one's callback leaves its action in `action`.
void declare(CLI::App& app, Values& v, Action& action, Standalone& standalone) {
  const auto simple = [&](const char* name, const char* help, ladder_msg_Command (*make)()) {
    app.add_subcommand(name, help)->callback([&action, make] {
      action = [make](Client& cl, const Connection& c) { return send(cl, c, make()); };
    });
  };
  simple("tip", "turn the held top block over (the ripple starts)", &cmd::tip);
  simple("pause", "stop the simulation clock", &cmd::pause);
  simple("resume", "start the simulation clock again", &cmd::resume);
  simple("reset", "back to the start of the current scene (live settings are kept, unless the last step failed: "
                  "then the scene's own)",
         &cmd::reset);

  auto* poke = app.add_subcommand("poke", "an impulse on a block");
  poke->add_option("BLOCK", v.index, "block number (0 is the top)")->required();
  poke->add_option("--impulse", v.impulse, "impulse X,Y [N s] (default 0.005,0)");
  poke->add_option("--at", v.at, "world point X,Y [m] where it strikes (default the block's centre)");
  poke->callback([&] {
    const auto j = numbers(v.impulse, 2, 2, "--impulse");
    ladder_msg_Command c = cmd::poke(v.index, j[0], j[1]);
    if (!v.at.empty()) {
      const auto p = numbers(v.at, 2, 2, "--at");
      c = cmd::poke_at(v.index, j[0], j[1], p[0], p[1]);
    }
    action = [c](Client& cl, const Connection& k) { return send(cl, k, c); };
  });

  auto* push = app.add_subcommand("push", "a force on a block for a while");
  push->add_option("BLOCK", v.index, "block number")->required();
  push->add_option("--force", v.force, "force X,Y [N]")->required();
  push->add_option("--for", v.duration, "how long [s]")->required()->check(ladder::client::positive());
  push->add_option("--at", v.at, "point X,Y in the block's frame [m] (default its centre)");
  push->callback([&] {
    const auto f = numbers(v.force, 2, 2, "--force");
    ladder_msg_Command c = cmd::push(v.index, f[0], f[1], v.duration);
    if (!v.at.empty()) {
      const auto p = numbers(v.at, 2, 2, "--at");
      c = cmd::push_at(v.index, f[0], f[1], v.duration, p[0], p[1]);
    }
    action = [c](Client& cl, const Connection& k) { return send(cl, k, c); };
  });

  auto* grab = app.add_subcommand("grab", "hold a block in a hand (a spring-damper); it stays where it is");
  grab->add_option("BLOCK", v.index, "block number")->required();
  grab->add_option("--to", v.to, "pull its centre toward world point X,Y [m] instead");
  grab->add_option("--stiffness", v.stiffness,
                   "spring stiffness [N/m] (default, or 0: 100 rad/s for the block alone)")
      ->check(ladder::client::non_negative());
  grab->callback([&] {
    ladder_msg_Command c = cmd::grab(v.index);
    if (!v.to.empty()) {
      const auto t = numbers(v.to, 2, 2, "--to");
      c = cmd::grab_to(v.index, t[0], t[1]);
    }
    c.e = v.stiffness;
    action = [c](Client& cl, const Connection& k) { return send(cl, k, c); };
  });

  auto* drag = app.add_subcommand("drag", "move a grabbed block's target");
  drag->add_option("BLOCK", v.index, "block number")->required();
  drag->add_option("POSE", v.pose, "X,Y [m] or X,Y,THETA [m, m, rad]")->required();
  drag->callback([&] {
    const auto p = numbers(v.pose, 2, 3, "POSE");
    const ladder_msg_Command c = p.size() == 3 ? cmd::drag_pose(v.index, p[0], p[1], p[2]) : cmd::drag(v.index, p[0], p[1]);
    action = [c](Client& cl, const Connection& k) { return send(cl, k, c); };
  });

  auto* release = app.add_subcommand("release", "let go of a grabbed block");
  release->add_option("BLOCK", v.index, "block number")->required();
  release->callback([&] {
    const ladder_msg_Command c = cmd::release(v.index);
    action = [c](Client& cl, const Connection& k) { return send(cl, k, c); };
  });

  for (const bool is_break : {true, false}) {
    auto* h = app.add_subcommand(is_break ? "break" : "join",
                                 is_break ? "break a hinge (the blocks below fall away)"
                                          : "join a broken hinge again (its corners must be close)");
    h->add_option("HINGE", v.index, "hinge k joins blocks k-1 and k; 0 is the top block's hold")->required();
    h->callback([&, is_break] {
      const ladder_msg_Command c = is_break ? cmd::break_hinge(v.index) : cmd::join_hinge(v.index);
      action = [c](Client& cl, const Connection& k) { return send(cl, k, c); };
    });
  }

  auto* step = app.add_subcommand("step", "advance N steps (while paused; default 1, as the viewer's s key)");
  step->add_option("N", v.count, "number of steps (default 1)")->check(ladder::client::count(UINT32_MAX));
  step->callback([&] {
    const ladder_msg_Command c = cmd::step(v.count);
    action = [c](Client& cl, const Connection& k) { return send(cl, k, c); };
  });

  auto* set = app.add_subcommand("set", "change a live setting, e.g. set damping.linear 0.5 (see status)");
  set->add_option("KEY", v.key, "sim.* (e.g. sim.accuracy fast), solver.*, damping.*, "
                                "server.real_time_factor or server.publish_rate")->required();
  set->add_option("VALUE", v.value, "the new value, written as in a scene file")->required();
  set->callback([&] {
    const ladder_msg_Command c = cmd::set(v.key + "=" + v.value);
    action = [c](Client& cl, const Connection& k) { return send(cl, k, c); };
  });

  auto* load = app.add_subcommand("load", "start another scene from the server's scene directory");
  load->add_option("SCENE", v.scene,
                   "the name of a scene in the server's scene directory, e.g. double-ripple (or double-ripple.toml)")
      ->required();
  load->callback([&] {
    const ladder_msg_Command c = cmd::load(v.scene);
    action = [c](Client& cl, const Connection& k) { return send(cl, k, c); };
  });

  app.add_subcommand("status", "the scene, sim time, rates and step statistics, once")->callback([&] {
    action = [](Client& cl, const Connection& k) { return status(cl, k); };
  });

  auto* w = app.add_subcommand("watch", "print a live stream until Ctrl-C");
  w->add_option("WHAT", v.watch.what, "events, stats or state")
      ->required()
      ->check(CLI::IsMember({"events", "stats", "state"}));
  w->add_flag("--json", v.watch.json, "one JSON object per line");
  w->add_option("--rate", v.watch.rate, "most state lines per second in text (default 10; 0 = every state)")
      ->check(ladder::client::non_negative());
  w->add_option("--kinds", v.kinds, "with events: only these kinds, e.g. flip_flop,lock (flip_flop, impact, lock, "
                                    "unlock, break, join, solver_warning, solver_failure, command_refused)");
  w->callback([&] {
    if (!v.kinds.empty() && v.watch.what != "events")
      throw CLI::ValidationError("--kinds", "only watch events takes --kinds");
    v.watch.kinds = event_kinds(v.kinds);
    action = [&v](Client& cl, const Connection& k) { return watch(cl, k, v.watch); };
  });

  app.add_subcommand("list", "every ladderd on the domain: sim id, host, scene, blocks, real-time factor")
      ->callback([&] { standalone = [](const Connection& c) { return list(c.domain, std::max(c.timeout, 1.5)); }; });

  auto* p = app.add_subcommand("plot", "the ripple's front (hinge of each flip-flop against time) and the energy as "
                                       "a PNG, from the running server or a recorded session");
  p->add_option("PNG", v.plot.png, "the picture to write")->required();
  p->add_option("--log", v.plot.log, "a recorded session (ladderd --record): all of its states, no server needed")
      ->check(CLI::ExistingFile);
  p->add_option("--for", v.plot.seconds, "the running server: watch its states this long [s] (default 10)")
      ->check(ladder::client::positive());
  p->add_option("--size", v.plot_size, "WxH pixels (default 900x600)");
  p->callback([&] {
    if (!v.plot_size.empty()) {
      char x = 0, rest = 0;
      if (std::sscanf(v.plot_size.c_str(), "%d%c%d%c", &v.plot.width, &x, &v.plot.height, &rest) != 3 || x != 'x' ||
          v.plot.width < 200 || v.plot.height < 150 || v.plot.width > 8192 || v.plot.height > 8192)
        throw CLI::ValidationError("--size", "'" + v.plot_size + "' is not a size like 900x600 (200x150 to 8192x8192)");
    }
    // Before any watching: a live plot would otherwise find out that it cannot write only after --for seconds.
    if (const std::string why = client::unwritable(v.plot.png); !why.empty())
      throw CLI::ValidationError("PNG", "cannot write '" + v.plot.png + "': " + why);
    if (!v.plot.log.empty())
      standalone = [&v](const Connection&) { return plot_log(v.plot); };
    else
      action = [&v](Client& cl, const Connection&) { return plot_live(cl, v.plot); };
  });

  auto* r = app.add_subcommand("replay", "publish a recorded session (ladderd --record) as if live, for viewers");
  r->add_option("FILE", v.replay.log, "the session log")->required()->check(CLI::ExistingFile);
  r->add_option("--speed", v.replay.speed,
                "pace: 2 = twice as fast, 0 = as fast as possible (default 1; otherwise 1e-6 to 1e6)")
      ->check(ladder::client::non_negative(1e6))
      ->check(CLI::Validator(
          [](std::string& t) -> std::string {
            const double s = std::strtod(t.c_str(), nullptr);
            return s == 0 || s >= 1e-6 ? "" : "must be 0 (as fast as possible) or at least 1e-6, not " + t;
          },
          "SPEED"));
  r->add_option("--from", v.replay.from, "start at this sim time [s] (default 0)")
      ->check(ladder::client::non_negative());
  r->add_option("--as", v.replay.sim_id, "publish as this sim id (default 'replay', apart from live ladders)")
      ->check(ladder::client::sim_id_check());
  r->callback([&] {
    standalone = [&v](const Connection& c) {
      ReplayOptions o = v.replay;
      o.domain = c.domain;
      return replay(o);
    };
  });
}

// Where the first word of `args` that is neither an option nor an option's value is: the command, if any.
std::optional<std::size_t> command_at(const std::vector<std::string>& args) {
  static const std::vector<std::string> with_value{"--domain", "--sim-id", "--timeout", "--security"};
  for (std::size_t i = 0; i < args.size(); ++i) {
    if (std::find(with_value.begin(), with_value.end(), args[i]) != with_value.end()) {
      ++i;
      continue;
    }
    if (!args[i].starts_with("-")) return i;
  }
  return std::nullopt;
}

}  // namespace

std::string unknown_command(const std::string& word) {
  const std::string best = nearest(word, command_names());
  std::string out = "unknown command '" + word + "'";
  if (!best.empty()) out += "; did you mean '" + best + "'?";
  out += "\ncommands:";
  for (const std::string& n : command_names()) out += " " + n;
  return out + "\n(each takes --help; ladderctl --help for the options)";
}

const std::vector<std::string>& command_names() {
  static const std::vector<std::string> names{"tip",  "poke",  "push", "grab",   "drag", "release",
                                              "break", "join", "pause", "resume", "step", "reset",
                                              "set",  "load",  "status", "watch", "list", "plot", "replay", "help",
                                              "quit"};
  return names;
}

int run(const std::vector<std::string>& args, Connection& conn, std::unique_ptr<client::Client>& client,
        bool interactive) {
  CLI::App app{"ladderctl: drive a ladderd server. Without a command: an interactive prompt.", "ladderctl"};
  Values v;
  Action action;
  Standalone standalone;
  add_connection(app, conn);
  app.set_version_flag("--version", std::string("ladderctl ") + kVersion);
  app.fallthrough();  // inherited by the subcommands: --domain, --sim-id and --timeout may also come after one
  declare(app, v, action, standalone);
  app.require_subcommand(interactive ? 1 : 0, 1);
  const Connection before = conn;
  std::vector<std::string> words = args;
  if (const auto at = command_at(words)) {
    const auto& names = command_names();
    // (A word after an option ladderctl does not know is more likely that option's value than a command: `--domian
    // 201 tip` is a mistyped option, which the parse below names, not an unknown command '201'.)
    const bool after_unknown_option = *at > 0 && words[*at - 1].starts_with("-") &&
                                      words[*at - 1].find('=') == std::string::npos &&
                                      !app.get_option_no_throw(words[*at - 1]);
    if (std::find(names.begin(), names.end(), words[*at]) == names.end() && !after_unknown_option) {
      std::cerr << (interactive ? "" : "ladderctl: ") << unknown_command(words[*at]) << "\n";
      return kUsage;
    }
    if (words[*at] == "help") words[*at] = "--help";  // `ladderctl help`: the usage
  }
  std::vector<std::string> reversed(words.rbegin(), words.rend());
  try {
    app.parse(reversed);
  } catch (const CLI::ParseError& e) {
    return report_parse_error(app, e, interactive ? "" : "ladderctl") == 0 ? kAccepted : kUsage;
  }
  if (conn.domain != before.domain || conn.sim_id != before.sim_id || conn.security != before.security)
    client.reset();
  if (standalone) {
    try {
      return standalone(conn);  // list, replay, plot: their own participants
    } catch (const transport::DdsError& e) {
      std::cerr << (interactive ? "" : "ladderctl: ") << e.what() << "\n";
      return kUsage;
    }
  }
  if (!action) return kNoCommand;
  if (const int code = make_client(conn, client); code != kAccepted) return code;
  Client* c = connect(conn, client);
  if (!c) return kNoServer;
  return action(*c, conn);
}

std::vector<std::string> split_words(const std::string& line) {
  std::vector<std::string> words;
  std::string word;
  bool in_word = false;
  char quote = 0;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char ch = line[i];
    if (quote) {
      if (ch == quote) quote = 0;
      else word += ch;
    } else if (ch == '"' || ch == '\'') {
      quote = ch;
      in_word = true;
    } else if (ch == '\\' && i + 1 < line.size()) {
      word += line[++i];
      in_word = true;
    } else if (std::isspace(static_cast<unsigned char>(ch))) {
      if (in_word) words.push_back(word);
      word.clear();
      in_word = false;
    } else {
      word += ch;
      in_word = true;
    }
  }
  if (in_word) words.push_back(word);
  return words;
}

}  // namespace ladder::ctl
