#include "geometry/reprojection_cost.h"

#include <Eigen/Geometry>

namespace mcslam::geometry {

namespace {

// The cross-product matrix [a]x: [a]x b = a x b.
Eigen::Matrix3d Cross(const Eigen::Vector3d& a) {
  Eigen::Matrix3d m;
  m << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
  return m;
}

// The residual at p in camera coordinates and, if wanted, its derivative by p (2x3); false at or behind the camera.
bool Project(const Eigen::Vector3d& p, double u, double v, double f, double* r, Eigen::Matrix<double, 2, 3>* d_p) {
  if (!(p.z() > 1e-9)) return false;
  const double iz = 1.0 / p.z(), x = p.x() * iz, y = p.y() * iz;
  r[0] = f * (x - u);
  r[1] = f * (y - v);
  if (d_p) *d_p << f * iz, 0, -f * x * iz, 0, f * iz, -f * y * iz;
  return true;
}

}  // namespace

bool ReprojectionCost::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const double* pose = parameters[0];
  const Eigen::Map<const Eigen::Vector3d> X(parameters[1]), t(pose + 4);
  const Eigen::Vector3d qv(pose[0], pose[1], pose[2]);
  const double qw = pose[3];
  // R(q) X = X + 2 w (v x X) + 2 v x (v x X) for the unit quaternion (v, w): the polynomial Ceres'
  // UnitQuaternionRotatePoint evaluates, so that its derivatives by all four components are those the automatic
  // differentiation gave (the manifold keeps only their part along the unit sphere).
  const Eigen::Matrix3d V = Cross(qv);
  const Eigen::Matrix3d R = Eigen::Matrix3d::Identity() + 2.0 * qw * V + 2.0 * V * V;
  const Eigen::Vector3d p = R * X + t;
  const bool want = jacobians != nullptr && (jacobians[0] != nullptr || jacobians[1] != nullptr);
  Eigen::Matrix<double, 2, 3> d_p;
  if (!Project(p, u_, v_, f_, residuals, want ? &d_p : nullptr)) return false;
  if (!want) return true;
  if (jacobians[0]) {
    Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> J(jacobians[0]);
    const Eigen::Vector3d vxX = qv.cross(X);
    // d/dv: -2 w [X]x + 2 ((v . X) I + v X^T - 2 X v^T); d/dw: 2 v x X; d/dt: I.
    const Eigen::Matrix3d d_v = -2.0 * qw * Cross(X) +
                                2.0 * (qv.dot(X) * Eigen::Matrix3d::Identity() + qv * X.transpose() - 2.0 * X * qv.transpose());
    J.block<2, 3>(0, 0) = d_p * d_v;
    J.col(3) = d_p * (2.0 * vxX);
    J.block<2, 3>(0, 4) = d_p;
  }
  if (jacobians[1]) {
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> J(jacobians[1]);
    J = d_p * R;
  }
  return true;
}

FixedCameraReprojectionCost::FixedCameraReprojectionCost(const Pose& cam_from_world, const Eigen::Vector2d& uv_norm,
                                                         double focal_px)
    : R_(cam_from_world.q.normalized().toRotationMatrix()),
      t_(cam_from_world.t),
      u_(uv_norm.x()),
      v_(uv_norm.y()),
      f_(focal_px) {}

bool FixedCameraReprojectionCost::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const Eigen::Map<const Eigen::Vector3d> X(parameters[0]);
  const Eigen::Vector3d p = R_ * X + t_;
  const bool want = jacobians != nullptr && jacobians[0] != nullptr;
  Eigen::Matrix<double, 2, 3> d_p;
  if (!Project(p, u_, v_, f_, residuals, want ? &d_p : nullptr)) return false;
  if (want) {
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> J(jacobians[0]);
    J = d_p * R_;
  }
  return true;
}

}  // namespace mcslam::geometry
