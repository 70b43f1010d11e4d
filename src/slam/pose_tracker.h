#pragma once
// Monte Carlo pose estimation of one frame (paper §5): hypotheses drawn around the previous pose, the
// translation spread set from a linearised translation-only model (LinearisedTranslation), scored by
// reprojection distance over the map points that were inliers before (the pose kernel, compute/); the best is
// the pose.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "compute/pose_kernel.h"
#include "core/camera.h"
#include "core/pose.h"

namespace mcslam::slam {

enum class RandomMode {
  kTable,  // the paper's: one table of normals made from the seed, rescaled every frame
  kFresh,  // new normals every frame from the counter-based generator (seed, frame index)
};
RandomMode ParseRandomMode(const std::string& name);  // "table" | "fresh"; throws naming the value

struct PoseTrackerOptions {
  int hypotheses = 1 << 18;            // per frame, all rounds together (the paper: 2^18)
  uint64_t seed = 1;                   // the random table / stream
  RandomMode random = RandomMode::kTable;
  // Std of the rotation per axis (Sigma_rot), degrees per frame: at least sigma_rot_deg, and at least
  // sigma_rot_motion_scale times the rotation between the last two poses this tracker estimated (0: the
  // paper's fixed Sigma_rot). A fixed spread is either too wide for a car or a tripod (fewer hypotheses near
  // the answer: KITTI 06 measured 5-29 cm over seeds at 1 degree, 5-8 cm at 0.5) or too narrow for a fast
  // hand-held turn; the motion the tracker measured says which, as the linearised model does for the translation.
  double sigma_rot_deg = 0.5;
  double sigma_rot_motion_scale = 1.0;
  double sigma_trans_floor_m = 0.002;  // Sigma_trans never falls below this (m), so sampling never collapses
  double sigma_trans_scale = 1.0;      // Sigma_trans = diag(scale * |t_hat - t_prev| + floor)
  // The linearised translation t_hat - t_prev (Eqs. 3-5) is solved with a prior: a change of the translation of
  // zero mean and this many times the last tracked frame's step (per frame since it, at least the floor) as its
  // standard deviation, against the scoring points' 1 px. Where the points fix the translation the prior changes
  // nothing; where they leave a direction free (few points in one part of the image) the spread along it stays
  // near what the camera's motion makes likely instead of whatever the noise gives. 0: no prior (the paper's).
  double translation_prior_steps = 3.0;
  double inlier_threshold_px = 3.0;    // residual under which a point is an inlier at the best pose
  double max_distance_px = 1e4;        // cap on one point's contribution to the score (1e4: the paper's plain sum)
  int min_points = 6;                  // fewer scoring points than this: the frame is lost, nothing is scored
  int min_inliers = 8;                 // fewer inliers at the best pose: the frame is lost
  // Fewer inliers than this fraction of the scoring points: the frame is lost too. A pose that most of the
  // points disagree with is more likely wrong than right: after a gap in the frames (unreadable ones
  // skipped) the tracks that survive are mostly wrong, and 10 of 37 agreeing on a pose 0.8 m off was taken
  // as tracking. Tracked frames of the shared real sequences and the synthetic runs have 0.73 or more.
  double min_inlier_ratio = 0.5;
  double keyframe_min_inlier_ratio = 0.6;  // keyframe when inliers >= ratio * scored points (and >= min_inliers)
  // Where the rotation samples pivot. The paper's hypotheses perturb q and t of cam_from_world, so a rotation
  // sample turns the scene about the world origin; when that origin is far from the scene (a SLAM map starts at
  // the first camera, 3 m away) each rotation sample also throws the scene sideways and only hypotheses whose
  // translation happens to cancel it score well. kCentroid draws the same hypotheses in a world
  // moved to the centroid of the scoring points (x' = x - m, t' = t + R m), which leaves the scene's
  // projection nearly in place under rotation samples; kOrigin is the paper's literal form.
  enum class Pivot { kCentroid, kOrigin };
  Pivot pivot = Pivot::kCentroid;
  int rounds = 3;                      // resample around the best with shrinking spread; 1 = the paper's one-shot sampling
  double round_shrink = 0.35;          // spread factor from one round to the next
  // A frame whose best hypothesis is no pose (LostReason) is scored once more with a rotation spread this many
  // times wider (0: no second try). The spread follows the rotation measured in the last frame, so the first
  // frame of a turn (a car entering a bend, a hand-held pan starting) is sampled as if the camera were still
  // going straight: rendered forward seed 10 was lost for good at its bend's first frame, fast seed 5 at frame
  // 9. The second try costs one more scoring, on lost frames only.
  double retry_rot_scale = 4.0;
  // The second try searches a far larger volume with the same hypotheses, so its best can be a wrong pose that
  // a little over half of the points happen to fit loosely (after a gap of 30 frames: 27 of 46 points, 47 cm
  // off, their median residual 2.3 px where the tracker's frames had 0.07). Its winner is first refined by one
  // scoring at the normal spread about it, then kept only when its inliers' median residual is at most
  // retry_max_residual_ratio times the tracker's typical one (the median, over its last tracked frames, of each
  // frame's inlier median), and never above retry_max_residual_fraction of inlier_threshold_px (inliers spread
  // evenly over the threshold's disc, as a chance fit's do, have a median of 0.71 of it). The typical residual
  // counts as at least retry_min_typical_fraction of the threshold, so that a noiseless run's is not a needle's
  // eye. 0 ratio: no check.
  double retry_max_residual_ratio = 3.0;
  double retry_max_residual_fraction = 0.5;
  double retry_min_typical_fraction = 0.1;
  void Check() const;                  // throws std::invalid_argument naming the bad field
  // Why an estimate is no pose; empty when it is one. `inliers`: observations within the threshold (against
  // min_inliers); `scoring_inliers` of the `scored` points (against min_inlier_ratio).
  std::string LostReason(int inliers, int scoring_inliers, int scored) const;
};

// One map point seen in this frame.
struct PointObservation {
  Eigen::Vector3d point_in_world;
  Eigen::Vector2d uv_undistorted_px;  // the tracked feature, undistorted
  bool was_inlier = true;             // inlier in the previous frames: only these take part in the score
};

struct PoseEstimate {
  bool tracked = false;          // false: lost (cam_from_world is then the sampling centre, not an estimate)
  bool keyframe = false;
  Pose cam_from_world;
  int scored = 0;                // points that took part in the score
  int inliers = 0;               // observations with residual under the threshold at the best pose
  double score = 0;              // best summed distance (px)
  double mean_inlier_residual_px = 0;
  double median_inlier_residual_px = 0;
  Eigen::Vector3d sigma_t = Eigen::Vector3d::Zero();  // the translation spread used (m)
  std::string lost_reason;       // why, when not tracked
  bool widened = false;          // tracked at the second try, with the wider rotation spread (retry_rot_scale)
};

// How many of the observations that took part in the score (was_inlier) are flagged in `inliers`.
int ScoringInliers(const std::vector<PointObservation>& obs, const std::vector<uint8_t>& inliers);

class PoseTracker {
 public:
  PoseTracker(const PinholeCamera& camera, const PoseTrackerOptions& options,
              std::unique_ptr<compute::PoseKernel> kernel);

