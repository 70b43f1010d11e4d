#pragma once
// The seam between front end and back end: per frame, the tracked features (feature id -> pixel). The front
// end produces it, the back end (slam) consumes it and knows nothing of images; both depend on core only, so
// neither includes the other (docs/design.md).
#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"

namespace mcslam {

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
  // (track id, map point id): the tracks relocalisation matched to map points by their descriptors, renamed to
  // those points from this frame on. The frames lost before this one saw them under their track ids.
  std::vector<std::pair<int64_t, int64_t>> relabelled;
  // The front end measured the frame as blurred (frontend::FrameStats::blurred: its patches less sharp than
  // their birth patches): its features lie less precisely, and the System does not initialise on it.
  bool blurred = false;
};

}  // namespace mcslam
