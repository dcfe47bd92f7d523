// Direct solver for block-tridiagonal systems with 2x2 blocks: the hinge system of a chain of bodies.
//
// Row k of the system is one hinge (two equations, x and y). Hinges k-1 and k are coupled only when they share a
// body, so a chain gives a block-tridiagonal matrix and a forest of chains a block-diagonal set of them. A block LU
// (the block Thomas algorithm) factors it in O(n) with no fill-in; the cost per hinge is one 2x2 inverse and three
// 2x2 products. Pivoting is not needed for the symmetric positive definite G M^-1 G^T systems the engine builds;
// the non-symmetric Newton Jacobians of the paper's solver stay close enough to them in practice, and a tiny
// diagonal shift guards the rare singular pivot (a degenerate configuration), which is counted, not hidden.
//
// Two ways to use it. The plain one: fill diag, lower and upper, factor(), solve(). The fused one, for the hot
// loop of the step: factor_forward() builds each row's blocks through a callback, factors and forward-substitutes
// in the same pass, and backward() back-substitutes while handing each finished x_k to a callback (which applies
// it to the bodies). A chain of n hinges then costs two passes over its arrays instead of five (build, factor,
// forward, backward, apply); at N = 10 000 these arrays are several MiB, larger than L2, so passes are what cost.
// Both ways do the same arithmetic in the same order: their results are bit-identical.
#pragma once

#include "core/geometry.hpp"

#include <cmath>
#include <vector>

namespace ladder::core {

class BlockTridiag {
 public:
  void resize(int n);
  int size() const { return static_cast<int>(lower.size()); }

  // Filled by the caller: diag[k] = A(k,k), lower[k] = A(k,k-1), upper[k] = A(k,k+1).
  // lower[0] and upper[n-1] are ignored; zero blocks separate independent chains.
  std::vector<Mat2> diag, lower, upper;

  // Factors in place. Returns the number of pivot blocks that had to be regularised (0 in a healthy system).
  int factor();
  // Solves A x = b in place (b becomes x). factor() (or factor_forward()) must have been called since the blocks
  // last changed.
  void solve(std::vector<Vec2>& b) const {
    forward(b, [&b](int k) { return b[k]; });
    backward(b, [](int) {});
  }

  // Builds, factors and forward-substitutes in one pass over k = 0..n-1. row(k, d, l, u_prev, b) sets D_k,
  // L_k = A(k,k-1), U_{k-1} = A(k-1,k) (both zero when the rows do not share a body; not read at k = 0) and the
  // right-hand side b_k. Leaves z (the forward-substituted right-hand side) for backward(); diag and upper are
  // not stored. Returns the number of regularised pivots.
  template <class RowFn>
  int factor_forward(int n, RowFn&& row, std::vector<Vec2>& z) {
    if (size() != n) resize(n);
    z.resize(static_cast<size_t>(n));
    return factor_down(n, row, z);
  }

