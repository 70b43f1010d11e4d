#pragma once
// The front end's per-frame result as the back end's input. Header only: slam/types.h is plain data
// (Eigen and core's Pose only), so the front end library does not link the back end.
#include "frontend/frontend.h"
#include "slam/types.h"

namespace mcslam::frontend {

inline slam::FrameObservations ToObservations(const FrameResult& result) {
  slam::FrameObservations out;
  out.index = result.index;
  out.stamp_s = result.stamp_s;
  out.features.reserve(result.features.size());
  for (const TrackedFeature& f : result.features) out.features.push_back({f.feature_id, f.uv_px});
  return out;
}

}  // namespace mcslam::frontend
