// The rolling hinge (World::combine/connect with a radius): two rounded block ends rolling on each other without
// slipping. Checked against what rolling means geometrically: the arc centres stay 2 r apart, the two blocks' points
// at the contact move together, a crossed tape wrapped over both arcs keeps its length; and against the midpoint
// integrator's exact energy ledger with a rolling hinge driven by a kinematic body.
#include "core/world.hpp"
#include "test_blocks.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

namespace ladder::core {
namespace {

using test::kL, test::kW, test::kM;
constexpr double kR = 0.004;  // arc radius [m], below kW / 2

// A block whose four corner particles are its ends' arc centres, r in from both edges (particle c as in
// test::block: 0 bottom-right, 1 top-right, 2 bottom-left, 3 top-left), with the block's exact inertia.
PartDef rounded_block_r(Vec2 centre, double angle, double r, Vec2 v = Vec2::Zero(), double w = 0) {
  const double hw = kW / 2 - r, hl = kL / 2 - r;
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
PartDef rounded_block(Vec2 centre, double angle, Vec2 v = Vec2::Zero(), double w = 0) {
  return rounded_block_r(centre, angle, kR, v, w);
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
// O(h^2), docs/model.md section 3.1), so its geometry is held to 1e-12 (the tape's length is the no-slip condition
// over a step) and its end-of-step slip falls as h^2: 3.9e-5 m/s at 1 ms, a quarter of that at 0.5 ms (its mean
// velocity over a step has none). The solve is taken to 1e-15 m: the contact point the test finds (halfway between
// the arc centres) is off the solver's by up to its tolerance, which at the swing's 30 rad/s is a velocity of 3e-11
// m/s at 1e-12 m.
Contact worst_contact(Integrator integrator, double dt) {
  Options o;
  o.integrator = integrator;
  o.tolerance = 1e-15;
  World world(o);
  const Pair p = hanging_pair(world, 2.8);
  const int ca = world.first_particle(p.a), cb = world.first_particle(p.b) + 1;
  const double wrap0 = contact(world, p, ca, cb).wrap;
  Contact worst{0, 0, 0};
  double lowest = 10;
  for (int i = 0; i < static_cast<int>(std::lround(0.6 / dt)); ++i) {
    world.step(dt);
    const Contact c = contact(world, p, ca, cb);
    worst.gap = std::max(worst.gap, std::abs(c.gap));
    worst.slip = std::max(worst.slip, c.slip);
    worst.wrap = std::max(worst.wrap, std::abs(std::remainder(c.wrap - wrap0, 2 * std::numbers::pi * kR)));
    lowest = std::min(lowest, world.part_angle(p.b));
  }
  EXPECT_LT(lowest, -2.0) << to_string(integrator) << ": the swing should reach the other side";
  return worst;
}

TEST(Rolling, ArcsRollWithoutSlippingAndTheTapeKeepsItsLength) {
  for (const Integrator integrator : {Integrator::SymplecticEuler, Integrator::Rattle, Integrator::Midpoint}) {
    const char* name = to_string(integrator);
    const Contact c = worst_contact(integrator, 1e-3);
    EXPECT_LT(c.gap, 1e-12) << name;
    EXPECT_LT(c.wrap, 1e-12) << name;
    if (integrator != Integrator::Midpoint) {
      EXPECT_LT(c.slip, 1e-12) << name;
    } else {
      const Contact half = worst_contact(integrator, 5e-4);
      EXPECT_LT(half.wrap, 1e-12) << name;
      EXPECT_NEAR(c.slip / half.slip, 4.0, 0.5) << name << ": " << c.slip << " and " << half.slip << " m/s";
      EXPECT_LT(c.slip, 1e-4) << name;
    }
    std::printf("%s: worst slip %.3g m/s, gap %.3g m, tape %.3g m\n", name, c.slip, c.gap, c.wrap);
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

namespace ladder::core {
namespace {

// The dip of what hangs below a toppling block (docs/model.md section 9, "The well"): block B turns over about its
// rolling contact with the block beside it, its bottom end's two arcs carrying that contact (side s) and the next
// hinge (side -s), and a block C hangs from the next hinge. B is driven (kinematic) as the rolling contact makes it
// move: turned by phi, its arc centre kR from the still neighbour's arc rolled around it by phi / 2. C is dynamic and
// damped to rest at phi = 0 and again at phi = 90 degrees; C's centre (the weight, whose potential energy is the
// well) and the contact point of hinge B-C then drop by the predicted dips, found from the geometry and C's
// equilibrium (its centre below the contact). The contact is not a point of C: it moves around C's arc as the pair
// rolls, so it drops further than C does.
struct Topple {
  double r, T = kW, L = kL;
  // B's pose at phi: its bottom-right arc centre rolled from (T/2 - r, r) around the neighbour's, at (T/2 + r, r).
  Vec2 centre_b(double phi) const {
    const Vec2 neighbour(T / 2 + r, r);
    const Vec2 arc = neighbour + 2 * r * (Rot::of(0.5 * phi) * Vec2(-1, 0));
    return arc - Rot::of(phi) * Vec2(T / 2 - r, -(L / 2 - r));
  }
  // The contact of hinge B-C with B at phi and C at theta: D (B's bottom-left arc centre) + r u, u from D toward C's
  // top-left arc centre, u = R((phi + theta) / 2) (0, -1).
  Vec2 contact(double phi, double theta, Vec2* c_centre = nullptr) const {
    const Vec2 d = centre_b(phi) + Rot::of(phi) * Vec2(-(T / 2 - r), -(L / 2 - r));
    const Vec2 u = Rot::of(0.5 * (phi + theta)) * Vec2(0, -1);
    if (c_centre) *c_centre = d + 2 * r * u - Rot::of(theta) * Vec2(-(T / 2 - r), L / 2 - r);
    return d + r * u;
  }
  // C at rest hangs with its centre straight below the contact: theta by Newton's method on that condition.
  double equilibrium(double phi) const {
    double theta = 0;
    for (int i = 0; i < 60; ++i) {
      const auto f = [&](double th) {
        Vec2 c;
        const Vec2 p = contact(phi, th, &c);
        return c.x() - p.x();
      };
      const double e = 1e-7, fx = f(theta), df = (f(theta + e) - f(theta - e)) / (2 * e);
      theta -= fx / df;
    }
    return theta;
  }
  double predicted_dip(double phi) const {
    return contact(0, equilibrium(0)).y() - contact(phi, equilibrium(phi)).y();
  }
  // C's centre's drop, with C at rest (theta = its equilibrium) or held vertical (theta = 0).
  double centre_dip(double phi, bool at_rest) const {
    Vec2 c0, c1;
    contact(0, at_rest ? equilibrium(0) : 0.0, &c0);
    contact(phi, at_rest ? equilibrium(phi) : 0.0, &c1);
    return c0.y() - c1.y();
  }
};

struct Dips {
  double contact, centre;  // [m]
};

Dips measured_dip(double r, double phi_end) {
  const Topple g{r};
  Options o;
  o.linear_damping = 40;
  o.angular_damping = 40;
  World world(o);
  // The drive: still for 2 s, then phi from 0 to phi_end by a smoothstep over 2 s, then still again.
  const auto phi_at = [phi_end](double t) {
    const double u = std::clamp((t - 2) / 2, 0.0, 1.0);
    return phi_end * u * u * u * (10 - 15 * u + 6 * u * u);
  };
  PartDef b = rounded_block_r(g.centre_b(0), 0, r);
  b.kinematic = true;
  const int pb = world.add_part(b);
  world.set_drive(pb, [&g, phi_at](double t) {
    Kinematics k;
    const double phi = phi_at(t), e = 1e-6;
    k.theta = phi;
    k.x = g.centre_b(phi);
    // Velocities by central differences: the drive is smooth, and the test reads positions at rest only.
    k.v = (g.centre_b(phi_at(t + e)) - g.centre_b(phi_at(t - e))) / (2 * e);
    k.omega = (phi_at(t + e) - phi_at(t - e)) / (2 * e);
    return k;
  });
  Vec2 c_centre;
  g.contact(0, 0, &c_centre);
  const int pc = world.add_part(rounded_block_r(c_centre, 0, r));
  // B's bottom-left arc (particle 2) on C's top-left arc (particle 3).
  world.connect(world.first_particle(pb) + 2, world.first_particle(pc) + 3, r);
  world.finalize();
  const auto contact_y = [&] {
    return 0.5 * (world.particle_position(world.first_particle(pb) + 2) +
                  world.particle_position(world.first_particle(pc) + 3)).y();
  };
  for (int i = 0; i < 2000; ++i) world.step(1e-3);
  const double y0 = contact_y(), c0 = world.part_position(pc).y();
  for (int i = 0; i < 8000; ++i) world.step(1e-3);
  EXPECT_LT(world.kinetic_energy(), 1e-15) << "not at rest";
  return {y0 - contact_y(), c0 - world.part_position(pc).y()};
}

TEST(Rolling, ToppleDipsAsTheGeometryPredicts) {
  constexpr double kQuarter = std::numbers::pi / 2;
  for (const double r : {0.0, 0.0025, kW / 2}) {
    const Topple g{r};
    const double predicted = g.predicted_dip(kQuarter), centre = g.centre_dip(kQuarter, true);
    const Dips measured = measured_dip(r, kQuarter);
    EXPECT_NEAR(measured.contact, predicted, 1e-9) << "r = " << r;
    EXPECT_NEAR(measured.centre, centre, 1e-9) << "r = " << r;
    // With C held vertical (a heavy chain below), the closed form: T - (4 - 2 sqrt 2) r at 90 degrees (the corner
    // hinge's T when r = 0, 0.414 T for fully rounded ends), and nothing at the end of the topple.
    EXPECT_NEAR(g.centre_dip(kQuarter, false), kW - (4 - 2 * std::numbers::sqrt2) * r, 1e-12) << "r = " << r;
    EXPECT_NEAR(g.centre_dip(2 * kQuarter, false), 0.0, 1e-12) << "r = " << r;
    if (r == 0) {
      EXPECT_NEAR(predicted, kW, 1e-12);  // the corner hinge: the other corner drops by the thickness
    }
    std::printf("r = %.4f m: at 90 degrees the contact dips %.9f m (%.4f of the thickness), C's centre %.9f m "
                "(%.4f; %.4f held vertical)\n",
                r, predicted, predicted / kW, centre, centre / kW, g.centre_dip(kQuarter, false) / kW);
  }
}

}  // namespace
}  // namespace ladder::core
