#pragma once
// Trajectory evaluation against ground truth: association by timestamp, alignment of the estimate onto the
// ground truth (Umeyama Sim(3)/SE(3) on camera positions), absolute trajectory error (ATE), per-frame
// rotation error and relative pose error (RPE). Both trajectories hold `world_from_cam` poses, each in its
// own world frame: `gt_world` and `est_world`.
#include <cstddef>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"
#include "io/trajectory_io.h"

namespace mcslam::eval {

enum class Alignment {
  kSim3,  // rotation, translation and scale: what a monocular estimate needs (its scale is arbitrary)
  kSE3,   // rotation and translation
  kNone,  // the estimate is already in the ground truth's frame
};
// "sim3" | "se3" | "none" (any case); throws std::invalid_argument naming the value.
Alignment ParseAlignment(const std::string& name);
std::string ToString(Alignment a);

// ---- association -------------------------------------------------------------------------------------

struct AssociationOptions {
  // Largest |t_est - t_gt| for a match, seconds. 0.02 s is the default of the TUM benchmark tools.
  double max_dt_s = 0.02;
  // Throws std::invalid_argument when max_dt_s is negative or not finite.
  void Check() const;
};

struct MatchedPair {
  size_t gt_index = 0;   // into the ground truth trajectory
  size_t est_index = 0;  // into the estimated trajectory
  double dt_s = 0;       // t_est - t_gt; 0 when matched by index
};

// One-to-one matches, ordered by estimate stamp (by index when matched by index). With stamps on both
// sides: each estimate pose is matched to a ground-truth pose within max_dt_s, greedily by smallest |dt|
// (ties by estimate index, then ground-truth index), each pose used at most once. When either trajectory
// has no stamps (KITTI without a times file): pose i with pose i, for i < min(sizes).
std::vector<MatchedPair> Associate(const io::Trajectory& gt, const io::Trajectory& est,
                                   const AssociationOptions& options = {});

// ---- alignment ---------------------------------------------------------------------------------------

// x_gt = scale * rotation * x_est + translation.
struct Similarity3 {
  double scale = 1.0;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Eigen::Vector3d operator*(const Eigen::Vector3d& point_in_est_world) const {
    return scale * (rotation * point_in_est_world) + translation;
  }
  // An estimated camera pose moved into the ground-truth world: position s R p + t, orientation R R_est.
  Pose Apply(const Pose& est_world_from_cam) const;
};

struct AlignmentResult {
  Similarity3 gt_world_from_est_world;
  // The path's extent across its main direction: the second singular value of the centred positions, as an
  // RMS distance in ground-truth metres (the smaller of the ground truth's and the scaled estimate's).
  double lateral_spread_m = 0;
  double residual_rmse_m = 0;  // RMS position residual of the alignment (the ATE RMSE)
  // True when the positions do not fix the alignment's rotation about the path's main direction: they lie on
  // a line, or the residuals are at least a quarter of the lateral spread, so that the lateral shape they
  // align is mostly error (KITTI 06: 2.8 cm residual on a 4.4 cm lateral spread over 60 m; Umeyama then turns
  // about the road by 9 degrees that the orientations do not show). Per-frame rotation errors then measure the
  // alignment more than the tracker; rot_orient_deg does not depend on it. ATE is unaffected.
  bool rotation_ambiguous = false;
};

// Aligns the estimated positions onto the ground-truth ones (same length, paired by index) with
// Eigen::umeyama. Throws std::runtime_error for different lengths, fewer than 3 points (Sim(3)/SE(3)),
// non-finite positions, or positions that are all equal (on either side) — no alignment exists then.
// kNone returns the identity (and needs at least one point).
AlignmentResult AlignPositions(const std::vector<Eigen::Vector3d>& est_positions,
                               const std::vector<Eigen::Vector3d>& gt_positions, Alignment alignment);

// ---- metrics -----------------------------------------------------------------------------------------

struct EvalOptions {
  Alignment alignment = Alignment::kSim3;
  AssociationOptions association;
  // RPE compares the motion between matched pose k and matched pose k + rpe_delta (a count of matched
  // poses, as the TUM tool's frame delta). At least 1.
  int rpe_delta = 1;
  // Throws std::invalid_argument naming the bad field.
  void Check() const;
};

// Summary statistics of a set of non-negative errors. NaN when there are none.
struct ErrorStats {
  size_t count = 0;
  double rmse = 0, mean = 0, median = 0, max = 0;
};
ErrorStats ComputeStats(std::vector<double> errors);

struct FrameError {
  double stamp_s = 0;  // the estimate's stamp (its index when it has none)
  size_t gt_index = 0, est_index = 0;
  Eigen::Vector3d gt_position = Eigen::Vector3d::Zero();
  Eigen::Vector3d est_position_aligned = Eigen::Vector3d::Zero();  // in the ground-truth world
  double trans_err_m = 0;                                           // |est_aligned - gt|
  double rot_err_deg = 0;  // angle of R_gt^T R_est_aligned
};

struct TrajectoryErrors {
  Alignment alignment = Alignment::kSim3;
  size_t gt_size = 0, est_size = 0;
  AlignmentResult alignment_result;
  std::vector<FrameError> frames;  // one per matched pair, in association order
  ErrorStats ate_m;                // position error after alignment (the ATE), metres
  ErrorStats rot_deg;              // orientation error after alignment, degrees
  // Orientation error after the rotation that best aligns the orientations themselves (the chordal mean of
  // R_gt R_est^T), not the positions: the tracker's orientation accuracy whatever the path's shape, and the
  // figure to read when alignment_result.rotation_ambiguous.
  ErrorStats rot_orient_deg;
  int rpe_delta = 1;
  ErrorStats rpe_trans_m;  // of the relative pose error, on the aligned (for Sim(3): scaled) estimate
  ErrorStats rpe_rot_deg;
  double gt_path_length_m = 0;  // length of the ground-truth path through the matched poses
  // The estimate is a mirror image of the truth (a depth-reversed monocular map): a similarity with a
  // reflection maps the estimated positions onto the true ones with at most half the rms residual of the best
  // Sim(3) (positions spread in 3D; a trajectory that is only wrong fits neither), or the Sim(3) fits the
  // positions (rms residual at most half their spread: a flat path mirrored across its plane) and the
  // orientations are still more than 90 degrees off after it (median), which no proper rotation of a mirrored
  // trajectory can undo.
  bool mirrored = false;
  size_t matched() const { return frames.size(); }
};

// Associates, aligns and measures. Throws std::runtime_error with a clear message when the trajectories
// are empty, share no stamps (naming both time ranges), have fewer than 3 matches for Sim(3)/SE(3),
// hold non-finite poses, or cannot be aligned. The RPE statistics are NaN when fewer than rpe_delta + 1
// poses matched.
TrajectoryErrors EvaluateTrajectory(const io::Trajectory& gt, const io::Trajectory& est,
                                    const EvalOptions& options = {});

// ---- scale drift ---------------------------------------------------------------------------------------

// A run of consecutive matched poses aligned on its own (Sim(3)). A monocular estimate's scale drifts; one
// alignment for the whole run hides where, and the ATE then mostly measures the drift. Segment scales that
// change along the trajectory show it directly, and a segment's own ATE what is left (local consistency).
struct SegmentErrors {
  size_t first = 0, count = 0;           // matched poses first .. first + count - 1 (association order)
  double first_stamp_s = 0, last_stamp_s = 0;
  // Ground-truth metres per estimate unit in this segment, and that over the whole run's (Sim(3)) scale;
  // NaN for a segment whose positions are all the same (nothing to align).
  double scale = 1;
  double scale_vs_whole = 1;
  ErrorStats ate_m;                      // position error after the segment's own alignment (NaN as above)
};
struct ScaleDrift {
  std::vector<SegmentErrors> segments;
  double max_over_min_scale = 1;  // largest segment scale over the smallest (NaN ones left out): 1 for no drift
};
// Splits the matched poses of `errors` into `segments` consecutive runs of (nearly) equal length and aligns
// each on its own with Sim(3). Throws std::invalid_argument when segments < 1 or a segment would hold fewer
// than 3 poses.
ScaleDrift EvaluateScaleDrift(const TrajectoryErrors& errors, int segments);

// CSV, one row per matched pose:
// stamp,gt_x,gt_y,gt_z,est_x,est_y,est_z,trans_err_m,rot_err_deg (est_* aligned into the ground-truth world).
// Throws std::runtime_error naming the file when it cannot be written.
void WriteFrameErrorsCsv(const std::string& path, const TrajectoryErrors& errors);

// One line, space-separated key=value, no newline, e.g.
// "matched=300 align=sim3 scale=1 ate_rmse=0.0123 ate_mean=... ate_median=... ate_max=... rot_mean_deg=...
//  rot_median_deg=... rot_max_deg=... rot_orient_mean_deg=... rot_orient_median_deg=... rpe_delta=1 rpe_trans_rmse=... rpe_trans_mean=... rpe_rot_mean_deg=... mirrored=0|1"
// Values with 6 significant digits ({:.6g}), so tiny errors stay visible.
std::string FormatSummary(const TrajectoryErrors& errors);

}  // namespace mcslam::eval
