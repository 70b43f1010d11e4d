#pragma once
// The SLAM back end (paper §5-6): from feature observations alone, it initialises from two views (§6.1),
// tracks every frame by Monte Carlo pose estimation (§5), and on keyframes adds points by linear
// triangulation and refines points by Monte Carlo adjustment over Fibonacci-spaced keyframes (§6.2-6.3).
// Process is the paper's per-frame loop over the stages, each a unit of its own that owns its state
// (docs/design.md): Initializer and Settler (§6.1), FrameTracker (§5), Mapper and PointAdjuster (§6.2-6.3),
// Bridge (the provisional map after a turn) and Relocalise; SlamState is what they share. The System itself
// keeps the restarts (SystemOptions::restart_min_lost_frames).
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "compute/point_kernel.h"
#include "compute/pose_kernel.h"
#include "core/camera.h"
#include "core/observations.h"
#include "slam/frame_report.h"
#include "slam/map.h"
#include "slam/relocaliser.h"
#include "slam/settler.h"
#include "slam/system_options.h"

namespace mcslam::slam {

class System {
 public:
  ~System();
  System& operator=(System&& other) noexcept;  // (a restart: SystemOptions::restart_min_lost_frames)
  System(const PinholeCamera& camera, const SystemOptions& options, std::unique_ptr<compute::PoseKernel> pose_kernel,
         std::unique_ptr<compute::PointKernel> point_kernel);

  // Processes the next frame. Returns the reports of the frames that became final: normally this frame;
  // when the map is initialised, also the frames from the reference frame on, and those before it that
  // could be placed (their reports replace the earlier 'waiting' ones).
  std::vector<FrameReport> Process(const FrameObservations& frame);
  // MappingOptions::local_ba_async: waits for the last keyframe's local bundle adjustment, applies it and returns
  // that keyframe's revised report (none when nothing is pending; also those a Process that threw had flushed).
  // Process does it first; call it after the last frame, before reading the final map.
  std::vector<FrameReport> Flush();
  // After the last frame: Flush, and when the map started after a restart (SystemOptions::restart_min_lost_frames)
  // has not yet posed more frames than the map before it, that map's poses stand and the new map's frames are
  // reported again without a pose (FrameReport::map_dropped); result_map() is then that map.
  std::vector<FrameReport> Finish();
  // The same wait and application, the revised report held for the next Process or Flush to return: for a caller
  // that reads the map (relocalisation) before it processes the frame.
  void ApplyPendingAdjustment();

  // After the track is lost: the pose of a frame from features matched to map points by their look alone
  // (no pose prior), by RANSAC PnP on the points that are in the map. nullopt when fewer than
  // relocalise_min_inliers matches agree, or before initialisation. Changes nothing; the caller passes the
  // pose as the frame's pose_hint with the inlier features under their map points' ids.
  std::optional<Relocalisation> Relocalise(const std::vector<RelocalisationMatch>& matches) const;

  // For --gt-scale: the true distance between the camera centres at two stamps, when known. The first
  // baseline is then scaled to it instead of to 1.
  void SetBaselineOracle(std::function<std::optional<double>(double, double)> oracle);
  // Whether a new track looks like a map point (the caller's descriptors of both: VisualSlam). Set, a place seen
  // again (MappingOptions::merge_revisited_points, and always in a loaded map: a new track whose triangulated point
  // is where an unseen map point projects goes on as that point) is merged only where the two also look alike,
  // and those that do not are not counted among the candidates. Called from Process, on the thread that calls it.
  void SetLookCheck(std::function<bool(int64_t track, int64_t point)> check);
  // Whether a place seen again may be merged into its map points now (merge_revisited_points, or a loaded map).
  bool merges_revisits() const;

