#pragma once
// The essential matrix of two calibrated views and what it gives: the linear normalised 8-point estimate,
// the Sampson distance that scores a correspondence against it, its four (R, t) decompositions, and a
// Levenberg-Marquardt refinement of the relative pose on the 5-dimensional manifold of essential matrices
// (rotation x unit translation direction). The robust two-view estimator built from these is in two_view.h.
//
// Convention: x1 = [uv_norm1; 1], x2 = [uv_norm2; 1] are the normalised image coordinates of one scene point
// in view 1 and view 2, and for cam2_from_cam1 = (R, t), i.e. point_in_cam2 = R point_in_cam1 + t,
//   E = [t]x R   and   x2^T E x1 = 0                      (Hartley & Zisserman 2nd ed., §9.6, (9.12)).
#include <array>
#include <optional>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"

namespace mcslam::geometry {

// [v]x, the matrix of the cross product: Skew(v) * w = v x w.
Eigen::Matrix3d Skew(const Eigen::Vector3d& v);

// E = [t]x R of a relative pose. Its Frobenius norm is sqrt(2) |t|.
Eigen::Matrix3d EssentialFromPose(const Pose& cam2_from_cam1);

// Linear essential matrix by the normalised 8-point algorithm (H&Z §11.2, their algorithm 11.1; Hartley 1997,
// "In defense of the eight-point algorithm"): each image's points are translated to their centroid and
// scaled to mean distance sqrt(2) from it, the 9 entries solve A e = 0 in the least-squares sense (the right
// singular vector of the smallest singular value), the result is de-normalised, and then projected onto the
// essential manifold (H&Z §11.3 / Result 9.17: singular values (s, s, 0)).
// Uses the correspondences listed in `indices` (all of them when empty); needs at least 8.
// Returns a matrix with singular values (1, 1, 0) (sign arbitrary), or nullopt when the correspondences do
// not determine E: fewer than 8, a non-finite coordinate, all points of an image coincide, or the
// solution space of A e = 0 is more than one-dimensional (exactly planar scene, pure rotation, no motion,
// repeated points). Near-degenerate noisy data (noisy planar scene) still yields a matrix, but an
// unreliable one; two_view.h detects that case with a homography test.
std::optional<Eigen::Matrix3d> EssentialEightPoint(std::span<const Eigen::Vector2d> uv_norm1,
                                                   std::span<const Eigen::Vector2d> uv_norm2,
                                                   std::span<const int> indices = {});

// Sampson distance of a correspondence to the epipolar constraint (H&Z §11.4.3, (11.9)): the first-order
// approximation of the distance, in the 4D space of (uv_norm1, uv_norm2), to the nearest pair that satisfies
// x2^T E x1 = 0. In normalised units (multiply by the focal length for pixels). Signed variant: the sign of
// x2^T E x1. A correspondence at both epipoles (gradient zero) has distance 0.
double SampsonDistance(const Eigen::Matrix3d& essential, const Eigen::Vector2d& uv_norm1,
                       const Eigen::Vector2d& uv_norm2);
double SignedSampsonDistance(const Eigen::Matrix3d& essential, const Eigen::Vector2d& uv_norm1,
                             const Eigen::Vector2d& uv_norm2);

// The four relative poses (R, t) with E ~ [t]x R, |t| = 1 (H&Z §9.6.2, Result 9.19): with E = U diag(1,1,0)
// V^T (U, V proper rotations) and W the rotation by +90 deg about z,
//   {(U W V^T, +u3), (U W V^T, -u3), (U W^T V^T, +u3), (U W^T V^T, -u3)}.
// Exactly one of them puts a scene point in front of both cameras (cheirality); see two_view.h.
// E is used up to scale and sign; it need not lie exactly on the essential manifold (the nearest is taken).
std::array<Pose, 4> DecomposeEssential(const Eigen::Matrix3d& essential);

// The residual the refinement minimises for one correspondence: the signed Sampson distance of
// E = [t]x R of `cam2_from_cam1` (|t| = 1), scaled by `scale` (the focal length, for pixels), and
// optionally its 1x5 Jacobian with respect to the manifold update used by RefineRelativePose:
//   R <- exp([w]x) R  (w = delta[0..2], in view 2),   t <- normalize(t + B delta[3..4]),
// with B = TangentBasis(t) the 3x2 orthonormal basis of the plane orthogonal to t.
double SampsonResidual(const Pose& cam2_from_cam1, const Eigen::Vector2d& uv_norm1, const Eigen::Vector2d& uv_norm2,
                       double scale, Eigen::Matrix<double, 1, 5>* jacobian = nullptr);
// Orthonormal basis (3x2) of the plane orthogonal to the unit vector t; a fixed, continuous choice.
Eigen::Matrix<double, 3, 2> TangentBasis(const Eigen::Vector3d& t);
// Applies the manifold update above: the pose delta moves to. t is renormalised.
Pose ApplyRelativePoseUpdate(const Pose& cam2_from_cam1, const Eigen::Matrix<double, 5, 1>& delta);

struct RefineOptions {
  int max_iterations = 50;          // LM iterations (each one linear solve); >= 1
  double scale = 500.0;             // residual scale: the focal length, so that costs are in px^2; > 0
  double gradient_tolerance = 1e-10;  // stop when the max |J^T r| falls below this (px^2 per unit step)
  double step_tolerance = 1e-12;    // stop when the update's norm falls below this (rad / unit-vector units)
  // Robust loss: 0 for plain least squares; else the Cauchy loss c^2 log(1 + r^2 / c^2) with c = cauchy_scale
  // (same unit as the scaled residuals, px), minimised by reweighting (weights 1 / (1 + r^2 / c^2)).
  double cauchy_scale = 0.0;        // >= 0
  void Check() const;               // throws std::invalid_argument naming the bad field
};

struct RefineSummary {
  int iterations = 0;        // accepted and rejected steps together
  double initial_cost = 0;   // sum of squared residuals (px^2 with scale = focal), or of the Cauchy loss, at the start
  double final_cost = 0;     // ... at the returned pose; never above initial_cost
  bool converged = false;    // a tolerance was met (else max_iterations ran out)
};

// Levenberg-Marquardt on the 5-dof relative pose (rotation, unit translation direction) minimising the sum
// of squared Sampson distances (or of their Cauchy loss) of the correspondences in `indices` (all when empty),
// i.e. a first-order approximation of the reprojection error of the optimal triangulation (H&Z §11.4.3), with
// the points eliminated. The damping follows
// Madsen, Nielsen & Tingleff, "Methods for non-linear least squares problems" (2004), their algorithm 3.16
// (gain-ratio update of mu). A step is kept only when it lowers the cost, so the result is never worse
// (by this cost) than the start. The returned pose has |t| = 1. Throws std::invalid_argument on bad options.
Pose RefineRelativePose(const Pose& cam2_from_cam1, std::span<const Eigen::Vector2d> uv_norm1,
                        std::span<const Eigen::Vector2d> uv_norm2, std::span<const int> indices,
                        const RefineOptions& options, RefineSummary* summary = nullptr);

// The unit translation direction that best satisfies the epipolar constraint for a given rotation: x2^T [t]x R x1
// = t . (R x1 x x2) = 0 for every correspondence in `indices` (all when empty), solved in least squares (the
// eigenvector of the smallest eigenvalue of sum a a^T, a = R x1 x x2). The sign is arbitrary (cheirality decides
// it); the zero vector when there are fewer than 2 correspondences or a non-finite coordinate.
Eigen::Vector3d TranslationGivenRotation(const Eigen::Matrix3d& cam2_from_cam1_rotation,
                                         std::span<const Eigen::Vector2d> uv_norm1,
                                         std::span<const Eigen::Vector2d> uv_norm2, std::span<const int> indices = {});

struct RelativePoseMinimum {
  Pose cam2_from_cam1;  // |t| = 1, sign as the refinement left it (cheirality decides it)
  double cost = 0;      // RefineRelativePose's final cost: sum of squared Sampson distances (px^2 with scale = focal)
};

// The local minima of the two-view (Sampson) cost around a relative pose, by multi-start refinement. Through a
// narrow field of view a small rotation about an axis in the image plane and a sideways translation move the
// image alike (the bas-relief ambiguity), so the cost has a long, nearly flat valley that may hold more than one
// minimum, and a refinement stops in whichever basin its start lies in. The starts: the given pose, and its
// rotation turned by radius_deg / 2 and by radius_deg about each of the 26 directions of a cube's faces, edges
// and corners (in view 2), the translation re-solved for each (TranslationGivenRotation); each refined by
// RefineRelativePose(options) over `indices`, in parallel (the result does not depend on the threads). Returns the
// distinct minima (the refinements that converged, their rotations more than radius_deg / 10 apart), cheapest
// first; empty when none converged. radius_deg is best set to the views' parallax: the valley's extent in rotation
// is about the angle the baseline subtends. Throws std::invalid_argument on bad options or radius_deg <= 0.
// bench/bench_relative_pose_minima measures it.
std::vector<RelativePoseMinimum> RelativePoseMinima(const Pose& cam2_from_cam1, std::span<const Eigen::Vector2d> uv_norm1,
                                                    std::span<const Eigen::Vector2d> uv_norm2,
                                                    std::span<const int> indices, double radius_deg,
                                                    const RefineOptions& options);

}  // namespace mcslam::geometry
