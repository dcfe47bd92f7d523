// The 3-D chain (chain3d.hpp): construction, the SHAKE step and the O(n) block-tridiagonal solve with 5x5 blocks.
//
// Jacobian of row r (bodies a and b, generalised velocities (v, w) with w the world angular velocity):
//   G_a = [ P | A(u_a)^T ],  G_b = [ -P | -A(u_b)^T ],  P = [I3; 0] (5x3),
//   A(u) = [ u x e_x, u x e_y, u x e_z, n1, n2 ] (3x5),  n1 = W z_a x x_b,  n2 = W z_a x y_b,
// so a multiplier mu (5) acts on body a as the force mu_p (its first three rows) at the anchor plus the torque
// n1 mu_3 + n2 mu_4, and on body b as their opposite: the torque on a is A(u_a) mu = u_a x mu_p + n1 mu_3 + n2 mu_4.
// (d(z_a . x_b) = (dtheta_a - dtheta_b) . (z_a x x_b) for small world rotations dtheta.) With W_i = diag(1/m, I_i^-1),
// I_i^-1 = R_i diag(1/I) R_i^T the world inverse inertia, K = G W G^T has the 5x5 blocks
//   K(r, r)     = (w_a + w_b) P P^T + A(u_a)^T I_a^-1 A(u_a) + A(u_b)^T I_b^-1 A(u_b)
//   K(r-1, r)   = -(w_s P P^T + A(u_b,r-1)^T I_s^-1 A(u_a,r))      (s: the body rows r-1 and r share)
// (w = 1/m; the world has w = 0 and I^-1 = 0). A block Cholesky factors it: per row one 5x5 Cholesky, one 5x5
// triangular solve for Y and one 5x5 product Y^T Y, where 2-D takes one 2x2 inverse and three 2x2 products.
#include "core/chain3d.hpp"
#include "core/hot_inline.hpp"

#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace ladder::core {

