// The engine against closed-form physics: free fall, the compound pendulum's period, energy conservation,
// momentum conservation through restructuring, exact round trips, and refusals.
#include "core/world.hpp"
#include "core/fp_mode.hpp"
#include "test_blocks.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <numbers>
#include <stdexcept>
#include <utility>
#include <vector>

namespace ladder::core {
namespace {

using test::anchor, test::block, test::rotate_about, test::kL, test::kW, test::kM;

double pendulum_period(Integrator integrator, double dt) {
  Options opt;
  opt.integrator = integrator;
  World world(opt);
  // Pinned at its top-left corner (0, 0); the centre hangs at (W/2, -L/2) when straight. Equilibrium: the centre
  // straight below the pivot, i.e. the block turned by -atan(W/L)... plus 0.01 rad of amplitude.
  const double eq = -std::atan2(kW, kL);
  const double amp = 0.01;
  const Vec2 straight(kW / 2, -kL / 2);
  const int part = world.add_part(block(rotate_about(straight, Vec2::Zero(), eq + amp), eq + amp));
  const int pin = anchor(world, Vec2::Zero());
  world.connect(pin, world.first_particle(part) + 3);
  world.finalize();
  // Upward zero crossings of the angle about equilibrium, linearly interpolated.
  std::vector<double> crossings;
  double prev = world.part_angle(part) - eq;
  while (crossings.size() < 11 && world.time() < 20) {
    world.step(dt);
    const double now = world.part_angle(part) - eq;
    if (prev < 0 && now >= 0) crossings.push_back(world.time() - dt * now / (now - prev));
    prev = now;
  }
  EXPECT_EQ(crossings.size(), 11u);
  return (crossings.back() - crossings.front()) / 10;
}

TEST(World, FreeFallIsExactForRK4AndFirstOrderForSymplecticEuler) {
  const Vec2 g(0, -9.81), x0(0.1, 2.0), v0(0.3, 1.0);
  for (auto integrator : {Integrator::RK4, Integrator::SymplecticEuler, Integrator::Reduced}) {
    Options opt;
    opt.integrator = integrator;
    World world(opt);
    const int part = world.add_part(block(x0, 0.3, v0, 2.0));
    const double h = 1e-3;
    for (int i = 0; i < 1000; ++i) world.step(h);
    const double t = world.time();
    const Vec2 exact = x0 + v0 * t + 0.5 * g * t * t;
    const double err = (world.part_position(part) - exact).norm();
    if (integrator == Integrator::RK4) {
      EXPECT_LT(err, 1e-12);  // RK4 integrates a quadratic exactly; what is left is rounding
    } else {
      // Symplectic Euler (a body in no hinge steps so under reduced too): x_n = x0 + v0 t + g h^2 n (n + 1) / 2, off
      // by exactly g h t / 2.
      EXPECT_NEAR(err, 0.5 * g.norm() * h * t, 1e-9);
    }
    EXPECT_NEAR(world.part_angle(part), 0.3 + 2.0 * t, 1e-12);
  }
}

// A step runs with subnormal numbers flushed to zero (core/fp_mode.hpp: on a long chain they cost 2x the step) and
// gives the caller back its own mode. A free body whose velocity and spin are subnormal (1e-310) stops: read as zero,
// they move it by nothing; without the flush its spin would stay near 1e-310 (w1 = 4 t / h - w0 with t = h w0 / 2).
TEST(World, AStepFlushesSubnormalsAndRestoresTheCallersMode) {
  if (kFlushSubnormals == 0) GTEST_SKIP() << "the flush is x86-64's (MXCSR)";
  Options opt;
  opt.gravity = Vec2::Zero();
  World world(opt);
  const double tiny = 1e-310;
  ASSERT_EQ(std::fpclassify(tiny), FP_SUBNORMAL);
  const int part = world.add_part(block(Vec2(0.5, 0.25), 0.0, Vec2(tiny, 0), tiny));
  const unsigned mode = fp_mode() & kFpControl;
  ASSERT_EQ(mode & kFlushSubnormals, 0u);  // the caller's: subnormals kept
  world.step(1e-3);
  EXPECT_EQ(fp_mode() & kFpControl, mode);
  EXPECT_EQ(world.part_omega(part), 0.0);
  EXPECT_EQ(world.part_velocity(part).x(), 0.0);
  EXPECT_EQ(world.part_position(part).x(), 0.5);
  EXPECT_EQ(std::fpclassify(tiny * 0.5), FP_SUBNORMAL);  // and the caller's arithmetic keeps them
}

// The compound pendulum: T = 2 pi sqrt(I_P / (m g d)), with I_P = m (L^2 + W^2) / 12 + m d^2 about the pivot and
// d = sqrt(L^2 + W^2) / 2; at 0.01 rad the amplitude correction (1 + a^2 / 16) is 6e-6, well inside the 0.1 %
// the issue asks for. Measured over ten periods for every integrator.
TEST(World, CompoundPendulumPeriodWithinPointOnePercent) {
  const double d = 0.5 * std::hypot(kL, kW);
  const double ip = kM * (kL * kL + kW * kW) / 12 + kM * d * d;
  const double expected = 2 * std::numbers::pi * std::sqrt(ip / (kM * 9.81 * d)) * (1 + 1e-4 / 16);
  for (auto [integrator, dt] : {std::pair{Integrator::SymplecticEuler, 1e-3}, std::pair{Integrator::Rattle, 1e-3},
                                std::pair{Integrator::RK4, 1e-3}, std::pair{Integrator::Euler, 1e-4},
                                std::pair{Integrator::Reduced, 1e-3}}) {
    const double period = pendulum_period(integrator, dt);
    EXPECT_NEAR(period / expected, 1.0, 1e-3) << to_string(integrator);
  }
}

// A free double pendulum (two blocks, no damping) for 20 s: the symplectic integrators keep the energy error
// bounded, with no drift between the first and the last two seconds.
TEST(World, SymplecticIntegratorsConserveEnergyWithoutDrift) {
  for (auto integrator : {Integrator::SymplecticEuler, Integrator::Rattle}) {
    Options opt;
    opt.integrator = integrator;
    World world(opt);
    const int b0 = world.add_part(block(Vec2(kW / 2, -kL / 2)));
    const int b1 = world.add_part(block(Vec2(kW / 2, -3 * kL / 2), 0, Vec2(0.15, -0.025), 5.0));
    const int pin = anchor(world, Vec2::Zero());
    world.connect(pin, world.first_particle(b0) + 3);
    world.connect(world.first_particle(b0), world.first_particle(b1) + 1);  // b0 bottom-right to b1 top-right
    world.finalize();
    world.project_velocities();
    const double e0 = world.kinetic_energy() + world.potential_energy();
    double scale = 0;  // the largest kinetic energy of the run: the energy the motion exchanges
    double worst = 0, first = 0, last = 0;
    int nfirst = 0, nlast = 0;
    for (int i = 0; i < 20000; ++i) {
      world.step(1e-3);
      const double e = world.kinetic_energy() + world.potential_energy() - e0;
      scale = std::max(scale, world.kinetic_energy());
      worst = std::max(worst, std::abs(e));
      if (i < 2000) first += e, ++nfirst;
      if (i >= 18000) last += e, ++nlast;
    }
    // First order: the error oscillates with amplitude O(h); second order (RATTLE): O(h^2).
    // (measured 1.4e-2 and 1.2e-4 here; w h is about 0.02)
    const double bound = integrator == Integrator::Rattle ? 3e-4 : 3e-2;
    EXPECT_LT(worst / scale, bound) << to_string(integrator) << " worst " << worst / scale;
    EXPECT_LT(std::abs(last / nlast - first / nfirst) / scale, bound / 5) << to_string(integrator);
    EXPECT_LT(world.max_hinge_error(), 1e-9);
  }
}

// Three free blocks in a chain, no gravity, spinning and drifting: every restructuring is internal, so the total
// linear momentum and the angular momentum about any point are conserved, to rounding (1e-12 relative).
class Restructuring : public ::testing::Test {
 protected:
  void SetUp() override {
    Options opt;
    opt.gravity = Vec2::Zero();
    world = World(opt);
    // A bent chain: block 1's top-right corner on block 0's bottom-right, block 2's top-left on block 1's
    // bottom-left, each block moving differently, so that every combine is a real inelastic meeting.
    const double a[3] = {0.0, 0.4, -0.3};
    Vec2 c[3];
    c[0] = Vec2(0.1, 1.0);
    c[1] = c[0] + Rot::of(a[0]) * Vec2(kW / 2, -kL / 2) - Rot::of(a[1]) * Vec2(kW / 2, kL / 2);
    c[2] = c[1] + Rot::of(a[1]) * Vec2(-kW / 2, -kL / 2) - Rot::of(a[2]) * Vec2(-kW / 2, kL / 2);
    for (int i = 0; i < 3; ++i)
      parts.push_back(world.add_part(block(c[i], a[i], Vec2(0.2 * i - 0.1, 0.05 * i + 0.02), 1.5 - i)));
    world.connect(p(0, 0), p(1, 1));
    world.finalize();
    world.project_velocities();
  }
  int p(int block, int c) const { return world.first_particle(parts[block]) + c; }
  void expect_conserved(const std::function<void()>& op) {
    const Vec2 origin(0.37, -0.21);
    const Vec2 lin = world.linear_momentum(parts);
    const double ang = world.angular_momentum(parts, origin);
    const double ke = world.kinetic_energy();
    op();
    const double scale_l = std::max(lin.norm(), 1e-3);
    EXPECT_LT((world.linear_momentum(parts) - lin).norm() / scale_l, 1e-12);
    EXPECT_NEAR(world.angular_momentum(parts, origin), ang, 1e-12 * std::max(std::abs(ang), 1e-4));
    EXPECT_LE(world.kinetic_energy(), ke * (1 + 1e-12));
  }
  World world;
  std::vector<int> parts;
};

TEST_F(Restructuring, CombineWeldAndFlipConserveMomentum) {
  // Hinge block 2 to block 1 where their corners touch: an inelastic meeting of two moving bodies.
  Restructure hinge;
  expect_conserved([&] { hinge = world.combine(p(1, 2), p(2, 3)); });
  EXPECT_GT(hinge.energy_removed, 1e-6);
  for (int i = 0; i < 50; ++i) world.step(1e-3);
  // Lock: combine the hinged pair again.
  Restructure r;
  expect_conserved([&] { r = world.combine(p(0, 0), p(1, 1)); });
  EXPECT_EQ(r.kind, JointKind::Weld);
  EXPECT_GE(r.energy_removed, 0);
  EXPECT_EQ(world.body_count(), 2);
  // Unlock: the weld splits back into two bodies moving as they did.
  expect_conserved([&] { world.separate(p(0, 0), p(1, 1)); });
  for (int i = 0; i < 50; ++i) world.step(1e-3);
  EXPECT_LT(world.max_hinge_error(), 1e-9);
}

// A part refused for want of rotational inertia (one particle, dynamic) leaves no particle behind: the next part's
// particles start where the refused one's would have.
TEST(World, RefusedPartLeavesNoTrace) {
  World world;
  world.add_part(block(Vec2(0, 0)));
  const int particles = world.particle_count();
  PartDef point;
  point.particles.push_back({1.0, Vec2::Zero()});
  EXPECT_THROW(world.add_part(point), std::invalid_argument);
  EXPECT_EQ(world.particle_count(), particles);
  const int next = world.add_part(block(Vec2(1, 0)));
  EXPECT_EQ(world.first_particle(next), particles);
  EXPECT_EQ(world.part_count(), 2);
}

// A folded pair (block 1 turned half a turn about the hinge, lying along block 0) spinning and drifting: moving
// the hinge to the far corners, which touch, is a perfectly inelastic meeting there; momentum is conserved.
TEST(World, FlipOfAFoldedPairConservesMomentum) {
  Options opt;
  opt.gravity = Vec2::Zero();
  World world(opt);
  const Vec2 hinge(0.2, 0.5);
  const int b0 = world.add_part(block(hinge - Vec2(kW / 2, -kL / 2), 0, Vec2(0.1, -0.2), 0.7));
  // Block 1's top-right corner (W/2, L/2) on the hinge, turned by pi: it lies along block 0, right of it.
  const int b1 = world.add_part(block(hinge - Rot::of(std::numbers::pi) * Vec2(kW / 2, kL / 2), std::numbers::pi,
                                      Vec2(-0.3, 0.1), -4.0));
  const int p0 = world.first_particle(b0), p1 = world.first_particle(b1);
  world.connect(p0 + 0, p1 + 1);
  world.finalize();
  world.project_velocities();
  ASSERT_LT((world.particle_position(p0 + 1) - world.particle_position(p1 + 0)).norm(), 1e-15);  // far corners touch
  const Vec2 origin(-0.4, 0.9);
  const Vec2 lin = world.linear_momentum({b0, b1});
  const double ang = world.angular_momentum({b0, b1}, origin);
  const double ke = world.kinetic_energy();
  world.separate(p0 + 0, p1 + 1);
  const Restructure r = world.combine(p0 + 1, p1 + 0);
  EXPECT_LT((world.linear_momentum({b0, b1}) - lin).norm(), 1e-12 * lin.norm());
  EXPECT_NEAR(world.angular_momentum({b0, b1}, origin), ang, 1e-12 * std::abs(ang));
  EXPECT_NEAR(r.energy_removed, ke - world.kinetic_energy(), 1e-15);
  EXPECT_GT(r.energy_removed, 0);
  const Vec2 va = world.particle_velocity(p0 + 1), vb = world.particle_velocity(p1 + 0);
  EXPECT_LT((va - vb).norm(), 1e-12);  // the new hinge's particles now move together
}

// part_rotation() and part_omega() (what Algorithm 1 reads for every block) follow each part into and out of a weld:
// the turn of the line between two of its particles since the start, and their relative velocity.
TEST_F(Restructuring, PartRotationAndSpinFollowEachPartThroughAWeld) {
  std::vector<Vec2> d0;
  std::vector<Rot> q0;
  for (int part : parts) {
    const int first = world.first_particle(part);
    d0.push_back(world.particle_position(first + 1) - world.particle_position(first));
    q0.push_back(world.part_rotation(part));
  }
  const auto check = [&] {
    for (size_t i = 0; i < parts.size(); ++i) {
      const int first = world.first_particle(parts[i]);
      const Vec2 d = world.particle_position(first + 1) - world.particle_position(first);
      const Vec2 dv = world.particle_velocity(first + 1) - world.particle_velocity(first);
      const Rot turned = Rot::of(std::atan2(cross(d0[i], d), d0[i].dot(d))) * q0[i];
      const Rot q = world.part_rotation(parts[i]);
      EXPECT_NEAR(q.c, turned.c, 1e-12) << "part " << i;
      EXPECT_NEAR(q.s, turned.s, 1e-12) << "part " << i;
      EXPECT_NEAR(world.part_omega(parts[i]), cross(d, dv) / d.squaredNorm(), 1e-9) << "part " << i;
    }
  };
  world.combine(p(0, 0), p(1, 1));  // lock: blocks 0 and 1 are one body, each part turned in it
  ASSERT_EQ(world.body_count(), 2);
  for (int i = 0; i < 50; ++i) world.step(1e-3);
  check();
  world.separate(p(0, 0), p(1, 1));  // unlock
  for (int i = 0; i < 50; ++i) world.step(1e-3);
  check();
}

TEST_F(Restructuring, RoundTripsRestoreTheModel) {
  for (int i = 0; i < 20; ++i) world.step(1e-3);
  const int bodies = world.body_count();
  std::vector<Vec2> where;
  for (int i = 0; i < world.particle_count(); ++i) where.push_back(world.particle_position(i));
  const auto check = [&] {
    EXPECT_EQ(world.body_count(), bodies);
    for (int b = 0; b < world.body_count(); ++b) EXPECT_EQ(world.body_parts(b).size(), 1u);
    EXPECT_EQ(world.find_joint(p(0, 0), p(1, 1)) >= 0, true);
    EXPECT_EQ(world.joint_kind(world.find_joint(p(0, 0), p(1, 1))), JointKind::Hinge);
    for (int i = 0; i < world.particle_count(); ++i) EXPECT_LT((world.particle_position(i) - where[i]).norm(), 1e-15);
  };
  world.combine(p(0, 0), p(1, 1));  // lock
  EXPECT_EQ(world.body_count(), bodies - 1);
  world.separate(p(0, 0), p(1, 1));  // unlock
  check();
  world.separate(p(0, 0), p(1, 1));  // break
  EXPECT_LT(world.find_joint(p(0, 0), p(1, 1)), 0);
  world.combine(p(0, 0), p(1, 1));  // join again at the same (coincident) corners
  check();
}

TEST_F(Restructuring, RefusesWhatItCannotSolveAndChangesNothing) {
  world.combine(p(1, 2), p(2, 3));
  const int joints_before = world.find_joint(p(1, 2), p(2, 3));
  // A fourth block hinged to the middle one's centre: body 1 would be in three hinges.
  const int extra = world.add_part(block(Vec2(0.3, 1.0 - kL)));
  try {
    world.combine(world.first_particle(extra), p(1, 4));
    FAIL() << "a third hinge on one body was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("at most two hinges"), std::string::npos) << e.what();
  }
  // Closing the chain into a loop.
  try {
    world.combine(p(2, 0), p(0, 3));
    FAIL() << "a loop was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("loop"), std::string::npos) << e.what();
  }
  EXPECT_EQ(world.find_joint(p(1, 2), p(2, 3)), joints_before);
  EXPECT_LT(world.find_joint(p(2, 0), p(0, 3)), 0);
  EXPECT_THROW(world.combine(p(0, 0), p(0, 1)), std::invalid_argument);      // same part
  EXPECT_THROW(world.separate(p(0, 3), p(2, 1)), std::invalid_argument);     // nothing joins them
  EXPECT_THROW(world.combine(-1, p(0, 1)), std::invalid_argument);           // no such particle
  EXPECT_THROW(world.step(std::nan("")), std::invalid_argument);
  EXPECT_THROW(world.apply_impulse(parts[0], Vec2(0, 0), Vec2(std::nan(""), 0)), std::invalid_argument);
}

// A held block (kinematic, still) and a free block folded against it and spinning: moving the hinge to the far
// corners (the paper's Algorithm 2: separate, then combine the far corners) is an impulse at the new hinge only,
// so the free block's angular momentum about the new hinge is conserved (1e-12 relative).
TEST(World, HeldPairFlipConservesTheFreeBlocksAngularMomentumAboutTheNewHinge) {
  World world;
  const Vec2 hinge(0.0, 0.0);
  PartDef held = block(hinge - Vec2(kW / 2, -kL / 2));
  held.kinematic = true;
  const int b0 = world.add_part(held);
  const int b1 = world.add_part(block(hinge - Rot::of(std::numbers::pi) * Vec2(kW / 2, kL / 2), std::numbers::pi));
  const int p0 = world.first_particle(b0), p1 = world.first_particle(b1);
  world.connect(p0 + 0, p1 + 1);
  world.finalize();
  world.apply_impulse(b1, world.particle_position(p1 + 0), Vec2(-2e-3, 1e-3));  // spin it about the hinge
  ASSERT_GT(std::abs(world.part_omega(b1)), 0.1);
  const Vec2 pivot = world.particle_position(p1 + 0);  // the new hinge: block 1's far corner, on block 0's
  ASSERT_LT((pivot - world.particle_position(p0 + 1)).norm(), 1e-15);
  const double before = world.angular_momentum({b1}, pivot);
  world.separate(p0 + 0, p1 + 1);
  const Restructure r = world.combine(p0 + 1, p1 + 0);
  EXPECT_NEAR(world.angular_momentum({b1}, pivot), before, 1e-12 * std::abs(before));
  EXPECT_GT(r.energy_removed, 0);
  EXPECT_LT(world.particle_velocity(p1 + 0).norm(), 1e-14);  // its corner is now held still
}

// A held block and a block welded below it at its top-right corner, pushed sideways at its bottom-left corner:
// at rest, the weld must carry the push's and gravity's moment about the weld point exactly, F L - m g W / 2
// (counter-clockwise positive) for a push to the left, the opposite sign plus gravity for a push to the right.
TEST(World, WeldMomentBalancesTheLoads) {
  for (double push : {-0.5, 0.5}) {
    World world;
    PartDef held = block(Vec2(kW / 2, -kL / 2));
    held.kinematic = true;
    const int b0 = world.add_part(held);
    const int b1 = world.add_part(block(Vec2(kW / 2, -3 * kL / 2)));
    const int p0 = world.first_particle(b0), p1 = world.first_particle(b1);
    world.connect(p0 + 0, p1 + 1);
    world.finalize();
    world.combine(p0 + 0, p1 + 1);
    world.add_force(b1, Vec2(-kW / 2, -kL / 2), Vec2(push, 0), 1.0);
    world.step(1e-3);
    const double expected = -push * kL - kM * 9.81 * kW / 2;
    EXPECT_NEAR(world.weld_moment(p0 + 0, p1 + 1), expected, 1e-12) << "push " << push;
  }
}

// A user's force is part of the state a redone step needs: a step redone from a snapshot as two half steps
// applies the same force, and a force that ends inside a step gives its own impulse F * duration, not F * h.
TEST(World, AppliedForcesSurviveRedoneStepsAndEndOnTime) {
  Options opt;
  opt.gravity = Vec2::Zero();
  World world(opt);
  const int b = world.add_part(block(Vec2(0, 0)));
  world.add_force(b, Vec2::Zero(), Vec2(1.0, 0.0), 1e-3);
  const Snapshot start = world.save();
  world.step(1e-3);
  const Vec2 one_step = world.part_velocity(b);
  world.restore(start);
  world.step(5e-4);
  world.step(5e-4);
  EXPECT_NEAR((world.part_velocity(b) - one_step).norm(), 0.0, 1e-15);
  EXPECT_NEAR(one_step.x(), 1.0 * 1e-3 / kM, 1e-12);  // F t / m
  World short_push(opt);
  const int c = short_push.add_part(block(Vec2(0, 0)));
  short_push.add_force(c, Vec2::Zero(), Vec2(1.0, 0.0), 1e-6);  // a microsecond push inside a 1 ms step
  short_push.step(1e-3);
  short_push.step(1e-3);
  EXPECT_NEAR(short_push.part_velocity(c).x(), 1.0 * 1e-6 / kM, 1e-15);
}

// StepStats::work, which the ladder's watchdog sets against each step's energy gain, is the work put in:
//  - a push off centre on a free block: F . (v0 + v1) / 2 h, which for symplectic Euler is the kinetic energy gained
//    exactly (translation and rotation);
//  - a hand lifting a block hinged at its centre at a constant 0.1 m/s for 100 steps of 1 ms: the hinge holds the
//    block against gravity, so the hand's work is m g v h a step, all of it potential energy (with the sign wrong
//    it would be -m g v h).
TEST(World, StepWorkIsTheWorkOfForcesAndDrives) {
  {
    Options opt;
    opt.gravity = Vec2::Zero();
    World world(opt);
    const int b = world.add_part(block(Vec2(0, 0), 0.3, Vec2(0.2, -0.1), 1.5));
    world.add_force(b, Vec2(kW / 2, kL / 2), Vec2(0.5, 0.25), 1.0);
    for (int i = 0; i < 10; ++i) {
      const double e0 = world.kinetic_energy();
      world.step(1e-3);
      EXPECT_GT(world.last_step().work, 1e-5);
      EXPECT_NEAR(world.last_step().work, world.kinetic_energy() - e0, 1e-15);
    }
  }
  World world;
  const double v = 0.1;
  const int hand = world.add_part(block(Vec2(0, 0)));
  world.set_drive(hand, [v](double t) {
    Kinematics k;
    k.x = Vec2(0, v * t);
    k.v = Vec2(0, v);
    return k;
  });
  const int b = world.add_part(block(Vec2(0, 0), 0.4, Vec2(0, v)));  // hinged at its centre: it does not swing
  world.connect(world.first_particle(hand) + 4, world.first_particle(b) + 4);
  world.finalize();
  const double g = 9.81;
  for (int i = 0; i < 100; ++i) {
    const Energy e0 = world.energy();
    world.step(1e-3);
    const Energy e1 = world.energy();
    EXPECT_NEAR(world.last_step().work, kM * g * v * 1e-3, 1e-9 * kM * g * v * 1e-3);
    EXPECT_NEAR(e1.total() - e0.total(), world.last_step().work, 1e-9 * kM * g * v * 1e-3);
  }
  EXPECT_NEAR(world.part_position(b).y(), v * 0.1, 1e-12);
}

// World::energy() is kept while nothing moves; anything that moves must renew it: an impulse on a block in no hinge
// (whose velocity projection has no rows to project), a step, a change of gravity.
TEST(World, EnergyFollowsEveryChange) {
  World world;
  const int b = world.add_part(block(Vec2(0, 0)));
  world.finalize();
  EXPECT_EQ(world.energy().kinetic, 0.0);
  world.apply_impulse(b, world.part_position(b), Vec2(0.02, 0));
  EXPECT_DOUBLE_EQ(world.energy().kinetic, world.kinetic_energy());
  EXPECT_GT(world.energy().kinetic, 0.0);
  world.step(1e-3);
  EXPECT_DOUBLE_EQ(world.energy().total(), world.kinetic_energy() + world.potential_energy());
  Options zero_g = world.options();
  zero_g.gravity = Vec2::Zero();
  world.set_options(zero_g);
  EXPECT_EQ(world.energy().potential, 0.0);
}

// The adaptive step always ends where it was asked to, even when its solves stop short of the hinge tolerance (one
// Newton iteration allowed, a tolerance of 1e-14 m): a swinging 3-block chain, three steps of 1 ms. Before this was
// tested, such a step ended after 0.5 us, its trial size driven to zero by an infinite error estimate.
TEST(World, AdaptiveStepReachesTheEndEvenWhenSolvesStopShort) {
  Options opt;
  opt.adaptive = true;
  opt.tolerance = 1e-14;
  opt.max_iterations = 1;
  World world(opt);
  int prev = anchor(world, Vec2::Zero());
  for (int i = 0; i < 3; ++i) {
    const int part = world.add_part(block(Vec2(kW / 2, -kL / 2 - kL * i), 0.5 * (i == 1)));
    world.connect(prev, world.first_particle(part) + 3);
    prev = world.first_particle(part) + 2;
  }
  world.finalize();
  world.project_velocities();
  for (int i = 1; i <= 3; ++i) {
    world.step(1e-3);
    EXPECT_DOUBLE_EQ(world.time(), 1e-3 * i);
    EXPECT_TRUE(world.finite());
    EXPECT_GE(world.last_step().substeps, 1);
  }
  // A tolerance nothing meets and a step of 1e-11 s at t = 1000 s, where half of the smallest sub-step is below the
  // clock's resolution: the step still ends (it used to loop for ever), in one plain step.
  Options strict = world.options();
  strict.error_tolerance = 1e-300;
  world.set_options(strict);
  Snapshot late = world.save();
  late.t = 1000;
  world.restore(late);
  world.step(1e-11);
  EXPECT_EQ(world.time(), 1000 + 1e-11);
  EXPECT_TRUE(world.finite());
}

// Same model, same steps: the same bits (floating-point contraction is off in the build).
TEST(World, DeterministicToTheBit) {
  const auto run = [] {
    World world;
    const int b0 = world.add_part(block(Vec2(kW / 2, -kL / 2)));
    const int b1 = world.add_part(block(Vec2(kW / 2, -3 * kL / 2), 0, Vec2(0.15, -0.025), 5.0));
    world.connect(anchor(world, Vec2::Zero()), world.first_particle(b0) + 3);
    world.connect(world.first_particle(b0), world.first_particle(b1) + 1);
    for (int i = 0; i < 3000; ++i) world.step(1e-3);
    return world.save();
  };
  const Snapshot a = run(), b = run();
  ASSERT_EQ(a.bodies.size(), b.bodies.size());
  EXPECT_EQ(std::memcmp(a.bodies.data(), b.bodies.data(), a.bodies.size() * sizeof(BodyState)), 0);
}

// The two particles of hinge i of a straight chain of blocks `parts` (between blocks i - 1 and i): their right
// corners for odd i, their left ones for even i, as in the ladder.
std::pair<int, int> hinge_particles(const World& world, const std::vector<int>& parts, int i) {
  return {world.first_particle(parts[i - 1]) + (i % 2 ? 0 : 2), world.first_particle(parts[i]) + (i % 2 ? 1 : 3)};
}

void connect_hinge(World& world, const std::vector<int>& parts, int i) {
  const auto [p, q] = hinge_particles(world, parts, i);
  world.connect(p, q);
}

// A straight chain of n blocks hanging from a pin at (0, 0).
std::vector<int> hanging_chain(World& world, int n) {
  std::vector<int> parts;
  for (int i = 0; i < n; ++i) parts.push_back(world.add_part(block(Vec2(kW / 2, -kL / 2 - kL * i))));
  world.connect(anchor(world, Vec2::Zero()), world.first_particle(parts[0]) + 3);
  for (int i = 1; i < n; ++i) connect_hinge(world, parts, i);
  return parts;
}

// The reduced integrator places every body by its hinge, so the hinges hold to rounding with no solve: a chain of 200
// blocks pinned at its top in zero gravity, its top block kicked (a whip along the chain), for 1 s at 1 ms keeps its
// hinges within 1e-14 m (SHAKE stops at its 1e-12 m tolerance) and its hinges' two velocities equal (G v = 0) to
// rounding, with no Newton iteration. A chain held at both ends cannot grow from its first body: SHAKE steps it
// (iterations counted, hinges within the solver's tolerance).
TEST(World, ReducedStepKeepsHingesWithoutASolve) {
  Options opt;
  opt.integrator = Integrator::Reduced;
  opt.gravity = Vec2::Zero();
  World world(opt);
  const int n = 200;
  const std::vector<int> parts = hanging_chain(world, n);
  world.finalize();
  world.apply_impulse(parts[0], world.particle_position(world.first_particle(parts[0])), Vec2(1e-3, 0));
  int iterations = 0;
  for (int i = 0; i < 1000; ++i) {
    world.step(1e-3);
    iterations += world.last_step().iterations;
  }
  EXPECT_EQ(iterations, 0);
  EXPECT_LT(world.max_hinge_error(), 1e-14);
  EXPECT_GT(world.kinetic_energy(), 1e-6);  // it moves
  double slip = 0;  // relative velocity of each hinge's two particles
  for (int i = 1; i < n; ++i) {
    const auto [p, q] = hinge_particles(world, parts, i);
    slip = std::max(slip, (world.particle_velocity(p) - world.particle_velocity(q)).norm());
  }
  EXPECT_LT(slip, 1e-12);

  Options held_opt;
  held_opt.integrator = Integrator::Reduced;
  World held(held_opt);
  const std::vector<int> three = hanging_chain(held, 3);
  held.connect(held.first_particle(three[2]) + 0, anchor(held, Vec2(kW, -3 * kL)));  // its bottom-right corner
  held.finalize();
  iterations = 0;
  for (int i = 0; i < 100; ++i) {
    held.step(1e-3);
    iterations += held.last_step().iterations;
  }
  EXPECT_GT(iterations, 0);
  EXPECT_LT(held.max_hinge_error(), 1e-12);
}

// Three chains of 3 blocks the reduced step walks differently: from a pin that a drive shakes sideways (the drive's
// acceleration enters the hinge forces), free-floating (its first body has a whole pose of its own), and pinned at
// its top but with the pin's hinge made last, so that the rows run from the free bottom block up to the pin (the
// chain grows from its end). Gravity on, a kick to the bottom block.
enum class ChainShape { ShakenPin, FreeFloating, FromEnd };

World chain_of_three(ChainShape shape, Integrator integrator) {
  Options opt;
  opt.integrator = integrator;
  World world(opt);
  std::vector<int> parts;
  for (int i = 0; i < 3; ++i) parts.push_back(world.add_part(block(Vec2(kW / 2, -kL / 2 - kL * i))));
  if (shape == ChainShape::ShakenPin) {
    const int pin = anchor(world, Vec2::Zero());
    world.set_drive(world.part_of_particle(pin), [](double t) {
      Kinematics k;
      k.x = Vec2(0.02 * std::sin(6 * t), 0);
      k.v = Vec2(0.12 * std::cos(6 * t), 0);
      k.a = Vec2(-0.72 * std::sin(6 * t), 0);
      return k;
    });
    world.connect(pin, world.first_particle(parts[0]) + 3);
  }
  connect_hinge(world, parts, 1);
  connect_hinge(world, parts, 2);
  if (shape == ChainShape::FromEnd) world.connect(anchor(world, Vec2::Zero()), world.first_particle(parts[0]) + 3);
  world.finalize();
  world.apply_impulse(parts[2], world.part_position(parts[2]) + Vec2(0, -kL / 2), Vec2(2e-3, 0));
  return world;
}

double largest_angle_difference(const World& a, const World& b) {
  double worst = 0;
  for (int i = 0; i < 3; ++i) worst = std::max(worst, std::abs(a.part_angle(i) - b.part_angle(i)));
  return worst;
}

// The reduced step is first order on each of those shapes (the error against RK4 at 1/64 ms halves with the step,
// over 0.3 s), never falls back to SHAKE on them (no Newton iteration), and keeps their hinges to rounding. A wrong
// drive acceleration, a free first body that ignored its hinge forces or a chain walked from the wrong end gives an
// error that does not shrink with the step, and a chain walked from its free end drags its pin along.
TEST(World, ReducedStepIsFirstOrderOnEveryChainShape) {
  for (ChainShape shape : {ChainShape::ShakenPin, ChainShape::FreeFloating, ChainShape::FromEnd}) {
    World reference = chain_of_three(shape, Integrator::RK4);
    for (int i = 0; i < 0.3 * 64e3; ++i) reference.step(1.0 / 64e3);
    double err[3];
    for (int j = 0; j < 3; ++j) {
      const double dt = 1e-3 / (1 << j);
      World w = chain_of_three(shape, Integrator::Reduced);
      int iterations = 0;
      for (int i = 0; i < std::lround(0.3 / dt); ++i) {
        w.step(dt);
        iterations += w.last_step().iterations;
      }
      EXPECT_EQ(iterations, 0) << "shape " << static_cast<int>(shape);
      EXPECT_LT(w.max_hinge_error(), 1e-14) << "shape " << static_cast<int>(shape);
      if (shape != ChainShape::FreeFloating) {  // the pin (part 3) is where its drive puts it, not where a hinge would
        const Vec2 pin(shape == ChainShape::ShakenPin ? 0.02 * std::sin(6 * w.time()) : 0.0, 0.0);
        EXPECT_LT((w.particle_position(w.first_particle(3)) - pin).norm(), 1e-15)
            << "shape " << static_cast<int>(shape);
      }
      err[j] = largest_angle_difference(w, reference);
    }
    for (int j = 0; j < 2; ++j) {
      EXPECT_GT(err[j] / err[j + 1], 1.6) << "shape " << static_cast<int>(shape) << ": " << err[j] << " " << err[j + 1];
      EXPECT_LT(err[j] / err[j + 1], 2.6) << "shape " << static_cast<int>(shape) << ": " << err[j] << " " << err[j + 1];
    }
    EXPECT_LT(err[0], 0.05) << "shape " << static_cast<int>(shape);
  }
}

// A reduced step redone from a snapshot (the watchdog's halving, event location) ends on the same bits as the first
// try, even when a drive accelerates: the drive's acceleration is taken at the step's start time, not left from a
// later step.
TEST(World, ReducedStepRedoneFromASnapshotEndsOnTheSameBits) {
  World w = chain_of_three(ChainShape::ShakenPin, Integrator::Reduced);
  for (int i = 0; i < 100; ++i) w.step(1e-3);
  const Snapshot start = w.save();
  w.step(1e-3);
  const Snapshot first = w.save();
  for (int i = 0; i < 50; ++i) w.step(1e-3);
  w.restore(start);
  w.step(1e-3);
  const Snapshot again = w.save();
  EXPECT_EQ(std::memcmp(first.bodies.data(), again.bodies.data(), first.bodies.size() * sizeof(BodyState)), 0);
}

// step(h, adaptive, &before) leaves the state before the step in `before`, as save() would have: the reduced step by
// handing over the buffer it stepped from, the others by a copy. The same `before` serves step after step (its
// buffer goes back and forth with the world's). Restored, a reduced step is redone to the same bits (SHAKE's solve
// starts from the last step's multipliers, so its redo agrees only to the solver's tolerance).
TEST(World, StepHandsOverTheStateBeforeIt) {
  for (const Integrator integrator : {Integrator::Reduced, Integrator::SymplecticEuler}) {
    SCOPED_TRACE(static_cast<int>(integrator));
    World w = chain_of_three(ChainShape::ShakenPin, integrator);
    Snapshot before;
    for (int i = 0; i < 20; ++i) {
      const Snapshot saved = w.save();
      w.step(1e-3, false, &before);
      const Snapshot after = w.save();
      ASSERT_EQ(before.bodies.size(), saved.bodies.size());
      EXPECT_EQ(std::memcmp(before.bodies.data(), saved.bodies.data(), saved.bodies.size() * sizeof(BodyState)), 0)
          << "step " << i;
      EXPECT_EQ(before.t, saved.t);
      EXPECT_EQ(before.structure, saved.structure);
      if (integrator != Integrator::Reduced) continue;
      w.restore(before);
      w.step(1e-3, false, &before);
      EXPECT_EQ(std::memcmp(w.save().bodies.data(), after.bodies.data(), after.bodies.size() * sizeof(BodyState)), 0)
          << "step " << i << " redone";
    }
  }
}

// An impulse on a free chain changes its total linear momentum by exactly the impulse, and the hinges carry it.
TEST(World, ImpulseTravelsThroughTheChain) {
  Options opt;
  opt.gravity = Vec2::Zero();
  World world(opt);
  const int b0 = world.add_part(block(Vec2(0, 0)));
  const int b1 = world.add_part(block(Vec2(0, -kL)));
  world.connect(world.first_particle(b0), world.first_particle(b1) + 1);
  world.finalize();
  const Vec2 j(0.01, 0.002);
  world.apply_impulse(b1, world.part_position(b1) + Vec2(0, -kL / 2), j);
  EXPECT_LT((world.linear_momentum({b0, b1}) - j).norm(), 1e-15);
  EXPECT_GT(world.part_velocity(b0).norm(), 0.0);  // the upper block moved too
  const Vec2 pa = world.particle_velocity(world.first_particle(b0));
  const Vec2 pb = world.particle_velocity(world.first_particle(b1) + 1);
  EXPECT_LT((pa - pb).norm(), 1e-14);  // the hinged corners move together
}

}  // namespace
}  // namespace ladder::core