  // The twisted use, for two threads ("burn at both ends"): rows [0, mid) are factored from the top by
  // factor_down(mid, ...) and rows [mid, n) from the bottom by factor_up(mid, n, ...), concurrently (they touch
  // disjoint rows; call resize(n) and size z first); meet() then solves the two middle rows, and backward(x, done,
  // mid) and downward(mid, x, done) finish the two halves, again concurrently. The row callbacks are factor_forward()'s
  // (factor_up() calls them for k = n-1 down to mid). The arithmetic differs from the one-sided elimination's in
  // rounding only, and does not depend on whether the halves run concurrently.
  // With `from`, rows [from, end) alone, as a system of their own (row from's coupling to row from - 1 is not read:
  // the unknowns of the rows outside are held, which is how the midpoint step solves a window of a chain).
  template <class RowFn>
  int factor_down(int end, RowFn&& row, std::vector<Vec2>& z, int from = 0) {
    int regularised = 0;
    Mat2 d, u_prev;
    Vec2 b;
    for (int k = from; k < end; ++k) {
      row(k, d, lower[k], u_prev, b);
      if (k > from) {
        gain_[k - 1].noalias() = schur_inv_[k - 1] * u_prev;
        d.noalias() -= lower[k] * gain_[k - 1];
      }
      regularised += invert(d, schur_inv_[k]) ? 1 : 0;
      if (k > from) b.noalias() -= lower[k] * z[k - 1];
      z[k].noalias() = schur_inv_[k] * b;
    }
    return regularised;
  }
  // From the bottom: T_k = D_k - U_k H_{k+1} with H_k = T_k^-1 L_k (kept for downward()), z_k = T_k^-1 (b_k - U_k
  // z_{k+1}). Row mid's L and U_{mid-1} are kept for meet().
  template <class RowFn>
  int factor_up(int mid, int n, RowFn&& row, std::vector<Vec2>& z) {
    int regularised = 0;
    Mat2 d, l, u_prev;
    Mat2 t_inv = Mat2::Zero(), l_below = Mat2::Zero(), u_below = Mat2::Zero();  // L_{k+1} and U_k, from row k + 1
    Vec2 b;
    for (int k = n - 1; k >= mid; --k) {
      row(k, d, l, u_prev, b);
      if (k < n - 1) {
        Mat2& h = rgain_[k + 1];
        h.noalias() = t_inv * l_below;
        d.noalias() -= u_below * h;
        b.noalias() -= u_below * z[k + 1];
      }
      regularised += invert(d, t_inv) ? 1 : 0;
      z[k].noalias() = t_inv * b;
      l_below = l;
      u_below = u_prev;
    }
    meet_t_inv_ = t_inv;
    meet_l_ = l_below;
    meet_u_ = u_below;
    return regularised;
  }
  // The two middle rows from the halves' last: x_{mid-1} = z_{mid-1} - G x_mid with G = S_{mid-1}^-1 U_{mid-1}
  // (kept for backward()) and x_mid = z_mid - H x_{mid-1} with H = T_mid^-1 L_mid, so (I - G H) x_{mid-1} =
  // z_{mid-1} - G z_mid. In place in x (= z). Returns 1 when that pivot had to be regularised.
  int meet(int mid, std::vector<Vec2>& x) {
    Mat2& g = gain_[mid - 1];
    Mat2& h = rgain_[mid];
    g.noalias() = schur_inv_[mid - 1] * meet_u_;
    h.noalias() = meet_t_inv_ * meet_l_;
    Mat2 m = Mat2::Identity(), m_inv;
    m.noalias() -= g * h;
    const int regularised = invert(m, m_inv) ? 1 : 0;
    const Vec2 top = m_inv * (x[mid - 1] - g * x[mid]);
    x[mid].noalias() -= h * top;
    x[mid - 1] = top;
    return regularised;
  }
  // After meet(): x_k = z_k - H_k x_{k-1} for k = mid+1..n-1, calling done(k) as soon as x_k is final (from mid, which
  // is final already; x_{k-1} is final too by then).
  template <class Done>
  void downward(int mid, std::vector<Vec2>& x, Done&& done) const {
    const int n = static_cast<int>(x.size());
    done(mid);
    for (int k = mid + 1; k < n; ++k) {
      x[k].noalias() -= rgain_[k] * x[k - 1];
      done(k);
    }
  }

