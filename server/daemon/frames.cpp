#include "daemon/frames.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>

namespace ladder::daemon {

Percentiles percentiles(std::vector<double>& v) {
  Percentiles p;
  if (v.empty()) return p;
  const auto at = [&](double q) {
    const auto k = static_cast<std::ptrdiff_t>(q * static_cast<double>(v.size() - 1));
    std::nth_element(v.begin(), v.begin() + k, v.end());
    return v[static_cast<std::size_t>(k)];
  };
  p.p50 = at(0.5);
  p.p99 = at(0.99);
  p.max = *std::max_element(v.begin(), v.end());
  v.clear();
  return p;
}

void fill_frame(const Session& s, std::uint64_t commands_applied, StateFrame& f) {
  const model::Ladder& l = s.sim().ladder();
  f.generation = s.generation();
  f.step = s.sim().steps();
  f.t = s.sim().time();
  f.paused = s.paused();
  f.commands_applied = commands_applied;
  f.energy = l.energy();
  const auto n = static_cast<std::size_t>(l.blocks());
  f.poses.resize(3 * n);
  f.hinge_corner.resize(n);
  f.hinge_status.resize(n);
  f.hinge_flips.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    core::Vec2 c;
    l.block_pose(static_cast<int>(i), c, f.poses[3 * i + 2]);
    f.poses[3 * i] = c.x();
    f.poses[3 * i + 1] = c.y();
    const model::HingeInfo& h = l.hinges()[i];
    f.hinge_corner[i] = static_cast<std::uint8_t>(h.corner);
    f.hinge_status[i] = h.status == model::HingeStatus::Hinged   ? ladder_msg_HINGED
                        : h.status == model::HingeStatus::Locked ? ladder_msg_LOCKED
                                                                 : ladder_msg_BROKEN;
    f.hinge_flips[i] = static_cast<std::uint32_t>(h.flips);
  }
  f.grips.clear();
  for (const model::Ladder::Grip& g : l.grips())
    f.grips.push_back({g.block, g.target.x(), g.target.y(), g.hold_angle, g.angle});
}

std::string non_finite_in(const StateFrame& f) {
  if (!std::isfinite(f.t)) return "sim_time";
  if (!std::isfinite(f.energy)) return "energy";
  static constexpr const char* kPose[] = {"x", "y", "theta"};
  for (std::size_t i = 0; i < f.poses.size(); ++i)
    if (!std::isfinite(f.poses[i])) return "block " + std::to_string(i / 3) + "'s " + kPose[i % 3];
  for (const ladder_msg_Grip& g : f.grips)
    if (!std::isfinite(g.target_x) || !std::isfinite(g.target_y) || !std::isfinite(g.angle))
      return "the grip on block " + std::to_string(g.block);
  return {};
}

std::string non_finite_in(const Session& s) {
  StateFrame f;
  fill_frame(s, 0, f);
  return non_finite_in(f);
}

void finite_or_zero(double& v, const char* name, std::string& fields, std::uint64_t& count) {
  if (std::isfinite(v)) return;
  v = 0;
  ++count;
  fields += fields.empty() ? name : std::string(", ") + name;
}

SceneOut scene_out(const Session& s) {
  const scene::Scene& sc = s.sim().scene();
  const model::LadderSpec& l = sc.ladder;
  SceneOut o;
  o.generation = s.generation();
  o.name = sc.name;
  o.description = sc.description;
  o.top = l.top == model::Top::Held ? "held" : l.top == model::Top::Pinned ? "pinned" : "free";
  o.options = scene::live_settings(sc);
  o.blocks = l.blocks;
  o.length = l.length;
  o.thickness = l.thickness;
  o.inset = l.hinge_inset;
  o.dt = sc.dt;
  o.masses = l.masses.empty() ? std::vector<double>(static_cast<std::size_t>(l.blocks), l.mass) : l.masses;
  o.rates = s.rates();
  o.text = sc.text;
  o.source = sc.source;
  o.overrides = sc.overrides;
  o.timeline_dropped = sc.timeline_dropped;
  return o;
}

}  // namespace ladder::daemon
