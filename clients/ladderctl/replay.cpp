#include "replay.hpp"

#include "directory.hpp"
#include "stop_signals.hpp"
#include "ladderlcm/event_t.hpp"
#include "ladderlcm/scene_t.hpp"
#include "ladderlcm/state_t.hpp"
#include "scene/scene.hpp"
#include "transport/default_config.hpp"
#include "transport/dds.hpp"
#include "transport/lcm_log.hpp"
#include "transport/topics.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <map>
#include <sstream>
#include <thread>
#include <vector>

namespace ladder::ctl {

namespace {

using transport::copy_text;
std::atomic<bool> g_stop{false};
constexpr double kNameCheckSeconds = 1.0;  // how long the replay looks for a ladder of its sim id first

// What a viewer draws that a scene record has no field of its own for (ladder.depth, ladder.hinge,
// ladder.end_radius): the scene made again from the record's text and overrides, as the re-run makes it, and its
// settings put in SceneInfo's options as the live server puts them. Only the keys that are fixed for a scene: the
// live ones (sim.*, solver.*, damping.*) may have been set since the text was recorded. Throws scene::SceneError
// when the text does not make a scene in this build.
std::string fixed_settings(const ladderlcm::scene_t& s) {
  const scene::Scene sc = scene::remake_scene(s.toml, s.source, s.overrides, s.clear_timeline);
  std::istringstream lines(scene::live_settings(sc));
  std::string out;
  for (std::string line; std::getline(lines, line);)
    if (!scene::is_live_key(line.substr(0, line.find('=')))) out += line + "\n";
  return out;
}
extern "C" void on_stop(int) { g_stop = true; }

class Publisher {
 public:
  Publisher(int domain, const std::string& sim_id)
      : sim_id_(sim_id),
        participant_((transport::use_default_config(transport::kDefaultCycloneConfig),
                      transport::make_participant(static_cast<dds_domainid_t>(domain)))),
        topics_(participant_),
        scene_w_(participant_, topics_.scene_info, transport::Profile::SceneInfo),
        state_w_(participant_, topics_.state, transport::Profile::State),
        event_w_(participant_, topics_.event, transport::Profile::Event) {}

  // Publishes a scene record; `options` as fixed_settings() made them ("" if the scene did not build).
  void scene(const ladderlcm::scene_t& s, const std::string& options) {
    ladder_msg_SceneInfo m{};
    copy_text(m.sim_id, sim_id_);
    m.generation = static_cast<std::uint32_t>(s.generation);
    copy_text(m.scene_name, s.name);
    copy_text(m.description, "replay of a recorded session");
    copy_text(m.server_version, s.server_version);
    m.replay = true;
    m.blocks = static_cast<std::uint32_t>(s.blocks);
    m.length = s.length;
    m.thickness = s.thickness;
    m.hinge_inset = s.hinge_inset;
    transport::lend(m.masses, s.masses);
    copy_text(m.top, s.top);
    m.dt = s.dt;
    copy_text(m.options, options);
    scene_w_.write(m);
  }

  // Publishes a recorded state; false (nothing published) if a hinge status is not one the message can carry.
  bool state(const ladderlcm::state_t& s) {
    if (!std::all_of(s.status.begin(), s.status.end(), [](std::int8_t v) { return v >= 0 && v <= 2; })) return false;
    const auto n = static_cast<std::size_t>(s.num_blocks);
    poses_.resize(3 * n);
    corner_.resize(n);
    status_.resize(n);
    flips_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      poses_[3 * i] = s.x[i];
      poses_[3 * i + 1] = s.y[i];
      poses_[3 * i + 2] = s.theta[i];
      corner_[i] = static_cast<std::uint8_t>(s.corner[i]);
      status_[i] = static_cast<ladder_msg_HingeStatus>(s.status[i]);
      flips_[i] = static_cast<std::uint32_t>(s.flips[i]);
    }
    ladder_msg_State m{};
    copy_text(m.sim_id, sim_id_);
    m.generation = static_cast<std::uint32_t>(s.generation);
    m.seq = ++seq_;
    m.step = static_cast<std::uint64_t>(s.step);
    m.sim_time = s.sim_time;
    m.paused = s.paused;
    m.commands_applied = static_cast<std::uint64_t>(s.commands_applied);
    m.energy = s.energy;
    transport::lend_blocks(m, poses_, corner_, status_, flips_);
    state_w_.write(m);
    return true;
  }