namespace {

using Mat5 = Eigen::Matrix<double, 5, 5>;
using Vec5 = Eigen::Matrix<double, 5, 1>;
using Mat35 = Eigen::Matrix<double, 3, 5>;

void require(bool ok, const char* what) {
  if (!ok) throw std::invalid_argument(what);
}

// A(u) of the file comment: the angular directions of a row's five multipliers on one body.
Mat35 angular_block(const Vec3& u, const Vec3& n1, const Vec3& n2) {
  Mat35 a;
  a << 0, -u.z(), u.y(), n1.x(), n2.x(),  //
      u.z(), 0, -u.x(), n1.y(), n2.y(),   //
      -u.y(), u.x(), 0, n1.z(), n2.z();
  return a;
}

// A(u) mu without forming A: the torque of a row's multipliers about a body's centre.
Vec3 row_torque(const Vec3& u, const Vec3& n1, const Vec3& n2, const Vec5& mu) {
  return u.cross(mu.head<3>()) + mu[3] * n1 + mu[4] * n2;
}

// R diag(d) R^T: a body's world inverse inertia from its principal one.
Mat3 world_inertia(const Mat3& r, const Vec3& d) { return r * d.asDiagonal() * r.transpose(); }

// q turned by the world rotation vector a: exp(a / 2) q, then pulled back to unit length by one Newton step for
// 1/sqrt (exact to rounding while |q| - 1 is below 1e-8; without it rounding grows |q| and the bodies stretch).
// The half-angle's cos and sinc are short series below 0.1 rad, where they are exact to rounding (as
// rotation_of_small_angle() in 2-D), and libm above.
Eigen::Quaterniond turned(const Eigen::Quaterniond& q, const Vec3& a) {
  const Vec3 half = 0.5 * a;
  const double s2 = half.squaredNorm();
  double c, sinc;
  if (s2 > 0.01) {
    const double s = std::sqrt(s2);
    c = std::cos(s);
    sinc = std::sin(s) / s;
  } else {
    c = 1.0 - s2 * (1.0 / 2 - s2 * (1.0 / 24 - s2 * (1.0 / 720 - s2 * (1.0 / 40320))));
    sinc = 1.0 - s2 * (1.0 / 6 - s2 * (1.0 / 120 - s2 * (1.0 / 5040 - s2 * (1.0 / 362880))));
  }
  const Vec3 v = sinc * half;
  Eigen::Quaterniond out = Eigen::Quaterniond(c, v.x(), v.y(), v.z()) * q;
  out.coeffs() *= 1.5 - 0.5 * out.coeffs().squaredNorm();
  return out;
}

// q turned by a Newton correction's rotation a (|a| <= 2^-12, the corrections of a converging solve being 1e-5
// rad and less): two terms of each series are exact to rounding there (the first omitted ones, s^4 / 24 with
// s = |a| / 2 <= 2^-13, are below half an ulp), and |exp(a / 2)| = 1 - s^4 / 12 differs from 1 by less than an ulp,
// so no renormalisation: the next drift's renormalises. Half the work of turned(); larger angles take that path.
Eigen::Quaterniond corrected(const Eigen::Quaterniond& q, const Vec3& a) {
  const Vec3 half = 0.5 * a;
  const double s2 = half.squaredNorm();
  if (!(s2 <= 0x1p-26)) return turned(q, a);
  const Vec3 v = (1.0 - s2 * (1.0 / 6)) * half;
  return Eigen::Quaterniond(1.0 - s2 * (1.0 / 2), v.x(), v.y(), v.z()) * q;
}

// s += sign a^T m, the lower triangle only: a^T m is symmetric wherever it is used (m = I^-1 a with I^-1
// symmetric, or m = a), and the Cholesky factorisation reads the lower triangle alone. Half the products of the
// full 5x5 result.
template <int K>
void add_lower_product(Mat5& s, const Eigen::Matrix<double, K, 5>& a, const Eigen::Matrix<double, K, 5>& m,
                       double sign) {
  for (int j = 0; j < 5; ++j)
    for (int i = j; i < 5; ++i) {
      double x = 0;
      for (int k = 0; k < K; ++k) x += a(k, i) * m(k, j);
      s(i, j) += sign * x;
    }
}

// In-place Cholesky of a symmetric positive definite 5x5 block (lower triangle), with the reciprocals of the
// diagonal kept for the substitutions. A pivot that is negligible next to the block's scale (a degenerate
// configuration) is shifted by 1e-12 of that scale and counted, as the 2-D solver does (block_tridiag.hpp).
int cholesky(Mat5& s, Vec5& inv_diag) {
  const double scale = s.diagonal().cwiseAbs().maxCoeff();
  int regularised = 0;
  for (int j = 0; j < 5; ++j) {
    double d = s(j, j);
    for (int k = 0; k < j; ++k) d -= s(j, k) * s(j, k);
    if (!(d > 1e-14 * scale)) {
      d = std::max(d, 0.0) + 1e-12 * (scale > 0 ? scale : 1.0);
      ++regularised;
    }
    const double l = std::sqrt(d);
    s(j, j) = l;
    inv_diag[j] = 1.0 / l;
    for (int i = j + 1; i < 5; ++i) {
      double x = s(i, j);
      for (int k = 0; k < j; ++k) x -= s(i, k) * s(j, k);
      s(i, j) = x * inv_diag[j];
    }
  }
  return regularised;
}

// b <- L^-1 b, L the lower triangle of l.
void solve_lower(const Mat5& l, const Vec5& inv_diag, Vec5& b) {
  for (int i = 0; i < 5; ++i) {
    double x = b[i];
    for (int k = 0; k < i; ++k) x -= l(i, k) * b[k];
    b[i] = x * inv_diag[i];
  }
}

// b <- L^-T b.
void solve_upper(const Mat5& l, const Vec5& inv_diag, Vec5& b) {
  for (int i = 4; i >= 0; --i) {
    double x = b[i];
    for (int k = i + 1; k < 5; ++k) x -= l(k, i) * b[k];
    b[i] = x * inv_diag[i];
  }
}

// Y <- L^-1 U, column by column.
void solve_lower(const Mat5& l, const Vec5& inv_diag, Mat5& u) {
  for (int c = 0; c < 5; ++c) {
    Vec5 col = u.col(c);
    solve_lower(l, inv_diag, col);
    u.col(c) = col;
  }
}

}  // namespace