  // factor_forward() for a symmetric matrix (L_k = U_{k-1}^T, D_k symmetric), written out in scalars: every Schur
  // complement is symmetric, so its update and inverse take about half the arithmetic of the general case (the
  // velocity projection of every step is this). row(k, d, u_prev, b) sets D_k as {d00, d01, d11}, U_{k-1} (zero
  // when the rows share no body; not read at k = 0) and b_k. Stores what forward() and backward() need, as
  // factor_forward() does. Results differ from factor_forward()'s in rounding only.
  // With kForwardLater false only what backward() needs is stored, not the Schur inverses and L blocks that a later
  // forward() reads: a one-off solve writes half as much.
  template <bool kForwardLater = true, class RowFn>
  int factor_forward_symmetric(int n, RowFn&& row, std::vector<Vec2>& z) {
    if (size() != n) resize(n);
    z.resize(static_cast<size_t>(n));
    int regularised = 0;
    double d[3];
    Mat2 u;
    Vec2 b;
    double s00 = 0, s01 = 0, s11 = 0;  // the last Schur complement's inverse (symmetric)
    for (int k = 0; k < n; ++k) {
      row(k, d, u, b);
      double b0 = b.x(), b1 = b.y();
      if (k > 0) {
        const double u00 = u(0, 0), u01 = u(0, 1), u10 = u(1, 0), u11 = u(1, 1);
        const double g00 = s00 * u00 + s01 * u10, g01 = s00 * u01 + s01 * u11;
        const double g10 = s01 * u00 + s11 * u10, g11 = s01 * u01 + s11 * u11;
        gain_[k - 1] << g00, g01, g10, g11;
        if constexpr (kForwardLater) lower[k] << u00, u10, u01, u11;  // U_{k-1}^T
        d[0] -= u00 * g00 + u10 * g10;
        d[1] -= u00 * g01 + u10 * g11;
        d[2] -= u01 * g01 + u11 * g11;
        const Vec2& zp = z[static_cast<size_t>(k - 1)];
        b0 -= u00 * zp.x() + u10 * zp.y();
        b1 -= u01 * zp.x() + u11 * zp.y();
      } else if constexpr (kForwardLater) {
        lower[k].setZero();
      }
      double a = d[0], c = d[2];
      const double off = d[1];
      const double scale = std::abs(a) + std::abs(c) + 2 * std::abs(off);
      double det = a * c - off * off;
      if (!(std::abs(det) > 1e-14 * scale * scale)) {  // as invert()
        const double shift = 1e-12 * (scale > 0 ? scale : 1.0);
        a += shift;
        c += shift;
        det = a * c - off * off;
        ++regularised;
      }
      const double inv = 1.0 / det;
      const double i00 = c * inv, i01 = -off * inv, i11 = a * inv;
      if constexpr (kForwardLater) schur_inv_[k] << i00, i01, i01, i11;
      s00 = i00, s01 = i01, s11 = i11;
      z[static_cast<size_t>(k)] = Vec2(i00 * b0 + i01 * b1, i01 * b0 + i11 * b1);
    }
    return regularised;
  }

  // Forward substitution z_k = S_k^-1 (b_k - L_k z_{k-1}) with b_k = rhs(k), read before z_k is written (so rhs
  // may read z itself).
  template <class Rhs>
  void forward(std::vector<Vec2>& z, Rhs&& rhs) const {
    const int n = size();
    z.resize(static_cast<size_t>(n));
    for (int k = 0; k < n; ++k) {
      Vec2 r = rhs(k);
      if (k > 0) r.noalias() -= lower[k] * z[k - 1];
      z[k].noalias() = schur_inv_[k] * r;
    }
  }

  // Backward substitution x_k = z_k - S_k^-1 U_k x_{k+1} for k = n-1..0, in place, calling done(k) as soon as x_k
  // is final (x_{k+1} is final too by then). With `end`, for k = end-1..0 (x_{end-1} being final: meet()); with
  // `from`, down to k = from (after factor_down(end, row, z, from)).
  template <class Done>
  void backward(std::vector<Vec2>& x, Done&& done, int end = -1, int from = 0) const {
    const int n = end >= 0 ? end : size();
    if (n <= from) return;
    done(n - 1);
    for (int k = n - 2; k >= from; --k) {
      x[k].noalias() -= gain_[k] * x[k + 1];
      done(k);
    }
  }

