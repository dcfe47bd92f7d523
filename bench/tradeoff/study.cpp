#include "study.hpp"

#include "core/chain3d.hpp"
#include "scene/simulation.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace ladder::tradeoff {
namespace {

constexpr double kSample = 0.01;  // [s] sampling interval of the traces
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string ms(double seconds) {
  std::ostringstream o;
  o << seconds * 1e3;
  return o.str();
}

std::string number(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}

scene::Scene make_scene(const Case& c, const Setting& s, const Options& options) {
  std::vector<std::string> overrides = c.overrides;
  overrides.insert(overrides.end(), s.sets.begin(), s.sets.end());
  return scene::load_scene(options.scenes_dir + "/" + c.file, overrides);
}

// One simulation from start to c.duration, sampled every 10 ms. Throws what the simulation throws.
void simulate(const scene::Scene& sc, double duration, Trace& trace) {
  scene::Simulation sim(sc);
  const double dt = sc.dt;
  const long per_sample = std::lround(kSample / dt);
  if (per_sample < 1 || std::abs(static_cast<double>(per_sample) * dt - kSample) > 1e-9 * kSample)
    throw std::invalid_argument("sim.dt = " + number(dt) + " s does not divide the 10 ms sampling interval");
  const long frames = std::lround(duration / dt);
  const model::Ladder& l = sim.ladder();
  trace = {};
  trace.energy_start = l.energy();
  for (long f = 1; f <= frames; ++f) {
    sim.step();
    for (const model::Event& e : sim.take_events()) {
      if (e.kind == model::EventKind::SolverWarning) continue;
      trace.events.emplace_back(model::to_string(e.kind), e.hinge);
      if (e.kind == model::EventKind::FlipFlop) trace.flips.emplace_back(e.hinge, e.t);
    }
    if (f % per_sample == 0) {
      std::vector<double> a(static_cast<size_t>(l.blocks()));
      for (int i = 0; i < l.blocks(); ++i) a[static_cast<size_t>(i)] = l.block_angle(i);
      trace.angles.push_back(std::move(a));
      trace.hinge_error = std::max(trace.hinge_error, l.world().max_hinge_error());
    }
  }
  trace.energy_end = l.energy();
}

// The 3-D model of a free-chain scene (core/chain3d.hpp): its blocks, kick and solver settings. Only what the 3-D
// model reproduces is accepted; anything else is the study's bug.
core::Chain3DSpec chain3d_spec(const scene::Scene& sc) {
  const model::LadderSpec& l = sc.ladder;
  const core::Options& o = sc.options;
  if (l.top != model::Top::Pinned || l.start != model::Start::Straight || l.logic || !l.masses.empty() ||
      l.tilt != 0 || o.integrator != core::Integrator::SymplecticEuler || o.linear_damping != 0 ||
      o.angular_damping != 0 || o.hinge_friction != 0 || sc.substeps != 1 || !sc.timeline.empty())
    throw std::logic_error("the 3-D model runs only the free chain (pinned, straight, no logic, no damping, "
                           "symplectic_euler, one step per frame, no timeline)");
  core::Chain3DSpec spec;
  spec.blocks = l.blocks;
  spec.length = l.length;
  spec.thickness = l.thickness;
  spec.mass = l.mass;
  spec.hinge_inset = l.hinge_inset;
  spec.kick_omega = l.kick_omega;
  spec.tolerance = o.tolerance;
  spec.max_iterations = o.max_iterations;
  spec.gravity = core::Vec3(o.gravity.x(), o.gravity.y(), 0);
  return spec;
}

// The 2-D runner's watchdog (Ladder::step_guarded, docs/model.md) for the 3-D model: a step that leaves a hinge
// error above 1 um or a non-finite state is undone and redone as two half steps, down to 1/64 of the step.
void step_guarded(core::Chain3D& chain, double h, int depth = 0) {
  const core::Chain3D::Snapshot start = chain.save();
  chain.step(h);
  if (chain.last_step().residual <= 1e-6 && chain.finite()) return;
  if (depth == 6)
    throw std::runtime_error("the 3-D hinge solve failed even with 1/64 of the time step at t = " +
                             number(start.t) + " s");
  chain.restore(start);
  step_guarded(chain, 0.5 * h, depth + 1);
  step_guarded(chain, 0.5 * h, depth + 1);
}

// simulate() for the 3-D model: the same steps, watchdog and samples.
void simulate_3d(const scene::Scene& sc, double duration, Trace& trace) {
  core::Chain3D chain(chain3d_spec(sc));
  const double dt = sc.dt;
  const long per_sample = std::lround(kSample / dt);
  if (per_sample < 1 || std::abs(static_cast<double>(per_sample) * dt - kSample) > 1e-9 * kSample)
    throw std::invalid_argument("sim.dt = " + number(dt) + " s does not divide the 10 ms sampling interval");
  const long frames = std::lround(duration / dt);
  trace = {};
  trace.energy_start = chain.kinetic_energy() + chain.potential_energy();
  for (long f = 1; f <= frames; ++f) {
    step_guarded(chain, dt);
    if (f % per_sample == 0) {
      std::vector<double> a(static_cast<size_t>(chain.blocks()));
      for (int i = 0; i < chain.blocks(); ++i) a[static_cast<size_t>(i)] = chain.block_angle(i);
      trace.angles.push_back(std::move(a));
      trace.hinge_error = std::max(trace.hinge_error, chain.max_hinge_error());
    }
  }
  trace.energy_end = chain.kinetic_energy() + chain.potential_energy();
}

double first_flip(const Trace& t, int hinge) {
  for (const auto& [k, time] : t.flips)
    if (k == hinge) return time;
  return kNaN;
}

void compare(Result& r, const Trace& t, const Reference& ref) {
  const Trace& e = ref.trace;
  double worst = 0, sum = 0;
  long count = 0;
  const size_t samples = std::min(t.angles.size(), e.angles.size());
  for (size_t i = 0; i < samples; ++i)
    for (size_t b = 0; b < t.angles[i].size(); ++b) {
      const double d = std::abs(t.angles[i][b] - e.angles[i][b]);
      worst = std::max(worst, d);
      sum += d * d;
      ++count;
    }
  r.angle_error_max = worst;
  r.angle_error_rms = count ? std::sqrt(sum / static_cast<double>(count)) : kNaN;
  r.energy_error = t.energy_end - e.energy_end;
  r.flips_same = t.flips.size() == e.flips.size() &&
                 std::equal(t.flips.begin(), t.flips.end(), e.flips.begin(),
                            [](const auto& a, const auto& b) { return a.first == b.first; });
  r.events_same = t.events == e.events;
  r.deepest_hinge = 0;
  for (const auto& f : e.flips) r.deepest_hinge = std::max(r.deepest_hinge, f.first);
  if (r.deepest_hinge > 0) {
    const double t_ref = first_flip(e, r.deepest_hinge);
    r.arrival_error = std::abs(first_flip(t, r.deepest_hinge) - t_ref) / (t_ref - ref.tip_time);  // NaN if never
  } else {
    r.arrival_error = kNaN;
  }
}

}  // namespace

