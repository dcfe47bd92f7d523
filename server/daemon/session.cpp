#include "daemon/session.hpp"

#include "transport/dds.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string_view>
#include <utility>

namespace ladder::daemon {

namespace {

using core::Vec2;
using transport::text_of;

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

// Each check throws std::invalid_argument with the user-facing reason; apply() turns it into a refusal.
void finite(double v, const char* name) {
  if (!std::isfinite(v)) throw std::invalid_argument(std::string(name) + " is " + number(v) + ", not a finite number");
}

Vec2 vec(double x, double y, const char* name) {
  finite(x, name);
  finite(y, name);
  return {x, y};
}

// hypot, not norm(): |(1e300, 0)| is 1e300, where the sum of squares overflows to inf.
Vec2 bounded(double x, double y, const char* name, double limit, const char* unit, const char* key) {
  const Vec2 v = vec(x, y, name);
  const double size = std::hypot(x, y);
  if (size > limit)
    throw std::invalid_argument(std::string(name) + " of " + number(size) + " " + unit + " is beyond the limit of " +
                                number(limit) + " " + unit + " (" + key + ")");
  return v;
}

Vec2 within_reach(double x, double y, const char* name, double reach) {
  const Vec2 v = vec(x, y, name);
  const double distance = std::hypot(x, y);
  if (distance > reach)
    throw std::invalid_argument(std::string(name) + " is " + number(distance) +
                                " m from the origin, beyond the reach of " + number(reach) + " m (commands.reach)");
  return v;
}

// A point on block i: `offset` from its centre must lie inside the block (1 % slack for rounding).
void on_block(const model::Ladder& l, int i, const Vec2& offset, const char* name) {
  const double half_diagonal = 0.5 * std::hypot(l.spec().length, l.spec().thickness);
  const double distance = std::hypot(offset.x(), offset.y());
  if (distance > 1.01 * half_diagonal)
    throw std::invalid_argument(std::string(name) + " is " + number(distance * 1e3) + " mm from block " +
                                std::to_string(i) + "'s centre, outside the block (at most " +
                                number(half_diagonal * 1e3) + " mm)");
}

// A grip's stiffness: 0 (the default) to kMaxStiffness.
double stiffness(double v) {
  finite(v, "the stiffness");
  if (!(v >= 0 && v <= kMaxStiffness))
    throw std::invalid_argument("the stiffness must be from 0 (the default) to " + number(kMaxStiffness) +
                                " N/m, not " + number(v));
  return v;
}

// A grip's angle: finite and within kMaxAngle.
double angle_in_range(double v) {
  finite(v, "the angle");
  if (!(std::abs(v) <= kMaxAngle))
    throw std::invalid_argument("the angle must be from -" + number(kMaxAngle) + " to " + number(kMaxAngle) +
                                " rad, not " + number(v));
  return v;
}

// The turn of `angle` nearest the block's own angle (unwrapped, so several turns from 0 after tips): the grip's
// torsional spring then turns it at most half a turn. An angle already that near is kept exactly as given.
double nearest_turn(double angle, double block_angle) {
  if (std::abs(angle - block_angle) <= M_PI) return angle;
  return block_angle + std::remainder(angle - block_angle, 2 * M_PI);
}

scene::TimedCommand timed(const char* command) {
  scene::TimedCommand t;
  t.command = command;
  return t;
}

}  // namespace

const char* to_string(ladder_msg_CommandKind kind) {
  switch (kind) {
    case ladder_msg_TIP: return "tip";
    case ladder_msg_POKE: return "poke";
    case ladder_msg_PUSH: return "push";
    case ladder_msg_GRAB: return "grab";
    case ladder_msg_DRAG: return "drag";
    case ladder_msg_RELEASE: return "release";
    case ladder_msg_BREAK_HINGE: return "break";
    case ladder_msg_JOIN_HINGE: return "join";
    case ladder_msg_PAUSE: return "pause";
    case ladder_msg_RESUME: return "resume";
    case ladder_msg_STEP: return "step";
    case ladder_msg_RESET: return "reset";
    case ladder_msg_SET_PARAM: return "set";
    case ladder_msg_LOAD_SCENE: return "load";
  }
  return "unknown";
}

Session::Session(const scene::Scene& scene, std::string scenes_dir, Limits limits, Rates rates)
    : sim_(std::make_unique<scene::Simulation>(scene)),
      base_(scene),
      scenes_dir_(std::move(scenes_dir)),
      limits_(limits),
      rates_(rates) {}

void Session::start(const scene::Scene& scene) {
  sim_ = std::make_unique<scene::Simulation>(scene);
  pending_steps_ = 0;
  failed_ = false;
  ++generation_;
}

void Session::step() {
  try {
    sim_->step();
  } catch (const std::runtime_error&) {
    paused_ = true;
    pending_steps_ = 0;
    failed_ = true;
    throw;
  }
  failed_ = false;
}

Outcome Session::reset() {
  if (!failed_) {
    start(sim_->scene());  // the live settings kept
    return {};
  }
  const bool changed = scene::live_settings(base_) != scene::live_settings(sim_->scene());
  start(base_);
  if (!changed) return {true, "the last step failed: the scene restarted (its settings were unchanged)"};
  return {true, "the last step failed: the scene restarted with its own settings (the live settings dropped)"};
}

Outcome Session::apply(const ladder_msg_Command& c) {
  model::Ladder& l = sim_->ladder();
  // The kind's bytes as a number first: an enum object holding a value beyond the enum's range (a caller that
  // filled the struct from elsewhere) is undefined behaviour at its first read.
  static_assert(sizeof c.kind == sizeof(std::int32_t));
  std::int32_t kind = 0;
  std::memcpy(&kind, &c.kind, sizeof kind);
  if (kind < 0 || kind > ladder_msg_LOAD_SCENE) return {false, "unknown command kind " + std::to_string(kind)};
  try {
    switch (static_cast<ladder_msg_CommandKind>(kind)) {
      case ladder_msg_TIP:
        sim_->apply(timed("tip"));
        break;
      case ladder_msg_POKE: {
        scene::TimedCommand t = timed("poke");
        t.impulse = bounded(c.a, c.b, "the impulse", limits_.max_impulse, "N s", "commands.max_impulse");
        l.check_block(c.block);
        t.block = c.block;
        if (c.has_point) {
          t.at = vec(c.c, c.d, "the point");
          t.has_at = true;
          on_block(l, c.block, t.at - l.block_centre(c.block), "the point");
        }
        sim_->apply(t);
        break;
      }
      case ladder_msg_PUSH: {
        scene::TimedCommand t = timed("push");
        t.force = bounded(c.a, c.b, "the force", limits_.max_force, "N", "commands.max_force");
        t.at = c.has_point ? vec(c.c, c.d, "the point") : Vec2::Zero();
        t.has_at = true;
        finite(c.e, "the duration");
        if (!(c.e > 0 && c.e <= limits_.max_duration))
          throw std::invalid_argument("the duration must be > 0 and at most " + number(limits_.max_duration) +
                                      " s (commands.max_duration), not " + number(c.e));
        t.duration = c.e;
        l.check_block(c.block);
        t.block = c.block;
        on_block(l, c.block, t.at, "the point");
        sim_->apply(t);
        break;
      }
      case ladder_msg_GRAB: {
        model::Ladder::Grip g;
        g.local = c.has_point ? vec(c.c, c.d, "the point") : Vec2::Zero();
        g.stiffness = stiffness(c.e);
        const double angle = c.has_angle ? angle_in_range(c.f) : 0;
        l.check_block(c.block);
        g.block = c.block;
        on_block(l, c.block, g.local, "the point");
        g.target = c.has_target ? within_reach(c.a, c.b, "the target", limits_.reach)
                                : l.block_centre(c.block) + l.world().part_rotation(c.block) * g.local;
        g.hold_angle = c.has_angle;
        // Without an angle, f is not read at all: whatever a client left there (NaN too) must not reach the State.
        g.angle = c.has_angle ? nearest_turn(angle, l.block_angle(c.block)) : 0;
        l.grab(g);
        break;
      }
      case ladder_msg_DRAG: {
        const Vec2 target = within_reach(c.a, c.b, "the target", limits_.reach);
        double angle = c.has_angle ? angle_in_range(c.f) : 0;
        const auto& grips = l.grips();
        const bool grabbed = std::any_of(grips.begin(), grips.end(), [&](const auto& g) { return g.block == c.block; });
        if (grabbed && c.has_angle) angle = nearest_turn(angle, l.block_angle(c.block));
        l.drag(c.block, target, c.has_angle ? &angle : nullptr);  // refuses a block that is not grabbed
        break;
      }
      case ladder_msg_RELEASE:
        l.release(c.block);
        break;
      case ladder_msg_BREAK_HINGE:
      case ladder_msg_JOIN_HINGE: {
        scene::TimedCommand t = timed(c.kind == ladder_msg_BREAK_HINGE ? "break" : "join");
        t.hinge = c.hinge;
        sim_->apply(t);
        break;
      }
      case ladder_msg_PAUSE:
        if (paused_) throw std::invalid_argument("already paused");
        paused_ = true;
        break;
      case ladder_msg_RESUME:
        if (!paused_) throw std::invalid_argument("not paused");
        paused_ = false;
        pending_steps_ = 0;
        break;
      case ladder_msg_STEP:
        if (!paused_) throw std::invalid_argument("step works while paused: send pause first");
        if (c.count < 1 || c.count > limits_.max_step_count)
          throw std::invalid_argument("the step count must be 1 to " + std::to_string(limits_.max_step_count) +
                                      " (commands.max_step_count), not " + std::to_string(c.count));
        pending_steps_ += c.count;
        break;
      case ladder_msg_RESET:
        return reset();
      case ladder_msg_SET_PARAM:
        return set_param(text_of(c.text));
      case ladder_msg_LOAD_SCENE:
        return load(text_of(c.text));
      default:
        throw std::invalid_argument("unknown command kind " + std::to_string(kind));
    }
  } catch (const std::invalid_argument& e) {
    return {false, e.what()};
  }
  return {};
}

namespace {
struct Fnv {
  std::uint64_t h = 1469598103934665603ull;
  void bytes(const void* p, std::size_t n) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  }
  template <class T>
  void value(const T& v) {
    bytes(&v, sizeof v);
  }
};
}  // namespace

