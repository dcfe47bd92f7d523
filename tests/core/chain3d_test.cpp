// The 3-D model of the free chain (core/chain3d.hpp): closed-form physics, the 2-D model it must reproduce, and what
// only a 3-D model can get wrong.
#include "core/chain3d.hpp"
#include "scene/scene.hpp"
#include "scene/simulation.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

namespace ladder::core {
namespace {

// The free-chain scene's blocks (config/scenes/free-chain.toml), as a 3-D chain.
Chain3DSpec free_chain(int blocks) {
  Chain3DSpec spec;
  spec.blocks = blocks;
  spec.length = 0.06;
  spec.thickness = 0.01;
  spec.mass = 0.02;
  spec.kick_omega = 5.0;
  return spec;
}

// The compound pendulum: T = 2 pi sqrt(I_P / (m g d)) about the pivot corner, I_P = m (L^2 + T^2) / 12 + m d^2,
// d = sqrt(L^2 + T^2) / 2 (the box's width along the hinge does not enter). Swinging by 0.01 rad about the hanging
// equilibrium (diagonal vertical: angle -atan(T / L)), the amplitude correction (1 + a^2 / 16) is 6e-6; symplectic
// Euler's own period error at 1 ms is (w h)^2 / 24 = 1e-5. Measured over ten periods: 0.403969 s against
// 0.403974 s, 1.0e-5 short, as predicted.
TEST(Chain3D, CompoundPendulumPeriodWithinPointOnePercent) {
  Chain3DSpec spec = free_chain(1);
  const double L = spec.length, T = spec.thickness, m = spec.mass, g = 9.81;
  const double eq = -std::atan2(T, L);
  spec.tilt = eq + 0.01;
  Chain3D chain(spec);
  const double d = 0.5 * std::hypot(L, T);
  const double ip = m * (L * L + T * T) / 12 + m * d * d;
  const double expected = 2 * std::numbers::pi * std::sqrt(ip / (m * g * d)) * (1 + 1e-4 / 16);
  const double dt = 1e-3;
  std::vector<double> crossings;
  double prev = chain.block_angle(0) - eq;
  while (crossings.size() < 11 && chain.time() < 10) {
    chain.step(dt);
    const double now = chain.block_angle(0) - eq;
    if (prev < 0 && now >= 0) crossings.push_back(chain.time() - dt * now / (now - prev));
    prev = now;
  }
  ASSERT_EQ(crossings.size(), 11u);
  const double period = (crossings.back() - crossings.front()) / 10;
  EXPECT_NEAR(period / expected, 1.0, 1e-3) << "period " << period << " s, expected " << expected << " s";
  EXPECT_LT(chain.max_hinge_error(), 1e-12);
}

// The 2-D model of the same scene (the project's default: symplectic Euler, SHAKE to 1e-12 m) against the 3-D one
// at the same step. For a chain whose hinge axes are parallel the 3-D motion is planar and its equations reduce to
// the 2-D ones exactly, and the two discretisations are the same method: they may differ only by how far each
// Newton solve stops inside the tolerance (1e-12 m per step), amplified by the motion's sensitivity. Both are
// also compared with a converged 2-D run (RK4 at dt / 16) to show that their mutual difference is far below the
// discretisation error they share.
struct Comparison {
  double max_diff = 0;     // largest |angle_3D - angle_2D| at any step [rad]
  double max_error = 0;    // largest |angle_3D - angle_reference| at the 10 ms samples [rad]
  double max_gap = 0;      // largest anchor gap at any step [m]
  double max_planar = 0;   // largest out_of_plane() and max_axis_error() at any step
};

scene::Scene free_chain_scene(int blocks, const std::vector<std::string>& more = {}) {
  std::vector<std::string> overrides{"ladder.blocks=" + std::to_string(blocks)};
  overrides.insert(overrides.end(), more.begin(), more.end());
  return scene::load_scene(std::string(LADDER_SOURCE_DIR) + "/config/scenes/free-chain.toml", overrides);
}

Chain3DSpec spec_of(const scene::Scene& sc) {
  Chain3DSpec spec;
  spec.blocks = sc.ladder.blocks;
  spec.length = sc.ladder.length;
  spec.thickness = sc.ladder.thickness;
  spec.mass = sc.ladder.mass;
  spec.hinge_inset = sc.ladder.hinge_inset;
  spec.kick_omega = sc.ladder.kick_omega;
  spec.tilt = sc.ladder.tilt;
  spec.tolerance = sc.options.tolerance;
  spec.max_iterations = sc.options.max_iterations;
  spec.gravity = Vec3(sc.options.gravity.x(), sc.options.gravity.y(), 0);
  return spec;
}

Comparison compare_with_2d(int blocks, double duration) {
  // The 3-D model steps by SHAKE, so the 2-D model it is compared with does too (the scene's own is the midpoint).
  const scene::Scene sc = free_chain_scene(blocks, {"sim.integrator=symplectic_euler"});
  scene::Simulation plane(sc);
  Chain3D space(spec_of(sc));
  const double dt = sc.dt;
  const int sub = 16;
  char fine[64];
  std::snprintf(fine, sizeof fine, "sim.dt=%.17g", dt / sub);
  scene::Simulation reference(free_chain_scene(blocks, {"sim.integrator=rk4", fine}));
  Comparison c;
  const long steps = std::lround(duration / dt);
  for (long s = 1; s <= steps; ++s) {
    plane.step();
    space.step(dt);
    for (int i = 0; i < sub; ++i) reference.step();
    for (int i = 0; i < blocks; ++i) {
      c.max_diff = std::max(c.max_diff, std::abs(space.block_angle(i) - plane.ladder().block_angle(i)));
      if (s % 10 == 0)
        c.max_error = std::max(c.max_error, std::abs(space.block_angle(i) - reference.ladder().block_angle(i)));
    }
    c.max_gap = std::max(c.max_gap, space.max_hinge_error());
    c.max_planar = std::max({c.max_planar, space.out_of_plane(), space.max_axis_error()});
    EXPECT_TRUE(space.last_step().converged) << "step " << s;
  }
  return c;
}

// N = 2 over 2 s and N = 10 over 1 s (N = 10 whips; later it turns chaotic and any two runs' 1e-12 m differences
// grow exponentially). Measured: the models differ by 1e-14 rad (N = 2) and 1e-12 rad (N = 10), while both are
// 4.4e-3 and 3.2e-2 rad from the converged motion (the study's symplectic_euler error at 1 ms). The bound, 1e-10
// rad, is what 1e-12 m solve differences (over a 0.03 m lever, 3e-11 rad) allow after a little amplification, and
// eight orders below the discretisation error: a model or integrator that differed in any term would miss it.
TEST(Chain3D, ReproducesThe2DModelOfTheFreeChain) {
  for (auto [blocks, duration] : {std::pair{2, 2.0}, std::pair{10, 1.0}}) {
    const Comparison c = compare_with_2d(blocks, duration);
    EXPECT_LT(c.max_diff, 1e-10) << "N = " << blocks;
    EXPECT_GT(c.max_error, 1e-3) << "N = " << blocks;  // the agreement is not that of two converged answers
    EXPECT_LT(c.max_diff, 1e-7 * c.max_error) << "N = " << blocks;
    EXPECT_LT(c.max_gap, 1e-9) << "N = " << blocks;  // measured 1.0e-12 m (the solver tolerance)
    EXPECT_LT(c.max_planar, 1e-9) << "N = " << blocks;  // measured 0: a planar motion stays exactly planar
  }
}

// Symplectic Euler with SHAKE: the energy error oscillates with amplitude O(h) and does not drift. The free
// double pendulum for 10 s at 1 ms (the 2-D model's test, World.SymplecticIntegratorsConserveEnergyWithoutDrift,
// measures the same 1.4e-2 of the largest kinetic energy). Measured: 1.4e-2, and a drift of 1.1e-4.
TEST(Chain3D, EnergyIsBoundedWithoutDrift) {
  Chain3D chain(free_chain(2));
  const double e0 = chain.kinetic_energy() + chain.potential_energy();
  double scale = 0, worst = 0, first = 0, last = 0, gap = 0;
  int nfirst = 0, nlast = 0;
  for (int i = 0; i < 10000; ++i) {
    chain.step(1e-3);
    const double e = chain.kinetic_energy() + chain.potential_energy() - e0;
    scale = std::max(scale, chain.kinetic_energy());
    worst = std::max(worst, std::abs(e));
    gap = std::max(gap, chain.max_hinge_error());
    if (i < 1000) first += e, ++nfirst;
    if (i >= 9000) last += e, ++nlast;
  }
  const double drift = std::abs(last / nlast - first / nfirst) / scale;
  EXPECT_LT(worst / scale, 3e-2);
  EXPECT_LT(drift, 2e-3);
  EXPECT_LT(gap, 1e-9);
}

// An out-of-plane velocity (block 1 rolling about its length and yawing, block 2 moving along the hinge axis) is
// what the 2-D model cannot even represent. The hinges of a chain whose axes are parallel forbid it entirely: at a
// planar configuration the mass matrix does not couple in-plane and out-of-plane motion, so the projection onto
// the hinges removes exactly the out-of-plane part (its kinetic energy) and leaves the in-plane motion unchanged,
// and the chain then moves as the unperturbed one. Measured over 2 s: out of plane 3e-27, the angles identical to the
// bit.
TEST(Chain3D, HingesRemoveOutOfPlaneMotion) {
  const Chain3DSpec spec = free_chain(3);
  Chain3D flat(spec), perturbed(spec);
  const Vec3 v1 = perturbed.block_velocity(1), w1 = perturbed.block_omega(1), v2 = perturbed.block_velocity(2);
  const Vec3 w_out(2.0, -1.0, 0.0), v_out(0, 0, 0.3);
  perturbed.set_velocity(1, v1, w1 + w_out);
  perturbed.set_velocity(2, v2 + v_out, perturbed.block_omega(2));
  // Block 1's principal axes are the world's at the start: I_x = m (L^2 + W^2) / 12, I_y = m (T^2 + W^2) / 12.
  const double L = spec.length, T = spec.thickness, W = spec.width, m = spec.mass;
  const double out_energy = 0.5 * m * v_out.squaredNorm() +
                            0.5 * (m * (L * L + W * W) / 12 * w_out.x() * w_out.x() +
                                   m * (T * T + W * W) / 12 * w_out.y() * w_out.y());
  const double removed = -perturbed.project_velocities();
  EXPECT_NEAR(removed / out_energy, 1.0, 1e-12);
  for (int i = 0; i < spec.blocks; ++i) {
    EXPECT_LT((perturbed.block_velocity(i) - flat.block_velocity(i)).norm(), 1e-12) << i;
    EXPECT_LT((perturbed.block_omega(i) - flat.block_omega(i)).norm(), 1e-12) << i;
  }
  double planar = 0, diff = 0, gap = 0;
  for (int s = 0; s < 2000; ++s) {
    flat.step(1e-3);
    perturbed.step(1e-3);
    planar = std::max({planar, perturbed.out_of_plane(), perturbed.max_axis_error()});
    gap = std::max(gap, perturbed.max_hinge_error());
    for (int i = 0; i < spec.blocks; ++i)
      diff = std::max(diff, std::abs(perturbed.block_angle(i) - flat.block_angle(i)));
  }
  EXPECT_LT(planar, 1e-9);
  EXPECT_LT(diff, 1e-9);
  EXPECT_LT(gap, 1e-9);
}

// What only the 3-D model has to get right: the gyroscopic term. With W = 40 mm the hinge axis z is a block's
// intermediate principal axis (I_y < I_z < I_x), and a free rigid body spinning about its intermediate axis is
// unstable (the tennis-racket effect): a block with its top free, spinning at 10 rad/s about z with 1e-3 rad/s
// of wobble, turns over within seconds while conserving its angular momentum and energy. The same spin with the
// block pinned stays in the plane: the hinge, not the physics of a spinning body, keeps the chain planar. The
// gyroscopic term is explicit (first order): measured over 5 s at 0.1 ms, angular momentum within 6.8e-4 and energy
// within 1.2e-3 of their start for the free block; without the term the block would not turn over at all.
TEST(Chain3D, FreeBlockSpinningAboutItsIntermediateAxisTurnsOverAPinnedOneDoesNot) {
  Chain3DSpec spec = free_chain(1);
  spec.gravity = Vec3::Zero();
  const Vec3 w0(1e-3, 0, 10.0);
  for (bool pinned : {false, true}) {
    spec.pinned = pinned;
    Chain3D block(spec);
    block.set_velocity(0, Vec3::Zero(), w0);
    block.project_velocities();
    const auto momentum = [&] {
      const Eigen::Quaterniond q = block.block_orientation(0);
      const Vec3 wb = q.conjugate() * block.block_omega(0);
      const Vec3 principal(spec.length * spec.length + spec.width * spec.width,
                           spec.thickness * spec.thickness + spec.width * spec.width,
                           spec.length * spec.length + spec.thickness * spec.thickness);
      return Vec3(q * (spec.mass / 12 * principal.cwiseProduct(wb)));
    };
    const Vec3 l0 = momentum();
    const double e0 = block.kinetic_energy();
    double tilt = 0, l_err = 0, e_err = 0;
    for (int s = 0; s < 50000; ++s) {
      block.step(1e-4);
      tilt = std::max(tilt, block.out_of_plane());
      if (!pinned) l_err = std::max(l_err, (momentum() - l0).norm() / l0.norm());
      e_err = std::max(e_err, std::abs(block.kinetic_energy() - e0) / e0);
    }
    if (pinned) {
      EXPECT_LT(tilt, 1e-9);
    } else {
      EXPECT_GT(tilt, 0.9);  // the z axis turned over (|sin| of its tilt passed 0.9)
      EXPECT_LT(l_err, 1e-2);
    }
    EXPECT_LT(e_err, 1e-2);
  }
}

TEST(Chain3D, RefusesBadInput) {
  Chain3DSpec spec = free_chain(2);
  spec.width = 0;
  EXPECT_THROW(Chain3D{spec}, std::invalid_argument);
  Chain3D chain(free_chain(2));
  EXPECT_THROW(chain.step(0), std::invalid_argument);
  EXPECT_THROW(chain.step(NAN), std::invalid_argument);
  EXPECT_THROW(chain.block_angle(2), std::invalid_argument);
  EXPECT_THROW(chain.set_velocity(0, Vec3(NAN, 0, 0), Vec3::Zero()), std::invalid_argument);
}

}  // namespace
}  // namespace ladder::core