  // Starts in a map made before (a map file): its points and its keyframes (poses and features). Only before
  // the first frame; throws std::logic_error after one. The System is then initialised but not localised: a
  // frame without a pose hint is lost until one is relocalised against the map (Relocalise, then Process with
  // the pose as its hint); tracking and mapping go on from there, in the map's frame and scale.
  // `camera`, when given, replaces the System's: a map made by a run that self-calibrated its k1 carries the
  // refined camera (its features are undistorted with it). The caller checks that it differs only in k1.
  void StartInMap(std::vector<MapPoint> points, std::vector<FrameRecord> keyframes,
                  const std::optional<PinholeCamera>& camera = std::nullopt);
  bool initialised() const;
  // Some map was initialised in this run: this one, or one dropped since (SystemOptions::restart_min_lost_frames),
  // whose frames keep their poses until a new map initialises.
  bool made_a_map() const { return initialised() || restarts_ > 0; }
  // The map a run's outputs hold (map.ply): this one, or the one before a restart while the new one is not
  // initialised, and after Finish when it had posed more frames than the new one.
  const Map& result_map() const;
  // Some frame has a pose: false before the initialisation, and in a loaded map before its first relocalisation.
  bool localised() const;
  // A provisional map is being tracked (SystemOptions::bridge): the caller should try to relocalise every frame
  // against the rest of the map (Relocalise leaves the provisional points out) and pass the pose as its hint.
  bool bridging() const;
  bool Provisional(int64_t point_id) const;
  // A point the pose step and the remapping may use now: any, or while a provisional map is tracked only its own
  // (the rest of the map is at another scale).
  bool AtCurrentScale(int64_t point_id) const;
  // A point of the map this run started in (StartInMap), held where that map put it: no adjustment moves it. One
  // that left the map and was triangulated again from this run's views is this run's from then on.
  bool Loaded(int64_t point_id) const;
  // (This reference, and those of merged_tracks, camera, self_calibration and result_map, hold until the next Process,
  // Flush or Finish: a restart replaces the map and the stages that keep them.)
  const Map& map() const;
  // The tracks that went on as an older map point in the last Process (MappingOptions::merge_revisited_points):
  // (track id, map point id) pairs. The System already takes the track's features under the point's id; a
  // front end should relabel the track (the System otherwise renames its features frame by frame).
  const std::vector<std::pair<int64_t, int64_t>>& merged_tracks() const;
  // The camera the map is made with: the given one, or with its k1 self-calibrated (InitOptions::self_calibrate).
  const PinholeCamera& camera() const;
  // (Of result_map()'s map: after a restart that kept the old map, the old map's measure.)
  const SelfCalibration& self_calibration() const;
  // How many times the map was dropped and started again (SystemOptions::restart_min_lost_frames).
  int restarts() const { return restarts_; }

 private:
  // The stages and what they share, on the heap: they refer to each other. A restart replaces them (and the map)
  // with new ones.
  struct Stages;
  std::vector<FrameReport> ProcessFrame(const FrameObservations& frame);
  int PosedFrames() const;
  // After this frame's reports: drops the map and starts again with this frame when it has stayed lost long
  // enough; returns the reports to return instead (the dropped frames', then this frame's in the new start).
  std::vector<FrameReport> MaybeRestart(const FrameObservations& frame, std::vector<FrameReport> now);

  std::unique_ptr<Stages> st_;
  std::vector<FrameReport> held_reports_;  // revised, not yet returned (ApplyPendingAdjustment, a Process that threw)
  // Restarts (SystemOptions::restart_min_lost_frames): the camera as given (before any self-calibration), the
  // frames lost in a row, and the restarts so far.
  PinholeCamera given_camera_;
  int lost_run_ = 0;
  int restarts_ = 0;
  // A map replaced by a restart: its frames' reports without a pose (returned once the new map has posed more
  // frames than its dropped_posed_), and the map itself until then (result_map).
  std::vector<FrameReport> dropped_reports_;
  std::optional<Map> dropped_map_;
  std::optional<SelfCalibration> dropped_self_calibration_;
  int dropped_posed_ = 0;
  bool finished_with_dropped_map_ = false;  // Finish kept it
};

}  // namespace mcslam::slam