Chain3D::Chain3D(const Chain3DSpec& spec) : spec_(spec) {
  require(spec.blocks >= 1, "chain3d: blocks must be at least 1");
  for (double d : {spec.length, spec.thickness, spec.width, spec.mass})
    require(std::isfinite(d) && d > 0, "chain3d: length, thickness, width and mass must be positive");
  require(std::isfinite(spec.hinge_inset) && spec.hinge_inset >= 0 && spec.hinge_inset < 0.5,
          "chain3d: hinge_inset must be at least 0 and below 0.5");
  require(std::isfinite(spec.kick_omega) && std::isfinite(spec.tilt) && spec.gravity.allFinite(),
          "chain3d: initial conditions and gravity must be finite");
  require(std::isfinite(spec.tolerance) && spec.tolerance > 0, "chain3d: tolerance must be positive");
  require(spec.max_iterations >= 1, "chain3d: max_iterations must be at least 1");

  const double L = spec.length, T = spec.thickness, W = spec.width, m = spec.mass;
  const int n = spec.blocks;
  // A uniform box: principal moments about its x (across), y (along) and z (hinge) axes.
  inertia_ = Vec3(L * L + W * W, T * T + W * W, L * L + T * T) * (m / 12);
  inv_inertia_ = inertia_.cwiseInverse();
  inv_mass_ = 1.0 / m;
  first_ = spec.pinned ? 0 : 1;

  // The 2-D free chain's layout (ladder.cpp with top = pinned, start = straight), in the plane z = 0.
  const double hw = (0.5 - spec.hinge_inset) * T;  // the anchors' distance from the centre line
  const Eigen::AngleAxisd tilt(spec.tilt, Vec3::UnitZ());
  const auto centre = [&](int i) { return Vec3(hw, -0.5 * L - L * i, 0); };
  const auto hinge = [&](int k) { return Vec3(k % 2 == 1 ? 2 * hw : 0.0, -L * k, 0); };
  body_.resize(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    Body& b = body_[static_cast<size_t>(i)];
    b.x = tilt * centre(i);
    b.q = Eigen::Quaterniond(tilt);
    b.th = spec.tilt;
    if (i == 1) {
      b.w = Vec3(0, 0, spec.kick_omega);
      b.v = b.w.cross(tilt * (centre(1) - hinge(1)));
    } else if (i >= 2) {
      b.v = Vec3(0, 0, spec.kick_omega).cross(tilt * (hinge(2) - hinge(1)));
    }
  }
  // Row r joins body r + first_ - 1 (a) and r + first_ (b): hinge k = r + first_. Hinge 0 is the pin at the
  // origin; hinge k >= 1 sits at block k-1's bottom and block k's top corner, right edge for odd k, left for even.
  const int nrows = n - first_;
  ra_.resize(static_cast<size_t>(nrows));
  rb_.resize(static_cast<size_t>(nrows));
  for (int r = 0; r < nrows; ++r) {
    const int k = r + first_;
    const double side = k == 0 ? -hw : (k % 2 == 1 ? hw : -hw);
    ra_[static_cast<size_t>(r)] = k == 0 ? pin_ : Vec3(side, -0.5 * L, 0);
    rb_[static_cast<size_t>(r)] = Vec3(side, 0.5 * L, 0);
  }
  frame_.resize(static_cast<size_t>(n));
  row_frame_.resize(static_cast<size_t>(nrows));
  chol_.resize(static_cast<size_t>(nrows));
  gain_.resize(static_cast<size_t>(nrows));
  inv_diag_.resize(static_cast<size_t>(nrows));
  z_.resize(static_cast<size_t>(nrows));
  project_velocities();
}

