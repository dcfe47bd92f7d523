// The speed/accuracy trade-off study (ladder-tradeoff): every knob setting on the reference scenes, measured for
// cost and for error against a converged reference the project computes itself. No output here: study.cpp runs,
// report.cpp writes CSV, Markdown and the plot, main.cpp is the command line.
#pragma once

#include <functional>
#include <string>
#include <vector>

namespace ladder::tradeoff {

// A reference scene: a shipped scene file with overrides, simulated for `duration` seconds.
struct Case {
  std::string id;         // "free2", "free100", "classic", "long"
  std::string title;      // for tables and the plot
  std::string file;       // under the scenes directory
  std::vector<std::string> overrides;
  double duration = 2;    // [s]
  double reference_dt = 0;  // [s] the reference's step (RK4, tolerance 1e-12); its halving checks it
  std::vector<double> dts;  // [s] the steps each integrator is measured at
};

// One knob setting: the overrides that make it, on top of the case's.
struct Setting {
  std::string knob;   // the plot line it belongs to: "rk4", "tolerance", "preset", ...
  std::string label;  // what differs along the line: "dt=0.5 ms", "tol=1e-9", "fast"
  std::vector<std::string> sets;
  int dimensions = 2;  // 3: the scene's chain as the 3-D model (core/chain3d.hpp; free chains only)
};

// Samples of a run, every 10 ms of simulated time.
struct Trace {
  std::vector<std::vector<double>> angles;  // [sample][block] [rad]
  double hinge_error = 0;                   // largest joint gap at any sample [m]
  double energy_start = 0, energy_end = 0;  // [J]
  std::vector<std::pair<std::string, int>> events;  // (kind, hinge) in order, solver warnings left out
  std::vector<std::pair<int, double>> flips;        // (hinge, t) of every flip-flop
};

struct Result {
  std::string case_id, knob, label;
  std::string integrator, stabilization, solver;
  double dt = 0, tolerance = 0;
  int substeps = 1, blocks = 0;
  bool ok = true;
  std::string failure;           // why the run stopped, when !ok
  double wall_per_sim_second = 0;  // [s / s]
  double block_steps_per_second = 0;
  // Against the reference (NaN when not measured):
  double angle_error_max = 0, angle_error_rms = 0;  // [rad]
  double hinge_error = 0;                           // [m]
  double energy_drift = 0;                          // E_end - E_start [J] (conserved by the free chains' physics)
  double energy_error = 0;                          // E_end - E_end of the reference [J]
  double arrival_error = 0;    // ripple arrival at the reference's deepest flip-flop, relative to its travel time
  int deepest_hinge = 0;       // the reference's deepest flip-flop hinge (0: no ripple)
  bool flips_same = true;      // the same flip-flops in the same order
  bool events_same = true;     // the same flip-flops, locks and unlocks in the same order
  bool pareto = false;         // on the scene's error-cost front (angle_error_max against wall_per_sim_second)
};

struct Reference {
  Result coarse, fine;  // RK4 at reference_dt and reference_dt / 2; `fine` is the reference
  Trace trace;          // of `fine`
  double tip_time = 0;  // the scene's first tip [s], for the ripple's travel time
};

struct Options {
  std::string scenes_dir;         // where the shipped scene files are
  std::vector<std::string> cases;  // ids to run; empty = all
  bool quick = false;             // fewer settings and a coarser reference (for the test suite)
  double min_timing = 0.2;        // [s] short runs are repeated until this much wall time, the fastest kept
};

std::vector<Case> cases(const Options& options);
std::vector<Setting> settings(const Case& c, const Options& options);

// Runs one setting; with `reference`, measures its errors against it. Never throws for a failing simulation:
// that is a result (ok = false, failure says why).
Result run(const Case& c, const Setting& s, const Options& options, const Reference* reference,
           Trace* trace_out = nullptr);
Reference reference(const Case& c, const Options& options);
// Marks the Pareto front of one case's results.
void mark_pareto(std::vector<Result>& results);

}  // namespace ladder::tradeoff
