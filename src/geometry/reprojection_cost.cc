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

// p = R(q) X + t for the pose block (qx, qy, qz, qw, tx, ty, tz), and R. R(q) X = X + 2 w (v x X) + 2 v x (v x X) for
// the unit quaternion (v, w): the polynomial Ceres' UnitQuaternionRotatePoint evaluates, so that its derivatives by
// all four components are those the automatic differentiation gave (the manifold keeps only their part along the
// unit sphere).
Eigen::Vector3d Transform(const double* pose, const double* point, Eigen::Matrix3d* R) {
  const Eigen::Matrix3d V = Cross(Eigen::Vector3d(pose[0], pose[1], pose[2]));
  *R = Eigen::Matrix3d::Identity() + 2.0 * pose[3] * V + 2.0 * V * V;
  return *R * Eigen::Map<const Eigen::Vector3d>(point) + Eigen::Map<const Eigen::Vector3d>(pose + 4);
}

// The derivative of p = R(q) X + t by the pose block (3x7), given d, the residual's derivative by p (2x3), into the
// row-major 2x7 block J: by v, -2 w [X]x + 2 ((v . X) I + v X^T - 2 X v^T); by w, 2 v x X; by t, I.
void PoseJacobian(const double* pose, const double* point, const Eigen::Matrix<double, 2, 3>& d, double* J) {
  const Eigen::Vector3d qv(pose[0], pose[1], pose[2]);
  const Eigen::Map<const Eigen::Vector3d> X(point);
  const double qw = pose[3];
  const Eigen::Matrix3d d_v =
      -2.0 * qw * Cross(X) + 2.0 * (qv.dot(X) * Eigen::Matrix3d::Identity() + qv * X.transpose() - 2.0 * X * qv.transpose());
  Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> out(J);
  out.block<2, 3>(0, 0) = d * d_v;
  out.col(3) = d * (2.0 * qv.cross(X));
  out.block<2, 3>(0, 4) = d;
}

}  // namespace

bool ReprojectionCost::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  Eigen::Matrix3d R;
  const Eigen::Vector3d p = Transform(parameters[0], parameters[1], &R);
  const bool want = jacobians != nullptr && (jacobians[0] != nullptr || jacobians[1] != nullptr);
  Eigen::Matrix<double, 2, 3> d_p;
  if (!Project(p, u_, v_, f_, residuals, want ? &d_p : nullptr)) return false;
  if (!want) return true;
  if (jacobians[0]) PoseJacobian(parameters[0], parameters[1], d_p, jacobians[0]);
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

CalibratedReprojectionCost::CalibratedReprojectionCost(const PinholeCamera& camera, const Eigen::Vector2d& uv_px)
    : fx_(camera.fx),
      fy_(camera.fy),
      cx_(camera.cx),
      cy_(camera.cy),
      k1_(camera.dist.k1),
      k2_(camera.dist.k2),
      k3_(camera.dist.k3),
      p1_(camera.dist.p1),
      p2_(camera.dist.p2),
      u_(uv_px.x()),
      v_(uv_px.y()) {}

bool CalibratedReprojectionCost::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const double* intr = parameters[2];
  Eigen::Matrix3d R;
  const Eigen::Vector3d p = Transform(parameters[0], parameters[1], &R);
  if (!(p.z() > 1e-9)) return false;
  const double iz = 1.0 / p.z(), x = p.x() * iz, y = p.y() * iz;
  const double r2 = x * x + y * y;
  const double k1 = k1_ + intr[1];
  const double radial = 1.0 + r2 * (k1 + r2 * (k2_ + r2 * k3_));
  const double xd = x * radial + 2.0 * p1_ * x * y + p2_ * (r2 + 2.0 * x * x);
  const double yd = y * radial + p1_ * (r2 + 2.0 * y * y) + 2.0 * p2_ * x * y;
  const double sfx = intr[0] * fx_, sfy = intr[0] * fy_;
  residuals[0] = sfx * xd + cx_ - u_;
  residuals[1] = sfy * yd + cy_ - v_;
  if (jacobians == nullptr) return true;
  if (jacobians[0] != nullptr || jacobians[1] != nullptr) {
    // d(xd, yd) / d(x, y), then d(x, y) / dp.
    const double d_radial = k1 + r2 * (2.0 * k2_ + 3.0 * k3_ * r2);  // d radial / d r2
    const double cross = 2.0 * x * y * d_radial + 2.0 * p1_ * x + 2.0 * p2_ * y;  // d xd / dy = d yd / dx
    Eigen::Matrix2d d_xy;
    d_xy << radial + 2.0 * x * x * d_radial + 2.0 * p1_ * y + 6.0 * p2_ * x, cross,
        cross, radial + 2.0 * y * y * d_radial + 6.0 * p1_ * y + 2.0 * p2_ * x;
    Eigen::Matrix<double, 2, 3> d_proj;
    d_proj << iz, 0, -x * iz, 0, iz, -y * iz;
    const Eigen::Matrix<double, 2, 3> d_p = Eigen::Vector2d(sfx, sfy).asDiagonal() * (d_xy * d_proj);
    if (jacobians[0]) PoseJacobian(parameters[0], parameters[1], d_p, jacobians[0]);
    if (jacobians[1]) {
      Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> J(jacobians[1]);
      J = d_p * R;
    }
  }
  if (jacobians[2]) {
    Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>> J(jacobians[2]);
    J << fx_ * xd, sfx * x * r2, fy_ * yd, sfy * y * r2;
  }
  return true;
}

}  // namespace mcslam::geometry