void Chain3D::check_block(int i) const {
  if (i < 0 || i >= spec_.blocks)
    throw std::invalid_argument("chain3d: no block " + std::to_string(i) + " (0.." + std::to_string(spec_.blocks - 1) +
                                ")");
}

void Chain3D::step(double h) {
  require(h > 0 && std::isfinite(h), "chain3d: the time step must be a positive number");
  stats_ = {};
  if (!factored_) factor_at_current();
  kick_drift(h);
  stats_.converged = solve_positions(1.0 / h);
  t_ += h;
  project();
}

// Kick with gravity and the gyroscopic torque -w x (I w) (zero for a spin about a principal axis, so for any planar
// motion of the chain), then drift; both at q0 (the frames the last projection left), as symplectic Euler does.
void Chain3D::kick_drift(double h) {
  const Vec3 dv = h * spec_.gravity;
  for (size_t i = 0; i < body_.size(); ++i) {
    Body& b = body_[i];
    const Frame& f = frame_[i];
    const Vec3 momentum = f.r * inertia_.cwiseProduct(f.r.transpose() * b.w);
    b.v += dv;
    b.w -= h * (f.inv_inertia * b.w.cross(momentum));
    b.x += h * b.v;
    b.q = turned(b.q, h * b.w);
    b.th += h * b.w.z();
  }
  factored_ = false;
}

// C of row r at the current positions, given its bodies' rotations (the identity for the world): the anchor gap,
// then W (z_a . x_b, z_a . y_b).
Vec5 Chain3D::residual(int r, const Mat3& ra, const Mat3& rb) const {
  const int b = r + first_, a = b - 1;
  const Vec3 pa = a >= 0 ? Vec3(body_[static_cast<size_t>(a)].x + ra * ra_[static_cast<size_t>(r)])
                         : ra_[static_cast<size_t>(r)];
  Vec5 c;
  c.head<3>() = pa - (body_[static_cast<size_t>(b)].x + rb * rb_[static_cast<size_t>(r)]);
  c[3] = spec_.width * ra.col(2).dot(rb.col(0));
  c[4] = spec_.width * ra.col(2).dot(rb.col(1));
  return c;
}

Mat3 Chain3D::rotation(int body) const {
  return body >= 0 ? body_[static_cast<size_t>(body)].q.toRotationMatrix() : Mat3::Identity();
}

// Builds K at the current positions (the frames of every body and row) and factors it, in one pass along the
// chain; leaves factored_ set.
void Chain3D::factor_at_current() {
  const int n = rows();
  for (size_t i = 0; i < body_.size(); ++i) {
    frame_[i].r = body_[i].q.toRotationMatrix();
    frame_[i].inv_inertia = world_inertia(frame_[i].r, inv_inertia_);
  }
  Mat35 a_prev;  // A(u_b) of the previous row, for the coupling block
  for (int r = 0; r < n; ++r) {
    const int b = r + first_, a = b - 1;
    RowFrame& rf = row_frame_[static_cast<size_t>(r)];
    const Mat3& rb = frame_[static_cast<size_t>(b)].r;
    const Vec3 za = a >= 0 ? Vec3(frame_[static_cast<size_t>(a)].r.col(2)) : Vec3::UnitZ();
    rf.ua = a >= 0 ? Vec3(frame_[static_cast<size_t>(a)].r * ra_[static_cast<size_t>(r)]) : Vec3::Zero();
    rf.ub = rb * rb_[static_cast<size_t>(r)];
    rf.n1 = spec_.width * za.cross(rb.col(0));
    rf.n2 = spec_.width * za.cross(rb.col(1));
    const Mat35 ang_a = angular_block(rf.ua, rf.n1, rf.n2), ang_b = angular_block(rf.ub, rf.n1, rf.n2);
    const Mat35 mb = frame_[static_cast<size_t>(b)].inv_inertia * ang_b;
    Mat5 s = Mat5::Zero();
    add_lower_product(s, ang_b, mb, 1.0);
    double w = inv_mass_;
    if (a >= 0) {
      const Mat35 ma = frame_[static_cast<size_t>(a)].inv_inertia * ang_a;
      add_lower_product(s, ang_a, ma, 1.0);
      w += inv_mass_;
      if (r > 0) {  // K(r-1, r), then Y_{r-1} = L_{r-1}^-1 K(r-1, r) and the Schur complement
        Mat5& y = gain_[static_cast<size_t>(r - 1)];
        y.noalias() = -(a_prev.transpose() * ma);
        for (int i = 0; i < 3; ++i) y(i, i) -= inv_mass_;
        solve_lower(chol_[static_cast<size_t>(r - 1)], inv_diag_[static_cast<size_t>(r - 1)], y);
        add_lower_product(s, y, y, -1.0);
      }
    }
    for (int i = 0; i < 3; ++i) s(i, i) += w;
    stats_.regularised_pivots += cholesky(s, inv_diag_[static_cast<size_t>(r)]);
    chol_[static_cast<size_t>(r)] = s;
    a_prev = ang_b;
  }
  factored_ = true;
}

