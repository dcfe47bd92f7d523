// ladder-bench: block-steps per second of the simulation core (Google Benchmark).
//
// Workloads (dt = 1 ms, default settings: the midpoint integrator, Newton to 1e-12 m):
//  - ChainZeroG: the comparison chain pinned at its top in zero gravity, block 1 kicked at 5 rad/s and the rest
//    carried along: a travelling wave, no restructuring. The cost of the machinery per block and step, N = 10 to
//    100 000.
//  - ChainHanging: the same chain under gravity, hanging at rest, tilted 0.1 rad and released (N <= 1000: a
//    longer hanging chain needs a smaller step at its top, see docs/benchmarks.md).
//  - Ladder: the toy held at the top, hanging at rest, tipped at t = 0: the ripple, with Algorithm 1 and event
//    location on (N <= 1000).
//  - LadderNoLogic: the same ladder with Algorithm 1 off (what the flip/lock logic costs).
//  - LadderHeld: the server's default ladder (damped) hanging at rest in the hand, N = 10 000 and 100 000: what
//    ladderd's loop costs between interventions. LadderTipped...: the 10 000-block ladder tipped, with the two
//    integrators that run it at 1 ms.
//  - ...Rolling: Ladder, LadderHeld and LadderTipped with rolling hinges (end radius 0.4 of the thickness), N = 1000
//    and 10 000 (LadderHeldRolling also 100 000), against the same workloads with the paper's corner hinges
//    (LadderHeld, LadderTipped also at 1000).
//  - FreeChainStraight: config/scenes/free-chain.toml's chain of N blocks from its straight start under gravity,
//    N = 1000 to 100 000; ...Shake: with symplectic_euler, the former default; LadderHeldShake likewise.
//  - ...Fast: the same workloads with the `fast` accuracy preset's engine settings; ChainHangingProjection: the
//    projection integrator on a hanging chain too stiff for SHAKE at 1 ms.
// Counters: block_steps/s (the headline; 1e9 / it is ns per block-step), the solver's nonlinear iterations per step
// (the last step's of each advance), the steps that ended on Newton's remainder bound instead of a measuring pass
// (bound_ends/step, docs/model.md section 3.1), the passes that measured a first guess's residual alone before any
// Newton pass (checks/step) and those that found it short (short_checks/step; MidpointWork::GuessOdds), the passes
// over a window of the rows alone (window_passes/step, docs/model.md section 3.1) and the windows opened at the first
// guess (guess_windows/step), the largest hinge error after the run [m] and the simulated time covered.
// Run: build/bench/ladder-bench [--threads 1|2] [--tolerance M] [--benchmark_filter=...]; docs/benchmarks.md records
// the figures.
// --threads sets solver.threads (default 2): a chain of 2048 hinges or more is stepped on two threads with 2
// (docs/model.md section 3.2).
#include "core/chain3d.hpp"
#include "free_chain.hpp"
#include "ladder/ladder.hpp"
#include "scene/scene.hpp"

#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <stdexcept>

