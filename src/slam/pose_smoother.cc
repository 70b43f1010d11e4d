#include "slam/pose_smoother.h"

#include <stdexcept>

#include <fmt/format.h>

namespace mcslam::slam {

void PoseSmootherOptions::Check() const {
  if (!(alpha > 0 && alpha <= 1)) throw std::invalid_argument(fmt::format("smoothing alpha must be in (0, 1], got {}", alpha));
  if (!(predict_frames >= 0)) throw std::invalid_argument(fmt::format("predict_frames must be >= 0, got {}", predict_frames));
}

PoseSmoother::PoseSmoother(const PoseSmootherOptions& options) : options_(options) { options_.Check(); }

namespace {
// Slerp that also extrapolates (k > 1), along the shortest arc.
Eigen::Quaterniond SlerpExtrapolate(const Eigen::Quaterniond& a, Eigen::Quaterniond b, double k) {
  if (a.dot(b) < 0) b.coeffs() *= -1.0;
  const Eigen::Vector3d w = RotationVectorFromQuaternion(a.conjugate() * b);
  return (a * QuaternionFromRotationVector(k * w)).normalized();
}
}  // namespace

Pose PoseSmoother::Update(const Pose& cam_from_world) {
  const Pose world_from_cam = cam_from_world.Inverse();
  const Eigen::Vector3d p = world_from_cam.t;
  const Eigen::Quaterniond q = world_from_cam.q;
  const double a = options_.alpha;
  if (!initialised_) {
    s1_p_ = s2_p_ = p;
    s1_q_ = s2_q_ = q;
    initialised_ = true;
  } else {
    s1_p_ = a * p + (1 - a) * s1_p_;
    s2_p_ = a * s1_p_ + (1 - a) * s2_p_;
    s1_q_ = SlerpExtrapolate(s1_q_, q, a);
    s2_q_ = SlerpExtrapolate(s2_q_, s1_q_, a);
  }
  // alpha = 1 means no smoothing: S1 = S2 = sample, and the trend term vanishes.
  const double k = a < 1 ? a * options_.predict_frames / (1 - a) : 0.0;
  const Eigen::Vector3d p_out = (2 + k) * s1_p_ - (1 + k) * s2_p_;
  const Eigen::Quaterniond q_out = SlerpExtrapolate(s2_q_, s1_q_, 2 + k);
  return Pose(q_out, p_out).Inverse();
}

}  // namespace mcslam::slam