// Forward substitution z_k = L_kk^-1 (b_k - Y_{k-1}^T z_{k-1}) of the right-hand side rhs(r), in place in z_.
template <class Rhs>
void Chain3D::forward(Rhs&& rhs) {
  const int n = rows();
  for (int r = 0; r < n; ++r) {
    Vec5 z = rhs(r);
    if (r > 0) z.noalias() -= gain_[static_cast<size_t>(r - 1)].transpose() * z_[static_cast<size_t>(r - 1)];
    solve_lower(chol_[static_cast<size_t>(r)], inv_diag_[static_cast<size_t>(r)], z);
    z_[static_cast<size_t>(r)] = z;
  }
}

// Back-substitutes the forward-substituted z_ into the multipliers (in place) and hands each body its share,
// apply(body, force, torque) (world frame, the torque about its centre), as soon as both rows it is in are final:
// body b of row r takes -mu_r and, being row r + 1's body a, +mu_{r+1}; each body is handed its impulse once.
// With `exact`, the factorisation is the exact Newton matrix's (factor_exact_forward()).
template <class Apply>
void Chain3D::backward(Apply&& apply, bool exact) {
  const int n = rows();
  for (int r = n - 1; r >= 0; --r) {
    Vec5& mu = z_[static_cast<size_t>(r)];
    if (exact) {
      if (r + 1 < n) mu.noalias() -= exact_gain_[static_cast<size_t>(r)] * z_[static_cast<size_t>(r + 1)];
    } else {
      if (r + 1 < n) mu.noalias() -= gain_[static_cast<size_t>(r)] * z_[static_cast<size_t>(r + 1)];
      solve_upper(chol_[static_cast<size_t>(r)], inv_diag_[static_cast<size_t>(r)], mu);
    }
    distribute(r, z_, apply);
  }
}

// Hands the bodies of row r their share of the multipliers mu: body b takes -mu_r and, being row r + 1's body a,
// +mu_{r+1}; row 0's body a too when it is not the world (and so in no other row).
template <class Apply>
void Chain3D::distribute(int r, const std::vector<Vec5>& mu, Apply&& apply) const {
  const RowFrame& rf = row_frame_[static_cast<size_t>(r)];
  const Vec5& m = mu[static_cast<size_t>(r)];
  Vec3 force = -m.head<3>();
  Vec3 torque = -row_torque(rf.ub, rf.n1, rf.n2, m);
  if (r + 1 < rows()) {
    const RowFrame& next = row_frame_[static_cast<size_t>(r + 1)];
    const Vec5& mn = mu[static_cast<size_t>(r + 1)];
    force += mn.head<3>();
    torque += row_torque(next.ua, next.n1, next.n2, mn);
  }
  apply(r + first_, force, torque);
  if (r == 0 && first_ == 1) apply(0, Vec3(m.head<3>()), row_torque(rf.ua, rf.n1, rf.n2, m));
}

