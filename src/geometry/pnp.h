#pragma once
// Camera pose from 3D points and their normalised observations (OpenCV's RANSAC PnP, refined iteratively).
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"

namespace mcslam::geometry {

struct PnpOptions {
  double threshold_px = 3.0;  // RANSAC inlier threshold
  double focal_px = 500;      // converts it to normalised units
  int min_inliers = 10;
  int iterations = 200;
};

// cam_from_world, or nothing when fewer than max(4, min_inliers) correspondences agree.
std::optional<Pose> SolvePnp(const std::vector<Eigen::Vector3d>& points_in_world,
                             const std::vector<Eigen::Vector2d>& uv_norm, const PnpOptions& options,
                             int* num_inliers = nullptr);

}  // namespace mcslam::geometry
