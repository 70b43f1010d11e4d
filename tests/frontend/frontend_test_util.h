// Helpers of the front end's tests: the test image size and lookups in a frame's result.
#pragma once

#include <algorithm>
#include <cstdint>
#include <map>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "frontend/frontend.h"

namespace mcslam::frontend::test {

inline const cv::Size kSize(320, 240);

inline std::map<int64_t, Eigen::Vector2d> ById(const FrameResult& r) {
  std::map<int64_t, Eigen::Vector2d> m;
  for (const auto& f : r.features) m[f.feature_id] = f.uv_px;
  return m;
}

inline const TrackedFeature* Find(const FrameResult& r, int64_t id) {
  for (const auto& f : r.features)
    if (f.feature_id == id) return &f;
  return nullptr;
}

inline bool Lost(const FrameResult& r, int64_t id) {
  return std::any_of(r.lost.begin(), r.lost.end(), [&](const LostTrack& l) { return l.feature_id == id; });
}

}  // namespace mcslam::frontend::test
