#pragma once
// Camera pose from 3D points and their normalised observations (OpenCV's RANSAC PnP, refined iteratively).
#include <cstdint>
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

// The same, where the orientation is known to within max_rotation_deg of rotation_prior (cam_from_world): a RANSAC
// of its own over P3P samples (OpenCV's solveP3P) that keeps only the solutions so oriented, then the
// Levenberg-Marquardt refinement on their inliers, kept only if still so oriented. Where many of the matches are
// wrong, a consensus of wrong ones can outnumber the right ones in a free search; the prior rules those out.
// Seeded: the same input gives the same pose.
std::optional<Pose> SolvePnpNearRotation(const std::vector<Eigen::Vector3d>& points_in_world,
                                         const std::vector<Eigen::Vector2d>& uv_norm, const PnpOptions& options,
                                         const Eigen::Quaterniond& rotation_prior, double max_rotation_deg,
                                         uint64_t seed, int* num_inliers = nullptr);

}  // namespace mcslam::geometry
