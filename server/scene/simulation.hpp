// A running scene: the ladder, its fixed time step and its scripted timeline. The one simulation path shared by
// the offline runner and the real-time server: both call step(), and act on ladder() (Ladder::apply).
#pragma once

#include "scene/scene.hpp"

#include <cstdint>
#include <exception>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace ladder::scene {

// A timeline command that could not be applied when its time came (the reason is the ladder's refusal).
struct Refusal {
  double t = 0;
  std::string where;   // file:line:column of the timeline entry
  std::string reason;
};

// Thrown by Simulation::step() when its interrupt asked it to stop between two sub-steps (of sim.substeps, or of the
// adaptive step): the ladder is left at the end of the last sub-step taken, inside the step, and the simulation is not
// to be stepped again.
struct Interrupted : std::exception {
  int substeps_taken = 0, substeps = 0;  // substeps 0: the adaptive step's, whose number is not known before
  Interrupted(int taken, int of) : substeps_taken(taken), substeps(of) {}
  const char* what() const noexcept override { return "step interrupted between two sub-steps"; }
};

class Simulation {
 public:
  explicit Simulation(const Scene& scene);

  // Asked between two sub-steps of a step; true makes step() throw Interrupted there. A step of many sub-steps of a
  // long chain can take minutes (sim.substeps up to 1000, or an adaptive step's up to 1024 with many events): a
  // server that is told to stop does not wait for its end.
  void set_interrupt(std::function<bool()> interrupted) { interrupted_ = std::move(interrupted); }

  // Advances one time step of dt (in scene().substeps equal steps), first applying every timeline command due by
  // the start of the step.
  void step();
  // Applies a live setting "key=value" (see with_live_setting); throws SceneError, and then nothing changed.
  void set(const std::string& setting, std::string_view also_live = {});

  // The simulated time, counted in steps: the time when dt last changed plus the steps since times dt, so that the
  // 10 000th step of 1 ms ends at 10 s exactly. The core's own clock, a running sum of step lengths, is set to it
  // after every step (model::Ladder::set_clock), so that the events at a step's end carry the same time. After a
  // step that failed inside (step() threw), it is the time of the state the ladder stopped at.
  double time() const { return clock_base_ + static_cast<double>(clock_steps_) * dt_; }
  double dt() const { return dt_; }
  std::uint64_t steps() const { return steps_; }
  const Scene& scene() const { return scene_; }
  model::Ladder& ladder() { return ladder_; }
  const model::Ladder& ladder() const { return ladder_; }
  std::vector<model::Event> take_events() { return ladder_.take_events(); }
  std::vector<Refusal> take_refusals() { return std::exchange(refusals_, {}); }
  // Largest hinge solve residual at the end of any step (of dt / substeps) so far [m]: the solver's own measure of the
  // hinge gaps, free to keep (the adaptive step's sub-steps inside a step are not looked at one by one). Not
  // core::World::max_hinge_error(), the gaps of the current state measured anew.
  double max_step_residual() const { return max_step_residual_; }

 private:
  Scene scene_;
  model::Ladder ladder_;
  double dt_;
  std::size_t next_ = 0;  // next timeline entry
  std::uint64_t steps_ = 0;
  double clock_base_ = 0;            // time() when dt last changed
  std::uint64_t clock_steps_ = 0;    // steps since then
  double max_step_residual_ = 0;
  std::vector<Refusal> refusals_;
  std::function<bool()> interrupted_;
};

}  // namespace ladder::scene
