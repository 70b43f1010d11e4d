#pragma once
// The report of one frame that the System returns (and of an earlier frame it revises): status, pose, how it was
// posed, counts and times.
#include <cstdint>
#include <span>
#include <string>

#include <Eigen/Core>

#include "core/pose.h"

namespace mcslam::slam {

enum class FrameStatus { kWaitingForInit, kTracked, kLost };
const char* ToString(FrameStatus s);

// What kept a frame waiting for the first map (FrameReport::init_wait).
enum class InitWait {
  kNone,          // not waiting, or no reason recorded
  kReference,     // the frame became the reference (the first, or after a restart)
  kFewShared,     // too few features shared with the reference (the reference moved on): init_count of init_needed
  kBlurred,       // a blurred frame
  kMotion,        // the features had not moved enough since the reference
  kWindow,        // too few frames since the reference
  kFewInliers,    // too few correspondences fit one two-view motion: init_count of init_needed
  kGeometry,      // a two-view motion was found but fell short (parallax, points, the window's refinement)
  kRejected,      // an initialisation was found and rejected (a depth-reversal ambiguity)
};

struct FrameReport {
  int64_t index = 0;
  double stamp_s = 0;
  FrameStatus status = FrameStatus::kWaitingForInit;
  bool has_pose = false;
  Pose cam_from_world;
  Pose smoothed_cam_from_world;
  bool keyframe = false;
  bool initialisation = false;  // the pose came from the two-view initialisation
  bool self_calibration = false;  // the lens' k1 was measured on this frame (InitOptions::self_calibrate): the note says
  // A later correction of an earlier frame's pose (the settling after initialisation): only cam_from_world
  // (and the residual statistics) replace those of that frame's report; the rest of it stands.
  bool pose_update = false;
  // Lost when it came, posed later once a frame after it was tracked again (SystemOptions::pose_lost_frames_when_found):
  // the pose, its residuals, inliers and note replace those of the frame's report; its times and counts stand.
  bool placed_after_loss = false;
  int scored = 0, inliers = 0;
  // The pose step's best score (the capped reprojection distances summed, px) and the translation spread it sampled
  // with (m): zero when the frame was not posed by the pose step.
  double score = 0;
  Eigen::Vector3d sigma_t = Eigen::Vector3d::Zero();
  int map_points = 0;           // active + lost
  int new_points = 0, adjusted = 0, removed = 0;
  double reproj_mean_px = 0;    // mean residual of the inlier observations of map points in this frame
  double reproj_median_px = 0;  // median residual of all observations of map points in this frame
  double track_ms = 0, map_ms = 0, adjust_ms = 0, init_ms = 0;
  // adjust_ms's two parts on a keyframe: the Monte Carlo point adjustment and the local bundle
  // adjustment after it (MappingOptions::local_ba_keyframes; with local_ba_async its preparation, solve and
  // application, and local_ba_wait_ms what the next frame's Process waited for the solve to end).
  double adjust_points_ms = 0, local_ba_ms = 0, local_ba_wait_ms = 0;
  bool local_ba = false;  // a local bundle adjustment refined this keyframe's window (not skipped)
  int local_ba_span = 0;  // frames from the oldest keyframe it adjusted to this one (local_ba_min_step_of_depth)
  std::string note;             // why lost / waiting; how posed when not by the pose step
  bool rotation_only = false;   // tracked by its rotation about the last centre (SystemOptions::rotation_only)
  bool provisional = false;     // posed in a provisional map whose scale was guessed (SystemOptions::bridge)
  // That provisional map joined the map later (its frames scaled to the map's and adjusted: pose updates carry it).
  bool joined = false;
  // The pose's scale is still the provisional map's guess: it never joined the map (lost, or the run ended first),
  // so its frames are in a frame of their own, not the map's (a Sim(3) apart).
  bool guessed_scale() const { return provisional && !joined; }
  // Waiting: an initialisation was found and rejected in this frame (its note says why: a depth-reversal
  // ambiguity), as opposed to no initialisation being possible yet.
  bool init_rejected = false;
  // Waiting: what held the first map back in this frame, with the count behind it and the count it needed
  // (kFewShared: features shared with the reference; kFewInliers: correspondences fitting one two-view motion).
  InitWait init_wait = InitWait::kNone;
  int init_count = 0, init_needed = 0;
  // The map was found, while it settled, to be the mirror of the scene in depth and was flipped (note says by
  // how much the mirror explained the settling window better).
  bool depth_reversed = false;
  // A revised report: the frame had been posed in a map that was dropped (SystemOptions::restart_min_lost_frames);
  // it has no pose now (returned when the new map initialises). The report of the frame that started the new map
  // says so in its note, with map_restarted set.
  bool map_dropped = false;
  bool map_restarted = false;
};

// The reason's name in report.json's waiting_for_init ("reference", "few_shared", "blurred", "motion", "window",
// "few_inliers", "geometry", "rejected"; "none" for kNone).
const char* InitWaitName(InitWait w);
inline constexpr int kInitWaitReasons = static_cast<int>(InitWait::kRejected) + 1;

// Why a run never made its first map, from its frames' reports (the waiting ones count): the reasons by how many
// frames each held back, with their counts, and what a user can do about the leading one. `motion_rule` describes
// the motion the initialisation asks for (the options' thresholds in words). Empty when no frame waited.
struct NotInitialisedSummary {
  bool too_little_motion = false;  // the motion held most waiting frames back (the camera barely moved)
  bool too_few_features = false;   // too few features (shared, or fitting one motion) held most back
  std::string text;
};
NotInitialisedSummary WhyNotInitialised(std::span<const FrameReport> reports, const std::string& motion_rule);

}  // namespace mcslam::slam
