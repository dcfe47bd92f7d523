// The core tests' building blocks: a uniform block of the comparison chain's size as particles, and a kinematic pin.
#pragma once

#include "core/world.hpp"

namespace ladder::core::test {

constexpr double kL = 0.06, kW = 0.01, kM = 0.02;

// A uniform rectangle kW x kL as five particles: 1/12 of the mass on each corner and 2/3 at the centre give the
// exact mass, centre and moment of inertia m (L^2 + W^2) / 12. Particle c: 0 bottom-right, 1 top-right,
// 2 bottom-left, 3 top-left, 4 centre.
inline PartDef block(Vec2 centre, double angle = 0, Vec2 v = Vec2::Zero(), double w = 0) {
  PartDef d;
  for (int c = 0; c < 4; ++c)
    d.particles.push_back({kM / 12, Vec2((c & 2) ? -kW / 2 : kW / 2, (c & 1) ? kL / 2 : -kL / 2)});
  d.particles.push_back({2 * kM / 3, Vec2::Zero()});
  d.position = centre;
  d.angle = angle;
  d.velocity = v;
  d.omega = w;
  return d;
}

// A massless kinematic part at `at` with one particle; returns that particle.
inline int anchor(World& world, Vec2 at) {
  PartDef pin;
  pin.particles.push_back({0.0, Vec2::Zero()});
  pin.position = at;
  pin.kinematic = true;
  return world.first_particle(world.add_part(pin));
}

// Rotates a configuration about the pivot: position and angle of a block hanging from `pivot`.
inline Vec2 rotate_about(Vec2 p, Vec2 pivot, double a) { return pivot + Rot::of(a) * (p - pivot); }

}  // namespace ladder::core::test