std::vector<Case> cases(const Options& o) {
  std::vector<Case> all;
  if (o.quick) {
    all.push_back({"free2", "free chain, N = 2", "free-chain.toml", {}, 1.0, 1.0 / 16e3, {2e-3, 1e-3, 5e-4}});
  } else {
    const std::vector<double> dts{5e-3, 2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4};
    all.push_back({"free2", "free chain, N = 2", "free-chain.toml", {}, 2.0, 1.0 / 64e3, dts});
    all.push_back({"free100", "free chain, N = 100", "free-chain.toml", {"ladder.blocks=100"}, 0.5, 1.0 / 32e3, dts});
    all.push_back({"classic", "classic, tipped at 0.5 s", "classic.toml", {}, 2.5, 1.0 / 32e3,
                   {5e-3, 2e-3, 1e-3, 5e-4, 2.5e-4}});
    all.push_back({"long", "long (1000 blocks), tipped at 0.5 s", "long.toml", {}, 1.5, 6.25e-5, {1e-3, 5e-4, 2.5e-4}});
  }
  if (o.cases.empty()) return all;
  std::vector<Case> chosen;
  for (const std::string& id : o.cases) {
    const auto it = std::find_if(all.begin(), all.end(), [&](const Case& c) { return c.id == id; });
    if (it == all.end()) throw std::invalid_argument("no scene '" + id + "' in the study (free2, free100, classic, long)");
    chosen.push_back(*it);
  }
  return chosen;
}

