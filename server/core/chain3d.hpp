// A 3-D model of the free chain, to measure what the paper's planar reduction saves (issue 6, "model fidelity").
//
// The 2-D engine (world.hpp) gives a block 3 degrees of freedom (x, y, theta) and a hinge 2 equations, so a chain's
// hinge system is block-tridiagonal with 2x2 blocks. Here the same chain is modelled as it is in space: each block a
// rigid box (length L along the block, thickness T across it, width W along the hinge axis z) with 6 degrees of
// freedom (centre, orientation as a unit quaternion, linear and angular velocity), and each hinge a revolute joint
// of 5 equations:
//   C_p  = (x_a + R_a r_a) - (x_b + R_b r_b) = 0           the two anchors coincide (3 equations)
//   C_ax = W (z_a . x_b, z_a . y_b) = 0                     body a's z axis is normal to body b's x and y axes (2)
// where z_a = R_a e_z, x_b = R_b e_x, y_b = R_b e_y. The axis rows are scaled by the width W so that they are in
// metres: W times the misalignment is how far apart the two ends of the hinge line are, and one tolerance serves
// all five rows (it also keeps the five rows of K = G M^-1 G^T of one magnitude). Block 0 is hinged to the world
// (a fixed body) unless the chain is free at the top. The hinge system is block-tridiagonal with 5x5 blocks,
// factored by a block Cholesky in O(n) (chain3d.cpp).
//
// The layout is the 2-D free chain's (ladder.hpp, config/scenes/free-chain.toml) in the plane z = 0: a straight
// column, block i's centre at (T/2, -L/2 - L i), block 0 hinged at its top-left corner (the origin), hinge k at block
// k-1's bottom corner and block k's top corner, on the right edge for odd k and the left for even k; the anchors
// sit at mid-width (z = 0) on the hinge line. Block 1 turns at kick_omega about its top hinge and blocks 2.. move
// with hinge 2's velocity; the whole column may be tilted about the origin.
//
// The step is the 2-D default's analogue (SHAKE): kick (gravity and the gyroscopic torque -w x I w), drift, then
// Newton on the constraint impulses along M(q0)^-1 G(q0)^T until the end-of-step positions meet every hinge to the
// tolerance (the impulses enter the velocities too), then the velocities are projected onto G v = 0. First order,
// symplectic for the planar motion the free chain has. No I/O; errors are std::invalid_argument.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <vector>

namespace ladder::core {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

struct Chain3DSpec {
  int blocks = 2;
  double length = 0.06;      // [m] L, along the block
  double thickness = 0.01;   // [m] T, across the block, in the plane
  double width = 0.04;       // [m] W, along the hinge axis (out of the plane)
  double mass = 0.02;        // [kg] per block, uniform density
  double hinge_inset = 0;    // hinge anchors this fraction of T in from the edge (as LadderSpec::hinge_inset)
  bool pinned = true;        // block 0 hinged to the world at its top-left corner; false: the top is free
  double kick_omega = 0;     // [rad/s] block 1's initial angular velocity about its top hinge
  double tilt = 0;           // [rad] initial rotation of the whole column about the origin (about z)
  double tolerance = 1e-12;  // [m] every hinge row is driven below this by the position solve
  int max_iterations = 20;   // Newton iterations per position solve
  Vec3 gravity{0.0, -9.81, 0.0};  // [m/s^2]
};

// Per-step solver figures.
struct Chain3DStats {
  int iterations = 0;          // Newton iterations of the last position solve
  double residual = 0;         // largest hinge row after it [m]
  bool converged = true;       // it reached the tolerance
  int regularised_pivots = 0;  // singular pivots met in the last step (a degenerate configuration)
};

class Chain3D {
 public:
  // Hot per-body state: 128 bytes, two cache lines.
  struct Body {
    Vec3 x{0, 0, 0}, v{0, 0, 0}, w{0, 0, 0};  // centre [m], its velocity [m/s], angular velocity (world) [rad/s]
    Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
    double th = 0;  // accumulated rotation about z [rad]: picks block_angle()'s branch
  };
  static_assert(sizeof(Body) == 128, "the hot per-body state is two cache lines");
  struct Snapshot {
    std::vector<Body> bodies;
    double t = 0;
  };

  explicit Chain3D(const Chain3DSpec& spec);

