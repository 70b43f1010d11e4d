#pragma once
// Tracking one frame (paper §5): the Monte Carlo pose step (or PnP, the baseline) from the map points it sees, a
// turn about the last centre when the map leaves the view (SystemOptions::rotation_only), and on a keyframe the
// mapping after it (Mapper).
#include <cstdint>
#include <optional>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/pose.h"
#include "slam/frame_report.h"
#include "slam/pose_tracker.h"

namespace mcslam::slam {

struct SlamState;
class Mapper;
class Bridge;
class Settler;

class FrameTracker {
 public:
  FrameTracker(SlamState& s, Mapper& mapper, Bridge& bridge, const Settler& settler)
      : s_(s), mapper_(mapper), bridge_(bridge), settler_(settler) {}

  // Poses frame `slot` from the last posed frame, or from pose_hint (a relocalisation): its report.
  FrameReport TrackFrame(int slot, const std::optional<Pose>& pose_hint);

  // The last turn (under way, or ended by the frame just lost): each of its rotation-only frames (slot) and its
  // residual (px rms), in order, and the least of them.
  const std::vector<std::pair<int, double>>& turn_rms_px() const { return panorama_rms_px_; }
  double turn_min_rms_px() const { return panorama_min_rms_px_; }
  // A later turn starts afresh (its centre found again).
  void EndTurn() { panorama_bearings_.clear(); }
  // Frame `slot` was lost with the turn under way kept: its residual jumped, and the next frame tells a move from
  // noise (SystemOptions::rotation_only_keep_turn_over_a_jump).
  bool TurnKeptOver(int slot) const { return jump_slot_ == slot; }

 private:
  // SystemOptions::rotation_only: poses `slot` by its rotation about the last tracked centre when the tracks
  // agree on one; true when it did (r then says so).
  // over_pose: in place of a pose the pose step found from few points (SystemOptions::rotation_only_over_weak_pose),
  // which asks the tracks to agree on the turn within their noise from the first frame of the turn on.
  bool TrackRotationOnly(int slot, FrameReport* r, bool over_pose = false);
  PoseEstimate EstimatePosePnp(const std::vector<PointObservation>& obs, std::vector<double>* res,
                               std::vector<uint8_t>* inl) const;

  SlamState& s_;
  Mapper& mapper_;
  Bridge& bridge_;
  const Settler& settler_;
  // Rotation-only tracking (SystemOptions::rotation_only), under way while panorama_bearings_ holds any: the
  // centre all its frames share (a well-posed frame of the tracked run before), and each track's bearing in the
  // world as first seen from there.
  static constexpr int kPanoramaCentreLookback = 10;  // frames searched back for a well-posed centre
  // The first frame of the current run of poses that follow from one another: a relocalised frame starts one (its
  // pose does not follow from the frame before, which may have been posed in a provisional map given up since).
  // A turn's centre is looked for from there on.
  int pose_run_start_slot_ = 0;
  Eigen::Vector3d panorama_centre_ = Eigen::Vector3d::Zero();
  double panorama_min_rms_px_ = 0;  // the least residual of its frames so far: the tracks' noise
  std::vector<std::pair<int, double>> panorama_rms_px_;  // each of its frames (slot) and its residual, in order
  std::unordered_map<int64_t, Eigen::Vector3d> panorama_bearings_;
  // The frame of the turn under way whose residual jumped past the move test's bound, lost but the turn kept for
  // the next frame to tell a move from noise (-1: none); and how many frames in a row, up to it, jumped so (more
  // than one only through blurred frames).
  int jump_slot_ = -1;
  int jump_run_ = 0;
};

}  // namespace mcslam::slam
