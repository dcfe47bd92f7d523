// Scene files: a TOML description of a ladder, the engine options and a scripted timeline of interventions.
//
// Every key is optional and checked before anything is built: unknown keys (with a did-you-mean hint), wrong
// types, values out of range and non-finite numbers are all refused with the position of the offending value,
// so that a typo in a scene cannot silently fall back to a default. docs/scenes.md lists every key.
// Command-line overrides (`--set table.key=value`) are merged into the file before the checks, so they are held
// to exactly the same rules.
#pragma once

#include "ladder/ladder.hpp"

#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace ladder::scene {

// A scripted command of the timeline, and where in the file it was written (its origin, for messages).
struct TimedCommand {
  double t = 0;         // [s] sim time at which it is applied
  model::Action action;  // tip, poke, push, break or join
  std::string where;     // "file:line:column" of the entry
};

struct Scene {
  std::string name, description, source;  // source: the file path (or the name given to parse_scene)
  model::LadderSpec ladder;
  core::Options options;
  double dt = 0.001;                       // [s]
  int substeps = 1;                        // steps of dt / substeps per step of dt
  double depth = 0.045;                    // [m] a block's depth into the page: only drawn (ladder.depth)
  std::vector<TimedCommand> timeline;      // sorted by t; entries with equal t keep their file order
  // What the scene was made from, so that a session log can make it again (parse_scene(text, source, overrides),
  // then drop the timeline if timeline_dropped).
  std::string text;
  std::vector<std::string> overrides;
  bool timeline_dropped = false;
};

// what() is "FILE:LINE:COLUMN: message", "--set KEY=VALUE: message" for an override, or
// "FILE: cannot open scene file (reason)".
class SceneError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Each override is "table.key=value"; value is read as a TOML value, or as a bare string when it is not one (but an
// array or table that is not valid TOML is an error).
// The scene keeps the text and the overrides it was made from.
Scene load_scene(const std::string& path, const std::vector<std::string>& overrides = {});
Scene parse_scene(std::string_view toml_text, const std::string& source_name,
                  const std::vector<std::string>& overrides = {});

// The scene again from what it was made from (Scene::text, source, overrides, timeline_dropped).
Scene remake_scene(const std::string& text, const std::string& source, const std::vector<std::string>& overrides,
                   bool timeline_dropped);

// The accuracy presets (sim.accuracy): settings picked from the measured speed/accuracy front (docs/tradeoff.md).
struct AccuracyPreset {
  std::string_view name;
  core::Integrator integrator;
  core::Stabilization stabilization;
  core::SolverKind solver;
  double tolerance;
  int max_iterations;
  int substeps;
};
const std::vector<AccuracyPreset>& accuracy_presets();
// Sets the preset's knobs in `scene`; throws std::invalid_argument for an unknown name.
void apply_accuracy(std::string_view name, Scene& scene);
// The preset whose knobs the scene's settings equal, or "custom".
std::string accuracy_of(const Scene& scene);

// The keys that can change while a simulation runs: sim.*, solver.* and damping.*.
bool is_live_key(std::string_view key);
// A table of a scene file ([ladder], [sim], ..., [[timeline]]): ladderd's --config tells a scene file by it.
bool is_scene_table(std::string_view name);
// A copy of `scene` with one live setting "key=value" applied, checked exactly as --set checks it. Throws
// SceneError ("key=value: why") for a bad value, an unknown key, or a key that is not live (the ladder's shape
// and the initial state are fixed once built: change them in the scene file, or with ladderd's --set at its start,
// and load the scene again).
// `also_live`, when given, is added to the refusal of a key that cannot change live after the scene's own live keys
// (the server's live keys, which it takes before they reach the scene).
Scene with_live_setting(const Scene& scene, const std::string& setting, std::string_view also_live = {});
// Every live setting's current value, one "key=value" line each; then ladder.depth, which is not live but is
// published with them for the viewer (SceneInfo's options), the only program that uses it.
std::string live_settings(const Scene& scene);

// The bounds of a timeline command's values, checked where the file gives them: the server's default command
// limits (ladderd.toml [commands], whose defaults these are), so that a scene a server loads cannot script what the
// server would refuse a client (a poke of 1e300 N s made a non-finite state). Whether a point lies on its block is
// the ladder's own check, when the command comes (model::Ladder::check_on_block).
constexpr double kMaxImpulse = 1.0;    // [N s] poke (a 25 g block would leave at 40 m/s)
constexpr double kMaxForce = 100.0;    // [N] push
constexpr double kMaxDuration = 60.0;  // [s] push
constexpr double kReach = 10.0;        // [m] a poke's world point, from the origin

// The shortest text that reads back as the same double ("0.001", "1e-12", "-1"; whole numbers as integers, "10000000"
// rather than "1e+07"), as every message about a value shows it.
std::string format_number(double v);

// One line per key, "key  type  description (range)", for --help.
std::string keys_help();

}  // namespace ladder::scene
