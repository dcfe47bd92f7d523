// The block-tridiagonal solver against a dense LU solve of the same system.
#include "core/block_tridiag.hpp"

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include <random>
#include <string>

using ladder::core::BlockTridiag;
using ladder::core::BlockTridiag3;
using ladder::core::Coupling3;
using ladder::core::Mat2;
using ladder::core::Mat3;
using ladder::core::Vec2;
using ladder::core::Vec3;

namespace {

// A random symmetric positive definite block-tridiagonal system shaped like a chain's G M^-1 G^T: strong diagonal
// blocks, weaker couplings, and every `cut`-th coupling zero (independent chains).
BlockTridiag random_system(int n, int cut, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  BlockTridiag sys;
  sys.resize(n);
  for (int k = 0; k < n; ++k) {
    Mat2 a;
    a << u(rng), u(rng), u(rng), u(rng);
    sys.diag[k] = a * a.transpose() + 4.0 * Mat2::Identity();
  }
  for (int k = 1; k < n; ++k) {
    if (cut > 0 && k % cut == 0) continue;
    Mat2 c;
    c << u(rng), u(rng), u(rng), u(rng);
    sys.upper[k - 1] = c;
    sys.lower[k] = c.transpose();
  }
  return sys;
}

Eigen::MatrixXd dense(const BlockTridiag& sys) {
  const int n = sys.size();
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(2 * n, 2 * n);
  for (int k = 0; k < n; ++k) {
    a.block<2, 2>(2 * k, 2 * k) = sys.diag[k];
    if (k > 0) a.block<2, 2>(2 * k, 2 * (k - 1)) = sys.lower[k];
    if (k + 1 < n) a.block<2, 2>(2 * k, 2 * (k + 1)) = sys.upper[k];
  }
  return a;
}

}  // namespace

// A random right-hand side: b per row, and the same stacked for the dense solve.
Eigen::VectorXd random_rhs(int n, std::mt19937& rng, std::vector<Vec2>& b) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  b.resize(static_cast<size_t>(n));
  Eigen::VectorXd bd(2 * n);
  for (int k = 0; k < n; ++k) {
    b[k] = Vec2(u(rng), u(rng));
    bd.segment<2>(2 * k) = b[k];
  }
  return bd;
}

class BlockTridiagTest : public ::testing::TestWithParam<std::pair<int, int>> {};

// Relative error of the solution against partial-pivoting LU: both are backward stable on these well-conditioned
// systems (condition number < 10), so they agree to a few ulps times n; 1e-12 leaves a wide margin.
TEST_P(BlockTridiagTest, MatchesDenseLU) {
  const auto [n, cut] = GetParam();
  std::mt19937 rng(static_cast<unsigned>(n * 31 + cut));
  BlockTridiag sys = random_system(n, cut, rng);
  std::vector<Vec2> b;
  const Eigen::VectorXd ref = dense(sys).partialPivLu().solve(random_rhs(n, rng, b));
  EXPECT_EQ(sys.factor(), 0);
  sys.solve(b);
  double err = 0;
  for (int k = 0; k < n; ++k) err = std::max(err, (b[k] - ref.segment<2>(2 * k)).norm());
  EXPECT_LT(err / ref.norm(), 1e-12);
}

INSTANTIATE_TEST_SUITE_P(Sizes, BlockTridiagTest,
                         ::testing::Values(std::pair{1, 0}, std::pair{2, 0}, std::pair{7, 0}, std::pair{100, 0},
                                           std::pair{100, 5}, std::pair{300, 1}));