  void event(const ladderlcm::event_t& e) {
    ladder_msg_Event m{};
    copy_text(m.sim_id, sim_id_);
    m.seq = static_cast<std::uint64_t>(e.seq);
    m.t = e.t;
    copy_text(m.kind, e.kind);
    m.hinge = e.hinge;
    m.energy_removed = e.energy_removed;
    copy_text(m.detail, e.detail);
    event_w_.write(m);
  }

 private:
  std::string sim_id_;
  transport::Entity participant_;
  transport::Topics topics_;
  transport::Writer<ladder_msg_SceneInfo> scene_w_;
  transport::Writer<ladder_msg_State> state_w_;
  transport::Writer<ladder_msg_Event> event_w_;
  std::vector<double> poses_;  // x, y, theta per block
  std::vector<std::uint8_t> corner_;
  std::vector<ladder_msg_HingeStatus> status_;
  std::vector<std::uint32_t> flips_;
  std::uint64_t seq_ = 0;
};

using Clock = std::chrono::steady_clock;

// Paces the replay by the events' recorded wall times. A pause of more than kLongPause in the recording (a server
// left paused, or a forged timestamp 2^62 us ahead) is played as kLongPause: a replay never stalls on one gap.
// Times that go back a little (states and the other records are stamped on different paths) wait for nothing; times
// that go back by more than kLongPause (the recording host's clock stepped back, or the events after a forged
// timestamp ahead) are a new start: the replay is paced from them on, as before the step.
class Pacer {
 public:
  static constexpr double kLongPause = 10e6;  // [us of recorded time]
  explicit Pacer(double speed) : speed_(speed) {}

  void wait(std::int64_t utime, const std::atomic<bool>& stop) {
    const auto t = static_cast<double>(utime);  // in doubles: no overflow on any timestamp
    if (!started_) started_ = true, start_ = Clock::now(), latest_ = t;
    if (latest_ - t > kLongPause) {  // (the pacing would otherwise wait for nothing from here to the end)
      ++stepped_back_;
      latest_ = t;
    }
    double behind = 0;  // how far this event lies before the latest one [us]
    if (t > latest_) {
      played_ += std::min(t - latest_, kLongPause);
      shortened_ += t - latest_ > kLongPause;
      latest_ = t;
    } else {
      behind = latest_ - t;
    }
    if (speed_ <= 0 || behind > 0) return;
    const auto due = start_ + std::chrono::microseconds(static_cast<std::int64_t>(played_ / speed_));
    while (!stop && Clock::now() < due)
      std::this_thread::sleep_for(std::min<Clock::duration>(due - Clock::now(), std::chrono::milliseconds(50)));
  }
  std::uint64_t shortened() const { return shortened_; }
  std::uint64_t stepped_back() const { return stepped_back_; }

 private:
  double speed_;
  bool started_ = false;
  Clock::time_point start_{};
  double latest_ = 0, played_ = 0;  // [us] the latest timestamp so far; recorded time played, pauses shortened
  std::uint64_t shortened_ = 0, stepped_back_ = 0;
};

}  // namespace

