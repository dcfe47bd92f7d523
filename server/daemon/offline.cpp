#include "daemon/offline.hpp"
#include "daemon/fatal.hpp"
#include "ladder/printable.hpp"
#include "scene/simulation.hpp"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>

namespace ladder::daemon {

namespace {

using Clock = std::chrono::steady_clock;
using nlohmann::json;

// v as JSON text. A scene's name taken from its file's name, or a path, need not be UTF-8, and dump() throws on such
// bytes (a run that wrote its events or summary ended in an uncaught exception); they are written as U+FFFD.
std::string json_text(const json& v, int indent = -1) {
  return v.dump(indent, ' ', false, json::error_handler_t::replace);
}

// An output file opened up front, so that a bad path is refused before any simulation is run.
std::unique_ptr<std::ofstream> open_output(const std::string& path, const char* what) {
  if (path.empty()) return nullptr;
  errno = 0;
  auto out = std::make_unique<std::ofstream>(path, std::ios::out | std::ios::trunc);
  if (!*out) {
    const int why = errno;  // (set by the open(2) under the stream, which says nothing itself)
    throw std::invalid_argument(std::string("cannot write the ") + what + " file '" + path + "'" +
                                (why != 0 ? std::string(": ") + std::strerror(why) : std::string()));
  }
  out->precision(17);
  return out;
}

void write_samples(std::ostream& out, const model::Ladder& ladder, double t) {
  for (int i = 0; i < ladder.blocks(); ++i) {
    const core::Vec2 c = ladder.block_centre(i);
    out << t << ',' << i << ',' << c.x() << ',' << c.y() << ',' << ladder.block_angle(i) << '\n';
  }
}

json event_json(const model::Event& e) {
  json j{{"t", e.t}, {"kind", model::to_string(e.kind)}, {"hinge", e.hinge}, {"energy_removed", e.energy_removed}};
  if (!e.detail.empty()) j["detail"] = e.detail;
  return j;
}

struct Outputs {
  std::unique_ptr<std::ofstream> events, trajectory, summary;
};

Outputs open_outputs(const OfflineOptions& o) {
  Outputs out;
  out.events = open_output(o.events, "events");
  out.trajectory = open_output(o.trajectory, "trajectory");
  out.summary = open_output(o.summary, "summary");
  if (out.trajectory) *out.trajectory << "t,block,x,y,theta\n";
  return out;
}

}  // namespace

int run_offline(const OfflineOptions& o) {
  if (!(o.duration > 0) || !std::isfinite(o.duration)) {
    return exit_with(2, fmt::format("--duration must be a positive number of seconds (got {})", o.duration));
  }
  std::optional<scene::Simulation> sim;
  Outputs out;
  try {
    sim.emplace(scene::load_scene(o.scene, o.overrides));
    out = open_outputs(o);
  } catch (const std::exception& e) {  // SceneError carries file:line:column; the rest name what was wrong
    return exit_with(2, e.what());
  }
  const scene::Scene& sc = sim->scene();
  if (o.duration < 0.5 * sc.dt)  // (the run stops at the step whose end is within half a step of --duration)
    return exit_with(2, fmt::format("--duration {} s is shorter than half a step (sim.dt = {} s): no step would run",
                                    o.duration, sc.dt));
  const int blocks = sc.ladder.blocks;
  spdlog::info("scene '{}' ({}): {} blocks, dt {} s, {}, solver {}, {} s of simulated time", printable(sc.name),
               printable(sc.source), blocks, sc.dt, core::to_string(sc.options.integrator),
               core::to_string(sc.options.solver), o.duration);

  const double energy_initial = sim->ladder().energy();
  std::map<std::string, int> counts;
  double sampled_error = sim->ladder().world().max_hinge_error();
  double stepping = 0;  // wall seconds spent in the simulation itself (not in writing files)
  // Sample k is due at the first step that reaches k * 10 ms, counted in steps (a comparison of times would drift a
  // step late at small dt); its time is the Simulation's, counted in steps too.
  int next_sample = 0;
  const auto sample_due = [&] {
    const double due = std::ceil(0.01 * next_sample / sim->dt() - 1e-6);
    return static_cast<double>(sim->steps()) >= due;
  };
  const auto started = Clock::now();
  auto last_report = started;
  try {
    while (true) {
      if (sample_due()) {
        if (out.trajectory) write_samples(*out.trajectory, sim->ladder(), sim->time());
        sampled_error = std::max(sampled_error, sim->ladder().world().max_hinge_error());
        ++next_sample;
      }
      if (sim->time() >= o.duration - 0.5 * sc.dt) break;
      const auto t0 = Clock::now();
      sim->step();
      stepping += std::chrono::duration<double>(Clock::now() - t0).count();
      for (const model::Event& e : sim->take_events()) {
        ++counts[model::to_string(e.kind)];
        if (out.events) *out.events << json_text(event_json(e)) << '\n';
        if (e.kind == model::EventKind::SolverWarning) spdlog::warn("t = {:.4f} s: {}", e.t, printable(e.detail));
      }
      for (const scene::Refusal& r : sim->take_refusals()) {
        ++counts["command_refused"];
        spdlog::warn("{}: timeline command refused at t = {:.4f} s: {}", printable(r.where), r.t,
                     printable(r.reason));
        if (out.events)
          *out.events << json_text({{"t", r.t}, {"kind", "command_refused"}, {"where", r.where}, {"reason", r.reason}})
                      << '\n';
      }
      if (o.progress && Clock::now() - last_report > std::chrono::seconds(2)) {
        last_report = Clock::now();
        spdlog::info("t = {:.2f} / {} s ({:.0f} %), {:.3g} block-steps/s", sim->time(), o.duration,
                     100 * sim->time() / o.duration, static_cast<double>(sim->steps()) * blocks / stepping);
      }
    }
  } catch (const std::exception& e) {
    if (out.summary)
      *out.summary << json_text({{"scene", sc.name},
                                 {"failed", true},
                                 {"error", e.what()},
                                 {"sim_time", sim->time()},
                                 {"steps", sim->steps()},
                                 {"events", counts}},
                                2)
                   << '\n';
    return exit_with(3, fmt::format("the simulation failed at t = {:.6f} s: {}", sim->time(), e.what()));
  }
  const double wall = std::chrono::duration<double>(Clock::now() - started).count();
  const double rate = stepping > 0 ? static_cast<double>(sim->steps()) * blocks / stepping : 0.0;
  const double max_error = std::max(sim->max_step_residual(), sampled_error);
  json summary{{"scene", sc.name},
               {"failed", false},
               {"blocks", blocks},
               {"logic", sc.ladder.logic},
               {"dt", sc.dt},
               {"integrator", core::to_string(sc.options.integrator)},
               {"solver", core::to_string(sc.options.solver)},
               {"sim_time", sim->time()},
               {"steps", sim->steps()},
               {"wall_seconds", stepping},
               {"total_wall_seconds", wall},
               {"block_steps_per_second", rate},
               {"max_hinge_error_m", max_error},
               {"rescued_solves", sim->ladder().rescued_solves()},
               {"energy_initial_J", energy_initial},
               {"energy_final_J", sim->ladder().energy()},
               {"events", counts}};
  // Where the energy went (model::Losses): each kind of event's velocity fix, and the motion between them.
  const model::Ladder& ladder = sim->ladder();
  const model::Losses& lost = ladder.losses();
  const auto removed = [&](model::EventKind k) { return lost.removed[static_cast<std::size_t>(k)]; };
  using model::EventKind;
  summary["energy_lost_J"] = json{{"flip_flop", removed(EventKind::FlipFlop)}, {"impact", removed(EventKind::Impact)},
                                  {"lock", removed(EventKind::Lock)},          {"join", removed(EventKind::Join)},
                                  {"motion", lost.motion},                     {"total", lost.total()}};
  const int flips = ladder.flip_flops();
  summary["energy_lost_per_flip_flop_J"] = flips > 0 ? json(ladder.lost_by_last_flip() / flips) : json(nullptr);
  summary["energy_put_in_J"] = ladder.work_put_in();
  // What the run was, so that two runs' summaries say how they differed: the file, the --set overrides, and every
  // live setting in force (a preset's integrator, step and sub-steps included).
  summary["source"] = sc.source;
  summary["overrides"] = sc.overrides;
  json settings = json::object();
  std::istringstream lines(scene::live_settings(sc));
  for (std::string line; std::getline(lines, line);)
    if (const std::size_t eq = line.find('='); eq != std::string::npos)
      settings[line.substr(0, eq)] = line.substr(eq + 1);
  summary["settings"] = settings;
  if (out.summary) *out.summary << json_text(summary, 2) << '\n';
  spdlog::info("done: {} steps in {:.3f} s ({:.3g} block-steps/s), max hinge error {:.3g} m", sim->steps(),
               stepping, rate, max_error);
  if (std::abs(sim->time() - o.duration) > 1e-9 * o.duration)  // (the step nearest --duration ends the run)
    spdlog::info("--duration {} s is not a whole number of steps of {} s: the run ended at t = {:.9g} s", o.duration,
                 sc.dt, sim->time());
  for (const auto& [kind, n] : counts) spdlog::info("  {:>16}: {}", kind, n);
  if (sim->ladder().rescued_solves() > 0)  // docs/model.md section 3.1
    spdlog::info("solves rescued after solver.max_iterations: {}", sim->ladder().rescued_solves());
  spdlog::info("energy lost: {:.3g} J (flip-flop landings {:.3g}, impacts {:.3g}, locks {:.3g}, damping and integrator "
               "{:.3g}){}",
               lost.total(), removed(EventKind::FlipFlop), removed(EventKind::Impact), removed(EventKind::Lock),
               lost.motion,
               flips > 0 ? fmt::format("; {:.3g} J per flip-flop", ladder.lost_by_last_flip() / flips) : "");
  std::string failed;  // the files whose writing failed, by name
  for (const auto& [file, path] : {std::pair{out.events.get(), &o.events}, {out.trajectory.get(), &o.trajectory},
                                   {out.summary.get(), &o.summary}})
    if (file && !file->flush())
      failed += (failed.empty() ? "" : ", ") + *path;
  if (!failed.empty()) return exit_with(2, "writing " + failed + " failed (is the disk full?)");
  return 0;
}

}  // namespace ladder::daemon
