#include "core/pose.h"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

namespace mcslam {

Pose::Pose(const Eigen::Quaterniond& rotation, const Eigen::Vector3d& translation)
    : q(rotation.normalized()), t(translation) {}

Pose Pose::FromRotationTranslation(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation) {
  return Pose(Eigen::Quaterniond(NearestRotation(rotation)), translation);
}

Pose Pose::FromMatrix(const Eigen::Matrix<double, 3, 4>& m) {
  return FromRotationTranslation(m.leftCols<3>(), m.col(3));
}

Pose Pose::FromMatrix(const Eigen::Matrix4d& m) { return FromMatrix(Eigen::Matrix<double, 3, 4>(m.topRows<3>())); }

Eigen::Matrix<double, 3, 4> Pose::Matrix3x4() const {
  Eigen::Matrix<double, 3, 4> m;
  m.leftCols<3>() = R();
  m.col(3) = t;
  return m;
}

Eigen::Matrix4d Pose::Matrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topRows<3>() = Matrix3x4();
  return m;
}

Eigen::Isometry3d Pose::Isometry() const {
  Eigen::Isometry3d iso = Eigen::Isometry3d::Identity();
  iso.linear() = R();
  iso.translation() = t;
  return iso;
}

Pose Pose::operator*(const Pose& other) const {
  Pose out;
  out.q = (q * other.q).normalized();
  out.t = q * other.t + t;
  return out;
}

Pose Pose::Inverse() const {
  Pose out;
  out.q = q.conjugate();
  out.t = -(out.q * t);
  return out;
}

double AngularDistanceRad(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  // |<a,b>| = cos(theta/2); atan2 form stays accurate for tiny angles where acos does not.
  const Eigen::Quaterniond d = a.conjugate() * b;
  const double v = d.vec().norm();
  return 2.0 * std::atan2(v, std::abs(d.w()));
}

double AngularDistanceDeg(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return RadToDeg(AngularDistanceRad(a, b));
}

Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& m) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

Eigen::Quaterniond QuaternionFromRotationVector(const Eigen::Vector3d& w) {
  const double angle = w.norm();
  if (angle < 1e-12) return Eigen::Quaterniond(1.0, 0.5 * w.x(), 0.5 * w.y(), 0.5 * w.z()).normalized();
  return Eigen::Quaterniond(Eigen::AngleAxisd(angle, w / angle));
}

Eigen::Vector3d RotationVectorFromQuaternion(const Eigen::Quaterniond& q_in) {
  Eigen::Quaterniond q = q_in.normalized();
  if (q.w() < 0) q.coeffs() *= -1.0;
  const double v = q.vec().norm();
  if (v < 1e-12) return 2.0 * q.vec();
  const double angle = 2.0 * std::atan2(v, q.w());
  return q.vec() * (angle / v);
}

}  // namespace mcslam