// Forward substitution of -C(q) through the factored K(q0), the residual measured in the same pass (each body's
// rotation matrix formed once). Returns the largest row residual [m].
double Chain3D::forward_residual() {
  double worst = 0;
  Mat3 ra = rotation(first_ - 1), rb;
  forward([&](int r) HOT_INLINE {
    rb = rotation(r + first_);
    const Vec5 c = residual(r, ra, rb);
    ra = rb;
    worst = std::max({worst, c.head<3>().squaredNorm(), c.tail<2>().squaredNorm()});
    return Vec5(-c);
  });
  return std::sqrt(worst);
}

// The exact Newton matrix G(q) W(q0) G(q0)^T (not symmetric) at the current positions, built, factored by a block
// LU (explicit inverses of the 5x5 Schur complements S_k, gains S_k^-1 U_k) and forward-substituted against -C(q)
// in one pass, the residual measured in the same pass. Its blocks are K's with the current anchors and axis
// directions on the left and q0's on the right:
//   D_r = (w_a + w_b) P P^T + A(u_a)^T I_a^-1 A(u_a0) + A(u_b)^T I_b^-1 A(u_b0)
//   U_{r-1} = -(w_s P P^T + A(u_b,r-1)^T I_s^-1 A(u_a0,r)),  L_r = -(w_s P P^T + A(u_a,r)^T I_s^-1 A(u_b0,r-1))
// (I^-1 at q0). Returns the largest row residual [m].
double Chain3D::factor_exact_forward() {
  const int n = rows();
  exact_gain_.resize(static_cast<size_t>(n));
  exact_inv_.resize(static_cast<size_t>(n));
  double worst = 0;
  Mat3 ra = rotation(first_ - 1), rb;
  Mat35 cur_b_prev, ref_b_prev;  // A(u_b) of the previous row, at q and at q0
  for (int r = 0; r < n; ++r) {
    const int b = r + first_, a = b - 1;
    rb = rotation(b);
    const Vec5 c = residual(r, ra, rb);
    worst = std::max({worst, c.head<3>().squaredNorm(), c.tail<2>().squaredNorm()});
    const Vec3 za = ra.col(2);
    const Vec3 n1 = spec_.width * za.cross(rb.col(0)), n2 = spec_.width * za.cross(rb.col(1));
    const Vec3 ua = a >= 0 ? Vec3(ra * ra_[static_cast<size_t>(r)]) : Vec3::Zero();
    const RowFrame& rf = row_frame_[static_cast<size_t>(r)];
    const Mat35 cur_b = angular_block(rb * rb_[static_cast<size_t>(r)], n1, n2);
    const Mat35 ref_b = angular_block(rf.ub, rf.n1, rf.n2);
    Mat5 d;
    d.noalias() = cur_b.transpose() * (frame_[static_cast<size_t>(b)].inv_inertia * ref_b);
    double w = inv_mass_;
    Vec5 rhs = -c;
    if (a >= 0) {
      const Mat3& ia = frame_[static_cast<size_t>(a)].inv_inertia;
      const Mat35 cur_a = angular_block(ua, n1, n2);
      const Mat35 ia_ref_a = ia * angular_block(rf.ua, rf.n1, rf.n2);
      d.noalias() += cur_a.transpose() * ia_ref_a;
      w += inv_mass_;
      if (r > 0) {
        Mat5 upper, lower;
        upper.noalias() = -(cur_b_prev.transpose() * ia_ref_a);
        lower.noalias() = -(cur_a.transpose() * (ia * ref_b_prev));
        for (int i = 0; i < 3; ++i) upper(i, i) -= inv_mass_, lower(i, i) -= inv_mass_;
        Mat5& gain = exact_gain_[static_cast<size_t>(r - 1)];
        gain.noalias() = exact_inv_[static_cast<size_t>(r - 1)] * upper;
        d.noalias() -= lower * gain;
        rhs.noalias() -= lower * z_[static_cast<size_t>(r - 1)];
      }
    }
    for (int i = 0; i < 3; ++i) d(i, i) += w;
    Mat5& inv = exact_inv_[static_cast<size_t>(r)];
    inv = d.inverse();
    if (!inv.allFinite()) {  // a singular pivot (a degenerate configuration): shifted as cholesky() does
      inv = (d + 1e-12 * d.diagonal().cwiseAbs().maxCoeff() * Mat5::Identity()).inverse();
      ++stats_.regularised_pivots;
    }
    z_[static_cast<size_t>(r)].noalias() = inv * rhs;
    ra = rb;
    cur_b_prev = cur_b;
    ref_b_prev = ref_b;
  }
  return std::sqrt(worst);
}

