#pragma once
// Constant-velocity Kalman filter of one image feature: state (u, v, du, dv) in pixels and pixels per
// frame, measurement (u, v). The two axes share the same dynamics and noise, so their covariances stay
// equal and one 2x2 (position, velocity) covariance serves both: a track costs 64 bytes and a few flops.
#include <Eigen/Core>

namespace mcslam::frontend {

class ConstantVelocityKalman {
 public:
  ConstantVelocityKalman() = default;
  // Starts at uv_px moving at velocity_px (per frame), with those standard deviations.
  ConstantVelocityKalman(const Eigen::Vector2d& uv_px, const Eigen::Vector2d& velocity_px, double position_sigma_px,
                         double velocity_sigma_px)
      : uv_px_(uv_px), velocity_px_(velocity_px) {
    P_ << position_sigma_px * position_sigma_px, 0, 0, velocity_sigma_px * velocity_sigma_px;
  }

  // Advances one frame; accel_sigma_px: standard deviation of the change of velocity per frame (white
  // acceleration noise). Returns the predicted position.
  const Eigen::Vector2d& Predict(double accel_sigma_px) {
    uv_px_ += velocity_px_;
    // P = F P F^T + Q, F = [1 1; 0 1], Q = s^2 [1/4 1/2; 1/2 1].
    const double p00 = P_(0, 0) + 2 * P_(0, 1) + P_(1, 1), p01 = P_(0, 1) + P_(1, 1), p11 = P_(1, 1);
    const double q = accel_sigma_px * accel_sigma_px;
    P_ << p00 + 0.25 * q, p01 + 0.5 * q, p01 + 0.5 * q, p11 + q;
    return uv_px_;
  }

  // Folds in a measured position with standard deviation measurement_sigma_px.
  void Update(const Eigen::Vector2d& measured_uv_px, double measurement_sigma_px) {
    const double s = P_(0, 0) + measurement_sigma_px * measurement_sigma_px;
    const double k0 = P_(0, 0) / s, k1 = P_(1, 0) / s;
    const Eigen::Vector2d innovation = measured_uv_px - uv_px_;
    uv_px_ += k0 * innovation;
    velocity_px_ += k1 * innovation;
    const double p00 = (1 - k0) * P_(0, 0), p01 = (1 - k0) * P_(0, 1), p11 = P_(1, 1) - k1 * P_(0, 1);
    P_ << p00, p01, p01, p11;
  }

  const Eigen::Vector2d& uv_px() const { return uv_px_; }
  const Eigen::Vector2d& velocity_px() const { return velocity_px_; }
  // Per-axis covariance of (position, velocity).
  const Eigen::Matrix2d& covariance() const { return P_; }

 private:
  Eigen::Vector2d uv_px_ = Eigen::Vector2d::Zero();
  Eigen::Vector2d velocity_px_ = Eigen::Vector2d::Zero();
  Eigen::Matrix2d P_ = Eigen::Matrix2d::Identity();
};

}  // namespace mcslam::frontend
