#include "slam/pose_tracker.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <Eigen/Dense>
#include <fmt/format.h>

#include "core/median.h"

namespace mcslam::slam {

RandomMode ParseRandomMode(const std::string& name) {
  if (name == "table") return RandomMode::kTable;
  if (name == "fresh") return RandomMode::kFresh;
  throw std::invalid_argument(fmt::format("random mode must be 'table' or 'fresh', got '{}'", name));
}

void PoseTrackerOptions::Check() const {
  auto fail = [](const std::string& what) { throw std::invalid_argument("pose tracker: " + what); };
  if (hypotheses < 1) fail(fmt::format("hypotheses must be >= 1, got {}", hypotheses));
  if (!(sigma_rot_deg >= 0)) fail(fmt::format("sigma_rot_deg must be >= 0, got {}", sigma_rot_deg));
  if (!(sigma_rot_motion_scale >= 0) || !std::isfinite(sigma_rot_motion_scale))
    fail(fmt::format("sigma_rot_motion_scale must be >= 0, got {}", sigma_rot_motion_scale));
  if (!(sigma_trans_floor_m > 0)) fail(fmt::format("sigma_trans_floor_m must be > 0, got {}", sigma_trans_floor_m));
  if (!(sigma_trans_scale >= 0)) fail(fmt::format("sigma_trans_scale must be >= 0, got {}", sigma_trans_scale));
  if (!(translation_prior_steps >= 0) || !std::isfinite(translation_prior_steps))
    fail(fmt::format("translation_prior_steps must be >= 0, got {}", translation_prior_steps));
  if (!(inlier_threshold_px > 0)) fail(fmt::format("inlier_threshold_px must be > 0, got {}", inlier_threshold_px));
  // Finite and well inside float range: scores are float sums over up to thousands of points.
  if (!(max_distance_px > 0 && max_distance_px <= 1e6))
    fail(fmt::format("max_distance_px must be in (0, 1e6], got {}", max_distance_px));
  if (min_points < 3) fail(fmt::format("min_points must be >= 3, got {}", min_points));
  if (min_inliers < 3) fail(fmt::format("min_inliers must be >= 3, got {}", min_inliers));
  if (!(min_inlier_ratio >= 0 && min_inlier_ratio <= 1))
    fail(fmt::format("min_inlier_ratio must be in [0, 1], got {}", min_inlier_ratio));
  if (!(keyframe_min_inlier_ratio >= 0 && keyframe_min_inlier_ratio <= 1))
    fail(fmt::format("keyframe_min_inlier_ratio must be in [0, 1], got {}", keyframe_min_inlier_ratio));
  if (rounds < 1 || rounds > 16) fail(fmt::format("rounds must be in [1, 16], got {}", rounds));
  if (rounds > hypotheses) fail(fmt::format("rounds ({}) must not exceed hypotheses ({})", rounds, hypotheses));
  if (!(round_shrink > 0 && round_shrink <= 1)) fail(fmt::format("round_shrink must be in (0, 1], got {}", round_shrink));
  if (!(retry_rot_scale == 0 || (retry_rot_scale > 1 && retry_rot_scale <= 100)))
    fail(fmt::format("retry_rot_scale must be 0 (no retry) or in (1, 100], got {}", retry_rot_scale));
  if (!(retry_max_residual_ratio >= 0 && retry_max_residual_ratio <= 1e3))
    fail(fmt::format("retry_max_residual_ratio must be in [0, 1000], got {}", retry_max_residual_ratio));
  if (!(retry_max_residual_fraction > 0 && retry_max_residual_fraction <= 1))
    fail(fmt::format("retry_max_residual_fraction must be in (0, 1], got {}", retry_max_residual_fraction));
  if (!(retry_min_typical_fraction >= 0 && retry_min_typical_fraction <= 1))
    fail(fmt::format("retry_min_typical_fraction must be in [0, 1], got {}", retry_min_typical_fraction));
}

std::string PoseTrackerOptions::LostReason(int inliers, int scoring_inliers, int scored) const {
  if (inliers < min_inliers) return fmt::format("{} inliers (< {})", inliers, min_inliers);
  if (scoring_inliers < min_inlier_ratio * scored)
    return fmt::format("{} inliers of {} scoring points (< {:.0f} %)", scoring_inliers, scored, 100 * min_inlier_ratio);
  return "";
}

int ScoringInliers(const std::vector<PointObservation>& obs, const std::vector<uint8_t>& inliers) {
  int n = 0;
  for (size_t i = 0; i < obs.size(); ++i) n += obs[i].was_inlier && inliers[i];
  return n;
}

PoseTracker::PoseTracker(const PinholeCamera& camera, const PoseTrackerOptions& options,
                         std::unique_ptr<compute::PoseKernel> kernel)
    : camera_(camera),
      ideal_(camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height),
      options_(options),
      kernel_(std::move(kernel)) {
  camera_.Check();
  options_.Check();
  if (!kernel_) throw std::invalid_argument("pose tracker: no compute kernel");
  table_ = compute::NormalTable(options_.hypotheses, options_.seed, /*stream=*/1);
  recent_median_residuals_.reserve(kTypicalFrames);
}

void PoseTracker::SetTranslationFloor(double sigma_trans_floor_m) {
  if (!(sigma_trans_floor_m > 0))
    throw std::invalid_argument(fmt::format("pose tracker: translation floor must be > 0, got {}", sigma_trans_floor_m));
  options_.sigma_trans_floor_m = sigma_trans_floor_m;
}

int PoseTracker::ClassifyInliers(const Pose& cam_from_world, const std::vector<PointObservation>& obs,
                                 std::vector<double>* residuals, std::vector<uint8_t>* inliers) const {
  residuals->assign(obs.size(), 0.0);
  inliers->assign(obs.size(), 0);
  // Residuals in the ideal pinhole (the observations are undistorted): the same distance the kernel scores.
  int count = 0;
  for (size_t i = 0; i < obs.size(); ++i) {
    Eigen::Vector2d uv;
    double r = std::numeric_limits<double>::infinity();
    if (ideal_.ProjectWorld(cam_from_world, obs[i].point_in_world, &uv)) r = (uv - obs[i].uv_undistorted_px).norm();
    (*residuals)[i] = r;
    (*inliers)[i] = r < options_.inlier_threshold_px;
    count += (*inliers)[i];
  }
  return count;
}

double PoseTracker::TranslationPriorSigma(uint64_t frame_index) const {
  if (!(options_.translation_prior_steps > 0) || last_tracked_index_ < 0) return 0;
  const double frames = static_cast<double>(frame_index) - static_cast<double>(last_tracked_index_);
  return options_.translation_prior_steps * std::max(frames, 1.0) * std::max(last_step_m_, options_.sigma_trans_floor_m);
}

Eigen::Vector3d PoseTracker::LinearisedTranslation(const Pose& prev, const std::vector<PointObservation>& obs,
                                                   double prior_sigma_m) const {
  // Eq. 3, Eq. 4 and Eq. 5: the translation change that moves the projections of the map the way the features
  // moved, least squares over all scoring points (stacked Jacobians, not only the centroid), with a few
  // iteratively reweighted (Huber) passes so that wrong matches do not drag it.
  Eigen::Vector3d dt = Eigen::Vector3d::Zero();
  const double huber = 3.0 * options_.inlier_threshold_px;
  for (int iter = 0; iter < 3; ++iter) {
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    int used = 0;
    for (const PointObservation& o : obs) {
      if (!o.was_inlier) continue;
      Eigen::Vector2d uv;
      Eigen::Matrix<double, 2, 3> Jt;
      if (!ideal_.ProjectWorld(prev, o.point_in_world, &uv, nullptr, &Jt)) continue;
      const Eigen::Vector2d r = o.uv_undistorted_px - uv;
      const double e = (r - Jt * dt).norm();
      const double w = e <= huber ? 1.0 : huber / e;
      A += w * Jt.transpose() * Jt;
      b += w * Jt.transpose() * r;
      ++used;
    }
    if (used < 2) return Eigen::Vector3d::Zero();
    // A tiny ridge keeps the depth direction defined when all points sit at one depth; the prior (1 px of the
    // points' noise against prior_sigma_m of the change) keeps a direction the points leave free near no change.
    A += 1e-9 * A.trace() * Eigen::Matrix3d::Identity();
    if (prior_sigma_m > 0) A += Eigen::Matrix3d::Identity() / (prior_sigma_m * prior_sigma_m);
    dt = A.ldlt().solve(b);
    if (!dt.allFinite()) return Eigen::Vector3d::Zero();
  }
  return dt;
}

bool PoseTracker::Score(const Pose& prev, const Eigen::Vector3d& m, double sigma_rot_deg,
                        const std::vector<PointObservation>& obs, PoseEstimate* est, std::vector<double>* residuals,
                        std::vector<uint8_t>* inliers) {
  // omega is added to all 4 quaternion components; a change dv of the vector part rotates by ~2|dv|.
  const float sigma_q = static_cast<float>(DegToRad(sigma_rot_deg) / 2.0);
  compute::PoseSampling s;
  const Eigen::Quaterniond q0 = prev.q.normalized();
  s.q[0] = static_cast<float>(q0.w()), s.q[1] = static_cast<float>(q0.x());
  s.q[2] = static_cast<float>(q0.y()), s.q[3] = static_cast<float>(q0.z());
  const Eigen::Vector3d t_pivot = prev.t + q0 * m;
  for (int k = 0; k < 3; ++k) s.t[k] = static_cast<float>(t_pivot[k]);
  compute::PoseScoringParams params;
  params.fx = static_cast<float>(camera_.fx);
  params.fy = static_cast<float>(camera_.fy);
  params.max_distance_px = static_cast<float>(options_.max_distance_px);
  const compute::PoseScoringPoints pts{sx_.data(), sy_.data(), sz_.data(), su_.data(), sv_.data(), est->scored};

  const double sigma_q4[4] = {sigma_q, sigma_q, sigma_q, sigma_q};
  const double sigma_t3[3] = {est->sigma_t[0], est->sigma_t[1], est->sigma_t[2]};
  const compute::BestHypothesis best = compute::ScoreInRounds(*kernel_, s, sigma_q4, sigma_t3, pts, params, table_,
                                                              options_.hypotheses, options_.rounds,
                                                              options_.round_shrink);
  if (best.index < 0) {
    est->lost_reason = "no finite hypothesis score";
    residuals->assign(obs.size(), std::numeric_limits<double>::infinity());
    inliers->assign(obs.size(), 0);
    return false;
  }
  const Eigen::Quaterniond q_best(best.q[0], best.q[1], best.q[2], best.q[3]);
  est->cam_from_world = Pose(q_best, Eigen::Vector3d(best.t[0], best.t[1], best.t[2]) - q_best.normalized() * m);
  est->score = best.score;
  est->inliers = ClassifyInliers(est->cam_from_world, obs, residuals, inliers);
  std::vector<double>& in = scratch_;  // no allocation per frame once warm
  in.clear();
  for (size_t i = 0; i < obs.size(); ++i)
    if ((*inliers)[i]) in.push_back((*residuals)[i]);
  double sum = 0;
  for (double r : in) sum += r;
  est->mean_inlier_residual_px = in.empty() ? 0.0 : sum / in.size();
  est->median_inlier_residual_px = UpperMedianInPlace(&in);
  return true;
}

double PoseTracker::FitLimitPx(double recent) const {
  const double threshold = options_.inlier_threshold_px;
  const double typical = std::max(recent, options_.retry_min_typical_fraction * threshold);
  return std::min(options_.retry_max_residual_ratio * typical, options_.retry_max_residual_fraction * threshold);
}

double PoseTracker::TypicalResidualPx() {
  scratch_.assign(recent_median_residuals_.begin(), recent_median_residuals_.end());
  return UpperMedianInPlace(&scratch_);
}

Eigen::Vector3d PoseTracker::TranslationSpread(const Pose& about, const std::vector<PointObservation>& obs,
                                               double prior_sigma_m) const {
  const Eigen::Vector3d dt = LinearisedTranslation(about, obs, prior_sigma_m);
  return (options_.sigma_trans_scale * dt.cwiseAbs()).array() + options_.sigma_trans_floor_m;
}

bool PoseTracker::ScoreWideThenFine(const Pose& prev, const Eigen::Vector3d& m, double wide_sigma_rot_deg,
                                    double fine_sigma_rot_deg, double prior_sigma_m,
                                    const std::vector<PointObservation>& obs, PoseEstimate* est,
                                    std::vector<double>* residuals, std::vector<uint8_t>* inliers) {
  if (!Score(prev, m, wide_sigma_rot_deg, obs, est, residuals, inliers)) return false;
  est->lost_reason = options_.LostReason(est->inliers, ScoringInliers(obs, *inliers), est->scored);
  if (!est->lost_reason.empty()) return true;
  PoseEstimate fine = *est;
  std::vector<double> fine_residuals;
  std::vector<uint8_t> fine_inliers;
  fine.sigma_t = TranslationSpread(est->cam_from_world, obs, prior_sigma_m);
  if (Score(est->cam_from_world, m, fine_sigma_rot_deg, obs, &fine, &fine_residuals, &fine_inliers) &&
      fine.score <= est->score &&
      options_.LostReason(fine.inliers, ScoringInliers(obs, fine_inliers), fine.scored).empty()) {
    fine.sigma_t = est->sigma_t;
    *est = fine;
    *residuals = std::move(fine_residuals);
    *inliers = std::move(fine_inliers);
  }
  return true;
}

PoseEstimate PoseTracker::Track(const Pose& prev, const std::vector<PointObservation>& obs, uint64_t frame_index,
                                std::vector<double>* residuals, std::vector<uint8_t>* inliers,
                                uint64_t frames_since_prev, double min_sigma_rot_deg) {
  PoseEstimate est;
  est.cam_from_world = prev;
  const double recent_rotation_deg = last_rotation_deg_;
  last_rotation_deg_ = 0;  // until this frame is tracked

  // The pivot m (see PoseTrackerOptions::pivot): the scoring points are passed as x - m, the pose as
  // (R, t + R m), and the winner converted back.
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  int n_scoring = 0;
  if (options_.pivot == PoseTrackerOptions::Pivot::kCentroid) {
    for (const PointObservation& o : obs)
      if (o.was_inlier) m += o.point_in_world, ++n_scoring;
    if (n_scoring > 0) m /= n_scoring;
  }
  sx_.clear(), sy_.clear(), sz_.clear(), su_.clear(), sv_.clear();
  for (const PointObservation& o : obs) {
    if (!o.was_inlier) continue;
    sx_.push_back(static_cast<float>(o.point_in_world.x() - m.x()));
    sy_.push_back(static_cast<float>(o.point_in_world.y() - m.y()));
    sz_.push_back(static_cast<float>(o.point_in_world.z() - m.z()));
    su_.push_back(static_cast<float>(o.uv_undistorted_px.x() - camera_.cx));
    sv_.push_back(static_cast<float>(o.uv_undistorted_px.y() - camera_.cy));
  }
  est.scored = static_cast<int>(sx_.size());
  if (est.scored < options_.min_points) {
    est.lost_reason = fmt::format("{} scoring points (< {})", est.scored, options_.min_points);
    residuals->assign(obs.size(), std::numeric_limits<double>::infinity());
    inliers->assign(obs.size(), 0);
    return est;
  }

  const double prior_sigma_m = TranslationPriorSigma(frame_index);
  est.sigma_t = TranslationSpread(prev, obs, prior_sigma_m);
  const double usual_sigma_rot_deg =
      std::max(options_.sigma_rot_deg, options_.sigma_rot_motion_scale * recent_rotation_deg);
  const double sigma_rot_deg = std::max(usual_sigma_rot_deg, min_sigma_rot_deg);  // the second try's base
  if (options_.random == RandomMode::kFresh) table_.Fill(options_.seed, /*stream=*/1, frame_index + 1);
  if (!Score(prev, m, usual_sigma_rot_deg, obs, &est, residuals, inliers)) return est;
  if (min_sigma_rot_deg > usual_sigma_rot_deg) {  // the tracks' turn, searched too (Track's comment)
    PoseEstimate turned = est;
    std::vector<double> turned_residuals;
    std::vector<uint8_t> turned_inliers;
    if (ScoreWideThenFine(prev, m, min_sigma_rot_deg, usual_sigma_rot_deg, prior_sigma_m, obs, &turned,
                          &turned_residuals, &turned_inliers) &&
        turned.lost_reason.empty() && turned.score < est.score) {
      est = turned;
      *residuals = std::move(turned_residuals);
      *inliers = std::move(turned_inliers);
    }
  }
  est.lost_reason = options_.LostReason(est.inliers, ScoringInliers(obs, *inliers), est.scored);
  // After frames the tracker did not pose (skipped, unreadable, lost), the camera may be anywhere: the first try's
  // pose is checked as a second try's is (a pose near the old one that a little over half of the stale tracks
  // fit loosely was taken 50-55 cm off).
  const bool after_gap = last_tracked_index_ >= 0 && frame_index > static_cast<uint64_t>(last_tracked_index_) + 1;
  if (est.lost_reason.empty() && after_gap && options_.retry_max_residual_ratio > 0) {
    const double recent = TypicalResidualPx();
    if (est.median_inlier_residual_px > FitLimitPx(recent))
      est.lost_reason = fmt::format("{} inliers fitting to a median of {:.2f} px after {} frames without a pose, the "
                                    "recent frames to {:.2f} px",
                                    est.inliers, est.median_inlier_residual_px,
                                    frame_index - static_cast<uint64_t>(last_tracked_index_) - 1, recent);
  }
  if (!est.lost_reason.empty() && options_.retry_rot_scale > 0) {
    PoseEstimate wide = est;
    std::vector<double> wide_residuals;
    std::vector<uint8_t> wide_inliers;
    // Refined about the wide winner at the normal spread; then the residual check
    // (PoseTrackerOptions::retry_max_residual_ratio).
    if (ScoreWideThenFine(prev, m, options_.retry_rot_scale * sigma_rot_deg, sigma_rot_deg, prior_sigma_m, obs, &wide,
                          &wide_residuals, &wide_inliers) &&
        wide.lost_reason.empty()) {
      const double recent = TypicalResidualPx();
      if (options_.retry_max_residual_ratio > 0 && wide.median_inlier_residual_px > FitLimitPx(recent)) {
        est.lost_reason += fmt::format(
            "; the {:g}x wider rotation spread found {} inliers fitting to a median of {:.2f} px, the recent frames "
            "to {:.2f} px: refused",
            options_.retry_rot_scale, wide.inliers, wide.median_inlier_residual_px, recent);
      } else {
        est = wide;
        *residuals = std::move(wide_residuals);
        *inliers = std::move(wide_inliers);
        est.widened = true;
      }
    }
  }
  if (!est.lost_reason.empty()) {
    est.cam_from_world = prev;
    return est;
  }
  est.tracked = true;
  last_tracked_index_ = static_cast<int64_t>(frame_index);
  est.keyframe = est.inliers >= options_.keyframe_min_inlier_ratio * est.scored;
  if (!est.widened) {
    if (recent_median_residuals_.size() == kTypicalFrames)
      recent_median_residuals_.erase(recent_median_residuals_.begin());
    recent_median_residuals_.push_back(est.median_inlier_residual_px);
  }
  // Per frame: a pose found after frames without one moved over all of them, and taken as one frame's motion it
  // would widen the next frame's spreads that many times (8 degrees found over 8 frames is a spread of 1 degree,
  // not 8: test_pose_tracker.cc, AMotionOverFramesWithoutAPoseCountsPerFrameInTheNextSpread).
  const double per_frame = 1.0 / static_cast<double>(std::max<uint64_t>(frames_since_prev, 1));
  last_rotation_deg_ = per_frame * AngularDistanceDeg(prev.q, est.cam_from_world.q);
  last_step_m_ = per_frame * (est.cam_from_world.OriginOfTargetInSource() - prev.OriginOfTargetInSource()).norm();
  return est;
}

}  // namespace mcslam::slam