namespace {

using namespace ladder;

// The `fast` accuracy preset's engine settings (scene::accuracy_presets()); it takes one step per step (substeps 1).
core::Options fast(const core::Options& o) {
  scene::Scene s;
  s.options = o;
  scene::apply_accuracy("fast", s);
  if (s.substeps != 1) throw std::logic_error("the fast preset takes sub-steps; advance() would not");
  return s.options;
}

using bench::free_chain_spec;  // config/scenes/free-chain.toml's chain (free_chain.hpp)

// The same chain from the hanging start: kicked in zero gravity, or tilted 0.1 rad and released under gravity.
std::unique_ptr<model::Ladder> chain(int n, bool gravity, bool fast_preset = false) {
  model::LadderSpec spec = free_chain_spec(n);
  spec.start = model::Start::Hanging;
  spec.tilt = gravity ? 0.1 : 0.0;
  spec.kick_omega = gravity ? 0.0 : 5.0;
  core::Options options;
  if (!gravity) options.gravity = core::Vec2::Zero();
  return std::make_unique<model::Ladder>(spec, fast_preset ? fast(options) : options);
}

std::unique_ptr<model::Ladder> ladder(int n, bool logic, bool fast_preset = false) {
  model::LadderSpec spec;
  spec.blocks = n;
  spec.logic = logic;
  return std::make_unique<model::Ladder>(spec, fast_preset ? fast(core::Options{}) : core::Options{});
}

// --threads N (Options::threads; the default is 2): the threads each step may use.
int threads = core::Options{}.threads;
// --tolerance M (Options::tolerance, solver.tolerance), or 0: each workload's own.
double tolerance = 0;

void run(benchmark::State& state, std::unique_ptr<model::Ladder> l, bool tip) {
  const int n = static_cast<int>(state.range(0));
  core::Options o = l->world().options();
  o.threads = threads;
  if (tolerance > 0) o.tolerance = tolerance;
  l->set_options(o);
  if (tip) l->tip();
  // One step before the timing: the first allocates the step's scratch and touches its pages for the first time,
  // a one-off that at N = 100 000 (about 130 MB) cost as much as 10 to 20 steps (docs/benchmarks.md, the twelfth
  // round), which the 30 timed steps there used to include.
  l->advance(1e-3);
  double iterations = 0, bound_ends = 0, checks = 0, short_checks = 0, window_passes = 0, guess_windows = 0;
  for (auto _ : state) {
    l->advance(1e-3);
    const core::StepStats& st = l->world().last_step();
    iterations += st.iterations;
    bound_ends += st.bound_ends;
    checks += st.checks;
    short_checks += st.short_checks;
    window_passes += st.window_passes;
    guess_windows += st.guess_windows;
  }
  state.counters["bound_ends/step"] = bound_ends / static_cast<double>(state.iterations());
  state.counters["checks/step"] = checks / static_cast<double>(state.iterations());
  state.counters["short_checks/step"] = short_checks / static_cast<double>(state.iterations());
  state.counters["window_passes/step"] = window_passes / static_cast<double>(state.iterations());
  state.counters["guess_windows/step"] = guess_windows / static_cast<double>(state.iterations());
  const double block_steps = static_cast<double>(state.iterations()) * n;
  state.counters["iterations/step"] = iterations / static_cast<double>(state.iterations());
  state.counters["block_steps/s"] = benchmark::Counter(block_steps, benchmark::Counter::kIsRate);
  state.counters["max_hinge_error_m"] = l->world().max_hinge_error();
  state.counters["sim_time_s"] = l->time();
}

void ChainZeroG(benchmark::State& state) { run(state, chain(static_cast<int>(state.range(0)), false), false); }
void ChainHanging(benchmark::State& state) { run(state, chain(static_cast<int>(state.range(0)), true), false); }
void Ladder(benchmark::State& state) { run(state, ladder(static_cast<int>(state.range(0)), true), true); }
void LadderNoLogic(benchmark::State& state) { run(state, ladder(static_cast<int>(state.range(0)), false), true); }
void ChainZeroGFast(benchmark::State& state) { run(state, chain(static_cast<int>(state.range(0)), false, true), false); }
void ChainHangingFast(benchmark::State& state) {
  run(state, chain(static_cast<int>(state.range(0)), true, true), false);
}
// A hanging chain too stiff for SHAKE at 1 ms (N = 10 000: its top link is a pendulum in 10 000 g), with the
// projection integrator, which runs it (docs/tradeoff.md).
core::Options projection(core::Options o) {
  o.integrator = core::Integrator::Projection;
  o.stabilization = core::Stabilization::None;
  o.tolerance = 1e-6;
  return o;
}
void ChainHangingProjection(benchmark::State& state) {
  auto l = chain(static_cast<int>(state.range(0)), true);
  l->set_options(projection(l->world().options()));
  run(state, std::move(l), false);
}
void LadderFast(benchmark::State& state) { run(state, ladder(static_cast<int>(state.range(0)), true, true), true); }
// The reduced integrator (minimal coordinates: no constraint solve, hinges exact to rounding) on the same workloads.
core::Options reduced(core::Options o) {
  o.integrator = core::Integrator::Reduced;
  return o;
}
void ChainZeroGReduced(benchmark::State& state) {
  auto l = chain(static_cast<int>(state.range(0)), false);
  l->set_options(reduced(l->world().options()));
  run(state, std::move(l), false);
}
void ChainHangingReduced(benchmark::State& state) {
  auto l = chain(static_cast<int>(state.range(0)), true);
  l->set_options(reduced(l->world().options()));
  run(state, std::move(l), false);
}
void LadderReduced(benchmark::State& state) {
  auto l = ladder(static_cast<int>(state.range(0)), true);
  l->set_options(reduced(l->world().options()));
  run(state, std::move(l), true);
}

// The ladder as ladderd holds it between interventions, at N = 10 000 and 100 000: the server's default scene
// (config/scenes/classic.toml's blocks and damping of 0.1 /s) hanging at rest in the hand, Algorithm 1 on, with
// the default settings and with `reduced`. Nothing moves, so Newton converges at once: the floor of a step's cost.
// With `rolling`, rolling hinges (ladder.hinge = "rolling") of end radius 0.4 of the thickness, as tall.toml's.
model::LadderSpec rolling(model::LadderSpec spec) {
  spec.hinge = model::HingeKind::Rolling;
  spec.end_radius = 0.4 * spec.thickness;
  return spec;
}
std::unique_ptr<model::Ladder> held_ladder(int n, bool reduced_integrator, bool rolling_hinges = false) {
  model::LadderSpec spec;
  spec.blocks = n;
  if (rolling_hinges) spec = rolling(spec);
  core::Options o;
  o.linear_damping = o.angular_damping = 0.1;
  if (reduced_integrator) o = reduced(o);
  return std::make_unique<model::Ladder>(spec, o);
}
void LadderHeld(benchmark::State& state) { run(state, held_ladder(static_cast<int>(state.range(0)), false), false); }
void LadderHeldReduced(benchmark::State& state) {
  run(state, held_ladder(static_cast<int>(state.range(0)), true), false);
}
// The same ladder of 10 000 blocks tipped at t = 0: the first 0.2 s of its 0.3 s tip (LadderSpec's tip duration).
// With the defaults this tip stops the simulation 35 ms in (offline, the same tip): the hinge solve fails even at
// 1/64 of the step, with the chain's 2 450 N weight on the top hinge (docs/benchmarks.md). The projection integrator
// (to 1e-6 m, as ChainHangingProjection) and `reduced` (whose watchdog redoes many steps in halves) run it.
void LadderTippedProjection(benchmark::State& state) {
  auto l = held_ladder(static_cast<int>(state.range(0)), false);
  l->set_options(projection(l->world().options()));
  run(state, std::move(l), true);
}
void LadderTippedReduced(benchmark::State& state) {
  run(state, held_ladder(static_cast<int>(state.range(0)), true), true);
}
// With the defaults (the midpoint integrator), which steps this tip at 1 ms.
void LadderTipped(benchmark::State& state) { run(state, held_ladder(static_cast<int>(state.range(0)), false), true); }
// The rolling hinge's cost against the corner hinge's: Ladder, LadderHeld and LadderTipped with rolling hinges.
void LadderRolling(benchmark::State& state) {
  model::LadderSpec spec;
  spec.blocks = static_cast<int>(state.range(0));
  run(state, std::make_unique<model::Ladder>(rolling(spec), core::Options{}), true);
}
void LadderHeldRolling(benchmark::State& state) {
  run(state, held_ladder(static_cast<int>(state.range(0)), false, true), false);
}
void LadderTippedRolling(benchmark::State& state) {
  run(state, held_ladder(static_cast<int>(state.range(0)), false, true), true);
}

// The free chain of config/scenes/free-chain.toml from its straight start under gravity (the stability
// workload: it falls, swings and whips), with the defaults and with SHAKE (symplectic_euler), the former default,
// which needs watchdog halvings from N = 1000 (docs/benchmarks.md).
core::Options shake(core::Options o) {
  o.integrator = core::Integrator::SymplecticEuler;
  return o;
}
void FreeChainStraight(benchmark::State& state) {
  run(state, std::make_unique<model::Ladder>(free_chain_spec(static_cast<int>(state.range(0))), core::Options{}),
      false);
}
void FreeChainStraightShake(benchmark::State& state) {
  run(state,
      std::make_unique<model::Ladder>(free_chain_spec(static_cast<int>(state.range(0))), shake(core::Options{})),
      false);
}
void LadderHeldShake(benchmark::State& state) {
  auto l = held_ladder(static_cast<int>(state.range(0)), false);
  l->set_options(shake(l->world().options()));
  run(state, std::move(l), false);
}

// A fixed number of steps per size (the same early motion at every size): 1.5 s of simulated time up to
// N = 1000, 0.2 s at 10 000 and 0.03 s at 100 000.
BENCHMARK(ChainZeroG)->Arg(10)->Arg(100)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(ChainZeroG)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(ChainZeroG)->Arg(100000)->Iterations(30)->Unit(benchmark::kMillisecond);
BENCHMARK(ChainHanging)->Arg(10)->Arg(100)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(ChainHanging)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(Ladder)->Arg(10)->Arg(100)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderNoLogic)->Arg(10)->Arg(100)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
// The `fast` preset (sim.accuracy = fast) on the same workloads, and the projection integrator on a hanging chain
// of 10 000 blocks, where SHAKE needs dt <= 0.25 ms (docs/benchmarks.md).
BENCHMARK(ChainZeroGFast)->Arg(10)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(ChainZeroGFast)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(ChainZeroGFast)->Arg(100000)->Iterations(30)->Unit(benchmark::kMillisecond);
BENCHMARK(ChainHangingFast)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(ChainHangingProjection)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderFast)->Arg(10)->Arg(100)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(ChainZeroGReduced)->Arg(10)->Arg(100)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(ChainZeroGReduced)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(ChainZeroGReduced)->Arg(100000)->Iterations(30)->Unit(benchmark::kMillisecond);
BENCHMARK(ChainHangingReduced)->Arg(10)->Arg(100)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderReduced)->Arg(10)->Arg(100)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderHeld)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderHeld)->Arg(100000)->Iterations(30)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderHeldReduced)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderHeldReduced)->Arg(100000)->Iterations(30)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderTippedProjection)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderTippedReduced)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderTipped)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderHeldShake)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderRolling)->Arg(10)->Arg(100)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderHeld)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderHeldRolling)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderHeldRolling)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderHeldRolling)->Arg(100000)->Iterations(30)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderTipped)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderTippedRolling)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(LadderTippedRolling)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(FreeChainStraight)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(FreeChainStraight)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(FreeChainStraight)->Arg(100000)->Iterations(30)->Unit(benchmark::kMillisecond);
BENCHMARK(FreeChainStraightShake)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(FreeChainStraightShake)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);

}  // namespace