std::vector<Setting> settings(const Case& c, const Options& o) {
  std::vector<Setting> out;
  // The time step, for every integrator (and the paper's solver with SHAKE, which the 3-D model below shares).
  for (const char* integrator : {"euler", "symplectic_euler", "rattle", "rk4", "projection", "reduced", "midpoint"})
    for (double dt : c.dts)
      out.push_back({integrator, "dt=" + ms(dt) + " ms",
                     {std::string("sim.integrator=") + integrator, "sim.dt=" + number(dt)}});
  for (double dt : c.dts)
    out.push_back({"symplectic_euler + newton_linesearch", "dt=" + ms(dt) + " ms",
                   {"sim.integrator=symplectic_euler", "solver.kind=newton_linesearch", "sim.dt=" + number(dt)}});
  if (o.quick) return out;
  // --- model fidelity (docs/fidelity.md): the free chains as the 3-D model (6 DOF per block, 5 equations per
  // hinge) at the steps the integrators are measured at, with SHAKE (symplectic_euler), the method the 3-D model
  // implements. The ladders are left out: their flip-flops and locks exist in the 2-D model only.
  if (c.id == "free2" || c.id == "free100")
    for (double dt : c.dts)
      out.push_back({"fidelity", "3-D, dt=" + ms(dt) + " ms",
                     {"sim.integrator=symplectic_euler", "sim.dt=" + number(dt)}, 3});
  // --- end of model fidelity
  // The solver tolerance, at the scene's own step.
  for (const char* tol : {"1e-6", "1e-8", "1e-10", "1e-12"})
    out.push_back({"tolerance (midpoint)", std::string("tol=") + tol, {std::string("solver.tolerance=") + tol}});
  // Stabilisation: the explicit integrators drift off the hinges without it; SHAKE keeps positions exact and
  // leaves its velocities O(h)-consistent.
  for (const char* integrator : {"euler", "symplectic_euler", "rk4", "midpoint"})
    for (const char* stab : {"none", "velocity", "position"})
      out.push_back({std::string("stabilization (") + integrator + ")", std::string(stab) + " " + integrator,
                     {std::string("sim.integrator=") + integrator, std::string("sim.stabilization=") + stab}});
  // Sub-steps per frame of 2 ms (1 ms for the long ladder), with the default integrator.
  if (c.id != "long")
    for (int n : {1, 2, 4, 8})
      out.push_back({"substeps (midpoint, 2 ms frame)", "substeps=" + std::to_string(n),
                     {"sim.dt=0.002", "sim.substeps=" + std::to_string(n)}});
  // The error-controlled adaptive step in frames of 10 ms (5 ms for the long ladder, whose fixed steps fail above
  // 1 ms), with the default integrator and with RK4: sub-steps chosen within each frame down to the tolerance.
  for (const char* integrator : {"midpoint", "symplectic_euler", "rk4"})
    for (const char* tol : {"1e-4", "1e-6", "1e-8"})
      out.push_back({std::string("adaptive (") + integrator + ")", std::string("tol=") + tol,
                     {std::string("sim.integrator=") + integrator, "sim.adaptive=true",
                      std::string("sim.error_tolerance=") + tol, c.id == "long" ? "sim.dt=0.005" : "sim.dt=0.01"}});
  // The presets, at the scene's own step.
  for (const char* preset : {"fast", "balanced", "accurate"})
    out.push_back({"preset", preset, {std::string("sim.accuracy=") + preset}});
  return out;
}