namespace ladder::core {
namespace {

// unit_at (the rolling contact's direction, computed without libm) against long double cos and sin: within 3 ulps of
// each component and 2.5e-16 absolute on angles up to 1e6 rad, including both sides of every multiple of pi / 4 up to
// 100 pi (a wrong reduction or quadrant swap is off by far more than that), exact at 0, and libm's beyond 1e6 rad.
TEST(Geometry, UnitAtMatchesCosAndSinToAFewUlps) {
  std::vector<double> angles = {0.0, -0.0, 1e-300, std::numbers::pi / 2, -std::numbers::pi, 3 * std::numbers::pi / 2};
  for (int q = -400; q <= 400; ++q)
    for (double d : {-1e-9, 0.0, 1e-9}) angles.push_back(q * (std::numbers::pi / 4) + d);
  uint64_t x = 88172645463325252ull;  // xorshift: angles spread over each range
  for (double range : {1.0, 10.0, 1e3, 1e6})
    for (int i = 0; i < 20000; ++i) {
      x ^= x << 13, x ^= x >> 7, x ^= x << 17;
      angles.push_back(range * (static_cast<double>(x >> 11) * 0x1p-53 * 2 - 1));
    }
  // In ulps of the true value; a value within 1e-10 of zero (an angle within that of a multiple of pi / 2) is judged
  // against 1e-24 absolute instead: its reduced angle carries the rounding of the reduction, ~1e-27 rad.
  const auto ulps = [](double got, long double want) {
    const double w = static_cast<double>(want), ulp = std::nextafter(std::abs(w), 2.0) - std::abs(w);
    const double err = static_cast<double>(std::abs(static_cast<long double>(got) - want));
    return std::abs(w) < 1e-10 ? err / 1e-24 * 3 : err / ulp;
  };
  double worst_ulps = 0, worst_abs = 0;
  for (const double a : angles) {
    const Vec2 u = unit_at(a);
    const long double c = std::cos(static_cast<long double>(a)), s = std::sin(static_cast<long double>(a));
    worst_ulps = std::max({worst_ulps, ulps(u.x(), c), ulps(u.y(), s)});
    const double err_c = static_cast<double>(std::abs(u.x() - c)), err_s = static_cast<double>(std::abs(u.y() - s));
    worst_abs = std::max({worst_abs, err_c, err_s});
  }
  EXPECT_LE(worst_ulps, 3.0);
  EXPECT_LE(worst_abs, 2.5e-16);
  EXPECT_EQ(unit_at(0.0), Vec2(1.0, 0.0));
  EXPECT_EQ(unit_at(2e6), Vec2(std::cos(2e6), std::sin(2e6)));  // beyond 1e6 rad: libm's
}

// rotation_of_small_angle's short form for |a| <= 2^-26 must give the bits of the full series (the step's results
// would change otherwise): checked on every binade below 2^-26, both signs, and the edges.
TEST(Geometry, ShortRotationSeriesIsBitIdenticalToTheFullOne) {
  const auto full = [](double a) {
    const double a2 = a * a;
    const double c = 1.0 - a2 * (1.0 / 2 - a2 * (1.0 / 24 - a2 * (1.0 / 720 - a2 * (1.0 / 40320))));
    const double s = a * (1.0 - a2 * (1.0 / 6 - a2 * (1.0 / 120 - a2 * (1.0 / 5040 - a2 * (1.0 / 362880)))));
    return Rot{c, s};
  };
  std::vector<double> angles = {0x1p-26, -0x1p-26, 0.0, -0.0, 5e-324};
  for (int e = -1074; e <= -27; ++e)
    for (double m : {1.0, 1.2345678901234567, 1.5, 1.9999999999999998})
      for (double sign : {1.0, -1.0}) angles.push_back(sign * std::ldexp(m, e));
  for (double a : angles) {
    const Rot x = rotation_of_small_angle(a), y = full(a);
    EXPECT_EQ(std::memcmp(&x.c, &y.c, sizeof(double)), 0) << a;
    EXPECT_EQ(std::memcmp(&x.s, &y.s, sizeof(double)), 0) << a;
  }
}

}  // namespace
}  // namespace ladder::core