  // Estimates the pose of a frame from the previous pose. `residuals_px` and `inliers` receive one entry
  // per observation (residual at the estimated pose; inlier flag for the next frame). frame_index seeds
  // the fresh random mode. frames_since_prev: how many frames after prev's this one is (> 1 after frames without
  // a pose): the motion from prev to the estimate counts per frame of it in the next frame's spread.
  // min_sigma_rot_deg: a turn the tracks measured since prev, where the tracker has no rate of its own (right
  // after a relocalised frame). Where it is wider than the usual spread, the frame is also sampled at that spread
  // and refined at the usual one about its winner; the lower score of the two searches wins. (Sampled at that
  // spread alone, a turn that is parallax more than rotation, a camera moving fast sideways, coarsened the pose:
  // TUM fr3 at 1 Hz, seeds 1 and 2, 1.6 -> 2.4 and 1.5 -> 2.5 cm.)
  PoseEstimate Track(const Pose& prev_cam_from_world, const std::vector<PointObservation>& observations,
                     uint64_t frame_index, std::vector<double>* residuals_px, std::vector<uint8_t>* inliers,
                     uint64_t frames_since_prev = 1, double min_sigma_rot_deg = 0);

  // Residuals and inlier flags of the observations at a given pose (used for the first frame).
  int ClassifyInliers(const Pose& cam_from_world, const std::vector<PointObservation>& observations,
                      std::vector<double>* residuals_px, std::vector<uint8_t>* inliers) const;

