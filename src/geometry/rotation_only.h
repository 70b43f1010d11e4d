#pragma once
// The rotation of a camera that turned about its own centre, from bearings: directions known in a reference
// frame (world) and the same directions as the camera sees them now. Wahba's problem, solved in closed form
// (the SVD of the 3x3 correlation of the bearings), inside a seeded RANSAC over pairs of bearings.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace mcslam::geometry {

struct RotationOnlyOptions {
  double threshold_px = 2.0;  // inlier: the rotated reference bearing lands within this of the observed one
  double focal_px = 500;      // converts it to an angle
  int min_inliers = 20;
  int iterations = 200;
  uint64_t seed = 0;
};

struct RotationOnlyResult {
  bool ok = false;
  Eigen::Matrix3d cam_from_ref = Eigen::Matrix3d::Identity();
  std::vector<uint8_t> inlier;  // per bearing pair
  int inliers = 0;
  double rms_px = 0;  // of the inliers, in pixels (angle x focal)
  std::string failure;
};

// The closed-form least-squares rotation taking `ref` onto `cam` (unit vectors, same length, >= 2 that are not
// parallel): argmax sum cam_k . (R ref_k) over rotations (Kabsch / Wahba).
Eigen::Matrix3d RotationFromBearings(std::span<const Eigen::Vector3d> ref, std::span<const Eigen::Vector3d> cam);

// The least-squares rotation of all pairs refitted three times, each time to the half of them that fits the last
// one best (a few wrong pairs must not tilt the rotation the others share). Identity with fewer than 2 pairs.
Eigen::Matrix3d RobustRotationFromBearings(std::span<const Eigen::Vector3d> ref, std::span<const Eigen::Vector3d> cam);

// The part of the bearings' motion that no rotation explains: the median angle (radians) between cam_k and
// R ref_k, R = RobustRotationFromBearings. A camera that turned about its centre leaves only the bearings' noise;
// one that moved leaves its parallax times the spread of the depths about the depth it fixates, however it turned
// meanwhile. 0 with fewer than 3 pairs.
double NonRotationalMotionRad(std::span<const Eigen::Vector3d> ref, std::span<const Eigen::Vector3d> cam);

// cam_from_ref such that cam_k ~ cam_from_ref * ref_k for the inliers (unit bearings). Fails (ok = false, with the
// reason) when fewer than options.min_inliers pairs agree.
RotationOnlyResult EstimateRotationOnly(std::span<const Eigen::Vector3d> ref, std::span<const Eigen::Vector3d> cam,
                                        const RotationOnlyOptions& options);

}  // namespace mcslam::geometry
