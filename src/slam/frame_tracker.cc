// Tracking a frame (frame_tracker.h, paper §5): the Monte Carlo pose step (or PnP, the baseline), rotation-only
// tracking when the map leaves the view, and the frame's report.
#include "slam/frame_tracker.h"


#include <algorithm>
#include <chrono>
#include <cmath>
#include <future>
#include <limits>
#include <stdexcept>
#include <system_error>
#include <unordered_map>

#include <Eigen/Dense>
#include <fmt/format.h>

#include "core/median.h"
#include "geometry/bundle_adjust.h"
#include "geometry/pnp.h"
#include "geometry/rotation_only.h"
#include "geometry/triangulation.h"
#include "slam/fibonacci.h"
#include "slam/bridge.h"
#include "slam/mapper.h"
#include "slam/settler.h"
#include "slam/slam_state.h"
#include "slam/system_internal.h"

namespace mcslam::slam {

using detail::Ms;
using detail::NoiseFromMedianResidualPx;
using detail::ParallaxForDepthNoiseDeg;

namespace {

// The angle (degrees) of the rotation that best takes the bearings of the tracks two frames share in `from` onto
// those in `to` (geometry::RobustRotationFromBearings: a few wrong tracks must not make the turn). A camera that
// moved without turning leaves its parallax in it, a small part of a fast turn. 0 with fewer than 6 shared tracks.
double TracksTurnDeg(const FrameRecord& from, const FrameRecord& to, const PinholeCamera& ideal) {
  std::vector<Eigen::Vector3d> in_from, in_to;
  detail::SharedBearings(to, from, ideal, &in_to, &in_from);  // in `to`'s order
  if (in_from.size() < 6) return 0;
  return Eigen::AngleAxisd(geometry::RobustRotationFromBearings(in_from, in_to)).angle() * 180.0 / M_PI;
}

}  // namespace

FrameReport FrameTracker::TrackFrame(int slot, const std::optional<Pose>& pose_hint) {
  FrameReport r;
  FrameRecord& fr = s_.map.frames[slot];
  r.index = fr.index;
  r.stamp_s = fr.stamp_s;
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<PointObservation> obs;
  std::vector<MapPoint*> pts;
  obs.reserve(fr.features.size());
  for (const FeatureUndistorted& f : fr.features) {
    MapPoint* p = s_.map.Find(f.id);
    if (!p || p->state == PointState::kRemoved) continue;
    // In a provisional map the rest of the map is at another scale: it only joins by relocalisation.
    if (!bridge_.AtCurrentScale(f.id)) continue;
    obs.push_back({p->position_in_world, f.uv_px, p->inlier});
    pts.push_back(p);
  }
  std::vector<double> res;
  std::vector<uint8_t> inl;
  const Pose prev = pose_hint ? *pose_hint : s_.map.frames[s_.last_posed_slot].cam_from_world;
  // A hint is this frame's own pose; the last posed frame may lie frames back (lost ones between).
  const uint64_t frames_since_prev =
      pose_hint ? 1 : static_cast<uint64_t>(std::max<int64_t>(fr.index - s_.map.frames[s_.last_posed_slot].index, 1));
  // After relocalisation the inlier flags are those of the last tracked frame, long ago: the points that
  // score are those that agree with the hint instead.
  if (pose_hint) {
    s_.pose_step->ClassifyInliers(*pose_hint, obs, &res, &inl);
    for (size_t i = 0; i < obs.size(); ++i) obs[i].was_inlier = inl[i] != 0;
  }
  // The frame right after a relocalised one: the pose step has no rate of turn of its own (the relocalised pose's
  // rotation from its hint is a correction, not a motion), and the least spread misses a fast turn (rendered
  // fast scenario, seed 2: relocalised at frame 26, then a turn of 12.6 degrees in one frame sampled at 0.5; 8 of
  // 11 points fitted a pose 8 degrees off and the points it made led the next frames 47 degrees astray). The turn
  // the tracks measured from the relocalised frame sets the least spread instead. Not after frames without a
  // pose: across a gap the tracks' turn is no one frame's motion, and a spread that wide found a pose 10 cm off
  // where the second try's checked search finds none (System.RelocalisesAfterAJumpFromMatchesAlone).
  double tracks_turn_deg = 0;
  if (!pose_hint && pose_run_start_slot_ == s_.last_posed_slot && frames_since_prev == 1)
    tracks_turn_deg = TracksTurnDeg(s_.map.frames[s_.last_posed_slot], fr, s_.ideal);
  const PoseEstimate est = s_.options.pose_method == PoseMethod::kPnp
                               ? EstimatePosePnp(obs, &res, &inl)
                               : s_.pose_step->Track(prev, obs, static_cast<uint64_t>(fr.index), &res, &inl,
                                                     frames_since_prev, tracks_turn_deg);
  r.track_ms = Ms(t0);
  r.scored = est.scored;
  r.inliers = est.inliers;
  if (est.widened)
    r.note = fmt::format("tracked with a {:g}x wider rotation spread", s_.options.tracker.retry_rot_scale);
  if (!est.tracked) {
    for (MapPoint* p : pts) p->inlier = true;  // everyone gets another chance in the next frame
    const bool turning = !panorama_bearings_.empty();
    const bool jumped_before = jump_slot_ == slot - 1;
    const int jumps_before = jumped_before ? jump_run_ : 0;
    if (!pose_hint && s_.options.rotation_only && TrackRotationOnly(slot, &r)) {
      r.provisional = bridge_.active();  // a turn in a provisional map: its scale is the provisional one
      r.track_ms = Ms(t0);
      s_.MarkSeen(slot);
      r.map_points = s_.MapPoints();
      return r;
    }
    r.status = FrameStatus::kLost;
    r.note = est.lost_reason + (r.note.empty() ? "" : "; " + r.note);
    const bool turn_kept = jump_slot_ == slot;  // the next frame tells whether the turn goes on
    if (bridge_.active() && !turn_kept) {
      r.note += "; the provisional map is lost, its points leave the map";
      bridge_.Abandon(fr.index);
    }
    // A turn that ended in a move, the map out of view: a bridge over what is not mapped.
    // (A turn whose residual jumped at this frame is still under way: the bridge waits for the next frame to tell.)
    const bool turn_ended = turning && panorama_bearings_.empty();
    const bool last_of_turn = s_.last_posed_slot == slot - 1 - jumps_before;
    if (s_.options.bridge && turn_ended && !pose_hint && !settler_.active() && last_of_turn && bridge_.Start(slot))
      r.note += fmt::format("; a provisional map will be made from frame {}", bridge_.anchor_index());
    s_.MarkSeen(slot);
    r.map_points = s_.MapPoints();
    return r;
  }
  for (size_t i = 0; i < pts.size(); ++i) pts[i]->inlier = inl[i] != 0;
  // A pose from fewer points than a turn needs tracks: the turn, when the tracks agree on one
  // (SystemOptions::rotation_only_over_weak_pose).
  const std::string pose_note = r.note;  // a turn refused says why in r.note: the pose step's frame keeps its own
  if (!pose_hint && !bridge_.active() && s_.options.rotation_only && s_.options.rotation_only_over_weak_pose &&
      est.inliers < s_.options.rotation_only_min_tracks && TrackRotationOnly(slot, &r, /*over_pose=*/true)) {
    r.track_ms = Ms(t0);
    s_.MarkSeen(slot);
    r.map_points = s_.MapPoints();
    return r;
  }
  r.note = pose_note;
  r.score = est.score;
  r.sigma_t = est.sigma_t;
  fr.has_pose = true;
  fr.cam_from_world = est.cam_from_world;
  fr.pose_inliers = est.inliers;
  s_.last_posed_slot = slot;
  if (pose_hint) pose_run_start_slot_ = slot;
  panorama_bearings_.clear();  // the pose step has points again: a later turn starts afresh
  r.status = FrameStatus::kTracked;
  r.has_pose = true;
  r.provisional = bridge_.active();
  r.cam_from_world = est.cam_from_world;
  // A relocalised pose may be far from where the smoother's state is: it starts again there.
  if (pose_hint) s_.smoother.Reset();
  r.smoothed_cam_from_world = s_.smoother.Update(est.cam_from_world);
  if (est.keyframe) mapper_.MapKeyframe(slot, est.inliers, &r);
  s_.MarkSeen(slot);
  s_.ResidualStats(slot, &r);
  r.map_points = s_.MapPoints();
  return r;
}

bool FrameTracker::TrackRotationOnly(int slot, FrameReport* r, bool over_pose) {
  // Only right after a posed frame: its centre is where the camera still is if it only turned (or after the
  // frames of a turn under way whose residual jumped, below).
  const bool after_jump =
      jump_slot_ == slot - 1 && !panorama_bearings_.empty() && s_.last_posed_slot == slot - 1 - jump_run_;
  const int jumps_before = after_jump ? jump_run_ : 0;
  jump_slot_ = -1;
  jump_run_ = 0;
  if ((s_.last_posed_slot != slot - 1 && !after_jump) || s_.last_posed_slot < 0) {
    panorama_bearings_.clear();
    return false;
  }
  auto bearing = [&](const FeatureUndistorted& f) {
    return Eigen::Vector3d(s_.ideal.PixelToNormalized(f.uv_px).homogeneous().normalized());
  };
  if (panorama_bearings_.empty()) {  // a new turn starts from the last posed frame
    const FrameRecord& prev = s_.map.frames[s_.last_posed_slot];
    // The centre: that of the latest frame of the tracked run before whose pose at least half as many points
    // agreed as at the best of the run's recent frames. The last frames before the map left the view hold few
    // points, all at one edge of the image, and their centres wander (rotation scenario, seed 6: 6.2 cm off with
    // 23 inliers, 0.9 cm two frames earlier with 45; the run's best had 77).
    int first = s_.last_posed_slot, most = 0;
    while (first - 1 >= pose_run_start_slot_ && first - 1 > s_.last_posed_slot - kPanoramaCentreLookback &&
           s_.map.frames[first - 1].has_pose)
      --first;
    for (int s = first; s <= s_.last_posed_slot; ++s) most = std::max(most, s_.map.frames[s].pose_inliers);
    panorama_centre_ = prev.cam_from_world.OriginOfTargetInSource();
    for (int s = s_.last_posed_slot; s >= first; --s)
      if (2 * s_.map.frames[s].pose_inliers >= most && s_.map.frames[s].pose_inliers > 0) {
        panorama_centre_ = s_.map.frames[s].cam_from_world.OriginOfTargetInSource();
        break;
      }
    panorama_bearings_.clear();
    const Eigen::Quaterniond world_from_cam = prev.cam_from_world.q.conjugate();
    for (const FeatureUndistorted& f : prev.features) panorama_bearings_[f.id] = world_from_cam * bearing(f);
    panorama_min_rms_px_ = std::numeric_limits<double>::infinity();
    panorama_rms_px_.clear();
  }
  FrameRecord& fr = s_.map.frames[slot];
  std::vector<Eigen::Vector3d> in_world, in_cam;
  for (const FeatureUndistorted& f : fr.features)
    if (auto it = panorama_bearings_.find(f.id); it != panorama_bearings_.end())
      in_world.push_back(it->second), in_cam.push_back(bearing(f));
  geometry::RotationOnlyOptions ro;
  // Agreement within the tracks' noise: 3 σ of the difference of two noisy positions (σ √2 per coordinate),
  // σ as the map's recent residuals measure it; never over the pose step's inlier threshold, never under half a
  // pixel (a camera that moves shows as parallax that grows frame after frame, so the bound needs no more).
  const double noise_px = mapper_.RecentNoisePx().value_or(s_.options.tracker.inlier_threshold_px);
  ro.threshold_px = std::clamp(3.0 * std::sqrt(2.0) * noise_px, 0.5, s_.options.tracker.inlier_threshold_px);
  ro.focal_px = s_.focal_px;
  ro.min_inliers = s_.options.rotation_only_min_tracks;
  ro.seed = s_.options.seed ^ (static_cast<uint64_t>(fr.index) * 0x9E3779B97F4A7C15ull);
  const geometry::RotationOnlyResult rot = geometry::EstimateRotationOnly(in_world, in_cam, ro);
  const double ratio = in_world.empty() ? 0.0 : static_cast<double>(rot.inliers) / in_world.size();
  // A camera that starts to move again while the turn goes on shows first as a residual that grows: the rotation
  // absorbs most of a sideways move, the depths' spread does not. The frames of a pure turn measure the tracks'
  // noise (the least rms so far); an rms beyond 3 standard errors of it (sqrt(2 n) inliers' worth) is a move.
  // Rotation scenario, 0.5 px noise: 0.95-1.03 px while turning, 1.14 px 2.7 cm into the move. Below a quarter
  // pixel (a KLT tracker's precision on real images) the rms is the images' own (texture, interpolation), not
  // Gaussian noise, and wanders more than that: rendered, 0.08-0.12 px while turning, 0.39 px 1 cm into the move.
  const double noise_rms = std::max(panorama_min_rms_px_, 0.25);
  bool moved = rot.ok && std::isfinite(panorama_min_rms_px_) &&
               rot.rms_px > noise_rms * (1.0 + 3.0 / std::sqrt(2.0 * rot.inliers));
  // Over a pose the pose step found, the turn must fit from its first frame: within the difference of two of the
  // tracks' noisy positions (sqrt 2 sigma), never under the quarter pixel above. A slow move that a turn absorbs
  // shows above it (rotation scenario, seed 8: 0.38-0.68 px a few frames into a move, 0.06-0.12 while turning).
  // And nearly every track must agree: in the rotation scenario's turns at least 96.9 % did; a map whose residuals
  // are large (sigma ~1 px) lets a wide threshold pass 70-90 % of the tracks of a camera that moves (sparse
  // scenario at 640x480, seed 3: nine such frames took the centre 30 cm off and the run was lost for good).
  constexpr double kOverPoseMinRatio = 0.95;
  if (over_pose && rot.ok &&
      (rot.rms_px > std::max(0.25, std::sqrt(2.0) * mapper_.RecentNoisePx().value_or(0.0)) || ratio < kOverPoseMinRatio))
    moved = true;
  // One frame whose residual jumps is not yet a move: a move only grows (the tracks' bearings drift further from
  // the turn's with every frame of it), while a turn under way through noisy images sees single frames jump and fall
  // back. Rotation scenario rendered with noise of 6 grey levels: seed 3's turn, frames 110-120, ended at frame 111
  // on 0.46 px against 0.32 with the camera still turning; the provisional map from frame 110 found only the turn
  // (a homography explained its tracks) until the turn had swept most of them out of view, and frames 111-190 were
  // lost. Such a frame is lost but the turn is kept; the next frame either turns on (about the same centre, its
  // residual back within the bound) or confirms the move, and the turn ends there as it would have a frame earlier.
  // A blurred frame (the front end measured its patches less sharp: a shake) tells nothing of a move either: its
  // corners lie off where the sharp frames see them. So a frame after a jump that jumps too is kept over when it is
  // blurred, and the first sharp frame tells (rotation scenario with exposure steps and two of every ten frames
  // blurred, seed 8: the second blurred frame of a pair ended the turn, the provisional map under it was lost and
  // the rest of the run took the old map's scale, 5.6 % of the path).
  if (s_.options.rotation_only_keep_turn_over_a_jump && moved && !over_pose && (!after_jump || fr.blurred) &&
      rot.ok && ratio >= s_.options.rotation_only_min_ratio) {
    r->note = fmt::format("no turn about the last centre: the tracks' residual jumped to {:.2f} px from {:.2f} (the "
                          "next {}frame tells a move from noise)", rot.rms_px, panorama_min_rms_px_,
                          fr.blurred ? "sharp " : "");
    jump_slot_ = slot;
    jump_run_ = jumps_before + 1;
    return false;
  }
  if (!rot.ok || ratio < s_.options.rotation_only_min_ratio || moved) {
    r->note = !rot.ok ? fmt::format("no turn about the last centre: {}", rot.failure)
              : moved ? fmt::format("no turn about the last centre: the tracks' residual grew to {:.2f} px from {:.2f} "
                                    "(the camera moves)", rot.rms_px, panorama_min_rms_px_)
                      : fmt::format("no turn about the last centre: {} of {} tracks agree on one", rot.inliers,
                                    in_world.size());
    panorama_bearings_.clear();
    return false;
  }
  // Only when the frame sees few map points: had the turn kept tracked map points in the image, the pose step
  // failed for another reason (a jolt, wrong tracks), and a turn would hide it (fast scenario, seed 3: a frame
  // posed so, 22 of 30 tracks agreeing, sent what followed 0.7 m astray). Map points that would project into the
  // image but whose tracks ended do not count: the front end has not found them again, and they kept the turn
  // from being followed while the map left the view (rotation scenario, seed 2: 22 such points, the map lost for
  // the rest of the turn). In a provisional map, only its own points count: the rest is at another scale.
  const Eigen::Quaterniond q(rot.cam_from_ref);
  const Pose turned(q, -(q * panorama_centre_));
  int in_view = 0;
  for (const FeatureUndistorted& f : fr.features)
    if (const MapPoint* p = s_.map.Find(f.id); p && p->state != PointState::kRemoved && bridge_.AtCurrentScale(f.id)) {
      Eigen::Vector2d uv;
      in_view += s_.ideal.ProjectWorld(turned, p->position_in_world, &uv) && s_.ideal.InImage(uv);
    }
  if (in_view >= s_.options.rotation_only_min_tracks) {
    r->note = fmt::format("no turn about the last centre: {} tracked map points in view", in_view);
    panorama_bearings_.clear();
    return false;
  }
  panorama_min_rms_px_ = std::min(panorama_min_rms_px_, rot.rms_px);
  panorama_rms_px_.emplace_back(slot, rot.rms_px);
  fr.has_pose = true;
  fr.cam_from_world = turned;
  s_.last_posed_slot = slot;
  // Tracks born during the turn join the panorama as seen from here.
  const Eigen::Quaterniond world_from_cam = q.conjugate();
  for (const FeatureUndistorted& f : fr.features) panorama_bearings_.try_emplace(f.id, world_from_cam * bearing(f));
  r->status = FrameStatus::kTracked;
  r->has_pose = true;
  r->rotation_only = true;
  r->cam_from_world = fr.cam_from_world;
  r->smoothed_cam_from_world = s_.smoother.Update(fr.cam_from_world);
  r->note = fmt::format("rotation only: the map is out of view; {} of {} tracks agree on a turn about the last "
                        "centre ({:.2f} px rms)",
                        rot.inliers, in_world.size(), rot.rms_px);
  s_.ResidualStats(slot, r);
  return true;
}

PoseEstimate FrameTracker::EstimatePosePnp(const std::vector<PointObservation>& obs, std::vector<double>* res,
                                     std::vector<uint8_t>* inl) const {
  // The pose baseline (§8): RANSAC EPnP on every observed map point, refined by Levenberg-Marquardt on the
  // inliers; inliers and keyframes decided as for the Monte Carlo estimate.
  PoseEstimate est;
  std::vector<Eigen::Vector3d> P;
  std::vector<Eigen::Vector2d> uv;
  for (const PointObservation& o : obs) P.push_back(o.point_in_world), uv.push_back(s_.ideal.PixelToNormalized(o.uv_undistorted_px));
  // Scored as in the Monte Carlo estimate: the points that were inliers at the last pose (the keyframe rule
  // compares the inliers with these; counting every observed point made PnP stop making keyframes).
  est.scored = static_cast<int>(
      std::count_if(obs.begin(), obs.end(), [](const PointObservation& o) { return o.was_inlier; }));
  const std::optional<Pose> pose = geometry::SolvePnp(P, uv, s_.TrackerPnpOptions(s_.options.tracker.min_inliers));
  res->assign(obs.size(), std::numeric_limits<double>::infinity());
  inl->assign(obs.size(), 0);
  if (!pose) {
    est.lost_reason = fmt::format("PnP failed on {} points", P.size());
    return est;
  }
  est.cam_from_world = *pose;
  est.inliers = s_.pose_step->ClassifyInliers(*pose, obs, res, inl);
  if (est.lost_reason = s_.options.tracker.LostReason(est.inliers, ScoringInliers(obs, *inl), est.scored);
      !est.lost_reason.empty())
    return est;
  est.tracked = true;
  est.keyframe = est.inliers >= s_.options.tracker.keyframe_min_inlier_ratio * est.scored;
  return est;
}

}  // namespace mcslam::slam