  // Advances by h [s]; throws std::invalid_argument unless h is positive and finite.
  void step(double h);
  double time() const { return t_; }
  const Chain3DSpec& spec() const { return spec_; }
  int blocks() const { return spec_.blocks; }
  const Chain3DStats& last_step() const { return stats_; }
  int last_iterations() const { return stats_.iterations; }

  // The state, to redo a step (a watchdog's halving): restore() returns to it exactly.
  Snapshot save() const { return {body_, t_}; }
  void restore(const Snapshot& s);
  // Sets a block's velocities (world frame, of the centre; angular [rad/s]); they are generally inconsistent with
  // the hinges until project_velocities().
  void set_velocity(int block, const Vec3& v, const Vec3& omega);
  // Makes velocities consistent with the hinges (G v = 0) by the impulse of least kinetic energy change; returns
  // the kinetic energy change [J].
  double project_velocities();

  // --- queries ---
  Vec3 block_centre(int i) const;
  Eigen::Quaterniond block_orientation(int i) const;
  Vec3 block_velocity(int i) const;
  Vec3 block_omega(int i) const;
  // Rotation about z [rad], unwrapped along the motion: the 2-D model's World::part_angle for a planar motion.
  double block_angle(int i) const;
  double kinetic_energy() const;    // [J], with the full 3x3 inertia
  double potential_energy() const;  // [J], gravity
  double max_hinge_error() const;   // largest anchor gap [m]
  double max_axis_error() const;    // largest |sin| of the angle between two hinged bodies' axes
  // Largest departure from the plane z = 0: |z| of a centre [m] and |sin| of a block's z axis' tilt, the larger.
  double out_of_plane() const;
  bool finite() const;

 private:
  // What the chord Newton iterations and the next step's kick need from the configuration q0 at which the last
  // velocity projection factored K: per body its rotation and world inverse inertia, per row the anchors and the
  // two axis directions. Row r joins body r + first_ - 1 (a, -1 = the world) and body r + first_ (b).
  struct Frame {
    Mat3 r, inv_inertia;
  };
  struct RowFrame {
    Vec3 ua, ub;  // anchors relative to the centres, world frame
    Vec3 n1, n2;  // W (z_a x x_b), W (z_a x y_b): the axis rows' angular directions
  };

  using Vec5 = Eigen::Matrix<double, 5, 1>;
  using Mat5 = Eigen::Matrix<double, 5, 5>;
  void check_block(int i) const;
  int rows() const { return static_cast<int>(row_frame_.size()); }
  Mat3 rotation(int body) const;  // the identity for the world (body -1)
  Vec5 residual(int r, const Mat3& ra, const Mat3& rb) const;
  void kick_drift(double h);
  void factor_at_current();
  template <class Rhs>
  void forward(Rhs&& rhs);
  template <class Apply>
  void backward(Apply&& apply, bool exact);
  template <class Apply>
  void distribute(int r, const std::vector<Vec5>& mu, Apply&& apply) const;
  double forward_residual();
  double factor_exact_forward();
  bool solve_positions(double velocity_scale);
  void project();

  Chain3DSpec spec_;
  Vec3 inertia_{0, 0, 0}, inv_inertia_{0, 0, 0};  // principal moments of a block (body axes) and their inverses
  double inv_mass_ = 0;
  int first_ = 0;           // body of row 0 (0 when pinned: row 0 is the pin; 1 when free at the top)
  Vec3 pin_{0, 0, 0};       // the pin's world point
  std::vector<Vec3> ra_, rb_;  // per row: anchors in the body frames (ra_ of row 0 is the pin when pinned)
  std::vector<Body> body_;
  std::vector<Frame> frame_;        // per body, at q0
  std::vector<RowFrame> row_frame_;  // per row, at q0

  // Block Cholesky of K(q0) = L L^T, L block-bidiagonal: per row the lower Cholesky factor of the k-th Schur
  // complement (with its reciprocal diagonal) and Y_k = L_kk^-1 K(k, k+1), so that L(k+1, k) = Y_k^T.
  std::vector<Mat5> chol_, gain_;
  std::vector<Vec5> inv_diag_;
  std::vector<Vec5> z_;  // forward-substituted right-hand side, then the multipliers
  // Block LU of the exact Newton matrix, when the chord converges slowly: inverses of the Schur complements and
  // the gains S_k^-1 U_k.
  std::vector<Mat5> exact_inv_, exact_gain_;
  bool factored_ = false;  // chol_ and the frames belong to the current positions
  double t_ = 0;
  Chain3DStats stats_;
};

}  // namespace ladder::core