// Solves C(q0 + W G(q0)^T mu) = 0 by Newton's method, starting from the drifted positions, as the 2-D engine's
// default solver does: K(q0) as a fixed (chord) Jacobian, which converges linearly at a rate of about |w h| per
// iteration, and the exact Jacobian G(q) W G(q0)^T from the first iteration that gains less than a factor 4 (a
// whipping chain at a long step). Each correction q += W(q0) G(q0)^T mu is made to the velocities too, divided by
// h (SHAKE: h mu are the step's impulses). The 2-D solver's cut-back of a correction that raises the residual is
// left out: tried here, it made the whipping 100-block chain at 2 and 5 ms 2 to 5 times slower (the runner's
// watchdog, which halves a failed step, does better).
bool Chain3D::solve_positions(double velocity_scale) {
  if (rows() == 0) return true;
  const auto correct = [this, velocity_scale](int body, const Vec3& force, const Vec3& torque) HOT_INLINE {
    Body& b = body_[static_cast<size_t>(body)];
    const Vec3 dx = inv_mass_ * force;
    const Vec3 dth = frame_[static_cast<size_t>(body)].inv_inertia * torque;
    b.x += dx;
    b.q = corrected(b.q, dth);
    b.th += dth.z();
    b.v += velocity_scale * dx;
    b.w += velocity_scale * dth;
  };
  bool exact = false;
  // The residual, forward-substituted for the next iteration's matrix in the same pass.
  const auto measure = [&] { return exact ? factor_exact_forward() : forward_residual(); };
  double res = measure();
  const double initial = res;
  for (int it = 0; it < spec_.max_iterations; ++it) {
    if (res <= spec_.tolerance || !(res < 1e3 * initial + 1e-9)) break;  // done, or diverging
    ++stats_.iterations;
    backward(correct, exact);
    double next = measure();
    if (!exact && next > 0.25 * res && next > spec_.tolerance) {  // the chord converges slowly
      exact = true;
      next = measure();  // the same residual, with the exact matrix's substitution
    }
    res = next;
  }
  stats_.residual = res;
  return res <= spec_.tolerance;
}

// G v = 0 by the impulse G^T nu of least kinetic energy change: K(q) nu = -G v. The factorisation of K(q) is kept
// as the next step's chord matrix, with the frames it was built from.
void Chain3D::project() {
  if (!factored_) factor_at_current();
  forward([this](int r) HOT_INLINE {
    const int b = r + first_, a = b - 1;
    const RowFrame& rf = row_frame_[static_cast<size_t>(r)];
    const Body& B = body_[static_cast<size_t>(b)];
    Vec3 va = Vec3::Zero(), wa = Vec3::Zero();
    if (a >= 0) {
      va = body_[static_cast<size_t>(a)].v;
      wa = body_[static_cast<size_t>(a)].w;
    }
    Vec5 rhs;
    rhs.head<3>() = (B.v + B.w.cross(rf.ub)) - (va + wa.cross(rf.ua));
    rhs[3] = rf.n1.dot(B.w - wa);
    rhs[4] = rf.n2.dot(B.w - wa);
    return rhs;
  });
  backward(
      [this](int body, const Vec3& force, const Vec3& torque) HOT_INLINE {
        Body& b = body_[static_cast<size_t>(body)];
        b.v += inv_mass_ * force;
        b.w += frame_[static_cast<size_t>(body)].inv_inertia * torque;
      },
      false);
}

