// ladder-bench: block-steps per second of the simulation core (Google Benchmark).
//
// Workloads, each at N = 10 ... 100 000 blocks with dt = 1 ms and the default (accurate) settings:
//  - FreeChain: the comparison chain pinned at its top, hanging at rest, tilted 0.1 rad and released: a smooth
//    swing, no restructuring, ladder logic off.
//  - Ladder: the toy held at the top, hanging at rest, tipped at t = 0: the ripple, with Algorithm 1 and event
//    location on.
//  - LadderNoLogic: the same ladder with Algorithm 1 off (what the flip/lock logic costs).
// Counters: block_steps/s (the headline), ns/block-step, and the largest hinge error after the run [m].
// Run: build/bench/ladder-bench [--benchmark_filter=...]; docs/benchmarks.md records the figures.
#include "ladder/ladder.hpp"

#include <benchmark/benchmark.h>

#include <memory>

namespace {

using namespace ladder;

std::unique_ptr<model::Ladder> make(int n, bool ladder_logic) {
  model::LadderSpec spec;
  spec.blocks = n;
  spec.start = model::Start::Hanging;
  if (ladder_logic) {
    spec.top = model::Top::Held;
  } else {
    spec.length = 0.06, spec.thickness = 0.01, spec.mass = 0.02;
    spec.top = model::Top::Pinned;
    spec.tilt = 0.1;
  }
  spec.logic = ladder_logic;
  return std::make_unique<model::Ladder>(spec, core::Options{});
}

void run(benchmark::State& state, std::unique_ptr<model::Ladder> l, bool tip) {
  const int n = static_cast<int>(state.range(0));
  if (tip) l->tip();
  for (auto _ : state) l->advance(1e-3);
  const double block_steps = static_cast<double>(state.iterations()) * n;
  state.counters["block_steps/s"] = benchmark::Counter(block_steps, benchmark::Counter::kIsRate);
  state.counters["ns/block-step"] =
      benchmark::Counter(block_steps * 1e-9, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["max_hinge_error_m"] = l->world().max_hinge_error();
  state.counters["sim_time_s"] = l->time();
}

void FreeChain(benchmark::State& state) { run(state, make(static_cast<int>(state.range(0)), false), false); }
void Ladder(benchmark::State& state) { run(state, make(static_cast<int>(state.range(0)), true), true); }
void LadderNoLogic(benchmark::State& state) {
  auto l = make(static_cast<int>(state.range(0)), true);
  auto spec = l->spec();
  spec.logic = false;
  run(state, std::make_unique<model::Ladder>(spec, core::Options{}), true);
}

// Each benchmark simulates a bounded span: at most ~1.5 s of simulated time per size, so that the large sizes
// measure the same early motion as the small ones.
#define LADDER_SIZES ->Arg(10)->Arg(100)->Arg(1000)->Arg(10000)->Arg(100000)->Unit(benchmark::kMillisecond)
BENCHMARK(FreeChain) LADDER_SIZES->Iterations(500);
BENCHMARK(Ladder) LADDER_SIZES->Iterations(1500);
BENCHMARK(LadderNoLogic) LADDER_SIZES->Iterations(1500);

}  // namespace

BENCHMARK_MAIN();
