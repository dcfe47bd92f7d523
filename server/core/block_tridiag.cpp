#include "core/block_tridiag.hpp"

#include <cmath>

namespace ladder::core {

namespace {

// Inverse of a 2x2 block. A pivot whose determinant is negligible next to its scale is shifted by a relative
// 1e-12 of its trace before inverting: that changes a well-posed answer by far less than the solver tolerance
// and turns a degenerate one (two hinges at one point) into a least-norm-like answer instead of an infinity.
bool invert(const Mat2& m, Mat2& out) {
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

}  // namespace

void BlockTridiag::resize(int n) {
  const auto un = static_cast<size_t>(n);
  diag.assign(un, Mat2::Zero());
  lower.assign(un, Mat2::Zero());
  upper.assign(un, Mat2::Zero());
  schur_inv_.resize(un);
  gain_.resize(un);
}

int BlockTridiag::factor() {
  const int n = size();
  int regularised = 0;
  for (int k = 0; k < n; ++k) {
    Mat2 s = diag[k];
    if (k > 0) s.noalias() -= lower[k] * gain_[k - 1];
    regularised += invert(s, schur_inv_[k]) ? 1 : 0;
    gain_[k].noalias() = schur_inv_[k] * upper[k];
  }
  return regularised;
}

void BlockTridiag::solve(std::vector<Vec2>& b) const {
  const int n = size();
  // Forward: z_k = S_k^-1 (b_k - L_k z_{k-1}).
  for (int k = 0; k < n; ++k) {
    Vec2 r = b[k];
    if (k > 0) r.noalias() -= lower[k] * b[k - 1];
    b[k].noalias() = schur_inv_[k] * r;
  }
  // Backward: x_k = z_k - S_k^-1 U_k x_{k+1}.
  for (int k = n - 2; k >= 0; --k) b[k].noalias() -= gain_[k] * b[k + 1];
}

}  // namespace ladder::core
