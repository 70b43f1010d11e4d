// Why a run never made its first map: its waiting frames' reasons, summarised for the user.
#include "slam/frame_report.h"

#include <algorithm>
#include <array>
#include <vector>

#include <fmt/format.h>

namespace mcslam::slam {

const char* InitWaitName(InitWait w) {
  switch (w) {
    case InitWait::kNone: return "none";
    case InitWait::kReference: return "reference";
    case InitWait::kFewShared: return "few_shared";
    case InitWait::kBlurred: return "blurred";
    case InitWait::kMotion: return "motion";
    case InitWait::kWindow: return "window";
    case InitWait::kFewInliers: return "few_inliers";
    case InitWait::kGeometry: return "geometry";
    case InitWait::kRejected: return "rejected";
  }
  return "none";
}

NotInitialisedSummary WhyNotInitialised(std::span<const FrameReport> reports, const std::string& motion_rule) {
  constexpr size_t kReasons = kInitWaitReasons;
  struct Tally {
    int frames = 0;
    int most = -1, needed = 0;  // the largest count seen and what that frame needed
  };
  std::array<Tally, kReasons> tally{};
  int waiting = 0;
  for (const FrameReport& r : reports) {
    if (r.status != FrameStatus::kWaitingForInit || r.init_wait == InitWait::kNone) continue;
    Tally& t = tally[static_cast<size_t>(r.init_wait)];
    ++t.frames;
    ++waiting;
    if (r.init_count > t.most) t.most = r.init_count, t.needed = r.init_needed;
  }
  NotInitialisedSummary s;
  if (waiting == 0) return s;
  auto phrase = [&](InitWait w) -> std::string {
    const Tally& t = tally[static_cast<size_t>(w)];
    switch (w) {
      case InitWait::kMotion:
        return fmt::format("in {} the features had not moved enough since the reference frame ({})", t.frames,
                           motion_rule);
      case InitWait::kFewShared:
        return fmt::format("in {} too few features were shared with the reference frame (at most {}, {} needed)",
                           t.frames, t.most, t.needed);
      case InitWait::kFewInliers:
        return fmt::format("in {} too few correspondences fit one motion between two views (at most {}, {} needed)",
                           t.frames, t.most, t.needed);
      case InitWait::kGeometry:
        return fmt::format("in {} a motion between two views was found but fell short (parallax, triangulated "
                           "points or the refinement of its window: frames.csv's note says which)",
                           t.frames);
      case InitWait::kRejected:
        return fmt::format("in {} an initialisation was found and rejected as ambiguous (report.json's "
                           "initialisation_rejections)",
                           t.frames);
      case InitWait::kBlurred: return fmt::format("{} were blurred", t.frames);
      case InitWait::kWindow: return fmt::format("in {} too few frames had passed since the reference frame", t.frames);
      case InitWait::kReference: return fmt::format("{} became the reference frame", t.frames);
      case InitWait::kNone: break;
    }
    return {};
  };
  std::vector<InitWait> order;
  for (size_t k = 1; k < kReasons; ++k)
    if (tally[k].frames > 0) order.push_back(static_cast<InitWait>(k));
  // Most frames first; the reference frames last (they say nothing about what was missing).
  std::stable_sort(order.begin(), order.end(), [&](InitWait a, InitWait b) {
    const bool ra = a == InitWait::kReference, rb = b == InitWait::kReference;
    if (ra != rb) return rb;
    return tally[static_cast<size_t>(a)].frames > tally[static_cast<size_t>(b)].frames;
  });
  const int features = tally[static_cast<size_t>(InitWait::kFewShared)].frames +
                       tally[static_cast<size_t>(InitWait::kFewInliers)].frames;
  const int motion = tally[static_cast<size_t>(InitWait::kMotion)].frames;
  // The leading cause, which the headline and the advice name: too few features (shared with the reference, or
  // fitting one motion) or too little motion, whichever held more frames back, where it held back more frames
  // than any other reason did (a tie goes to the features: no motion makes features).
  int others = 0;
  for (const InitWait w : {InitWait::kBlurred, InitWait::kWindow, InitWait::kGeometry, InitWait::kRejected})
    others = std::max(others, tally[static_cast<size_t>(w)].frames);
  s.too_few_features = features > 0 && features >= motion && features >= others;
  s.too_little_motion = !s.too_few_features && motion > 0 && motion >= others;
  s.text = fmt::format("of the {} frames waiting for the first map, ", waiting);
  for (size_t k = 0; k < order.size(); ++k)
    s.text += (k == 0 ? "" : k + 1 == order.size() ? " and " : ", ") + phrase(order[k]);
  if (s.too_few_features)
    s.text += ". The scene offers too few features to track: aim the camera at more texture (corners, print, "
              "clutter), and check that the images are neither too dark nor blurred";
  else if (s.too_little_motion)
    s.text += ". Move the camera sideways, not only turn it: depth comes from a change of viewpoint";
  else if (tally[static_cast<size_t>(InitWait::kRejected)].frames > 0)
    s.text += ". Two views that leave the depth ambiguous need a wider sideways move of the camera";
  return s;
}

}  // namespace mcslam::slam