// The twisted solve of `sys` (B x B blocks, rows from `row`) split at `mid`, against `ref`: within 1e-12 relative, no
// pivot regularised, and each half handing every x_k over once, in its order (the top half upwards from mid - 1, the
// bottom half downwards from mid), already final.
template <int B, class Sys, class Row>
void check_twisted(Sys& sys, Row&& row, int n, int mid, const Eigen::VectorXd& ref, bool cut) {
  using V = Eigen::Matrix<double, B, 1>;
  const std::string where = "n " + std::to_string(n) + " mid " + std::to_string(mid) + " cut " + std::to_string(cut);
  sys.resize(n);
  std::vector<V> x(static_cast<size_t>(n));
  EXPECT_EQ(sys.factor_down(mid, row, x) + sys.factor_up(mid, n, row, x) + sys.meet(mid, x), 0) << where;
  std::vector<int> top, bottom;
  std::vector<V> handed(static_cast<size_t>(n));
  sys.backward(x, [&](int k) { top.push_back(k), handed[k] = x[k]; }, mid);
  sys.downward(mid, x, [&](int k) { bottom.push_back(k), handed[k] = x[k]; });
  double err = 0;
  for (int k = 0; k < n; ++k) err = std::max(err, (x[k] - ref.template segment<B>(B * k)).norm());
  EXPECT_LT(err / ref.norm(), 1e-12) << where;
  EXPECT_EQ(handed, x) << where;
  ASSERT_EQ(top.size() + bottom.size(), static_cast<size_t>(n)) << where;
  for (int k = 0; k < mid; ++k) EXPECT_EQ(top[k], mid - 1 - k) << where;
  for (int k = mid; k < n; ++k) EXPECT_EQ(bottom[k - mid], k) << where;
}

// The twisted use (two halves, one factored from each end, met in the middle: the midpoint step's split passes)
// against a dense LU of the same non-symmetric system, for split points after the first row, in the middle and before
// the last row, with the couplings at the split present or cut (check_twisted).
TEST(BlockTridiag, TwistedSolveMatchesDenseLU) {
  for (const int n : {2, 3, 8, 101}) {
    for (const int mid : {1, n / 2, n - 1}) {
      for (const bool cut : {false, true}) {
        std::mt19937 rng(static_cast<unsigned>(n * 7 + mid * 3 + cut));
        std::uniform_real_distribution<double> u(-1.0, 1.0);
        BlockTridiag sys = random_system(n, 0, rng);
        for (int k = 1; k < n; ++k) sys.lower[k] << u(rng), u(rng), u(rng), u(rng);  // not symmetric
        if (cut) sys.lower[mid].setZero(), sys.upper[mid - 1].setZero();
        std::vector<Vec2> b;
        const Eigen::VectorXd ref = dense(sys).partialPivLu().solve(random_rhs(n, rng, b));
        const auto row = [&](int k, Mat2& d, Mat2& l, Mat2& u_prev, Vec2& rhs) {
          d = sys.diag[k];
          l = sys.lower[k];
          u_prev = k > 0 ? sys.upper[k - 1] : Mat2::Zero();
          rhs = b[k];
        };
        BlockTridiag twisted;
        check_twisted<2>(twisted, row, n, mid, ref, cut);
      }
    }
  }
}

// A singular pivot (two identical hinge rows) is regularised and counted, not turned into infinities.
TEST(BlockTridiag, SingularPivotIsCountedAndFinite) {
  BlockTridiag sys;
  sys.resize(2);
  sys.diag[0] = Mat2::Identity();
  sys.diag[1] = Mat2::Identity();
  sys.upper[0] = Mat2::Identity();
  sys.lower[1] = Mat2::Identity();  // rows 0 and 1 identical: S_1 = I - I = 0
  EXPECT_EQ(sys.factor(), 1);
  std::vector<Vec2> b{Vec2(1, 2), Vec2(1, 2)};
  sys.solve(b);
  EXPECT_TRUE(b[0].allFinite() && b[1].allFinite());
}

