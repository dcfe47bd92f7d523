// The Jacob's ladder with rolling hinges (LadderSpec::hinge, end_radius): the corner hinge as its limit, and the
// hanging start at rest.
#include "ladder/ladder.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

namespace ladder::model {
namespace {

// The classic toy (6 blocks, the hand's tip, the classic drag) for 2 s, as the largest difference of any block's angle
// from the same toy with corner hinges.
double largest_difference_from_corners(double end_radius) {
  LadderSpec corner;
  LadderSpec rolling = corner;
  rolling.hinge = HingeKind::Rolling;
  rolling.end_radius = end_radius;
  core::Options o;
  o.linear_damping = o.angular_damping = 0.1;
  Ladder a(corner, o), b(rolling, o);
  a.tip();
  b.tip();
  double worst = 0;
  for (int i = 0; i < 2000; ++i) {
    a.advance(1e-3);
    b.advance(1e-3);
    for (int k = 0; k < corner.blocks; ++k) worst = std::max(worst, std::abs(a.block_angle(k) - b.block_angle(k)));
  }
  return worst;
}

// end_radius = 0 is the corner hinge itself, and the rolling hinge tends to it linearly as the radius shrinks
// (measured: 8.6e-10 rad at 1e-12 m and 8.6e-7 rad at 1e-9 m, through the ripple with its flip-flops and locks).
TEST(RollingLadder, ZeroRadiusIsTheCornerHinge) {
  EXPECT_EQ(largest_difference_from_corners(0), 0.0);
  const double tiny = largest_difference_from_corners(1e-12), small = largest_difference_from_corners(1e-9);
  EXPECT_LT(tiny, 1e-8);
  EXPECT_GT(small, 0);
  EXPECT_NEAR(small / tiny, 1000, 100);  // first order in the radius
}

// Fully rounded ends hang straight at rest (each pair's contact on the axis, below both centres): the hanging start
// is exact, so nothing moves. Corner hinges hang zig-zag, exact too. (0 < r < thickness / 2 starts the top pair
// slightly off equilibrium: docs/model.md section 9.)
TEST(RollingLadder, HangsAtRestWithFullyRoundedEnds) {
  for (const double r : {0.0, 0.0065}) {
    LadderSpec s;
    s.blocks = 20;
    s.hinge = r > 0 ? HingeKind::Rolling : HingeKind::Corner;
    s.end_radius = r;
    Ladder l(s, core::Options{});
    double ke = 0;
    for (int i = 0; i < 1000; ++i) {
      l.advance(1e-3);
      ke = std::max(ke, l.world().kinetic_energy());
    }
    EXPECT_LT(ke, 1e-14) << "r = " << r;
    if (r > 0) {
      for (int k = 1; k < s.blocks; ++k) EXPECT_NEAR(l.block_angle(k), 0, 1e-12) << "block " << k;
    }
  }
}

}  // namespace
}  // namespace ladder::model
