#include "daemon/session.hpp"
#include "ladder/printable.hpp"

#include <toml++/toml.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace ladder::daemon {

namespace {

using core::Vec2;

// Six digits, or as many as it takes to tell the value from a limit it is compared with: an impulse of 1.0000001 is
// "beyond the limit of 1", not "1 ... beyond the limit of 1".
std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  if (!std::isfinite(v) || std::strtod(buf, nullptr) == v) return buf;
  const auto r = std::to_chars(buf, buf + sizeof buf, v);  // the shortest text that reads back as v
  return std::string(buf, r.ptr);
}

// Each check throws std::invalid_argument with the user-facing reason; apply() turns it into a refusal.
void finite(double v, const char* name) {
  if (!std::isfinite(v)) throw std::invalid_argument(std::string(name) + " is " + number(v) + ", not a finite number");
}

void finite(const Vec2& v, const char* name) {
  finite(v.x(), name);
  finite(v.y(), name);
}

// hypot, not norm(): |(1e300, 0)| is 1e300, where the sum of squares overflows to inf.
void bounded(const Vec2& v, const char* name, double limit, const char* unit, const char* key) {
  finite(v, name);
  const double size = std::hypot(v.x(), v.y());
  if (size > limit)
    throw std::invalid_argument(std::string(name) + " of " + number(size) + " " + unit + " is beyond the limit of " +
                                number(limit) + " " + unit + " (" + key + ")");
}

void within_reach(const Vec2& v, const char* name, double reach) {
  finite(v, name);
  const double distance = std::hypot(v.x(), v.y());
  if (distance > reach)
    throw std::invalid_argument(std::string(name) + " is " + number(distance) +
                                " m from the origin, beyond the reach of " + number(reach) + " m (commands.reach)");
}

// A grip's stiffness: 0 (the default) to kMaxStiffness.
void check_stiffness(double v) {
  finite(v, "the stiffness");
  if (!(v >= 0 && v <= kMaxStiffness))
    throw std::invalid_argument("the stiffness must be from 0 (the default) to " + number(kMaxStiffness) +
                                " N/m, not " + number(v));
}

// A grip's angle: finite and within kMaxAngle.
void check_angle(const std::optional<double>& v) {
  if (!v) return;
  finite(*v, "the angle");
  if (!(std::abs(*v) <= kMaxAngle))
    throw std::invalid_argument("the angle must be from -" + number(kMaxAngle) + " to " + number(kMaxAngle) +
                                " rad, not " + number(*v));
}

// The server's limits on an action, checked before the ladder sees it, in the order a reason is given when
// several are broken. The block must exist before a point is measured from it: the ladder's check comes first.
// Whether a poke's or push's point lies on its block is the ladder's own check (Ladder::poke, Ladder::push), the
// same for a client's command and a scene's timeline; a grab's is made here.
struct Check {
  const Limits& limits;
  const model::Ladder& l;
  void operator()(const model::Tip&) const {}
  void operator()(const model::Poke& p) const {
    bounded(p.impulse, "the impulse", limits.max_impulse, "N s", "commands.max_impulse");
    l.check_block(p.block);
    if (p.at) {
      within_reach(*p.at, "the point", limits.reach);  // (finite; and 1e308 away, its offset from the block is not)
    }
  }
  void operator()(const model::Push& p) const {
    bounded(p.force, "the force", limits.max_force, "N", "commands.max_force");
    finite(p.at, "the point");
    finite(p.duration, "the duration");
    if (!(p.duration > 0 && p.duration <= limits.max_duration))
      throw std::invalid_argument("the duration must be > 0 and at most " + number(limits.max_duration) +
                                  " s (commands.max_duration), not " + number(p.duration));
    l.check_block(p.block);
  }
  void operator()(const model::Grab& g) const {
    finite(g.local, "the point");
    check_stiffness(g.stiffness);
    check_angle(g.angle);
    l.check_block(g.block);
    l.check_on_block(g.block, g.local, "the point");
    if (g.target) within_reach(*g.target, "the target", limits.reach);
  }
  void operator()(const model::Drag& d) const {
    within_reach(d.target, "the target", limits.reach);
    check_angle(d.angle);
  }
  void operator()(const model::Release&) const {}
  void operator()(const model::Break&) const {}
  void operator()(const model::Join&) const {}
};

}  // namespace

Session::Session(const scene::Scene& scene, std::string scenes_dir, Limits limits, Rates rates)
    : sim_(std::make_unique<scene::Simulation>(scene)),
      base_(scene),
      scenes_dir_(std::move(scenes_dir)),
      limits_(limits),
      rates_(rates) {}

void Session::start(const scene::Scene& scene) {
  sim_ = std::make_unique<scene::Simulation>(scene);
  sim_->set_interrupt(interrupted_);
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
  if (!changed)
    return {true, "the last step failed: the scene restarted (its settings were unchanged), paused: resume runs it"};
  return {true,
          "the last step failed: the scene restarted with its own settings (the live settings dropped), paused: resume "
          "runs it"};
}

Outcome Session::apply(const CommandFields& f) {
  try {
    return apply(request_of(f));
  } catch (const std::invalid_argument& e) {  // an unknown kind
    return {false, e.what()};
  }
}

