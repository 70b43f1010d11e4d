// The bundle adjustment's residual with its Jacobians written out (not automatic differentiation): on the
// settling's adjustments, which refine every frame since the reference, Ceres spent 0.41 of its 0.80 s in
// evaluating the automatic Jacobians of 18,600 observations (7-Scenes' last settling step, 51 evaluations).
// Internal to the geometry layer (bundle_adjust.cc, self_calibration.cc; tests/geometry checks these Jacobians
// against Ceres' automatic ones). Only double* parameter blocks cross into Ceres.
#pragma once

#include <ceres/sized_cost_function.h>

#include <Eigen/Core>

#include "core/camera.h"
#include "core/pose.h"

namespace mcslam::geometry {

// The pixel residual focal * (p.xy / p.z - uv) of the point p = R(q) X + t, with the camera's pose block
// (qx, qy, qz, qw, tx, ty, tz) (the quaternion as Eigen stores it, unit norm: the block lives on a product of the
// quaternion and Euclidean manifolds) and the point X (3). Evaluate returns false for a point at or behind the
// camera (z <= 1e-9), so that Ceres rejects a step that puts it there.
class ReprojectionCost final : public ceres::SizedCostFunction<2, 7, 3> {
 public:
  ReprojectionCost(const Eigen::Vector2d& uv_norm, double focal_px) : u_(uv_norm.x()), v_(uv_norm.y()), f_(focal_px) {}
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  double u_, v_, f_;
};

// The same residual for a camera held fixed: only the point (3) varies.
class FixedCameraReprojectionCost final : public ceres::SizedCostFunction<2, 3> {
 public:
  FixedCameraReprojectionCost(const Pose& cam_from_world, const Eigen::Vector2d& uv_norm, double focal_px);
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  Eigen::Matrix3d R_;
  Eigen::Vector3d t_;
  double u_, v_, f_;
};

// The self-calibration's residual (geometry/self_calibration.h): a distorted observation uv_px (pixels) of the
// point X by the camera's pose block as above and the intrinsics block (focal scale s, k1 added to the given
// camera's): s f * distort(p.xy / p.z) + c - uv_px, the given camera's other terms (k2, k3, p1, p2) held.
class CalibratedReprojectionCost final : public ceres::SizedCostFunction<2, 7, 3, 2> {
 public:
  CalibratedReprojectionCost(const PinholeCamera& camera, const Eigen::Vector2d& uv_px);
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  double fx_, fy_, cx_, cy_, k1_, k2_, k3_, p1_, p2_, u_, v_;
};

}  // namespace mcslam::geometry
