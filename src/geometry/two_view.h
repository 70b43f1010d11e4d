#pragma once
// Relative pose and structure from two calibrated views: the paper's map initialisation (§6.1: essential
// matrix by the 8-point algorithm in RANSAC, refined by Levenberg-Marquardt, relative pose, linear
// triangulation). OpenCV's five-point solver (Nistér 2004, cv::findEssentialMat + cv::recoverPose) is offered
// as an alternative for comparison.
//
// Pipeline of EstimateTwoView:
//   1. RANSAC (8-point): samples of 8 drawn from CounterRng(seed); each model scored by MSAC (Sampson
//      distances truncated at ransac_threshold_px / focal_px; inliers: those below it); the number of samples
//      adapts to the best model's inlier ratio w as N = log(1 - confidence) / log(1 - w^8) (H&Z §4.7.1,
//      (4.18)), capped at max_iterations. With refine, every sample that beats the best sample so far is
//      locally optimised (LO-RANSAC, see step 2); the best model is finally re-fitted by the 8-point algorithm
//      on its inliers while that lowers the score.
//      5-point: cv::findEssentialMat (RANSAC, same threshold, confidence and max_iterations; OpenCV seeds its
//      own RANSAC with a fixed seed, so `seed` has no effect there) and cv::recoverPose.
//   2. Refinement (refine = true): Levenberg-Marquardt over the 5-dof pose (essential.h), first with a Cauchy
//      loss on all correspondences, then in least squares on the inliers, re-classified until stable.
//   3. Degeneracy test: a homography is fitted (cv::findHomography) to the epipolar inliers. When it explains
//      nearly all of them, the scene is planar or the motion a pure rotation (or none); E is then not
//      determined by the data (8-point: a family of solutions; any method: the two-fold ambiguity of a plane,
//      an arbitrary translation for a rotation) and the estimate fails.
//   4. Cheirality: of the four decompositions of E, the one with the most inliers triangulated in front of
//      both cameras; fails when the runner-up comes close (no clear winner).
//   5. Linear triangulation of every inlier with the checks of TriangulationOptions (positive depth, the
//      reprojection error, min parallax); fails when the median parallax is below min_parallax_deg (baseline
//      too short for the scene depth) or fewer than min_triangulated points pass.
//
// Accuracy (tests/geometry/test_two_view.cc, 1 px noise, 20 % wrong matches, f = 500 px, 320x240): on a
// scene whose points fill the view at 1-5 m, with 30 cm of motion, both methods with refinement reach the
// same estimate, at the noise level (rotation < 0.15 deg, direction < 0.8 deg over 10 seeds; the Cramer-Rao
// bound is up to 0.18 / 0.38 deg RMS there). On the paper's box (~200 points on 2-3 faces, half the image,
// 10-30 frames apart) the bound itself is 1.3-2.3 deg in rotation and 1.5-37 deg in direction: the 8-point
// then mostly fails or is wrong (there, its samples of 8 points are no better than chance even at 0.2 px of
// noise), OpenCV's 5-point does better but is noise-limited. The 5-point method, a homography, a longer
// baseline or a sub-pixel tracker serve the initialisation on such scenes better than the 8-point.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"
#include "geometry/essential.h"
#include "geometry/triangulation.h"