  // Inverse of a 2x2 block; returns whether the pivot had to be regularised. A pivot whose determinant is
  // negligible next to its scale is shifted by a relative 1e-12 of its trace before inverting: that changes a
  // well-posed answer by far less than the solver tolerance and turns a degenerate one (two hinges at one point)
  // into a least-norm-like answer instead of an infinity.
  static bool invert(const Mat2& m, Mat2& out) {
    double a = m(0, 0), b = m(0, 1), c = m(1, 0), d = m(1, 1);
    const double scale = std::abs(a) + std::abs(d) + std::abs(b) + std::abs(c);
    double det = a * d - b * c;
    bool regularised = false;
    if (!(std::abs(det) > 1e-14 * scale * scale)) {
      const double shift = 1e-12 * (scale > 0 ? scale : 1.0);
      a += shift;
      d += shift;
      det = a * d - b * c;
      regularised = true;
    }
    const double inv = 1.0 / det;
    out << d * inv, -b * inv, -c * inv, a * inv;
    return regularised;
  }

 private:
  std::vector<Mat2> schur_inv_;  // inverse of the k-th Schur complement S_k = D_k - L_k S_{k-1}^-1 U_{k-1}
  std::vector<Mat2> gain_;       // S_k^-1 U_k, reused by the back substitution
  std::vector<Mat2> rgain_;      // the twisted use's lower half: H_k = T_k^-1 L_k (factor_up)
  Mat2 meet_t_inv_, meet_l_, meet_u_;  // factor_up()'s last row: T_mid^-1, L_mid, U_{mid-1}
};

// The same block LU with 3x3 blocks and only the fused use: the midpoint step's Newton system when hinges roll
// (midpoint.cpp). A rolling hinge's contact point turns with both of its bodies, so a body's angular equation depends
// on its neighbours' turns too and cannot be eliminated body by body; the unknowns of row k are then its impulse (2)
// and the turn of its body b (1), and the system is still block-tridiagonal. The pivots are not symmetric and mix
// units (impulses and turns), so a pivot is judged singular against the product of its rows' norms (Hadamard's bound
// on the determinant) and each row is shifted by a relative 1e-12 of its own norm.
using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

// The off-diagonal blocks of that system have a fixed pattern, which the factorisation uses (each product then costs
// 15 multiplications instead of 27): row k's block on row k - 1's unknowns and row k - 1's on row k's are
//   L_k = [ l I2  s ]        U_{k-1} = [ u I2  0 ]
//         [ 0     g ]                  [ p^T   e ]
// (the shared body's mass terms on the diagonal, the gap's slope in that body's turn in s, its angular equation's
// slope in the impulse in p, and the two turns' couplings g and e). All zero: the rows share no body.
struct Coupling3 {
  double l = 0, g = 0, u = 0, e = 0;
  Vec2 s = Vec2::Zero(), p = Vec2::Zero();
  Mat3 lower() const {
    Mat3 m;
    m << l, 0, s.x(), 0, l, s.y(), 0, 0, g;
    return m;
  }
  Mat3 upper() const {
    Mat3 m;
    m << u, 0, 0, 0, u, 0, p.x(), p.y(), e;
    return m;
  }
};

class BlockTridiag3 {
 public:
  // As BlockTridiag::factor_forward(): row(k, d, c, b) sets D_k, the couplings c of L_k = A(k,k-1) and
  // U_{k-1} = A(k-1,k) (zero when the rows share no body; not read at k = 0) and b_k. Only the gains S_k^-1 U_k are
  // stored (backward() needs nothing else; 72 bytes a row instead of three times that, which is what a long chain's
  // pass costs).
  template <class RowFn>
  int factor_forward(int n, RowFn&& row, std::vector<Vec3>& z) {
    resize(n);
    z.resize(static_cast<size_t>(n));
    return factor_down(n, row, z);
  }
  void resize(int n) {
    gain_.resize(static_cast<size_t>(n));
    rgain_.resize(static_cast<size_t>(n));
  }