double Chain3D::project_velocities() {
  const double before = kinetic_energy();
  project();
  return kinetic_energy() - before;
}

void Chain3D::restore(const Snapshot& s) {
  require(s.bodies.size() == body_.size(), "chain3d: the snapshot belongs to another chain");
  body_ = s.bodies;
  t_ = s.t;
  factored_ = false;  // the next step factors K at the restored positions
}

void Chain3D::set_velocity(int block, const Vec3& v, const Vec3& omega) {
  check_block(block);
  require(v.allFinite() && omega.allFinite(), "chain3d: velocities must be finite");
  body_[static_cast<size_t>(block)].v = v;
  body_[static_cast<size_t>(block)].w = omega;
}

Vec3 Chain3D::block_centre(int i) const {
  check_block(i);
  return body_[static_cast<size_t>(i)].x;
}

Eigen::Quaterniond Chain3D::block_orientation(int i) const {
  check_block(i);
  return body_[static_cast<size_t>(i)].q;
}

Vec3 Chain3D::block_velocity(int i) const {
  check_block(i);
  return body_[static_cast<size_t>(i)].v;
}

Vec3 Chain3D::block_omega(int i) const {
  check_block(i);
  return body_[static_cast<size_t>(i)].w;
}

// The angle of the block's x axis projected on the plane, on the branch nearest the accumulated rotation about z.
double Chain3D::block_angle(int i) const {
  check_block(i);
  const Body& b = body_[static_cast<size_t>(i)];
  const Eigen::Quaterniond& q = b.q;
  const double a = std::atan2(2 * (q.x() * q.y() + q.w() * q.z()), 1 - 2 * (q.y() * q.y() + q.z() * q.z()));
  const double turn = 2 * std::numbers::pi;
  return a + turn * std::round((b.th - a) / turn);
}

double Chain3D::kinetic_energy() const {
  double e = 0;
  for (const Body& b : body_) {
    const Vec3 wb = b.q.conjugate() * b.w;  // in the body's principal axes
    e += 0.5 * (spec_.mass * b.v.squaredNorm() + wb.dot(inertia_.cwiseProduct(wb)));
  }
  return e;
}

double Chain3D::potential_energy() const {
  double e = 0;
  for (const Body& b : body_) e -= spec_.mass * spec_.gravity.dot(b.x);
  return e;
}

double Chain3D::max_hinge_error() const {
  double worst = 0;
  for (int r = 0; r < rows(); ++r)
    worst = std::max(worst, residual(r, rotation(r + first_ - 1), rotation(r + first_)).head<3>().norm());
  return worst;
}

double Chain3D::max_axis_error() const {
  double worst = 0;
  for (int r = 0; r < rows(); ++r) {
    const int b = r + first_, a = b - 1;
    const Vec3 za = a >= 0 ? Vec3(body_[static_cast<size_t>(a)].q * Vec3::UnitZ()) : Vec3::UnitZ();
    worst = std::max(worst, za.cross(body_[static_cast<size_t>(b)].q * Vec3::UnitZ()).norm());
  }
  return worst;
}

double Chain3D::out_of_plane() const {
  double worst = 0;
  for (const Body& b : body_) {
    const Vec3 z = b.q * Vec3::UnitZ();
    worst = std::max({worst, std::abs(b.x.z()), std::hypot(z.x(), z.y())});
  }
  return worst;
}

bool Chain3D::finite() const {
  for (const Body& b : body_)
    if (!b.x.allFinite() || !b.v.allFinite() || !b.w.allFinite() || !b.q.coeffs().allFinite()) return false;
  return true;
}

}  // namespace ladder::core
