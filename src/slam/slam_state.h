#pragma once
// What the System's stages share (docs/design.md, "The back end's stages"): the camera, the options, the map with
// its frame history, the pose step and the output smoother, and where the run stands (initialised, the reference
// frame, the last posed frame). Each stage (Initializer, Settler, FrameTracker, Mapper, PointAdjuster, Bridge, the
// relocaliser) owns its own state and reads and writes the map through this; the queries below are the map's that
// more than one stage asks.
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <unordered_set>
#include <vector>

#include <Eigen/Core>

#include "core/camera.h"
#include "geometry/bundle_adjust.h"
#include "geometry/pnp.h"
#include "slam/map.h"
#include "slam/pose_smoother.h"
#include "slam/pose_tracker.h"
#include "slam/system_options.h"

namespace mcslam::slam {

struct FrameReport;

// The points seen at least twice among some frames (slots), and their observations, for a bundle adjustment.
struct WindowPoints {
  std::vector<MapPoint*> pts;
  std::vector<Eigen::Vector3d> X;
  std::vector<geometry::BundleObservation> obs;  // camera: index into the window
};

struct SlamState {
  SlamState(const PinholeCamera& camera, const SystemOptions& options);

  PinholeCamera camera;  // as given, or with its k1 self-calibrated (Settler)
  PinholeCamera ideal;   // same intrinsics, no distortion: observations are undistorted on arrival
  double focal_px;       // mean focal length: converts pixel thresholds to normalised units
  SystemOptions options;
  Map map;
  std::unique_ptr<PoseTracker> pose_step;  // §5, from construction (System); its translation floor set at initialisation
  PoseSmoother smoother;
  std::function<std::optional<double>(double, double)> oracle;  // --gt-scale: the true baseline between two stamps
  // Whether new track `track` looks like map point `point` (System::SetLookCheck: their descriptors); empty: no look
  // is known here, and a place seen again is merged by projection alone.
  std::function<bool(int64_t track, int64_t point)> same_look;
  // The points of a map this run started in (System::StartInMap): the adjustments (local bundle adjustment, the
  // Monte Carlo point adjustment or the bundle adjustment in its place, a bridge's) hold them fixed, and the map is never dropped for a new one
  // (System::MaybeRestart). One removed and triangulated again from this run's views leaves the set.
  std::unordered_set<int64_t> loaded_points;

  bool initialised = false;
  // The initialisation's reference frame (moved on while it waits), then a provisional map's anchor once one is made.
  int reference_slot = -1;
  int last_posed_slot = -1;
  int posed_from = -1;       // the first posed slot: the reference, or a frame before it (pose_frames_before_reference)
  int pruned_until = 0;      // frames before this slot have dropped their features (MappingOptions::history_frames)

  // A place seen again may go on as its map points (Mapper::RevisitedPoint): MappingOptions::merge_revisited_points,
  // and always in a loaded map.
  bool MergesRevisits() const { return options.mapping.merge_revisited_points || !loaded_points.empty(); }
  // Active and lost map points.
  int MapPoints() const { return map.CountInState(PointState::kActive) + map.CountInState(PointState::kLost); }
  // The points this posed frame sees become active (seen now), those not seen lost.
  void MarkSeen(int slot);
  // Each point seen in this posed frame is an inlier when it projects within the inlier threshold of its
  // feature: the flags gate the next frame's score (§5.2).
  void RefreshInlierFlags(int slot);
  // A tracked frame's report: its pose and residual statistics.
  FrameReport PosedReport(int slot) const;
  void ResidualStats(int slot, FrameReport* r) const;
  // The upper median depth of the map points that frame `slot` sees (in front of it), at its pose; none when it
  // sees none.
  std::optional<double> MedianDepthSeenBy(int slot) const;
  // The Fibonacci-spaced posed keyframes (§6.3), newest first.
  std::vector<int> WindowSlots() const;
  WindowPoints CollectWindowPoints(const std::vector<int>& window);
  // A point of the map this run started in (loaded_points): no adjustment moves it.
  bool IsLoaded(int64_t point_id) const { return loaded_points.count(point_id) > 0; }
  // Per point of `wp`, whether a bundle adjustment holds it fixed (IsLoaded); empty when no map was loaded.
  std::vector<bool> HeldPoints(const WindowPoints& wp) const;
  // Writes the adjusted positions back; a point whose median residual over the window (at least 3 views)
  // is above the outlier threshold leaves the map. Returns how many left.
  int StoreAdjustedPoints(const std::vector<Pose>& cams, const WindowPoints& wp, int64_t frame_index);
  // RANSAC PnP as the pose step judges a point: its inlier threshold, this many inliers at least.
  geometry::PnpOptions TrackerPnpOptions(int min_inliers) const;
  // `inliers` (when given): PnP's inliers of the pose returned.
  std::optional<Pose> PlaceByPnp(int slot, int min_inliers, double min_inlier_ratio, int* inliers = nullptr) const;
};

}  // namespace mcslam::slam
