#include "scene/simulation.hpp"

#include <algorithm>
#include <stdexcept>
#include <utility>

namespace ladder::scene {

Simulation::Simulation(const Scene& scene) : scene_(scene), ladder_(scene.ladder, scene.options), dt_(scene.dt) {}

void Simulation::set(const std::string& setting, std::string_view also_live) {
  Scene changed = with_live_setting(scene_, setting, also_live);
  if (changed.dt != dt_) {  // the step count restarts from now
    clock_base_ = time();
    clock_steps_ = 0;
  }
  scene_ = std::move(changed);
  dt_ = scene_.dt;
  ladder_.set_options(scene_.options);
}

void Simulation::step() {
  // A command is due when its time is reached by the start of this step (half a step of slack for rounding).
  const auto& timeline = scene_.timeline;
  while (next_ < timeline.size() && timeline[next_].t <= time() + 0.5 * dt_) {
    const TimedCommand& c = timeline[next_++];
    try {
      ladder_.apply(c.action);
    } catch (const std::invalid_argument& e) {
      refusals_.push_back({time(), c.where, e.what()});
    }
  }
  const int substeps = scene_.substeps;
  try {
    for (int i = 0; i < substeps; ++i) {
      if (i > 0 && interrupted_ && interrupted_()) throw Interrupted(i, substeps);
      ladder_.advance(dt_ / substeps, interrupted_);
      max_step_residual_ = std::max(max_step_residual_, ladder_.world().last_step().residual);
    }
  } catch (const model::Ladder::Interrupted& e) {  // between two adaptive sub-steps
    throw Interrupted(e.substeps_taken, 0);
  } catch (const std::runtime_error&) {
    // The ladder stopped at the last state its watchdog accepted, which lies inside this step when the step was cut
    // at an event (a flip-flop, a stop) or into sub-steps: the clock goes on from that state's own time.
    clock_base_ = ladder_.time();
    clock_steps_ = 0;
    throw;
  }
  ++steps_;
  ++clock_steps_;
  ladder_.set_clock(time());  // events at the step's end then carry its time exactly, as the states do
}

}  // namespace ladder::scene
