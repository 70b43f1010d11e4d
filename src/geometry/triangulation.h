#pragma once
// Linear (DLT) triangulation of one scene point from two or more posed views, with the checks that decide
// whether the point may enter a map: in front of every camera, reprojection error under a threshold, and
// enough parallax. The paper triangulates new points linearly (its map initialisation and new points between
// frames with a long enough baseline, §6.1-6.2); this is that step.
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"

namespace mcslam::geometry {

struct TriangulationOptions {
  double max_reprojection_px = 3.0;  // largest allowed reprojection error in any view (pixels); > 0
  double focal_px = 500.0;           // focal length converting normalised errors to pixels; > 0
  double min_parallax_deg = 1.0;     // the largest angle between two viewing rays must reach this; in [0, 180)
  double min_depth = 1e-6;           // the point's depth (z in the camera) must exceed this in every view; >= 0
  void Check() const;                // throws std::invalid_argument naming the bad field and its value
};

// Why a triangulation was rejected (the first failed check, in this order).
enum class TriangulationStatus {
  kOk,
  kBadInput,        // fewer than 2 views, sizes differ, or a non-finite pose or observation
  kAtInfinity,      // the homogeneous solution has (numerically) zero weight: parallel rays
  kBehindCamera,    // depth <= min_depth in some view
  kLargeReprojection,  // reprojection error > max_reprojection_px in some view
  kSmallParallax,   // largest ray angle < min_parallax_deg
};
const char* ToString(TriangulationStatus status);

struct Triangulation {
  bool ok = false;
  TriangulationStatus status = TriangulationStatus::kBadInput;
  std::string failure;                      // why not, in words (empty when ok)
  Eigen::Vector3d point_in_world = Eigen::Vector3d::Zero();  // the DLT solution; set whenever it is finite,
                                                             // also when a check failed
  double max_reprojection_px = 0;           // largest reprojection error over the views (px)
  double min_depth = 0;                     // smallest depth over the views
  double parallax_deg = 0;                  // largest angle between two viewing rays at the point
};

// DLT triangulation (H&Z 2nd ed. §12.2): for every view, the two rows u p3^T - p1^T and v p3^T - p2^T of the
// 3x4 matrix P = [R | t] of cam_from_world and the observation uv_norm = (u, v) are stacked, and the point is
// the right singular vector of the smallest singular value. Exact on exact data. Then the checks of
// TriangulationOptions; every measured value is filled in even when a check fails.
// The parallax is the largest angle, over pairs of views, between the rays from the two camera centres to
// the triangulated point. Never throws on bad data (only on bad options).
Triangulation TriangulateDlt(std::span<const Pose> cam_from_world, std::span<const Eigen::Vector2d> uv_norm,
                             const TriangulationOptions& options);

// Homogeneous DLT solution alone (unit norm, no checks); the zero vector on bad input (sizes, < 2 views).
Eigen::Vector4d TriangulateHomogeneous(std::span<const Pose> cam_from_world, std::span<const Eigen::Vector2d> uv_norm);

// The correspondences whose two-view DLT triangulation (camera 1 at the origin, camera 2 at cam2_from_cam1) lies
// in front of both cameras: cheirality, which decides among the decompositions of an essential matrix and the sign
// of a translation. Over `indices` (every correspondence when empty); a point at infinity says nothing and is left
// out. The kept correspondences' indices, in the order given, with their points in camera 1.
struct InFrontOfBoth {
  std::vector<int> indices;
  std::vector<Eigen::Vector3d> points_in_cam1;
};
InFrontOfBoth TriangulateInFrontOfBoth(const Pose& cam2_from_cam1, std::span<const Eigen::Vector2d> uv_norm1,
                                       std::span<const Eigen::Vector2d> uv_norm2, std::span<const int> indices = {});

// Largest angle (degrees) between the rays from the camera centres to the point, over all pairs of views.
double ParallaxDeg(std::span<const Pose> cam_from_world, const Eigen::Vector3d& point_in_world);

}  // namespace mcslam::geometry
