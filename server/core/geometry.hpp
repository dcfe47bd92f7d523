// 2-D geometry used throughout the engine: vectors, 2x2 matrices and rotations as unit complex numbers.
#pragma once

#include <Eigen/Core>
#include <cmath>

namespace ladder::core {

using Vec2 = Eigen::Vector2d;
using Mat2 = Eigen::Matrix2d;

// z-component of the 3-D cross product of two in-plane vectors.
inline double cross(const Vec2& a, const Vec2& b) { return a.x() * b.y() - a.y() * b.x(); }
// a rotated by +90 degrees: the velocity of a point at offset a on a body turning at 1 rad/s is perp(a).
inline Vec2 perp(const Vec2& a) { return {-a.y(), a.x()}; }

// A rotation stored as (cos, sin). Applying it costs four multiplies; composing two costs four more. The
// engine keeps the unwrapped angle beside it as the source of truth for output and composes rotations
// incrementally in the step (see rotation_of_small_angle), which avoids a sin/cos call per body per stage.
struct Rot {
  double c = 1.0;
  double s = 0.0;
  static Rot of(double angle) { return {std::cos(angle), std::sin(angle)}; }
  // c v + s perp(v): written on whole 2-vectors so that it compiles to packed SSE2 (two multiplies, one add, one
  // shuffle) instead of four scalar multiplies; the same bits as (c x - s y, s x + c y).
  Vec2 operator*(const Vec2& v) const { return c * v + s * perp(v); }
  Rot operator*(const Rot& r) const { return {c * r.c - s * r.s, s * r.c + c * r.s}; }
  Rot inverse() const { return {c, -s}; }
  // Pulls |q| back to 1 (one Newton step for 1/sqrt: exact to rounding while |q| - 1 is below 1e-8). Without it,
  // rounding in repeated compositions grows |q| - 1 and the bodies stretch.
  Rot renormalised() const {
    const double k = 1.5 - 0.5 * (c * c + s * s);
    return {c * k, s * k};
  }
  Vec2 apply_inverse(const Vec2& v) const { return {c * v.x() + s * v.y(), -s * v.x() + c * v.y()}; }
};

// (cos a, sin a) for any angle, without libm: the direction of a rolling hinge's contact, found from its two bodies'
// unwrapped angles once per hinge and step. libm's sincos was 6 % of a rolling ladder's step at rest, and which of its
// builds runs depends on the processor (glibc picks an FMA one where it can), so its last bit could differ between
// two machines replaying one log; these are the same operations everywhere.
// The angle is reduced by the nearest multiple k of pi / 2 (pi / 2 split into two 33-bit parts and a rest, so that
// k times the parts is exact for |k| < 2^20) to |r| <= pi / 4, where the Taylor series below are exact to rounding
// (the first omitted terms, r^19 / 19! and r^18 / 18!, are below 1e-17); then the quadrant k mod 4 swaps and negates.
// Within 3 ulps of the true values and 2.5e-16 absolute (tests/core/world_test.cpp); beyond |a| = 1e6 rad, libm.
inline Vec2 unit_at(double a) {
  if (!(std::abs(a) <= 1e6)) return {std::cos(a), std::sin(a)};
  constexpr double kTwoOverPi = 0.63661977236758134308, kRound = 0x1.8p52;  // x + kRound - kRound rounds x
  constexpr double kPio2a = 1.5707963267341256, kPio2b = 6.077100506303966e-11, kPio2c = 2.0222662487959506e-21;
  const double k = (a * kTwoOverPi + kRound) - kRound;
  const double r = ((a - k * kPio2a) - k * kPio2b) - k * kPio2c;
  // The series in z = r^2 by Estrin's scheme (pairs, then pairs of pairs) rather than Horner's: about half the
  // chain of dependent operations, so that the rows of a pass overlap more instead of waiting on each other.
  const double z = r * r, z2 = z * z, z4 = z2 * z2;
  const double ps = ((-1.0 / 6 + z * (1.0 / 120)) + z2 * (-1.0 / 5040 + z * (1.0 / 362880))) +
                    z4 * ((-1.0 / 39916800 + z * (1.0 / 6227020800)) +
                          z2 * (-1.0 / 1307674368000 + z * (1.0 / 355687428096000)));
  const double pc = ((-1.0 / 2 + z * (1.0 / 24)) + z2 * (-1.0 / 720 + z * (1.0 / 40320))) +
                    z4 * ((-1.0 / 3628800 + z * (1.0 / 479001600)) +
                          z2 * (-1.0 / 87178291200 + z * (1.0 / 20922789888000)));
  const double s = r + (r * z) * ps, c = 1 + z * pc;
  // Quadrant q: (c, s), (-s, c), (-c, -s), (s, -c), chosen by indexing rather than by branches (along a tipped
  // ladder the quadrants of neighbouring hinges follow no pattern a branch predictor learns).
  const int q = static_cast<int>(static_cast<long long>(k) & 3);
  constexpr double kSignX[4] = {1, -1, -1, 1}, kSignY[4] = {1, 1, -1, -1};
  const double cs[2] = {c, s};
  return {kSignX[q] * cs[q & 1], kSignY[q] * cs[(q & 1) ^ 1]};
}

// cos and sin of a small increment. The step turns each body by at most a few hundredths of a radian, where
// truncated Taylor series are exact to the last bit and much cheaper than libm; larger angles use libm.
inline Rot rotation_of_small_angle(double a) {
  if (std::abs(a) > 0.1) return Rot::of(a);
  // |a| <= 2^-26 (the later Newton corrections): every inner term below is then under half an ulp of the constant
  // it is taken from (a^2 / 24 < 2^-56 next to 1/2, a^2 / 6 < 2^-54 next to 1, and smaller still further in), so
  // the full series rounds to exactly these two short forms: the same bits for a third of the work.
  if (std::abs(a) <= 0x1p-26) {
    const double a2 = a * a;
    return {1.0 - a2 * (1.0 / 2), a * (1.0 - a2 * (1.0 / 6))};
  }
  // |a| <= 0.1: the first omitted terms are a^10/10! < 3e-17 and a^11/11! < 3e-19, below half an ulp of 1.
  const double a2 = a * a;
  const double c = 1.0 - a2 * (1.0 / 2 - a2 * (1.0 / 24 - a2 * (1.0 / 720 - a2 * (1.0 / 40320))));
  const double s = a * (1.0 - a2 * (1.0 / 6 - a2 * (1.0 / 120 - a2 * (1.0 / 5040 - a2 * (1.0 / 362880)))));
  return {c, s};
}

// q turned by a Newton correction's angle a (|a| <= 2^-13; the corrections of a converging solve are 1e-5 rad and
// less): two terms of each series, accurate to rounding there (the first omitted ones, a^4/24 <= 2^-56 next to 1
// and a^4/120 relative to a, are below half an ulp), and no renormalisation, because |(c, s)|^2 = 1 - a^4/12
// differs from 1 by less than an ulp: the composition keeps |q| to within an ulp or two, and the next drift
// renormalises. Half the work of rotation_of_small_angle() plus renormalised(). Larger angles take that path.
inline Rot turned_by_small_correction(const Rot& q, double a) {
  if (!(std::abs(a) <= 0x1p-13)) return (q * rotation_of_small_angle(a)).renormalised();
  const double a2 = a * a;
  return q * Rot{1.0 - a2 * (1.0 / 2), a * (1.0 - a2 * (1.0 / 6))};
}

}  // namespace ladder::core
