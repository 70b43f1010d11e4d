#pragma once
// Pinhole camera with optional radial-tangential (Brown-Conrady / OpenCV "plumb bob") distortion.
// Coordinates: uv_px are pixels (origin at the centre of the top-left pixel, x right, y down);
// uv_norm are normalised image coordinates x/z, y/z, before distortion.
#include <Eigen/Core>
#include <string>

#include "core/pose.h"

namespace mcslam {

// The lens model between the ideal pinhole's normalised coordinates n = (x/z, y/z), r = |n|, and the distorted ones:
// - kRadialTangential (Brown-Conrady: OpenCV's, ORB-SLAM's "PinHole", EuRoC's "radial-tangential"):
//   n (1 + k1 r^2 + k2 r^4 + k3 r^6) plus the tangential terms of p1, p2;
// - kEquidistant (Kannala-Brandt, a fisheye: OpenCV's fisheye module, ORB-SLAM3's "KannalaBrandt8", Kalibr's and
//   TUM-VI's "equidistant"): n / r * theta_d with theta = atan(r), the ray's angle off the axis, and
//   theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8); p1, p2 are unused (0). Even with every
//   coefficient 0 it is not a pinhole: the image radius grows with the angle, not its tangent. Rays up to 90 degrees
//   off the axis only (Unproject returns [x, y, 1]).
enum class LensModel { kRadialTangential, kEquidistant };
struct Distortion {
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;
  double k4 = 0;  // kEquidistant only
  LensModel model = LensModel::kRadialTangential;
  bool IsZero() const {
    return model == LensModel::kRadialTangential && k1 == 0 && k2 == 0 && p1 == 0 && p2 == 0 && k3 == 0;
  }
  bool IsFisheye() const { return model == LensModel::kEquidistant; }
  // The equidistant lens of theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8).
  static Distortion Equidistant(double k1, double k2, double k3, double k4) {
    Distortion d;
    d.k1 = k1, d.k2 = k2, d.k3 = k3, d.k4 = k4;
    d.model = LensModel::kEquidistant;
    return d;
  }
};
const char* ToString(LensModel model);

class PinholeCamera {
 public:
  PinholeCamera() = default;
  PinholeCamera(double fx, double fy, double cx, double cy, int width, int height, Distortion dist = {});

  double fx = 0, fy = 0, cx = 0, cy = 0;
  int width = 0, height = 0;
  Distortion dist;

  // Throws std::invalid_argument naming the bad value (non-positive focal length or size, NaN, ...).
  void Check() const;
  bool HasDistortion() const { return !dist.IsZero(); }
  Eigen::Matrix3d K() const;

  // Without distortion: pixel = K * [uv_norm; 1], and its inverse.
  Eigen::Vector2d NormalizedToPixel(const Eigen::Vector2d& uv_norm) const;
  Eigen::Vector2d PixelToNormalized(const Eigen::Vector2d& uv_px) const {
    return {(uv_px.x() - cx) / fx, (uv_px.y() - cy) / fy};
  }

  // Apply the distortion model to undistorted normalised coordinates, optionally with its 2x2 Jacobian.
  Eigen::Vector2d Distort(const Eigen::Vector2d& uv_norm, Eigen::Matrix2d* J = nullptr) const;
  // Inverse of Distort by Gauss-Newton; exact to ~1e-12 inside the image for realistic lenses.
  Eigen::Vector2d Undistort(const Eigen::Vector2d& uv_norm_distorted) const;

  // Project a point in camera coordinates to pixels (through the distortion). Returns false when the
  // point is not in front of the camera (z <= min_depth); outputs are then untouched.
  // J_point: d uv_px / d point_in_cam (2x3).
  bool Project(const Eigen::Vector3d& point_in_cam, Eigen::Vector2d* uv_px,
               Eigen::Matrix<double, 2, 3>* J_point = nullptr, double min_depth = 1e-9) const;
  // Project a world point through cam_from_world; J_world: d uv_px / d point_in_world,
  // J_translation: d uv_px / d cam_from_world.t.
  bool ProjectWorld(const Pose& cam_from_world, const Eigen::Vector3d& point_in_world, Eigen::Vector2d* uv_px,
                    Eigen::Matrix<double, 2, 3>* J_world = nullptr,
                    Eigen::Matrix<double, 2, 3>* J_translation = nullptr) const;

  // Ray through a (distorted) pixel as [x, y, 1] in camera coordinates. Defined here: for a camera without
  // distortion (the renderer's, once per ray) it is a subtraction and a division, no call.
  Eigen::Vector3d Unproject(const Eigen::Vector2d& uv_px) const {
    const Eigen::Vector2d n = HasDistortion() ? Undistort(PixelToNormalized(uv_px)) : PixelToNormalized(uv_px);
    return {n.x(), n.y(), 1.0};
  }
  // Distorted pixel -> the pixel an ideal pinhole camera with the same K would have seen. The back end works with
  // such pixels (x/z, y/z): a fisheye's ray more than kMaxPinholeRayAngleDeg off the axis has none worth the name
  // (tan 90 degrees), and its pixel errors would grow as 1 / cos^2 of the angle: NaN is returned for it.
  static constexpr double kMaxPinholeRayAngleDeg = 80.0;
  Eigen::Vector2d UndistortPixel(const Eigen::Vector2d& uv_px) const;

  bool InImage(const Eigen::Vector2d& uv_px, double border = 0.0) const {
    return uv_px.x() >= border && uv_px.y() >= border && uv_px.x() <= width - 1 - border &&
           uv_px.y() <= height - 1 - border;
  }

  // The same camera for images scaled by `factor` (intrinsics scale, distortion does not).
  PinholeCamera Scaled(double factor) const;
  std::string ToString() const;
};

}  // namespace mcslam