namespace ladder::core {
namespace {

// finite() sums x * 0 over the state instead of testing each value: every kind of non-finite value, anywhere in a
// body's state, must still show.
TEST(World, FiniteSeesEveryNonFiniteValue) {
  const double bad[] = {std::nan(""), HUGE_VAL, -HUGE_VAL};
  for (int field = 0; field < 3; ++field) {
    for (double x : bad) {
      World world;
      world.add_part(block(Vec2(0.1, 0.2)));
      world.add_part(block(Vec2(1e300, -1e300), 0.3, Vec2(1e300, 1e300)));  // huge but finite
      EXPECT_TRUE(world.finite());
      PartDef def = block(Vec2::Zero());
      if (field == 0) def.position = Vec2(0.0, x);
      if (field == 1) def.velocity = Vec2(x, 0.0);
      if (field == 2) def.omega = x;
      world.add_part(def);
      EXPECT_FALSE(world.finite()) << field << " " << x;
    }
  }
}

}  // namespace
}  // namespace ladder::core

namespace ladder::core {
namespace {

// The Newton corrections turn bodies with two series terms and no renormalisation: within an ulp or two of the full
// series followed by renormalisation, for every angle they take that path, and |q| drifts from 1 by a fraction of
// an ulp per correction (measured: 3e-17), harmless over the few corrections of a solve (at most
// solver.max_iterations) before the next drift renormalises: a thousand of them here, with nothing renormalising.
TEST(Geometry, CorrectionRotationMatchesTheFullSeriesAndKeepsUnitLength) {
  const Rot q = Rot::of(0.7);
  for (int e = -60; e <= -13; ++e) {
    for (double sign : {1.0, -1.0}) {
      const double a = sign * std::ldexp(1.0, e);
      const Rot x = turned_by_small_correction(q, a), y = (q * rotation_of_small_angle(a)).renormalised();
      EXPECT_NEAR(x.c, y.c, 4e-16) << a;
      EXPECT_NEAR(x.s, y.s, 4e-16) << a;
    }
  }
  Rot r = q;
  double angle = 0.7;
  for (int i = 0; i < 1000; ++i) {
    const double a = (i % 2 ? -1.0 : 1.3) * 1e-5;
    r = turned_by_small_correction(r, a);
    angle += a;
  }
  EXPECT_NEAR(r.c * r.c + r.s * r.s, 1.0, 1e-13);
  EXPECT_NEAR(r.c, std::cos(angle), 1e-13);
  EXPECT_NEAR(r.s, std::sin(angle), 1e-13);
  // Past 2^-13 it is the full path.
  const Rot big = turned_by_small_correction(q, 0.01), full = (q * rotation_of_small_angle(0.01)).renormalised();
  EXPECT_EQ(big.c, full.c);
  EXPECT_EQ(big.s, full.s);
}

}  // namespace
}  // namespace ladder::core