Result run(const Case& c, const Setting& s, const Options& o, const Reference* ref, Trace* trace_out) {
  Result r;
  r.case_id = c.id;
  r.knob = s.knob;
  r.label = s.label;
  scene::Scene sc = make_scene(c, s, o);  // a bad setting is the study's bug: let it throw
  r.integrator = core::to_string(sc.options.integrator);
  r.stabilization = core::to_string(sc.options.stabilization);
  r.solver = core::to_string(sc.options.solver);
  r.dt = sc.dt;
  r.tolerance = sc.options.tolerance;
  r.substeps = sc.substeps;
  r.blocks = sc.ladder.blocks;
  Trace trace;
  double best = std::numeric_limits<double>::infinity(), spent = 0;
  for (int repeat = 0; repeat < 1000 && (repeat == 0 || spent < o.min_timing); ++repeat) {
    const auto t0 = std::chrono::steady_clock::now();
    try {
      if (s.dimensions == 3)
        simulate_3d(sc, c.duration, trace);
      else
        simulate(sc, c.duration, trace);
    } catch (const std::runtime_error& e) {  // the watchdog gave up: a result, not an error of the study
      r.ok = false;
      r.failure = e.what();
    }
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    best = std::min(best, wall);
    spent += wall;
    if (!r.ok) break;
  }
  r.wall_per_sim_second = best / c.duration;
  r.block_steps_per_second = static_cast<double>(r.blocks) * std::round(c.duration / r.dt) * r.substeps / best;
  r.hinge_error = trace.hinge_error;
  r.energy_drift = trace.energy_end - trace.energy_start;
  if (!r.ok) {
    r.angle_error_max = r.angle_error_rms = r.energy_error = r.arrival_error = kNaN;
    r.flips_same = r.events_same = false;
  } else if (ref) {
    compare(r, trace, *ref);
  } else {
    r.angle_error_max = r.angle_error_rms = r.energy_error = r.arrival_error = kNaN;
  }
  if (trace_out) *trace_out = std::move(trace);
  return r;
}

Reference reference(const Case& c, const Options& o) {
  Reference ref;
  const auto setting = [&](double dt) {
    return Setting{"reference", "rk4 dt=" + ms(dt) + " ms",
                   {"sim.integrator=rk4", "solver.tolerance=1e-12", "sim.substeps=1", "sim.stabilization=position",
                    "sim.dt=" + number(dt)}};
  };
  Options once = o;
  once.min_timing = 0;  // its cost is not part of the study
  Trace coarse;
  ref.coarse = run(c, setting(c.reference_dt), once, nullptr, &coarse);
  ref.fine = run(c, setting(0.5 * c.reference_dt), once, nullptr, &ref.trace);
  if (!ref.coarse.ok || !ref.fine.ok)
    throw std::runtime_error(c.id + ": the reference failed: " + ref.coarse.failure + ref.fine.failure);
  const scene::Scene sc = make_scene(c, Setting{}, o);
  ref.tip_time = 0;
  for (const scene::TimedCommand& t : sc.timeline)
    if (std::holds_alternative<model::Tip>(t.action)) {
      ref.tip_time = t.t;
      break;
    }
  compare(ref.coarse, coarse, ref);  // the halving check: how far the coarse reference is from the fine one
  compare(ref.fine, ref.trace, ref);
  return ref;
}

void mark_pareto(std::vector<Result>& results) {
  for (Result& a : results) {
    a.pareto = a.ok && std::isfinite(a.angle_error_max);
    if (!a.pareto) continue;
    for (const Result& b : results) {
      if (&a == &b || !b.ok || !std::isfinite(b.angle_error_max) || b.case_id != a.case_id) continue;
      const bool no_worse = b.wall_per_sim_second <= a.wall_per_sim_second && b.angle_error_max <= a.angle_error_max;
      const bool better = b.wall_per_sim_second < a.wall_per_sim_second || b.angle_error_max < a.angle_error_max;
      if (no_worse && better) {
        a.pareto = false;
        break;
      }
    }
  }
}

}  // namespace ladder::tradeoff