int replay(const ReplayOptions& o) {
  std::unique_ptr<transport::LogReader> reader;
  try {
    reader = std::make_unique<transport::LogReader>(o.log);
  } catch (const std::exception& e) {
    std::cerr << "ladderctl: " << e.what() << "\n";
    return 2;
  }
  // A sim id that a ladder on the domain already answers to (a live ladderd, or another replay) is refused: two
  // publishers of one name would send the live server's clients a replay's states, and their commands to a replay,
  // which takes none. (Discovery, as `ladderctl list`: a ladder's SceneInfo is kept for late joiners, so it comes
  // within the time it takes DDS to find the other side.)
  for (const client::LadderEntry& l : client::discover(o.domain, kNameCheckSeconds).ladders) {
    if (l.sim_id != o.sim_id) continue;
    std::cerr << "ladderctl: '" << o.sim_id << "' on DDS domain " << o.domain << " is already "
              << (l.replay ? "a replay" : "served by a live ladderd") << " (host " << l.host
              << "); give this replay another sim id with --as\n";
    return 2;
  }
  Publisher out(o.domain, o.sim_id);
  g_stop = false;
  const client::StopSignals stop(on_stop);
  std::cout << "replaying " << o.log << " as sim id '" << o.sim_id << "' on DDS domain " << o.domain
            << " (Ctrl-C to stop)" << std::endl;  // (at once, also into a file or a pipe)
  Pacer pacer(o.speed);
  std::uint64_t states = 0, events = 0, bad_states = 0, early_states = 0;
  double last_t = 0, last_early = 0;
  std::map<std::int32_t, std::int32_t> blocks;  // of each generation whose scene record has come
  // The last scene record's text and what it made: a live setting's record repeats its generation's text.
  std::string made_from, options;
  std::vector<std::string> made_with;
  bool tried = false;
  int rc = 0;
  try {
    while (!g_stop) {
      const auto e = reader->next();
      if (!e) break;
      const auto wait_for = [&](std::int64_t utime) { pacer.wait(utime, g_stop); };
      if (e->channel == transport::kSceneChannel) {
        const auto s = reader->decode<ladderlcm::scene_t>(*e);
        if (const auto b = blocks.try_emplace(s.generation, s.blocks).first; b->second != s.blocks)
          reader->refuse(*e, "scene_t", "generation " + std::to_string(s.generation) + " has " +
                                            std::to_string(s.blocks) + " blocks here, " + std::to_string(b->second) +
                                            " in its first scene record");
        if (!tried || s.toml != made_from || s.overrides != made_with) {
          tried = true;
          made_from = s.toml;
          made_with = s.overrides;
          try {
            options = fixed_settings(s);
          } catch (const std::exception& ex) {
            options.clear();
            std::cerr << "ladderctl: " << o.log << ": the scene of generation " << s.generation
                      << " does not build here (" << ex.what()
                      << "); viewers draw it at the default depth with square corners\n";
          }
        }
        out.scene(s, options);  // always, so a viewer knows what it sees
      } else if (e->channel == transport::kStateChannel) {
        const auto s = reader->decode<ladderlcm::state_t>(*e);
        // A viewer draws a state on its scene: their numbers of blocks must agree. (A state may come just before
        // the scene record of its generation: the two reach the recorder by different paths.)
        if (const auto b = blocks.find(s.generation); b != blocks.end() && b->second != s.num_blocks)
          reader->refuse(*e, "state_t", "a state of " + std::to_string(s.num_blocks) + " blocks in a scene of " +
                                            std::to_string(b->second));
        if (s.sim_time + 1e-9 < o.from) {
          ++early_states;
          last_early = s.sim_time;
          continue;
        }
        wait_for(e->utime);
        if (!out.state(s)) {
          ++bad_states;
          continue;
        }
        ++states;
        last_t = s.sim_time;
      } else if (e->channel == transport::kEventChannel) {
        const auto ev = reader->decode<ladderlcm::event_t>(*e);
        if (ev.t + 1e-9 < o.from) continue;
        wait_for(e->utime);
        out.event(ev);
        ++events;
      }
    }
  } catch (const std::exception& ex) {  // a bad event: what came before it was played
    std::cerr << "ladderctl: " << ex.what() << "; the replay stops there\n";
    rc = 2;
  }
  if (!reader->damage().empty()) std::cerr << "ladderctl: " << o.log << ": " << reader->damage() << "\n";
  if (pacer.shortened())
    std::cerr << "ladderctl: " << o.log << ": " << pacer.shortened() << " pause(s) longer than "
              << Pacer::kLongPause / 1e6 << " s in the recording played as " << Pacer::kLongPause / 1e6 << " s\n";
  if (pacer.stepped_back())
    std::cerr << "ladderctl: " << o.log << ": the recorded times went back by more than " << Pacer::kLongPause / 1e6
              << " s " << pacer.stepped_back() << " time(s) (a clock step, or a forged time before it); paced on "
              << "from each\n";
  if (bad_states)
    std::cerr << "ladderctl: " << o.log << ": skipped " << bad_states
              << " state(s) with a hinge status other than 0, 1 or 2 (hinged, locked, broken)\n";
  // Nothing a viewer could draw is a failure of the input, as a log that cannot be read is (unless stopped first):
  // said instead of "replayed 0 states".
  if (states > 0 || rc != 0 || g_stop)
    std::printf("replayed %llu states and %llu events, up to t = %.3f s\n", static_cast<unsigned long long>(states),
                static_cast<unsigned long long>(events), last_t);
  std::fflush(stdout);
  if (states == 0 && rc == 0 && !g_stop) {
    rc = 2;
    if (bad_states > 0)
      std::cerr << "ladderctl: " << o.log << ": every state was skipped; nothing to replay\n";
    else if (early_states > 0)
      std::fprintf(stderr, "ladderctl: %s: its states end at t = %.3f s, before --from %g s; nothing to replay\n",
                   o.log.c_str(), last_early, o.from);
    else
      std::cerr << "ladderctl: " << o.log << ": no state in the log; nothing to replay\n";
  }
  // Transient-local data lives as long as its writer: give late viewers a moment to take the last state.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  return rc;
}

}  // namespace ladder::ctl
