#include "slam/known_map_tracking.h"

#include <chrono>

namespace mcslam::slam {

KnownMapTracker::KnownMapTracker(const PinholeCamera& camera,
                                 std::unordered_map<int64_t, Eigen::Vector3d> points_in_world,
                                 const KnownMapOptions& options, std::unique_ptr<compute::PoseKernel> kernel)
    : camera_(camera), tracker_(camera, options.tracker, std::move(kernel)), smoother_(options.smoother) {
  points_.reserve(points_in_world.size());
  for (const auto& [id, p] : points_in_world) {
    index_of_id_[id] = static_cast<int>(points_.size());
    points_.push_back(p);
  }
  // A point never seen yet is given the benefit of the doubt: it takes part until it fails once.
  inlier_flag_.assign(points_.size(), 1);
}

void KnownMapTracker::Gather(const FrameObservations& frame) {
  obs_.clear();
  obs_point_.clear();
  for (const FeatureObservation& f : frame.features) {
    const auto it = index_of_id_.find(f.feature_id);
    if (it == index_of_id_.end()) continue;
    PointObservation o;
    o.point_in_world = points_[it->second];
    o.uv_undistorted_px = camera_.UndistortPixel(f.uv_px);
    if (!o.uv_undistorted_px.allFinite()) continue;  // not a ray of the pinhole pixels (UndistortPixel)
    o.was_inlier = inlier_flag_[it->second] != 0;
    obs_.push_back(o);
    obs_point_.push_back(it->second);
  }
}

void KnownMapTracker::Commit(const std::vector<uint8_t>& inliers) {
  for (size_t i = 0; i < obs_point_.size(); ++i) inlier_flag_[obs_point_[i]] = inliers[i];
}

FrameResult KnownMapTracker::Start(const FrameObservations& frame, const Pose& cam_from_world) {
  FrameResult r;
  r.index = frame.index;
  r.stamp_s = frame.stamp_s;
  r.given = true;
  Gather(frame);
  r.observed_map_points = static_cast<int>(obs_.size());
  r.estimate.cam_from_world = cam_from_world;
  r.estimate.tracked = true;
  r.estimate.scored = r.observed_map_points;
  r.estimate.inliers = tracker_.ClassifyInliers(cam_from_world, obs_, &residuals_, &inliers_);
  Commit(inliers_);
  last_ = cam_from_world;
  smoother_.Reset();
  r.smoothed_cam_from_world = smoother_.Update(cam_from_world);
  return r;
}

FrameResult KnownMapTracker::Track(const FrameObservations& frame) {
  FrameResult r;
  r.index = frame.index;
  r.stamp_s = frame.stamp_s;
  Gather(frame);
  r.observed_map_points = static_cast<int>(obs_.size());
  const auto t0 = std::chrono::steady_clock::now();
  r.estimate = tracker_.Track(last_, obs_, static_cast<uint64_t>(frame.index), &residuals_, &inliers_);
  r.time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (r.estimate.tracked) {
    Commit(inliers_);
    last_ = r.estimate.cam_from_world;
    r.smoothed_cam_from_world = smoother_.Update(last_);
  } else {
    // Lost: no invented pose. Every observed point gets another chance in the next frame.
    for (int p : obs_point_) inlier_flag_[p] = 1;
  }
  return r;
}

}  // namespace mcslam::slam
