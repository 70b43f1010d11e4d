#pragma once
// Rigid transforms as unit quaternion + translation. A Pose maps points from frame A to frame B and is
// named after that: `cam_from_world` maps world points into the camera (the paper's pose, Eq. 1),
// `world_from_cam` is what trajectory files hold.
#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace mcslam {

struct Pose {
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();  // unit quaternion, rotation B<-A
  Eigen::Vector3d t = Eigen::Vector3d::Zero();            // translation, in B

  Pose() = default;
  Pose(const Eigen::Quaterniond& rotation, const Eigen::Vector3d& translation);

  static Pose Identity() { return {}; }
  // From a rotation matrix; re-orthonormalised (SVD) so slightly non-orthonormal input is accepted.
  static Pose FromRotationTranslation(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation);
  // From the top 3x4 block of a homogeneous transform.
  static Pose FromMatrix(const Eigen::Matrix<double, 3, 4>& m);
  static Pose FromMatrix(const Eigen::Matrix4d& m);

  Eigen::Matrix3d R() const { return q.toRotationMatrix(); }
  Eigen::Matrix<double, 3, 4> Matrix3x4() const;
  Eigen::Matrix4d Matrix() const;
  Eigen::Isometry3d Isometry() const;

  // x_B = R x_A + t
  Eigen::Vector3d operator*(const Eigen::Vector3d& x) const { return q * x + t; }
  // (c_from_b * b_from_a) = c_from_a
  Pose operator*(const Pose& other) const;
  Pose Inverse() const;
  // Origin of frame B expressed in A (for cam_from_world: the camera centre in the world).
  Eigen::Vector3d OriginOfTargetInSource() const { return -(q.conjugate() * t); }

  bool AllFinite() const { return q.coeffs().allFinite() && t.allFinite(); }
};

// Smallest rotation angle between two orientations, in [0, pi].
double AngularDistanceRad(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b);
double AngularDistanceDeg(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b);
// Nearest rotation matrix (SVD, det = +1).
Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& m);
// Rotation by angle |w| about w (exponential map of so(3)).
Eigen::Quaterniond QuaternionFromRotationVector(const Eigen::Vector3d& w);
Eigen::Vector3d RotationVectorFromQuaternion(const Eigen::Quaterniond& q);

constexpr double kPi = 3.14159265358979323846;
constexpr double DegToRad(double deg) { return deg * kPi / 180.0; }
constexpr double RadToDeg(double rad) { return rad * 180.0 / kPi; }
// The angle between two vectors (radians): atan2(|a x b|, a . b), accurate for small angles, unlike acos.
inline double AngleBetween(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

}  // namespace mcslam
