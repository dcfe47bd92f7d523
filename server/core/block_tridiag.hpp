// Direct solver for block-tridiagonal systems with 2x2 blocks: the hinge system of a chain of bodies.
//
// Row k of the system is one hinge (two equations, x and y). Hinges k-1 and k are coupled only when they share a
// body, so a chain gives a block-tridiagonal matrix and a forest of chains a block-diagonal set of them. A block LU
// (the block Thomas algorithm) factors it in O(n) with no fill-in; the cost per hinge is one 2x2 inverse and three
// 2x2 products. Pivoting is not needed for the symmetric positive definite G M^-1 G^T systems the engine builds;
// the non-symmetric Newton Jacobians of the paper's solver stay close enough to them in practice, and a tiny
// diagonal shift guards the rare singular pivot (a degenerate configuration), which is counted, not hidden.
#pragma once

#include "core/geometry.hpp"

#include <vector>

namespace ladder::core {

class BlockTridiag {
 public:
  void resize(int n);
  int size() const { return static_cast<int>(diag.size()); }

  // Filled by the caller: diag[k] = A(k,k), lower[k] = A(k,k-1), upper[k] = A(k,k+1).
  // lower[0] and upper[n-1] are ignored; zero blocks separate independent chains.
  std::vector<Mat2> diag, lower, upper;

  // Factors in place. Returns the number of pivot blocks that had to be regularised (0 in a healthy system).
  int factor();
  // Solves A x = b in place (b becomes x). factor() must have been called since the blocks last changed.
  void solve(std::vector<Vec2>& b) const;

 private:
  std::vector<Mat2> schur_inv_;  // inverse of the k-th Schur complement S_k = D_k - L_k S_{k-1}^-1 U_{k-1}
  std::vector<Mat2> gain_;       // S_k^-1 U_k, reused by the back substitution
};

}  // namespace ladder::core
