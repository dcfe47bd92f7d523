#include "core/block_tridiag.hpp"

namespace ladder::core {

void BlockTridiag::resize(int n) {
  const auto un = static_cast<size_t>(n);
  diag.assign(un, Mat2::Zero());
  lower.assign(un, Mat2::Zero());
  upper.assign(un, Mat2::Zero());
  schur_inv_.resize(un);
  gain_.resize(un);
  rgain_.resize(un);
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

}  // namespace ladder::core