// Model fidelity (docs/fidelity.md): the free chain of config/scenes/free-chain.toml (pinned at its top-left
// corner, a straight column, block 1 kicked at 5 rad/s, no ladder logic) as the 2-D model and as the 3-D model of
// core/chain3d.hpp (6 DOF per block, 5 equations per hinge), the same steps at the same settings (dt = 1 ms,
// symplectic Euler / SHAKE to 1e-12 m). ...ZeroG: without gravity at N = 10 to 10 000 (the travelling wave of
// ChainZeroG, from the straight start); ...Gravity: under gravity, the study's scene (N = 10 and 100).
namespace {

using namespace ladder;

void FreeChain2D(benchmark::State& state, bool gravity) {
  const int n = static_cast<int>(state.range(0));
  core::Options options;
  if (!gravity) options.gravity = core::Vec2::Zero();
  model::Ladder l(free_chain_spec(n), options);
  for (auto _ : state) l.advance(1e-3);
  state.counters["block_steps/s"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * n, benchmark::Counter::kIsRate);
  state.counters["max_hinge_error_m"] = l.world().max_hinge_error();
  state.counters["sim_time_s"] = l.time();
}

void FreeChain3D(benchmark::State& state, bool gravity) {
  const int n = static_cast<int>(state.range(0));
  const model::LadderSpec s = free_chain_spec(n);
  core::Chain3DSpec spec;
  spec.blocks = n;
  spec.length = s.length, spec.thickness = s.thickness, spec.mass = s.mass;
  spec.kick_omega = s.kick_omega;
  if (!gravity) spec.gravity.setZero();
  core::Chain3D chain(spec);
  long iterations = 0;
  for (auto _ : state) {
    chain.step(1e-3);
    iterations += chain.last_iterations();
  }
  state.counters["block_steps/s"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * n, benchmark::Counter::kIsRate);
  state.counters["max_hinge_error_m"] = chain.max_hinge_error();
  state.counters["sim_time_s"] = chain.time();
  state.counters["newton_its/step"] = static_cast<double>(iterations) / static_cast<double>(state.iterations());
}

void FreeChain2DZeroG(benchmark::State& state) { FreeChain2D(state, false); }
void FreeChain3DZeroG(benchmark::State& state) { FreeChain3D(state, false); }
void FreeChain2DGravity(benchmark::State& state) { FreeChain2D(state, true); }
void FreeChain3DGravity(benchmark::State& state) { FreeChain3D(state, true); }

BENCHMARK(FreeChain2DZeroG)->Arg(10)->Arg(100)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(FreeChain2DZeroG)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(FreeChain3DZeroG)->Arg(10)->Arg(100)->Arg(1000)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(FreeChain3DZeroG)->Arg(10000)->Iterations(200)->Unit(benchmark::kMillisecond);
BENCHMARK(FreeChain2DGravity)->Arg(10)->Arg(100)->Iterations(1500)->Unit(benchmark::kMillisecond);
BENCHMARK(FreeChain3DGravity)->Arg(10)->Arg(100)->Iterations(1500)->Unit(benchmark::kMillisecond);

}  // namespace

