#pragma once
// The front end's per-frame result as the back end's input (core/observations.h, the seam both layers use).
#include "core/observations.h"
#include "frontend/frontend.h"

namespace mcslam::frontend {

inline FrameObservations ToObservations(const FrameResult& result) {
  FrameObservations out;
  out.index = result.index;
  out.stamp_s = result.stamp_s;
  out.blurred = result.stats.blurred;
  out.features.reserve(result.features.size());
  for (const TrackedFeature& f : result.features) out.features.push_back({f.feature_id, f.uv_px});
  return out;
}

}  // namespace mcslam::frontend