std::uint64_t Session::state_hash() const {
  const model::Ladder& l = sim_->ladder();
  const core::Snapshot snap = l.world().save();
  Fnv f;
  f.value(snap.t);
  f.value(snap.adaptive_h);  // shapes the adaptive step's next sub-steps
  for (const core::BodyState& b : snap.bodies) {
    f.value(b.x.x()), f.value(b.x.y()), f.value(b.v.x()), f.value(b.v.y());
    f.value(b.q.c), f.value(b.q.s), f.value(b.th), f.value(b.w);
  }
  for (const core::AppliedForce& a : snap.forces) {
    f.value(a.part), f.value(a.local.x()), f.value(a.local.y()), f.value(a.force.x()), f.value(a.force.y());
    f.value(a.until);
  }
  for (const model::HingeInfo& h : l.hinges()) f.value(h.corner), f.value(h.status), f.value(h.flips);
  for (const model::Ladder::Grip& g : l.grips()) {
    f.value(g.block), f.value(g.target.x()), f.value(g.target.y()), f.value(g.hold_angle), f.value(g.angle);
  }
  return f.h;
}

Outcome Session::set_param(const std::string& setting) {
  const size_t eq = setting.find('=');
  const std::string key = setting.substr(0, eq);
  if (key.starts_with("server.")) {
    if (eq == std::string::npos) return {false, setting + ": expected key=value"};
    const std::string text = setting.substr(eq + 1);
    char* end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    const bool is_number = !text.empty() && end == text.c_str() + text.size() && std::isfinite(v);
    if (key == "server.real_time_factor") {
      if (!is_number || !(v == 0 || (v >= kMinRealTimeFactor && v <= kMaxRealTimeFactor)))
        return {false, setting + ": server.real_time_factor must be a number from " + number(kMinRealTimeFactor) +
                           " to " + number(kMaxRealTimeFactor) + ", or 0 (as fast as possible)"};
      rates_.real_time_factor = v;
    } else if (key == "server.publish_rate") {
      if (!is_number || !(v >= kMinPublishRate && v <= rates_.physics))
        return {false, setting + ": server.publish_rate must be a number from " + number(kMinPublishRate) +
                           " Hz to the physics rate (" + number(rates_.physics) + " Hz)"};
      rates_.publish = v;
    } else if (key == "server.physics_rate") {
      return {false, setting + ": server.physics_rate cannot change while the server runs; set it in ladderd.toml"};
    } else {
      return {false, setting + ": unknown key " + key +
                         " (server keys: server.real_time_factor, server.publish_rate)"};
    }
    return {};
  }
  try {
    sim_->set(setting);
  } catch (const scene::SceneError& e) {
    return {false, e.what()};
  }
  return {};
}

std::string scene_names(const std::string& dir) {
  std::string names;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec))
    if (entry.path().extension() == ".toml") names += (names.empty() ? "" : ", ") + entry.path().stem().string();
  return names;
}

Outcome Session::load(const std::string& name) {
  namespace fs = std::filesystem;
  if (name.empty()) return {false, "load: give a scene name, e.g. classic"};
  if (name.find('/') != std::string::npos || name.find('\\') != std::string::npos || name.starts_with("."))
    return {false, "not permitted: scenes are loaded by name from the server's scene directory " + scenes_dir_};
  const fs::path path = fs::path(scenes_dir_) / (name.ends_with(".toml") ? name : name + ".toml");
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) {
    return {false, "no scene '" + name + "' in " + scenes_dir_ + " (available: " + scene_names(scenes_dir_) + ")"};
  }
  try {
    const scene::Scene scene = scene::load_scene(path.string());
    start(scene);
    base_ = scene;
  } catch (const scene::SceneError& e) {
    return {false, e.what()};
  }
  return {};
}

}  // namespace ladder::daemon
