#pragma once
// The map the back end builds: points (id = the feature id of their track, position, state, inlier flag),
// the frames it has seen with their undistorted features, and which of them are keyframes with poses.
// What the kernels read per frame (positions, features) is gathered into contiguous arrays by the users.
#include <algorithm>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"

namespace mcslam::slam {

enum class PointState : uint8_t {
  kActive,   // tracked in the latest frame
  kLost,     // in the map, its track ended (a front end may re-attach it)
  kRemoved,  // rejected as an outlier by the Monte Carlo adjustment; may be triangulated again later
};

struct MapPoint {
  int64_t id = 0;
  Eigen::Vector3d position_in_world = Eigen::Vector3d::Zero();
  PointState state = PointState::kActive;
  bool inlier = true;        // inlier at the last estimated pose: only these score the next pose (§5.2)
  int64_t last_seen_frame = 0;
  int64_t removed_frame = -1;  // when it was last removed
};

struct FeatureUndistorted {
  int64_t id = 0;
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();  // undistorted pixels
};

struct FrameRecord {
  int64_t index = 0;
  double stamp_s = 0;
  std::vector<FeatureUndistorted> features;  // sorted by id
  bool has_pose = false;
  Pose cam_from_world;
  int pose_inliers = 0;  // the map points that agreed with the pose step's pose (0: posed otherwise)
  bool blurred = false;  // FrameObservations::blurred

  const FeatureUndistorted* Find(int64_t id) const {
    auto it = LowerBound(id);
    return it != features.end() && it->id == id ? &*it : nullptr;
  }
  // Where `id` is or would go in `features` (sorted by id).
  std::vector<FeatureUndistorted>::const_iterator LowerBound(int64_t id) const {
    return std::lower_bound(features.begin(), features.end(), id,
                            [](const FeatureUndistorted& f, int64_t v) { return f.id < v; });
  }
  // The observation of track `from` becomes one of point `to` (kept in id order); dropped when the frame already
  // observes `to`. True when the frame observes `to` through it now.
  bool Rename(int64_t from, int64_t to) {
    auto at = LowerBound(from);
    if (at == features.end() || at->id != from) return false;
    const Eigen::Vector2d uv = at->uv_px;
    features.erase(at);
    if (Find(to)) return false;
    features.insert(LowerBound(to), {to, uv});
    return true;
  }
};

class Map {
 public:
  MapPoint* Find(int64_t id) {
    auto it = index_.find(id);
    return it == index_.end() ? nullptr : &points_[it->second];
  }
  const MapPoint* Find(int64_t id) const {
    auto it = index_.find(id);
    return it == index_.end() ? nullptr : &points_[it->second];
  }
  MapPoint& Add(const MapPoint& p) {
    index_[p.id] = static_cast<int>(points_.size());
    points_.push_back(p);
    return points_.back();
  }
  const std::vector<MapPoint>& points() const { return points_; }
  std::vector<MapPoint>& points() { return points_; }
  int CountInState(PointState s) const {
    return static_cast<int>(std::count_if(points_.begin(), points_.end(), [s](const MapPoint& p) { return p.state == s; }));
  }

  std::vector<FrameRecord> frames;  // every frame seen, in order
  std::vector<int> keyframes;       // indices into frames

 private:
  std::vector<MapPoint> points_;
  std::unordered_map<int64_t, int> index_;
};

}  // namespace mcslam::slam