  // The translation the linearised translation-only model predicts, from the scoring points.
  // prior_sigma_m > 0: the zero-mean prior of PoseTrackerOptions::translation_prior_steps with that deviation.
  Eigen::Vector3d LinearisedTranslation(const Pose& prev_cam_from_world,
                                        const std::vector<PointObservation>& observations,
                                        double prior_sigma_m = 0) const;

  // The least translation spread (m), options().sigma_trans_floor_m: a System sets it once the map's scale is
  // known. Throws std::invalid_argument unless > 0.
  void SetTranslationFloor(double sigma_trans_floor_m);

  const PoseTrackerOptions& options() const { return options_; }
  compute::PoseKernel& kernel() { return *kernel_; }
  // Hands the kernel back (a System that starts again builds a new tracker with it); the tracker is unusable after.
  std::unique_ptr<compute::PoseKernel> ReleaseKernel() { return std::move(kernel_); }

 private:
  // One Monte Carlo scoring about prev (pivot m, rotation spread sigma_rot_deg, est->sigma_t): the best
  // hypothesis, its inliers, residuals and score into est. False (and est->lost_reason) when no hypothesis
  // has a finite score.
  bool Score(const Pose& prev, const Eigen::Vector3d& m, double sigma_rot_deg, const std::vector<PointObservation>& obs,
             PoseEstimate* est, std::vector<double>* residuals, std::vector<uint8_t>* inliers);
  // Score at the wide spread about prev, then, where that pose is tracked (est->lost_reason empty), once more at
  // the fine spread about its winner (the winner is one of those hypotheses, so the score can only improve), kept
  // where it does and the pose stays tracked; est->sigma_t stays the wide search's. False when Score is.
  // The translation spread of a search about `about`: sigma_trans_scale times the linearised translation's size
  // per axis, plus the floor.
  Eigen::Vector3d TranslationSpread(const Pose& about, const std::vector<PointObservation>& obs,
                                    double prior_sigma_m) const;
  bool ScoreWideThenFine(const Pose& prev, const Eigen::Vector3d& m, double wide_sigma_rot_deg,
                         double fine_sigma_rot_deg, double prior_sigma_m, const std::vector<PointObservation>& obs,
                         PoseEstimate* est, std::vector<double>* residuals, std::vector<uint8_t>* inliers);

  PinholeCamera camera_;
  PinholeCamera ideal_;  // same intrinsics, no distortion: the observations arrive undistorted
  PoseTrackerOptions options_;
  std::unique_ptr<compute::PoseKernel> kernel_;
  compute::NormalTable table_;
  // Scoring set, structure of arrays; reused across frames (no allocation per frame once warm).
  std::vector<float> sx_, sy_, sz_, su_, sv_;
  // Rotation between the previous pose and the estimate of the last tracked frame, per frame between them (0
  // after a lost one).
  double last_rotation_deg_ = 0;
  // The camera centre's move from the previous pose to the estimate of the last tracked frame, per frame (m).
  double last_step_m_ = 0;
  // The deviation of the linearised translation's prior for a frame (PoseTrackerOptions::translation_prior_steps).
  double TranslationPriorSigma(uint64_t frame_index) const;
  // Median inlier residual (px) of the last tracked frames, oldest first (at most kTypicalFrames).
  static constexpr size_t kTypicalFrames = 20;
  std::vector<double> recent_median_residuals_;
  double TypicalResidualPx();  // their median; 0 when none
  // The most a checked pose's inlier median may be (retry_max_residual_ratio), given TypicalResidualPx().
  double FitLimitPx(double recent) const;
  int64_t last_tracked_index_ = -1;  // frame index of the last frame Track posed
  std::vector<double> scratch_;  // inlier residuals of a scoring, or the recent medians being sorted
};

}  // namespace mcslam::slam
