// The rolling hinge (World::combine/connect with a radius): two rounded block ends rolling on each other without
// slipping. Checked against what rolling means geometrically: the arc centres stay 2 r apart, the two blocks' points
// at the contact move together, a crossed tape wrapped over both arcs keeps its length; and against the midpoint
// integrator's exact energy ledger with a rolling hinge driven by a kinematic body.
#include "core/world.hpp"
#include "test_blocks.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

namespace ladder::core {
namespace {

using test::kL, test::kW, test::kM;
constexpr double kR = 0.004;  // arc radius [m], below kW / 2

// A block whose four corner particles are its ends' arc centres, kR in from both edges (particle c as in
// test::block: 0 bottom-right, 1 top-right, 2 bottom-left, 3 top-left), with the block's exact inertia.
PartDef rounded_block(Vec2 centre, double angle, Vec2 v = Vec2::Zero(), double w = 0) {
  const double hw = kW / 2 - kR, hl = kL / 2 - kR;
  const double corner = kM * (kL * kL + kW * kW) / (12 * (4 * hw * hw + 4 * hl * hl));
  PartDef d;
  for (int c = 0; c < 4; ++c) d.particles.push_back({corner, Vec2((c & 2) ? -hw : hw, (c & 1) ? hl : -hl)});
  d.particles.push_back({kM - 4 * corner, Vec2::Zero()});
  d.position = centre;
  d.angle = angle;
  d.velocity = v;
  d.omega = w;
  return d;
}

// Block b (dynamic) hangs from block a (kinematic, upright at the origin) by a rolling hinge on their right edges,
// a's bottom-right arc on b's top-right arc, turned by `phi` about the hinge from the straight column. Returns the
// two parts.
struct Pair {
  int a, b;
};
Pair hanging_pair(World& world, double phi, Drive drive = nullptr) {
  PartDef top = rounded_block(Vec2::Zero(), 0);
  top.kinematic = true;
  const int a = world.add_part(top);
  if (drive) world.set_drive(a, std::move(drive));
  // Rolling from the straight column by phi: the contact direction turns by phi / 2 (psi = mean angle + psi0).
  const Vec2 ca(kW / 2 - kR, -kL / 2 + kR);                      // a's bottom-right arc centre
  const Vec2 u = Rot::of(0.5 * phi) * Vec2(0, -1);               // from a's arc centre toward b's
  const Vec2 cb = ca + 2 * kR * u;                               // b's top-right arc centre
  const Vec2 centre = cb - Rot::of(phi) * Vec2(kW / 2 - kR, kL / 2 - kR);
  const int b = world.add_part(rounded_block(centre, phi));
  world.connect(world.first_particle(a), world.first_particle(b) + 1, kR);
  world.finalize();
  world.project_velocities();
  return {a, b};
}

// What the state says of the contact: the arc centres' distance from 2 r, the two blocks' velocities at the
// contact point (halfway between the arc centres) apart, and the length a crossed tape wrapped over both arcs
// changes by (r times the sum of the contact's angles on the two arcs, each in its block's frame).
struct Contact {
  double gap, slip, wrap;
};
Contact contact(const World& world, const Pair& p, int ca, int cb) {
  const Vec2 a = world.particle_position(ca), b = world.particle_position(cb);
  const Vec2 point = 0.5 * (a + b);
  const Vec2 xa = world.part_position(p.a), xb = world.part_position(p.b);
  const Vec2 va = world.part_velocity(p.a) + world.part_omega(p.a) * perp(point - xa);
  const Vec2 vb = world.part_velocity(p.b) + world.part_omega(p.b) * perp(point - xb);
  const Vec2 la = Rot::of(-world.part_angle(p.a)) * (point - a), lb = Rot::of(-world.part_angle(p.b)) * (point - b);
  return {(b - a).norm() - 2 * kR, (va - vb).norm(), kR * (std::atan2(la.y(), la.x()) + std::atan2(lb.y(), lb.x()))};
}

// A free swing through most of a turn: from 2.8 rad (nearly face to face) down through the straight column and
// up the other side, with every integrator that keeps hinges. SHAKE and RATTLE end each step with the velocities
// projected, so the contact points move together; the midpoint closes positions only (its velocity mismatch is
// O(h^2), docs/model.md section 3.1), so only its geometry is held to 1e-12. The solve is taken to 1e-15 m: the
// contact point the test finds (halfway between the arc centres) is off the solver's by up to its tolerance, which
// at the swing's 30 rad/s is a velocity of 3e-11 m/s at 1e-12 m.
TEST(Rolling, ArcsRollWithoutSlippingAndTheTapeKeepsItsLength) {
  for (const Integrator integrator : {Integrator::SymplecticEuler, Integrator::Rattle, Integrator::Midpoint}) {
    Options o;
    o.integrator = integrator;
    o.tolerance = 1e-15;
    World world(o);
    const Pair p = hanging_pair(world, 2.8);
    const int ca = world.first_particle(p.a), cb = world.first_particle(p.b) + 1;
    const double wrap0 = contact(world, p, ca, cb).wrap;
    double worst_gap = 0, worst_slip = 0, worst_wrap = 0, lowest = 10;
    for (int i = 0; i < 600; ++i) {
      world.step(1e-3);
      const Contact c = contact(world, p, ca, cb);
      worst_gap = std::max(worst_gap, std::abs(c.gap));
      worst_slip = std::max(worst_slip, c.slip);
      worst_wrap = std::max(worst_wrap, std::abs(std::remainder(c.wrap - wrap0, 2 * std::numbers::pi * kR)));
      lowest = std::min(lowest, world.part_angle(p.b));
    }
    const char* name = to_string(integrator);
    EXPECT_LT(lowest, -2.0) << name << ": the swing should reach the other side";
    EXPECT_LT(worst_gap, 1e-12) << name;
    EXPECT_LT(worst_wrap, 1e-12) << name;
    if (integrator != Integrator::Midpoint) {
      EXPECT_LT(worst_slip, 1e-12) << name;
    }
  }
}

// The midpoint step's exact ledger holds with a rolling hinge against a driven body: the top block turned by a
// smooth drive through half a turn drags the hanging block (damped), and every step's energy change equals the
// drive's work less the damping's dissipation to 1e-9 J (docs/model.md sections 3.1 and 9).
TEST(Rolling, MidpointLedgerClosesWithADrivenRollingHinge) {
  Options o;
  o.integrator = Integrator::Midpoint;
  o.linear_damping = 0.3;
  o.angular_damping = 0.2;
  o.hinge_friction = 1e-5;
  World world(o);
  const auto drive = [](double t) {
    Kinematics k;
    const double u = std::clamp(t / 0.4, 0.0, 1.0), d = std::numbers::pi;
    k.theta = d * u * u * u * (10 - 15 * u + 6 * u * u);
    if (t < 0.4) {
      k.omega = d / 0.4 * 30 * u * u * (1 - 2 * u + u * u);
      k.alpha = d / (0.4 * 0.4) * 60 * u * (1 - 3 * u + 2 * u * u);
    }
    return k;
  };
  const Pair p = hanging_pair(world, 0.3, drive);
  (void)p;
  double worst = 0, total_work = 0;
  for (int i = 0; i < 800; ++i) {
    const double e0 = world.energy().total();
    world.step(1e-3);
    const StepStats& st = world.last_step();
    ASSERT_TRUE(st.converged) << "step " << i;
    worst = std::max(worst, std::abs(world.energy().total() - e0 - st.work + st.dissipated));
    total_work += st.work;
  }
  EXPECT_GT(std::abs(total_work), 1e-4) << "the drive should do work on the hanging block";
  EXPECT_LT(worst, 1e-9);
}

}  // namespace
}  // namespace ladder::core