int main(int argc, char** argv) {
  // --threads N and --tolerance M, taken out before Google Benchmark reads its own flags.
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    // Whether arg is --name (its value the next argument) or --name=value; the value goes to `value`.
    std::string value;
    const auto flag = [&](const std::string& name) {
      if (arg == name) {
        value = i + 1 < argc ? argv[++i] : "";
        return true;
      }
      if (arg.rfind(name + "=", 0) != 0) return false;
      value = arg.substr(name.size() + 1);
      return true;
    };
    if (arg == "--help" || arg == "-h")
      std::printf("ladder-bench: block-steps per second of the simulation core (docs/benchmarks.md).\n"
                  "  --threads 1|2   solver.threads for every workload (default 2: a chain of 2048 hinges or more\n"
                  "                  is stepped on two threads; docs/model.md section 3.2)\n"
                  "  --tolerance M   solver.tolerance in metres for every workload (default: each workload's own,\n"
                  "                  1e-12 for the defaults; docs/benchmarks.md, the sixth round)\n"
                  "  (Neither reaches FreeChain2D*/FreeChain3D*, which compare the two models at fixed settings.)\n"
                  "Google Benchmark's own flags:\n");
    if (flag("--threads")) {
      if (value != "1" && value != "2") {
        std::fprintf(stderr, "ladder-bench: --threads must be 1 or 2 (got '%s')\n", value.c_str());
        return 2;
      }
      threads = value == "1" ? 1 : 2;
    } else if (flag("--tolerance")) {
      char* end = nullptr;
      const double m = std::strtod(value.c_str(), &end);
      if (value.empty() || *end != '\0' || !std::isfinite(m) || !(m > 0)) {
        std::fprintf(stderr, "ladder-bench: --tolerance must be a positive number of metres (got '%s')\n",
                     value.c_str());
        return 2;
      }
      tolerance = m;
    } else {
      argv[kept++] = argv[i];
    }
  }
  argc = kept;
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
