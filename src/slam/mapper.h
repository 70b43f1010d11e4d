#pragma once
// Mapping (paper §6.2-6.3): the frame history (each frame's features as the back end takes them, pruned to what the
// keyframe window can reach), new points by triangulation on each keyframe, tracks merged into the map points they
// revisit, and the refinement after it: the Monte Carlo point adjustment (PointAdjuster), or bundle adjustment of
// the keyframe window (the baseline), and the local bundle adjustment of the newest keyframes.
#include <chrono>
#include <cstdint>
#include <deque>
#include <future>
#include <memory>
#include <optional>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "core/observations.h"
#include "core/pose.h"
#include "geometry/bundle_adjust.h"
#include "slam/frame_report.h"
#include "slam/map.h"
#include "slam/slam_state.h"

namespace mcslam::slam {

class Bridge;
class Settler;
class PointAdjuster;

class Mapper {
 public:
  Mapper(SlamState& s, Bridge& bridge, const Settler& settler, PointAdjuster& adjuster);
  ~Mapper();  // waits for a local bundle adjustment still being solved (MappingOptions::local_ba_async)

  // The next frame into the history: its features undistorted (those that cannot be are dropped), under the map
  // point's id where their track was merged into one, sorted by id; older frames' features pruned. Returns its slot.
  int AddFrame(const FrameObservations& frame);
  // A new keyframe `slot` (posed from `inliers` points): new points, then the refinement after them; *r gets the
  // counts and times.
  void MapKeyframe(int slot, int inliers, FrameReport* r);
  // MappingOptions::local_ba_async: waits for the last keyframe's local bundle adjustment and applies it; that
  // keyframe's revised report (none when nothing is pending).
  std::optional<FrameReport> ApplyPending();
  // The report the System returns for the frame that started the pending adjustment completes that adjustment's
  // (nothing when none is pending; the caller passes that frame's report).
  void SetPendingReport(const FrameReport& r);
  // The tracks' noise sigma (px, per coordinate) from the map's residuals in the recent keyframes; nullopt before
  // any keyframe has measured one.
  std::optional<double> RecentNoisePx() const;
  // The tracks that went on as an older map point in the last frame (MappingOptions::merge_revisited_points).
  const std::vector<std::pair<int64_t, int64_t>>& merged_tracks() const { return merged_tracks_; }

 private:
  int TriangulateNewPoints(int slot, int inliers);
  // MappingOptions::merge_revisited_points: the map point not observed in `slot` that the new track `f`
  // triangulated from `views` is, if any; `unseen` holds those points and their projections into `slot`.
  // `seen`: the keyframes the track is seen in (a point seen there too is another point).
  std::optional<int64_t> RevisitedPoint(const FeatureUndistorted& f, const std::vector<int>& views,
                                        const std::vector<int>& seen,
                                        const std::vector<std::pair<int64_t, Eigen::Vector2d>>& unseen) const;
  // The track's features in every frame go under the point's id (dropped where that frame has the point too).
  void MergeTrack(int64_t track, int64_t point);
  void PruneHistory(int slot);
  void BundleAdjustWindow(int slot, FrameReport* r);
  // MappingOptions::local_ba_keyframes: the newest keyframes' poses and their points by one bundle
  // adjustment, the keyframes before them fixed (MappingOptions says which), a loaded map's points fixed. Not
  // while settling (the settling adjusts the whole window), on a provisional map (its scale is not the older
  // keyframes'), nor over fewer points than the adjusted poses have parameters. In three parts: the problem
  // (nullptr when it is skipped), copied out of the map; its solve (LocalBa::Solve, on another thread with
  // local_ba_async); the solution written back to the map.
  struct LocalBa;
  std::unique_ptr<LocalBa> PrepareLocalBa(int slot);
  void ApplyLocalBa(const LocalBa& ba, FrameReport* r);

  SlamState& s_;
  Bridge& bridge_;
  const Settler& settler_;
  PointAdjuster& adjuster_;
  // The median residual of the map's points in the last keyframes (MappingOptions::max_relative_depth_noise).
  static constexpr size_t kResidualHistory = 15;
  std::deque<double> recent_residual_px_;
  double noise_parallax_deg_ = 0;
  // Tracks merged into a map point (MergeTrack): their features are taken under the point's id until a frame comes
  // without them (a front end never reuses an id); and those merged in the last frame.
  std::unordered_map<int64_t, int64_t> track_alias_;
  std::vector<std::pair<int64_t, int64_t>> merged_tracks_;
  // MappingOptions::local_ba_async: the adjustment being solved.
  std::unique_ptr<LocalBa> pending_ba_;
};

}  // namespace mcslam::slam
