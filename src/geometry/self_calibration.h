#pragma once
// Self-calibration of a camera's focal length and radial distortion from a map (bundle adjustment with the
// intrinsics free). A camera given by a user is often a nominal one: a dataset's default focal length, no
// distortion where the lens has some (7-Scenes' colour camera is not calibrated at all). Monocular geometry is
// then inconsistent from view to view, and the map's scale drifts with the direction of motion. The
// reprojection errors of a map seen from many views measure the first radial coefficient (and the focal
// length, less well); RefineIntrinsics gives the refined camera and the likelihood ratio against the given one,
// and its caller decides (Settler::SelfCalibrate, docs/self_calibration.md).
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/camera.h"
#include "core/pose.h"

namespace mcslam::geometry {

struct PixelObservation {
  int camera = 0;                                 // index into cam_from_world
  int point = 0;                                  // index into points_in_world
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();  // as the camera saw it: distorted pixels
};

struct IntrinsicsOptions {
  double loss_px = 1.0;     // Cauchy scale of the reprojection residuals
  int max_iterations = 50;
  int num_threads = 1;
  bool free_focal = true;   // false: k1 only (the focal length held as given)
  void Check() const;       // throws std::invalid_argument naming the bad field
};

struct IntrinsicsFit {
  PinholeCamera camera;            // the given camera with the refined focal length and k1
  double focal_scale = 1;          // fx and fy both scaled by this (the aspect and the principal point kept)
  double delta_k1 = 0;             // added to the given k1
  // Robust costs (Ceres' 0.5 * sum of rho(r^2)) at the optimum of each adjustment, over the same residuals.
  double cost_fixed = 0, cost_free = 0;
  double rms_fixed_px = 0, rms_free_px = 0;  // over the residuals under 3 * loss_px at each optimum
  int observations = 0;
  // The likelihood-ratio statistic of the given camera against the refined one: 2 (cost_fixed - cost_free)
  // over the residuals' variance, chi-square with as many degrees of freedom as intrinsics were freed when the
  // given camera is right. With k1 alone, sqrt(chi2) is how many standard deviations k1 moved, and sigma_k1
  // = |delta_k1| / sqrt(chi2) (0 when chi2 is 0, or with the focal length free).
  double chi2 = 0;
  double sigma_k1 = 0;
  std::string report;
};

// Two bundle adjustments of the same poses, points and observations from the same start: one with the
// camera as given, one with its focal length (one scale for fx and fy) and k1 free as well. cam_from_world and
// points_in_world are left as given; fixed[i] holds camera i in both (at least the gauge: two cameras).
IntrinsicsFit RefineIntrinsics(const PinholeCamera& camera, const std::vector<Pose>& cam_from_world,
                               const std::vector<Eigen::Vector3d>& points_in_world,
                               const std::vector<PixelObservation>& observations, const std::vector<bool>& fixed,
                               const IntrinsicsOptions& options);

}  // namespace mcslam::geometry