Outcome Session::apply(const Request& r) {
  try {
    if (const auto* action = std::get_if<model::Action>(&r)) {
      std::visit(Check{limits_, sim_->ladder()}, *action);
      sim_->ladder().apply(*action);
      return {};
    }
    return std::visit([this](const auto& v) { return verb(v); }, std::get<Verb>(r));
  } catch (const std::invalid_argument& e) {
    return {false, e.what()};
  }
}

Outcome Session::verb(const Pause&) {
  if (paused_) throw std::invalid_argument("already paused");
  paused_ = true;
  return {};
}

Outcome Session::verb(const Resume&) {
  if (!paused_) throw std::invalid_argument("not paused");
  paused_ = false;
  pending_steps_ = 0;
  return {};
}

Outcome Session::verb(const Step& s) {
  if (!paused_) throw std::invalid_argument("step works while paused: send pause first");
  if (s.count < 1 || s.count > limits_.max_step_count)
    throw std::invalid_argument("the step count must be 1 to " + std::to_string(limits_.max_step_count) +
                                " (commands.max_step_count), not " + std::to_string(s.count));
  pending_steps_ += s.count;
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

// `text` as a TOML integer or float, if it is one and nothing else.
std::optional<double> toml_number(const std::string& text) {
  try {
    const toml::table t = toml::parse("v = " + text);
    if (t.size() != 1) return std::nullopt;
    if (const auto* i = t["v"].as_integer()) return static_cast<double>(i->get());
    if (const auto* f = t["v"].as_floating_point()) return f->get();
  } catch (const toml::parse_error&) {
  }
  return std::nullopt;
}

// The server's own live keys, which set_param() takes before a setting reaches the scene.
constexpr const char* kServerLiveKeys = "server.real_time_factor, server.publish_rate";

namespace {
// A client's text as a refusal quotes it: a setting or a scene name of up to 1024 characters would fill the 512 of an
// answer's reason before the reason came, so a long one is named by its first 80 characters and its length.
constexpr std::size_t kShown = 80;
std::string quoted(const std::string& text) {
  return text.size() <= kShown + 20 ? text
                                    : std::string(first_characters(text, kShown)) + "... (" +
                                          std::to_string(text.size()) + " characters)";
}
}  // namespace

Outcome Session::set_param(const std::string& full) {
  const std::string setting = quoted(full);  // a refusal names the setting first
  const size_t eq = full.find('=');
  const std::string key = full.substr(0, eq);
  if (key.starts_with("server.")) {
    if (eq == std::string::npos) return {false, setting + ": expected key=value"};
    // Read as TOML, as the scene's keys are (`sim.dt=1e-3`, `0x10`, `1_000` alike); strtod took `0x10` but not
    // `1_000`, and ` 5`.
    const std::optional<double> toml_value = toml_number(full.substr(eq + 1));
    const double v = toml_value.value_or(0);
    const bool is_number = toml_value && std::isfinite(v);
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
      return {false, setting + ": unknown key" + (key.size() <= kShown ? " " + key : "") +
                         " (server keys: " + kServerLiveKeys + ")"};
    }
    return {};
  }
  // A server key without its table, or as ladderd's option says it (`set rtf 0.25`): named, where the scene's keys
  // would offer the nearest of theirs ('sim.dt').
  for (const auto& [alias, server_key] : {std::pair{"rtf", "server.real_time_factor"},
                                          {"real_time_factor", "server.real_time_factor"},
                                          {"publish_rate", "server.publish_rate"},
                                          {"physics_rate", "server.physics_rate"}})
    if (key == alias) return {false, setting + ": unknown key '" + key + "' (did you mean '" + server_key + "'?)"};
  try {
    sim_->set(full, kServerLiveKeys);
  } catch (const scene::SceneError& e) {
    std::string why = e.what();
    if (setting != full && why.starts_with(full)) why = setting + why.substr(full.size());
    return {false, why};
  }
  return {};
}

std::string scene_names(const std::string& dir) {
  std::vector<std::string> stems;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    std::error_code kind;  // (a regular file, or a link to one: what `load` and --scene take)
    if (entry.path().extension() == ".toml" && entry.is_regular_file(kind))
      stems.push_back(entry.path().stem().string());
  }
  std::sort(stems.begin(), stems.end());
  std::string names;
  for (const std::string& s : stems) names += (names.empty() ? "" : ", ") + s;
  return names;
}

Outcome Session::load(const std::string& name) {
  namespace fs = std::filesystem;
  if (name.empty()) return {false, "load: give a scene name, e.g. classic"};
  // (A long name is no scene's: said before the reason and the list of scenes are cut.)
  if (const std::string shown = quoted(name); shown != name)
    return {false, "no scene '" + shown + "' in " + scenes_dir_ + " (available: " + scene_names(scenes_dir_) + ")"};
  if (name.find('/') != std::string::npos || name.find('\\') != std::string::npos || name.starts_with("."))
    return {false, "not permitted: scenes are loaded by name from the server's scene directory " + scenes_dir_};
  const fs::path path = fs::path(scenes_dir_) / (name.ends_with(".toml") ? name : name + ".toml");
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) {
    if (fs::exists(path, ec))  // a folder, a pipe, a device: never read (a pipe would hold the loop up)
      return {false, "'" + path.filename().native() + "' in " + scenes_dir_ +
                         " is not a regular file (a scene is a .toml file)"};
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
