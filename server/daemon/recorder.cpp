#include "daemon/recorder.hpp"

#include "ladderlcm/checkpoint_t.hpp"
#include "ladderlcm/event_t.hpp"
#include "ladderlcm/scene_t.hpp"
#include "ladderlcm/state_t.hpp"
#include "transport/dds.hpp"
#include "transport/lcm_decode.hpp"

#include <utility>

namespace ladder::daemon {

using transport::copy_text;

namespace {

// A text the server wrote (a command's reason, an event's kind or detail) as a log can hold it: LCM writes a C
// string, which ends at a NUL (the bytes after one were counted but not written, and the reader refused the whole
// log), and a reader takes at most kLogMaxText bytes of it. Longer, it is cut on a character's boundary and ends in
// "...". (The scene's own texts, which the re-run needs whole, are bounded where a scene is read.)
std::string loggable(std::string_view s) { return cut_text(s.substr(0, s.find('\0')), transport::kLogMaxText); }

}  // namespace

void Recorder::record(const Outbox& out) {
  const std::int64_t now = transport::now_us();
  for (const SceneOut& s : out.scenes) {
    ladderlcm::scene_t m;
    m.utime = now;
    m.sim_id = sim_id_;
    m.generation = static_cast<std::int32_t>(s.generation);
    m.name = s.name;
    m.source = s.source;
    m.toml = s.text;
    m.overrides = s.overrides;
    m.num_overrides = static_cast<std::int32_t>(s.overrides.size());
    m.clear_timeline = s.timeline_dropped;
    m.blocks = s.blocks;
    m.length = s.length;
    m.thickness = s.thickness;
    m.hinge_inset = s.inset;
    m.dt = s.dt;
    m.top = s.top;
    m.masses = s.masses;
    m.server_version = kServerVersion;
    log_.write(transport::kSceneChannel, now, m, false);
  }
  for (const CommandOut& c : out.commands) {
    ladderlcm::command_t m = command_record(c.command);
    m.utime = now;
    m.generation = static_cast<std::int32_t>(c.generation);
    m.step = static_cast<std::int64_t>(c.step);
    m.command_seq = static_cast<std::int64_t>(c.seq);
    m.accepted = c.accepted;
    m.reason = loggable(c.reason);
    log_.write(transport::kCommandChannel, now, m, false);
  }
  for (const EventOut& e : out.events) {
    ladderlcm::event_t m;
    m.utime = now;
    m.seq = static_cast<std::int64_t>(++logged_events_);
    m.t = e.t;
    m.kind = loggable(e.kind);
    m.hinge = e.hinge;
    m.energy_removed = e.energy_removed;
    m.detail = loggable(e.detail);
    log_.write(transport::kEventChannel, now, m, false);
  }
  const auto place = [&](const char* channel, const CheckpointOut& c) {
    ladderlcm::checkpoint_t m;
    m.utime = now;
    m.generation = static_cast<std::int32_t>(c.generation);
    m.step = static_cast<std::int64_t>(c.step);
    m.sim_time = c.t;
    m.commands_applied = static_cast<std::int64_t>(c.commands_applied);
    m.state_hash = static_cast<std::int64_t>(c.hash);
    log_.write(channel, now, m, false);
  };
  for (const CheckpointOut& c : out.checkpoints) place(transport::kCheckpointChannel, c);
  for (const CheckpointOut& c : out.failures) place(transport::kFailureChannel, c);
  for (const CheckpointOut& c : out.non_finite) place(transport::kNonFiniteChannel, c);
}

void Recorder::record_state(const StateFrame& f, std::uint64_t seq) {
  ladderlcm::state_t m;
  m.utime = transport::now_us();
  m.generation = static_cast<std::int32_t>(f.generation);
  m.seq = static_cast<std::int64_t>(seq);
  m.step = static_cast<std::int64_t>(f.step);
  m.sim_time = f.t;
  m.paused = f.paused;
  m.commands_applied = static_cast<std::int64_t>(f.commands_applied);
  m.energy = f.energy;
  const std::size_t n = f.hinge_corner.size();
  m.num_blocks = static_cast<std::int32_t>(n);
  m.x.resize(n), m.y.resize(n), m.theta.resize(n), m.corner.resize(n), m.status.resize(n), m.flips.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    m.x[i] = f.poses[3 * i], m.y[i] = f.poses[3 * i + 1], m.theta[i] = f.poses[3 * i + 2];
    m.corner[i] = static_cast<std::int8_t>(f.hinge_corner[i]);
    m.status[i] = static_cast<std::int8_t>(f.hinge_status[i]);
    m.flips[i] = static_cast<std::int32_t>(f.hinge_flips[i]);
  }
  log_.write(transport::kStateChannel, m.utime, m, true);
}

ladderlcm::command_t command_record(const ladder_msg_Command& c) {
  ladderlcm::command_t m;
  m.client_id = transport::text_of(c.client_id);
  m.command_id = static_cast<std::int64_t>(c.command_id);
  m.kind = static_cast<std::int32_t>(c.kind);
  m.block = c.block;
  m.hinge = c.hinge;
  m.count = static_cast<std::int32_t>(c.count);
  m.has_point = c.has_point;
  m.has_target = c.has_target;
  m.has_angle = c.has_angle;
  m.a = c.a, m.b = c.b, m.c = c.c, m.d = c.d, m.e = c.e, m.f = c.f;
  m.text = transport::text_of(c.text);
  return m;
}

CommandFields fields_of(const ladderlcm::command_t& m) {
  CommandFields f = shared_fields(m);
  f.kind = m.kind;
  f.text = m.text;
  return f;
}

}  // namespace ladder::daemon
