// ladder-box2d-bench: the core and Box2D 2.4 (Debian's libbox2d-dev) on the same free chain, in the same run.
//
// The chain is config/scenes/free-chain.toml's with N blocks: pinned to the world at block 0's top-left corner, a
// straight vertical column, corner hinges alternating between the right and the left edge, block 1 kicked at
// 5 rad/s, gravity, no damping, no ladder logic. Box2D gets the very same bodies (taken from the core's model: centres,
// angles, velocities, hinge points), boxes of the same mass and inertia, revolute joints at the same points, no
// collisions, and its default solver (8 velocity and 3 position iterations, one step per step). Both take dt = 1 ms
// steps for the same simulated time. Printed per N: block-steps per second and the largest hinge gap [m] at the end
// of the run for each, and the speed ratio. docs/benchmarks.md records the figures.
#include "free_chain.hpp"
#include "ladder/ladder.hpp"

#include <box2d/box2d.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace {

using namespace ladder;
using Clock = std::chrono::steady_clock;

model::LadderSpec free_chain(int n) { return bench::free_chain_spec(n); }

struct Result {
  double block_steps_per_s = 0, gap = 0;
};

Result run_core(int n, int steps, const core::Options& options) {
  model::Ladder ladder(free_chain(n), options);
  const auto start = Clock::now();
  for (int i = 0; i < steps; ++i) ladder.advance(1e-3);
  const double s = std::chrono::duration<double>(Clock::now() - start).count();
  return {static_cast<double>(n) * steps / s, ladder.world().max_hinge_error()};
}

// The chain of the core's model, rebuilt in Box2D.
Result run_box2d(int n, int steps) {
  const model::Ladder model(free_chain(n), core::Options{});
  const model::LadderSpec& spec = model.spec();
  b2World world(b2Vec2(0.0f, -9.81f));
  b2BodyDef ground_def;
  b2Body* ground = world.CreateBody(&ground_def);
  std::vector<b2Body*> blocks;
  const float hx = static_cast<float>(spec.thickness / 2), hy = static_cast<float>(spec.length / 2);
  const float density = static_cast<float>(spec.mass / (spec.thickness * spec.length));
  for (int i = 0; i < n; ++i) {
    b2BodyDef def;
    def.type = b2_dynamicBody;
    const core::Vec2 c = model.block_centre(i);
    def.position.Set(static_cast<float>(c.x()), static_cast<float>(c.y()));
    def.angle = static_cast<float>(model.block_angle(i));
    const core::Vec2 v = model.world().part_velocity(i);
    def.linearVelocity.Set(static_cast<float>(v.x()), static_cast<float>(v.y()));
    def.angularVelocity = static_cast<float>(model.world().part_omega(i));
    b2Body* body = world.CreateBody(&def);
    b2PolygonShape box;
    box.SetAsBox(hx, hy);
    b2FixtureDef fixture;
    fixture.shape = &box;
    fixture.density = density;
    fixture.filter.groupIndex = -1;  // the core's chain has no contacts: neither has this one
    body->CreateFixture(&fixture);
    blocks.push_back(body);
  }
  std::vector<b2Joint*> joints;
  const auto join = [&](b2Body* a, b2Body* b, const core::Vec2& at) {
    b2RevoluteJointDef def;
    def.Initialize(a, b, b2Vec2(static_cast<float>(at.x()), static_cast<float>(at.y())));
    def.collideConnected = false;
    joints.push_back(world.CreateJoint(&def));
  };
  join(ground, blocks[0], model.corner(0, model.hinges()[0].corner));
  for (int k = 1; k < n; ++k) join(blocks[static_cast<size_t>(k - 1)], blocks[static_cast<size_t>(k)],
                                   model.corner(k, model.hinges()[static_cast<size_t>(k)].corner));
  const auto start = Clock::now();
  for (int i = 0; i < steps; ++i) world.Step(1e-3f, 8, 3);
  const double s = std::chrono::duration<double>(Clock::now() - start).count();
  double gap = 0;
  for (b2Joint* j : joints) {
    const b2Vec2 d = j->GetAnchorA() - j->GetAnchorB();
    gap = std::max(gap, static_cast<double>(d.Length()));
  }
  return {static_cast<double>(n) * steps / s, gap};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ladder-box2d-bench: the core's default integrator and Box2D 2.4 on the same free chain (dt = 1 ms), "
               "in the same run: block-steps per second and the largest hinge gap of each."};
  std::vector<int> sizes{1000, 10000, 100000};
  double seconds = 0.2;
  std::string integrator = core::to_string(core::Options{}.integrator);
  app.add_option("-n,--blocks", sizes, "chain sizes")->check(CLI::Range(2, 1000000));
  app.add_option("--seconds", seconds, "simulated time per run [s]")->check(CLI::Range(0.001, 100.0));
  app.add_option("--integrator", integrator, "the core's integrator")
      ->check([](const std::string& s) {
        try {
          core::integrator_from_string(s);
          return std::string();
        } catch (const std::exception& e) {
          return std::string(e.what());
        }
      });
  CLI11_PARSE(app, argc, argv);
  core::Options options;
  options.integrator = core::integrator_from_string(integrator);
  const int steps = static_cast<int>(std::lround(seconds / 1e-3));
  std::printf("free chain from its straight start, dt = 1 ms, %d steps (%.3g s); core: %s, Box2D %d.%d.%d: 8 "
              "velocity + 3 position iterations\n",
              steps, seconds, integrator.c_str(), b2_version.major, b2_version.minor, b2_version.revision);
  std::printf("%8s  %20s %12s  %20s %12s  %8s\n", "N", "core block-steps/s", "core gap m", "box2d block-steps/s", "box2d gap m",
              "ratio");
  for (const int n : sizes) {
    std::fprintf(stderr, "box2d-bench: N = %d ...\n", n);
    const Result a = run_core(n, steps, options);
    const Result b = run_box2d(n, steps);
    std::printf("%8d  %20.3e %12.2e  %20.3e %12.2e  %8.2f\n", n, a.block_steps_per_s, a.gap, b.block_steps_per_s,
                b.gap, a.block_steps_per_s / b.block_steps_per_s);
    std::fflush(stdout);
  }
  return 0;
}