// The fused pass (build, factor and forward-substitute through a callback; back-substitute with a callback) does the
// same arithmetic in the same order as factor() and solve(): the step relies on it for bit-identical results.
TEST(BlockTridiag, FusedPassesGiveTheSameBits) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int n = 300;
  BlockTridiag plain = random_system(n, 37, rng);
  std::vector<Vec2> b(n);
  for (Vec2& v : b) v = Vec2(u(rng), u(rng));
  std::vector<Vec2> x = b;
  plain.factor();
  plain.solve(x);

  BlockTridiag fused;
  std::vector<Vec2> y;
  fused.factor_forward(
      n,
      [&](int k, Mat2& d, Mat2& l, Mat2& u_prev, Vec2& rhs) {
        d = plain.diag[k];
        l = k > 0 ? plain.lower[k] : Mat2::Zero();
        u_prev = k > 0 ? plain.upper[k - 1] : Mat2::Zero();
        rhs = b[k];
      },
      y);
  std::vector<int> order;
  fused.backward(y, [&](int k) { order.push_back(k); });
  ASSERT_EQ(order.size(), static_cast<size_t>(n));
  for (int k = 0; k < n; ++k) {
    EXPECT_EQ(order[k], n - 1 - k);
    EXPECT_EQ(x[k].x(), y[k].x()) << k;  // exactly, not approximately
    EXPECT_EQ(x[k].y(), y[k].y()) << k;
  }
}

// The symmetric fused pass (the velocity projection's) solves the same systems as the general one, to rounding
// (1e-12 relative: it rounds differently), and leaves a factorisation that forward() and backward() reuse: a
// second right-hand side solved with them agrees too.
TEST(BlockTridiag, SymmetricFusedPassSolvesTheSameSystem) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int n = 300;
  BlockTridiag plain = random_system(n, 37, rng);
  std::vector<Vec2> b(n), c(n);
  for (Vec2& v : b) v = Vec2(u(rng), u(rng));
  for (Vec2& v : c) v = Vec2(u(rng), u(rng));
  std::vector<Vec2> x = b, xc = c;
  plain.factor();
  plain.solve(x);
  plain.solve(xc);

  BlockTridiag sym;
  std::vector<Vec2> y;
  sym.factor_forward_symmetric(
      n,
      [&](int k, double* d, Mat2& u_prev, Vec2& rhs) {
        d[0] = plain.diag[k](0, 0), d[1] = plain.diag[k](0, 1), d[2] = plain.diag[k](1, 1);
        u_prev = k > 0 ? plain.upper[k - 1] : Mat2::Zero();
        rhs = b[k];
      },
      y);
  sym.backward(y, [](int) {});
  std::vector<Vec2> yc = c;
  sym.solve(yc);
  for (int k = 0; k < n; ++k) {
    EXPECT_LT((x[k] - y[k]).norm(), 1e-12 * (1 + x[k].norm())) << k;
    EXPECT_LT((xc[k] - yc[k]).norm(), 1e-12 * (1 + xc[k].norm())) << k;
  }
}

// A random 3x3 system of the midpoint step's pattern (its Newton system with rolling hinges): non-symmetric diagonal
// blocks with a dominant diagonal, random couplings (Coupling3) of rows k and k - 1 where coupled(k), and columns of
// mixed scale (impulses and turns) as the step's are: `a` and `bd` the dense system, row() the blocks for the
// solver, the unknowns' scales folded in (a coupling's columns 0 and 1 by scale(0), column 2 by scale(2)).
struct Random3 {
  std::vector<Mat3> d;
  std::vector<Coupling3> c;  // c[k]: L_k and U_{k-1}
  std::vector<Vec3> b;
  Eigen::Vector3d scale;
  Eigen::MatrixXd a;
  Eigen::VectorXd bd;

