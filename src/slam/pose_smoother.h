#pragma once
// Double exponential smoothing prediction (DESP, LaViola 2003) of a camera pose, for rendering: the
// estimated pose jitters by the sampling resolution of the Monte Carlo estimator; AR overlays want it
// smooth. Position: two cascaded exponential filters and the linear-trend predictor
//   p(t + tau) = (2 + a tau / (1 - a)) S1 - (1 + a tau / (1 - a)) S2.
// Orientation: the same with slerp in place of the weighted sums.
#include "core/pose.h"

namespace mcslam::slam {

struct PoseSmootherOptions {
  double alpha = 0.5;           // weight of the new sample, in (0, 1); 1 = no smoothing
  double predict_frames = 0.0;  // tau: how many frames ahead to predict (0 = the smoothed present)
  void Check() const;           // throws std::invalid_argument naming the bad field
};

class PoseSmoother {
 public:
  explicit PoseSmoother(const PoseSmootherOptions& options = {});
  // Feeds a pose (either direction of transform; smoothing acts on world_from_cam so that positions
  // are camera centres) and returns the smoothed / predicted pose in the same direction.
  Pose Update(const Pose& cam_from_world);
  void Reset() { initialised_ = false; }

 private:
  PoseSmootherOptions options_;
  bool initialised_ = false;
  Eigen::Vector3d s1_p_, s2_p_;
  Eigen::Quaterniond s1_q_, s2_q_;
};

}  // namespace mcslam::slam
