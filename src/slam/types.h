#pragma once
// What the back end consumes: per frame, the tracked features (feature id -> pixel). The back end knows
// nothing of images (../shared/DESIGN.md, the seam between front end and back end).
#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"

namespace mcslam::slam {

struct FeatureObservation {
  int64_t feature_id = 0;
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();  // as the camera saw it (distorted pixels)
};

struct FrameObservations {
  int64_t index = 0;
  double stamp_s = 0;
  std::vector<FeatureObservation> features;
  // cam_from_world found by relocalisation (System::Relocalise) for this frame: the pose step searches
  // around it instead of around the last pose.
  std::optional<Pose> pose_hint;
};

}  // namespace mcslam::slam