  // The twisted use, as BlockTridiag's (factor_down, factor_up, meet, backward with `end`, downward).
  template <class RowFn>
  int factor_down(int end, RowFn&& row, std::vector<Vec3>& z) {
    int regularised = 0;
    Mat3 d, schur_inv = Mat3::Zero();
    Coupling3 c;
    Vec3 b;
    for (int k = 0; k < end; ++k) {
      row(k, d, c, b);
      if (k > 0) {
        // G = S^-1 U: its first two columns u S(:, j) + p_j S(:, 2), its third e S(:, 2).
        Mat3& gain = gain_[k - 1];
        gain.col(0) = c.u * schur_inv.col(0) + c.p.x() * schur_inv.col(2);
        gain.col(1) = c.u * schur_inv.col(1) + c.p.y() * schur_inv.col(2);
        gain.col(2) = c.e * schur_inv.col(2);
        // D -= L G: rows i < 2 less l G(i, :) + s_i G(2, :), row 2 less g G(2, :); the same for b with z.
        const Vec3& zp = z[k - 1];
        for (int i = 0; i < 2; ++i) {
          d.row(i) -= c.l * gain.row(i) + c.s(i) * gain.row(2);
          b(i) -= c.l * zp(i) + c.s(i) * zp(2);
        }
        d.row(2) -= c.g * gain.row(2);
        b(2) -= c.g * zp(2);
      }
      regularised += invert(d, schur_inv) ? 1 : 0;
      z[k].noalias() = schur_inv * b;
    }
    last_inv_ = schur_inv;
    return regularised;
  }
  // From the bottom: T_k = D_k - U_k H_{k+1}, H_k = T_k^-1 L_k, with the couplings' patterns: H's first two columns
  // l T^-1(:, j), its third T^-1 (s, g); U H's first two rows u H(i, :), its third p^T H(0:1, :) + e H(2, :).
  template <class RowFn>
  int factor_up(int mid, int n, RowFn&& row, std::vector<Vec3>& z) {
    int regularised = 0;
    Mat3 d, t_inv = Mat3::Zero();
    Coupling3 c, below;  // below: row k + 1's couplings (its L and U_k)
    Vec3 b;
    for (int k = n - 1; k >= mid; --k) {
      row(k, d, c, b);
      if (k < n - 1) {
        Mat3& h = rgain_[k + 1];
        lower_gain(t_inv, below, h);
        const Vec3& zb = z[k + 1];
        for (int i = 0; i < 2; ++i) {
          d.row(i) -= below.u * h.row(i);
          b(i) -= below.u * zb(i);
        }
        d.row(2) -= below.p.x() * h.row(0) + below.p.y() * h.row(1) + below.e * h.row(2);
        b(2) -= below.p.x() * zb(0) + below.p.y() * zb(1) + below.e * zb(2);
      }
      regularised += invert(d, t_inv) ? 1 : 0;
      z[k].noalias() = t_inv * b;
      below = c;
    }
    meet_t_inv_ = t_inv;
    meet_ = below;
    return regularised;
  }
  // As BlockTridiag::meet().
  int meet(int mid, std::vector<Vec3>& x) {
    Mat3& g = gain_[mid - 1];
    Mat3& h = rgain_[mid];
    const Mat3& s = last_inv_;
    g.col(0) = meet_.u * s.col(0) + meet_.p.x() * s.col(2);
    g.col(1) = meet_.u * s.col(1) + meet_.p.y() * s.col(2);
    g.col(2) = meet_.e * s.col(2);
    lower_gain(meet_t_inv_, meet_, h);
    Mat3 m = Mat3::Identity(), m_inv;
    m.noalias() -= g * h;
    const int regularised = invert(m, m_inv) ? 1 : 0;
    const Vec3 top = m_inv * (x[mid - 1] - g * x[mid]);
    x[mid].noalias() -= h * top;
    x[mid - 1] = top;
    return regularised;
  }
  template <class Done>
  void downward(int mid, std::vector<Vec3>& x, Done&& done) const {
    const int n = static_cast<int>(x.size());
    done(mid);
    for (int k = mid + 1; k < n; ++k) {
      x[k].noalias() -= rgain_[k] * x[k - 1];
      done(k);
    }
  }

