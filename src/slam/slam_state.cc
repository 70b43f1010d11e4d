// What the System's stages share (slam_state.h): the map's queries that more than one stage asks.
#include "slam/slam_state.h"

#include <algorithm>
#include <unordered_map>

#include "core/median.h"
#include "slam/fibonacci.h"
#include "slam/frame_report.h"

namespace mcslam::slam {

const char* ToString(FrameStatus s) {
  switch (s) {
    case FrameStatus::kWaitingForInit: return "waiting";
    case FrameStatus::kTracked: return "tracked";
    case FrameStatus::kLost: return "lost";
  }
  return "?";
}

SlamState::SlamState(const PinholeCamera& camera_in, const SystemOptions& options_in)
    : camera(camera_in),
      ideal(camera_in.fx, camera_in.fy, camera_in.cx, camera_in.cy, camera_in.width, camera_in.height),
      focal_px(0.5 * (camera_in.fx + camera_in.fy)),
      options(options_in),
      smoother(options_in.smoother) {}

geometry::PnpOptions SlamState::TrackerPnpOptions(int min_inliers) const {
  geometry::PnpOptions po;
  po.focal_px = focal_px;
  po.threshold_px = options.tracker.inlier_threshold_px;
  po.min_inliers = min_inliers;
  return po;
}

std::optional<Pose> SlamState::PlaceByPnp(int slot, int min_inliers, double min_inlier_ratio, int* inliers) const {
  std::vector<Eigen::Vector3d> P;
  std::vector<Eigen::Vector2d> uv;
  for (const FeatureUndistorted& o : map.frames[slot].features)
    if (const MapPoint* p = map.Find(o.id); p && p->state != PointState::kRemoved)
      P.push_back(p->position_in_world), uv.push_back(ideal.PixelToNormalized(o.uv_px));
  int found = 0;
  std::optional<Pose> pose = geometry::SolvePnp(P, uv, TrackerPnpOptions(min_inliers), &found);
  if (pose && found < min_inlier_ratio * static_cast<double>(P.size())) return std::nullopt;
  if (inliers) *inliers = found;
  return pose;
}

WindowPoints SlamState::CollectWindowPoints(const std::vector<int>& window) {
  WindowPoints wp;
  std::unordered_map<int64_t, int> count, index;
  for (int s : window)
    for (const FeatureUndistorted& f : map.frames[s].features)
      if (const MapPoint* p = map.Find(f.id); p && p->state != PointState::kRemoved) ++count[f.id];
  for (size_t w = 0; w < window.size(); ++w)
    for (const FeatureUndistorted& f : map.frames[window[w]].features) {
      MapPoint* p = map.Find(f.id);
      if (!p || p->state == PointState::kRemoved || count[f.id] < 2) continue;
      auto [it, fresh] = index.try_emplace(f.id, static_cast<int>(wp.pts.size()));
      if (fresh) wp.pts.push_back(p), wp.X.push_back(p->position_in_world);
      wp.obs.push_back({static_cast<int>(w), it->second, ideal.PixelToNormalized(f.uv_px)});
    }
  return wp;
}

std::vector<bool> SlamState::HeldPoints(const WindowPoints& wp) const {
  std::vector<bool> held;
  if (loaded_points.empty()) return held;
  held.reserve(wp.pts.size());
  for (const MapPoint* p : wp.pts) held.push_back(IsLoaded(p->id));
  return held;
}

int SlamState::StoreAdjustedPoints(const std::vector<Pose>& cams, const WindowPoints& wp, int64_t frame_index) {
  std::vector<std::vector<double>> residuals(wp.pts.size());
  for (const geometry::BundleObservation& o : wp.obs)
    residuals[o.point].push_back(geometry::ReprojectionErrorPx(cams[o.camera], wp.X[o.point], o.uv_norm, focal_px));
  int removed = 0;
  for (size_t i = 0; i < wp.pts.size(); ++i) {
    wp.pts[i]->position_in_world = wp.X[i];
    if (residuals[i].size() >= 3 && UpperMedian(residuals[i]) > options.mapping.adjust_threshold_px) {
      wp.pts[i]->state = PointState::kRemoved;
      wp.pts[i]->removed_frame = frame_index;
      ++removed;
    }
  }
  return removed;
}

void SlamState::RefreshInlierFlags(int slot) {
  const FrameRecord& fr = map.frames[slot];
  for (const FeatureUndistorted& f : fr.features)
    if (MapPoint* p = map.Find(f.id); p && p->state != PointState::kRemoved) {
      Eigen::Vector2d uv;
      p->inlier = ideal.ProjectWorld(fr.cam_from_world, p->position_in_world, &uv) &&
                  (uv - f.uv_px).norm() < options.tracker.inlier_threshold_px;
    }
}

FrameReport SlamState::PosedReport(int slot) const {
  const FrameRecord& f = map.frames[slot];
  FrameReport r;
  r.index = f.index;
  r.stamp_s = f.stamp_s;
  r.status = FrameStatus::kTracked;
  r.has_pose = true;
  r.cam_from_world = f.cam_from_world;
  ResidualStats(slot, &r);
  return r;
}

void SlamState::ResidualStats(int slot, FrameReport* r) const {
  const FrameRecord& fr = map.frames[slot];
  if (!fr.has_pose) return;
  std::vector<double> all;
  double sum = 0;
  int n = 0;
  for (const FeatureUndistorted& f : fr.features) {
    const MapPoint* p = map.Find(f.id);
    if (!p || p->state == PointState::kRemoved) continue;
    Eigen::Vector2d uv;
    if (!ideal.ProjectWorld(fr.cam_from_world, p->position_in_world, &uv)) continue;
    const double d = (uv - f.uv_px).norm();
    all.push_back(d);
    if (d < options.tracker.inlier_threshold_px) sum += d, ++n;
  }
  r->reproj_mean_px = n > 0 ? sum / n : 0.0;
  r->reproj_median_px = UpperMedian(all);
}

void SlamState::MarkSeen(int slot) {
  const FrameRecord& fr = map.frames[slot];
  for (const FeatureUndistorted& f : fr.features)
    if (MapPoint* p = map.Find(f.id); p && p->state != PointState::kRemoved) {
      p->last_seen_frame = fr.index;
      p->state = PointState::kActive;
    }
  for (MapPoint& p : map.points())
    if (p.state == PointState::kActive && p.last_seen_frame < fr.index) p.state = PointState::kLost;
}

std::vector<int> SlamState::WindowSlots() const {
  std::vector<int> window;  // frame slots, newest first
  for (int wi : FibonacciWindow(static_cast<int>(map.keyframes.size()), options.mapping.window))
    if (map.frames[map.keyframes[wi]].has_pose) window.push_back(map.keyframes[wi]);
  return window;
}

std::optional<double> SlamState::MedianDepthSeenBy(int slot) const {
  const FrameRecord& f = map.frames[slot];
  std::vector<double> depths;
  for (const FeatureUndistorted& o : f.features)
    if (const MapPoint* p = map.Find(o.id); p && p->state != PointState::kRemoved)
      if (const double z = (f.cam_from_world * p->position_in_world).z(); z > 0) depths.push_back(z);
  if (depths.empty()) return std::nullopt;
  return UpperMedian(depths);
}

}  // namespace mcslam::slam
