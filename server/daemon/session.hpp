// The server's simulation session: the running scene, paused or running, and every user command applied to it.
//
// No DDS and no threads here: the real-time loop (physics.cpp) feeds it commands and ticks, so that the command
// rules (what is accepted, why one is refused, what changes) are tested without a network. The session checks a
// command against the server's limits (limits.hpp), then hands an action to the ladder (Ladder::apply, which
// refuses what the ladder cannot do) or carries out its own verb. A refused command changes nothing: every check
// comes before the first change.
#pragma once

#include "daemon/command.hpp"
#include "daemon/limits.hpp"
#include "scene/simulation.hpp"

#include <algorithm>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>

namespace ladder::daemon {

struct Outcome {
  bool accepted = true;
  std::string reason;  // why it was refused; empty when accepted
};

class Session {
 public:
  Session(const scene::Scene& scene, std::string scenes_dir, Limits limits, Rates rates);

  // Validates and applies one command now.
  Outcome apply(const Request& r);
  // The same for a command's fields as they came (from a client or a log): an unknown kind is refused.
  Outcome apply(const CommandFields& f);

  // Runs one physics step (the caller decides when: real-time pacing is the loop's job).
  // Throws std::runtime_error when the step fails (the watchdog gave up); the session is then paused at the last
  // good state, and a `reset` restores the scene's own settings (see failed()).
  void step();
  // The last step failed (until a step succeeds, or a reset or load). A reset then starts the scene with the
  // settings of its file (or text) instead of the live settings, which may be what made it fail.
  bool failed() const { return failed_; }
  bool paused() const { return paused_; }
  // Steps ordered by a step command and not yet taken (they run while paused).
  std::uint64_t pending_steps() const { return pending_steps_; }
  void take_pending_step() { --pending_steps_; }
  // At most n pending steps are kept (a resumed log's, whose step commands the re-run took within the widest limits).
  void limit_pending_steps(std::uint64_t n) { pending_steps_ = std::min(pending_steps_, n); }
  void pause() { paused_ = true; }
  // Marks the session failed as a failed step does (paused; a reset restores the scene's settings): for a state
  // that the server finds non-finite after a step that passed.
  void fail() {
    paused_ = true;
    pending_steps_ = 0;
    failed_ = true;
  }

  // Asked between the sub-steps of every step, of this scene and of those that follow (scene::Simulation).
  void set_interrupt(std::function<bool()> interrupted) {
    interrupted_ = std::move(interrupted);
    sim_->set_interrupt(interrupted_);
  }

  scene::Simulation& sim() { return *sim_; }
  const scene::Simulation& sim() const { return *sim_; }
  const Rates& rates() const { return rates_; }
  // Counts loads and resets; SceneInfo and State carry it.
  std::uint32_t generation() const { return generation_; }
  // The server's rules, for a session made elsewhere (a resumed log).
  void configure(std::string scenes_dir, Limits limits, Rates rates) {
    scenes_dir_ = std::move(scenes_dir), limits_ = limits, rates_ = rates;
  }
  // Starts `scene` as a load does (a replayed log brings its own scene text rather than a file name).
  void restart(const scene::Scene& scene) {
    start(scene);
    base_ = scene;
  }
  // FNV-1a over the bits of the complete dynamic state: every body's position, angle and velocities, the time,
  // the user forces, the hinges and the grips. Equal hashes mean (up to a 2^-64 chance) identical states.
  std::uint64_t state_hash() const;
  // Commands taken before this server (a resumed log's), accepted and refused: the server numbers its commands on
  // from them, so that command_seq and State.commands_applied go on where the log left off.
  struct Taken {
    std::uint64_t accepted = 0, refused = 0;
  };
  const Taken& taken_before() const { return taken_before_; }
  void set_taken_before(Taken t) { taken_before_ = t; }

 private:
  // The session's verbs; a refusal throws std::invalid_argument or is returned.
  Outcome verb(const Pause&);
  Outcome verb(const Resume&);
  Outcome verb(const Step& s);
  Outcome verb(const Reset&) { return reset(); }
  Outcome verb(const Set& s) { return set_param(s.setting); }
  Outcome verb(const Load& l) { return load(l.name); }
  Outcome set_param(const std::string& setting);
  // Back to the scene's start: with the live settings, unless the last step failed (then with the scene's own).
  Outcome reset();
  Outcome load(const std::string& name);
  void start(const scene::Scene& scene);

  std::unique_ptr<scene::Simulation> sim_;
  std::function<bool()> interrupted_;
  scene::Scene base_;  // the scene as loaded, before any live setting: what a reset after a failure starts
  bool failed_ = false;
  std::string scenes_dir_;
  Limits limits_;
  Rates rates_;
  bool paused_ = false;
  std::uint64_t pending_steps_ = 0;
  std::uint32_t generation_ = 0;
  Taken taken_before_;
};

// The scenes in `dir` (NAME of each NAME.toml), comma-separated; empty when there are none: what `load` and
// `--scene` list when a name is not found.
std::string scene_names(const std::string& dir);

}  // namespace ladder::daemon