  // As BlockTridiag::backward().
  template <class Done>
  void backward(std::vector<Vec3>& x, Done&& done, int end = -1) const {
    const int n = end >= 0 ? end : static_cast<int>(x.size());
    if (n == 0) return;
    done(n - 1);
    for (int k = n - 2; k >= 0; --k) {
      x[k].noalias() -= gain_[k] * x[k + 1];
      done(k);
    }
  }

  // By cofactors: the inverse is the adjugate over the determinant. Singular when det^2 <= 1e-28 times the product
  // of the rows' squared norms. Forced inline: called once per row from three places, GCC otherwise calls it (7 %
  // of a rolling ladder's step at 1000 blocks); the rare singular case is kept out of line.
  [[gnu::always_inline]] static bool invert(const Mat3& m, Mat3& out) {
    const double bound2 = m.row(0).squaredNorm() * m.row(1).squaredNorm() * m.row(2).squaredNorm();
    const double det = cofactors(m, out);
    if (!(det * det > 1e-28 * bound2)) {
      invert_regularised(m, out);
      return true;
    }
    out *= 1 / det;
    return false;
  }
  [[gnu::noinline, gnu::cold]] static void invert_regularised(Mat3 m, Mat3& out) {
    for (int i = 0; i < 3; ++i) {
      const double norm = m.row(i).norm();
      m(i, i) += 1e-12 * (norm > 0 ? norm : 1.0);
    }
    const double det = cofactors(m, out);
    out *= 1 / det;
  }

 private:
  // Writes the adjugate of m to adj and returns the determinant.
  static double cofactors(const Mat3& m, Mat3& adj) {
    adj(0, 0) = m(1, 1) * m(2, 2) - m(1, 2) * m(2, 1);
    adj(0, 1) = m(0, 2) * m(2, 1) - m(0, 1) * m(2, 2);
    adj(0, 2) = m(0, 1) * m(1, 2) - m(0, 2) * m(1, 1);
    adj(1, 0) = m(1, 2) * m(2, 0) - m(1, 0) * m(2, 2);
    adj(1, 1) = m(0, 0) * m(2, 2) - m(0, 2) * m(2, 0);
    adj(1, 2) = m(0, 2) * m(1, 0) - m(0, 0) * m(1, 2);
    adj(2, 0) = m(1, 0) * m(2, 1) - m(1, 1) * m(2, 0);
    adj(2, 1) = m(0, 1) * m(2, 0) - m(0, 0) * m(2, 1);
    adj(2, 2) = m(0, 0) * m(1, 1) - m(0, 1) * m(1, 0);
    return m(0, 0) * adj(0, 0) + m(0, 1) * adj(1, 0) + m(0, 2) * adj(2, 0);
  }

  // H = T^-1 L for L = c.lower(): l T^-1(:, 0), l T^-1(:, 1), T^-1 (s, g).
  static void lower_gain(const Mat3& t_inv, const Coupling3& c, Mat3& h) {
    h.col(0) = c.l * t_inv.col(0);
    h.col(1) = c.l * t_inv.col(1);
    h.col(2) = c.s.x() * t_inv.col(0) + c.s.y() * t_inv.col(1) + c.g * t_inv.col(2);
  }

  std::vector<Mat3> gain_;   // S_k^-1 U_k
  std::vector<Mat3> rgain_;  // the twisted use's lower half: H_k = T_k^-1 L_k
  Mat3 last_inv_, meet_t_inv_;  // factor_down()'s last S^-1, factor_up()'s last T^-1
  Coupling3 meet_;              // row mid's couplings (its L and U_{mid-1})
};

}  // namespace ladder::core