namespace mcslam::geometry {

enum class EssentialMethod {
  kEightPoint,        // normalised 8-point in seeded RANSAC (this library), the paper's choice
  kFivePointOpenCV,   // cv::findEssentialMat (Nistér's 5-point in RANSAC) + cv::recoverPose
};
const char* ToString(EssentialMethod method);
EssentialMethod ParseEssentialMethod(const std::string& name);  // "8point" | "5point"; throws naming the value

struct TwoViewOptions {
  EssentialMethod method = EssentialMethod::kEightPoint;
  double ransac_threshold_px = 1.0;   // epipolar inlier: Sampson distance below this (pixels); > 0
  double focal_px = 500.0;            // converts pixel thresholds to normalised units; > 0
  double confidence = 0.999;          // RANSAC stops once an all-inlier sample was drawn with this probability; (0, 1)
  int max_iterations = 5000;          // RANSAC cap; >= 1
  bool refine = true;                 // LM refinement (also inside RANSAC, as its local optimisation)
  uint64_t seed = 1;                  // RANSAC sampling (8-point only)
  double min_parallax_deg = 1.0;      // per triangulated point, and for the median over the inliers; in [0, 180)
  double max_reprojection_px = 4.0;   // per triangulated point, in both views; > 0
  int min_inliers = 15;               // fewer epipolar inliers: fail; >= 8 (5 for the 5-point method suffices
                                      // mathematically, but a pose from fewer than ~15 points is not trusted)
  int min_triangulated = 15;          // fewer points passing the triangulation checks: fail; >= 1
  // Degeneracy: fail when a homography explains at least this fraction of the epipolar inliers (with a
  // threshold matched to the 2-dof transfer error, see two_view.cc). In (0, 1]; above 1 disables the test.
  double max_homography_inlier_ratio = 0.9;
  void Check() const;                 // throws std::invalid_argument naming the bad field and its value
};

enum class TwoViewStatus {
  kOk,
  kBadInput,              // sizes differ, or a non-finite coordinate
  kTooFewCorrespondences, // fewer than the minimal sample (8, or 5 for the 5-point method)
  kNoModel,               // RANSAC found no non-degenerate model (e.g. every sample degenerate)
  kTooFewInliers,         // fewer than min_inliers epipolar inliers
  kPlanarOrRotation,      // a homography explains the inliers: planar scene, pure rotation or no motion
  kAmbiguousCheirality,   // no decomposition of E clearly puts the points in front of both cameras
  kTooFewTriangulated,    // fewer than min_triangulated points pass the triangulation checks
  kSmallParallax,         // median parallax below min_parallax_deg
};
const char* ToString(TwoViewStatus status);

struct TwoViewResult {
  bool ok = false;
  TwoViewStatus status = TwoViewStatus::kBadInput;
  std::string failure;                                    // why not, in words (empty when ok)
  // The fields below hold whatever was estimated before a failure, for diagnosis; trust them only when ok.
  Eigen::Matrix3d essential = Eigen::Matrix3d::Zero();     // E = [t]x R of cam2_from_cam1 (singular values 1,1,0)
  Pose cam2_from_cam1;                                     // |t| = 1: the scale is not observable
  std::vector<uint8_t> inliers;                            // per correspondence: epipolar inlier of the final E
                                                           // (Sampson distance < ransac_threshold_px)
  int num_inliers = 0;
  std::vector<uint8_t> triangulated;                       // per correspondence: passed the triangulation checks
  std::vector<Eigen::Vector3d> points_in_cam1;             // per correspondence; valid where triangulated (else 0)
  int num_triangulated = 0;
  double median_parallax_deg = 0;  // over the inliers triangulated in front of both cameras (before other checks)
  // Diagnostics.
  int ransac_iterations = 0;           // samples drawn (8-point); 0 for the 5-point method
  double homography_inlier_ratio = 0;  // fraction of the epipolar inliers a homography explains
  double cheirality_ratio = 0;         // runner-up / best count of points in front, over the 4 decompositions
};

// Estimates the relative pose of view 2 with respect to view 1 from normalised correspondences
// (uv_norm1[i] <-> uv_norm2[i], undistorted). Never throws on bad data: the result says why it failed.
// Throws std::invalid_argument on bad options. Same options and input give the same result.
TwoViewResult EstimateTwoView(std::span<const Eigen::Vector2d> uv_norm1, std::span<const Eigen::Vector2d> uv_norm2,
                              const TwoViewOptions& options);

// The planar path: when a homography explains the correspondences (a dominant plane, where EstimateTwoView
// refuses: kPlanarOrRotation), the homography (RANSAC with the threshold EstimateTwoView's degeneracy test
// uses) is decomposed into its motions (Faugeras; cv::decomposeHomographyMat with K = I), and each motion that
// puts at least half of the homography's inliers in front of both cameras is triangulated as in step 5 of
// EstimateTwoView (with its checks). Returns the solutions that pass, usually two for a plane seen from one
// side (the two-fold ambiguity of a plane: more views decide), none for a pure rotation (no translation, or
// too little parallax). Never throws on bad data (empty result); throws std::invalid_argument on bad options.
std::vector<TwoViewResult> EstimateTwoViewPlanar(std::span<const Eigen::Vector2d> uv_norm1,
                                                 std::span<const Eigen::Vector2d> uv_norm2,
                                                 const TwoViewOptions& options);

}  // namespace mcslam::geometry