  template <class Coupled>
  Random3(int n, std::mt19937& rng, Coupled coupled, const Eigen::Vector3d& column_scale)
      : d(n), c(n), b(n), scale(column_scale), a(Eigen::MatrixXd::Zero(3 * n, 3 * n)), bd(3 * n) {
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int k = 0; k < n; ++k) {
      for (int i = 0; i < 9; ++i) d[k](i / 3, i % 3) = u(rng);
      d[k] += 6.0 * Mat3::Identity();
      if (coupled(k)) {
        c[k].l = u(rng), c[k].g = u(rng), c[k].u = u(rng), c[k].e = u(rng);
        c[k].s = {u(rng), u(rng)};
        c[k].p = {u(rng), u(rng)};
      }
      b[k] = Vec3(u(rng), u(rng), u(rng));
    }
    for (int k = 0; k < n; ++k) {
      a.block<3, 3>(3 * k, 3 * k) = d[k] * scale.asDiagonal();
      if (k > 0) a.block<3, 3>(3 * k, 3 * (k - 1)) = c[k].lower() * scale.asDiagonal();
      if (k + 1 < n) a.block<3, 3>(3 * k, 3 * (k + 1)) = c[k + 1].upper() * scale.asDiagonal();
      bd.segment<3>(3 * k) = b[k];
    }
  }
  void row(int k, Mat3& dk, Coupling3& ck, Vec3& bk) const {
    dk = d[k] * scale.asDiagonal();
    ck = c[k];
    ck.l *= scale(0), ck.s *= scale(2), ck.g *= scale(2);
    ck.u *= scale(0), ck.p *= scale(0), ck.e *= scale(2);
    bk = b[k];
  }
};

// The 3x3 solver against a dense LU of the same system, every fifth pair of rows uncoupled. Same bound as above.
TEST(BlockTridiag3, MatchesDenseLU) {
  for (const int n : {1, 2, 7, 100}) {
    std::mt19937 rng(static_cast<unsigned>(n));
    const Random3 r(n, rng, [](int k) { return k % 5 != 0; }, Eigen::Vector3d(1e-2, 1e-2, 1.0));
    const Eigen::VectorXd ref = r.a.partialPivLu().solve(r.bd);
    BlockTridiag3 sys;
    std::vector<Vec3> x;
    const int regularised =
        sys.factor_forward(n, [&](int k, Mat3& dk, Coupling3& ck, Vec3& bk) { r.row(k, dk, ck, bk); }, x);
    EXPECT_EQ(regularised, 0);
    std::vector<int> order;
    sys.backward(x, [&](int k) { order.push_back(k); });
    double err = 0;
    for (int k = 0; k < n; ++k) err = std::max(err, (x[k] - ref.segment<3>(3 * k)).norm());
    EXPECT_LT(err / ref.norm(), 1e-12) << "n = " << n;
    for (int k = 0; k < n; ++k) EXPECT_EQ(order[k], n - 1 - k);  // each x_k handed over once it is final
  }
}

// The 3x3 twisted use against the same dense LU as above, split after the first row, in the middle and before the
// last, with the couplings at the split present or cut (check_twisted).
TEST(BlockTridiag3, TwistedSolveMatchesDenseLU) {
  for (const int n : {2, 3, 8, 101}) {
    for (const int mid : {1, n / 2, n - 1}) {
      for (const bool cut : {false, true}) {
        std::mt19937 rng(static_cast<unsigned>(n * 7 + mid * 3 + cut));
        const Random3 r(n, rng, [&](int k) { return k > 0 && !(cut && k == mid); }, Eigen::Vector3d(1e-2, 1e-2, 1));
        BlockTridiag3 sys;
        const auto row = [&](int k, Mat3& dk, Coupling3& ck, Vec3& bk) { r.row(k, dk, ck, bk); };
        check_twisted<3>(sys, row, n, mid, r.a.partialPivLu().solve(r.bd), cut);
      }
    }
  }
}

// A singular 3x3 pivot (a zero row) is regularised and counted; the answer stays finite.
TEST(BlockTridiag3, SingularPivotIsCountedAndFinite) {
  BlockTridiag3 sys;
  std::vector<Vec3> x;
  const int regularised = sys.factor_forward(1, [](int, Mat3& d, Coupling3& c, Vec3& b) {
    d << 1, 0, 0, 0, 1, 0, 0, 0, 0;
    c = {};
    b = Vec3(1, 2, 3);
  }, x);
  EXPECT_EQ(regularised, 1);
  EXPECT_EQ(x[0].head<2>(), Eigen::Vector2d(1, 2) / (1 + 1e-12));
  EXPECT_TRUE(x[0].allFinite());
}
