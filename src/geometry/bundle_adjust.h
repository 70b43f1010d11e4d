#pragma once
// Bundle adjustment (Levenberg-Marquardt, Ceres, Huber loss) of camera poses and points from normalised
// observations. mcslam's estimators are Monte Carlo; this is used where the problem is small and
// ill-conditioned for pairwise geometry: refining the whole initialisation window (many views constrain
// the bas-relief direction that two views leave nearly free), and as the baseline the paper compares with.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"

namespace mcslam::geometry {

struct BundleObservation {
  int camera = 0;                                  // index into cam_from_world
  int point = 0;                                   // index into points_in_world
  Eigen::Vector2d uv_norm = Eigen::Vector2d::Zero();  // undistorted, normalised
};

struct BundleAdjustOptions {
  double focal_px = 500;         // residuals are in pixels: normalised error times this
  double huber_px = 2.0;         // robust loss scale
  // Cauchy instead of Huber: its influence falls off for large residuals, so wrong matches (tens of px)
  // stop pulling; Huber's stays constant.
  bool cauchy = false;
  int max_iterations = 50;
  // Converged when an iteration lowers the (robust) cost by less than this fraction of it (Ceres' own test,
  // its default).
  double function_tolerance = 1e-6;
  int num_threads = 1;
  // How each Levenberg-Marquardt step's reduced camera system is solved. kSparseSchur (the default): where each
  // camera sees a small part of the map. kDenseSchur: faster where the cameras are few (tens) and most see most
  // points, as in a local window. kIterativeSchur: conjugate gradients on the Schur complement without forming
  // it (Jacobi preconditioner), for many cameras that all see the same points: forming it costs the square of a
  // point's views for every point (the settling adjustment of 7-Scenes' first 114 frames, each point seen by ~60
  // of them, took 3.1 s of its frame's 3.8 that way), the iterations only its observations (about 1.7x faster at
  // 40 and 112 frames: bench_bundle_adjust's BM_SettleBundleAdjust).
  enum class LinearSolver { kSparseSchur, kDenseSchur, kIterativeSchur };
  LinearSolver linear_solver = LinearSolver::kSparseSchur;
  void Check() const;            // throws std::invalid_argument naming the bad field
};

struct BundleAdjustSummary {
  bool converged = false;
  int iterations = 0;
  double initial_rms_px = 0, final_rms_px = 0;  // over all observations
  // Observations whose point starts behind (or on) its camera: no pixel residual exists for them, and one
  // such residual at the start would make Ceres give up the whole adjustment, so they are left out of it.
  int left_out_behind = 0;
  std::string report;                           // Ceres' brief report
};

// Reprojection error in pixels of a point seen at uv_norm (normalised) by a camera; +infinity when the
// point is not in front of it.
double ReprojectionErrorPx(const Pose& cam_from_world, const Eigen::Vector3d& point_in_world,
                           const Eigen::Vector2d& uv_norm, double focal_px);

// Adjusts cam_from_world (except those with fixed[i] = true) and points_in_world (except those with
// fixed_points[j] = true; an empty fixed_points: none) in place.
BundleAdjustSummary BundleAdjust(std::vector<Pose>& cam_from_world, std::vector<Eigen::Vector3d>& points_in_world,
                                 const std::vector<BundleObservation>& observations, const std::vector<bool>& fixed,
                                 const BundleAdjustOptions& options, const std::vector<bool>& fixed_points = {});

}  // namespace mcslam::geometry
