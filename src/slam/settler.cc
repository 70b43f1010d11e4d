// The settling of a new map (settler.h; after the initialisation, paper §6.1): the window since the reference
// frame adjusted together while the parallax grows, the depth-reversal test made again over it, and the lens'
// self-calibration when it has settled.
#include "slam/settler.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <unordered_map>

#include <Eigen/Dense>
#include <fmt/format.h>
#include <tbb/parallel_invoke.h>

#include "core/median.h"
#include "geometry/bundle_adjust.h"
#include "geometry/self_calibration.h"
#include "slam/initializer.h"
#include "slam/system_internal.h"

namespace mcslam::slam {

bool SelfCalibrationIsTaken(const SelfCalibration& c, const InitOptions& io) {
  // At calibration_min_half_share 0 only the halves' direction is tested (no bound on their size).
  return std::isfinite(c.z) && std::isfinite(c.corner_shift_px) && c.z >= io.calibration_min_z &&
         c.corner_shift_px >= io.calibration_min_shift_px && c.min_half_share >= io.calibration_min_half_share &&
         c.max_half_share * io.calibration_min_half_share <= 1.0 && c.min_half_z >= io.calibration_min_half_z;
}

using detail::CappedMeanSquarePx2;
using detail::EvenlySpread;
using detail::kCostFloorPx2;
using detail::MirrorInDepth;

namespace {

// Per point (of `points`), its observations in the window's frames that `among` maps to a position (>= 0).
std::vector<int> ViewsAmong(const std::vector<geometry::BundleObservation>& obs, size_t points,
                            const std::vector<int>& among) {
  std::vector<int> views(points, 0);
  for (const geometry::BundleObservation& o : obs)
    views[static_cast<size_t>(o.point)] += among[static_cast<size_t>(o.camera)] >= 0;
  return views;
}

}  // namespace

void Settler::BeginSettling(int init_slot, double baseline, double two_view_parallax_deg, int min_points) {
  init_slot_ = init_slot;
  init_baseline_ = baseline;
  init_min_points_ = min_points;
  settling_ = s_.options.init.settle_parallax_deg > 0;
  mirror_lead_ = 0;  // a lead found while an earlier map settled says nothing about this one
  next_settle_parallax_deg_ = s_.options.init.settle_step * std::max(two_view_parallax_deg, 1e-3);
}

double Settler::ParallaxFromReference(int slot) const {
  const FrameRecord& ref = s_.map.frames[s_.reference_slot];
  const FrameRecord& cur = s_.map.frames[slot];
  const Pose pair[2] = {ref.cam_from_world, cur.cam_from_world};
  std::vector<double> parallax;
  for (const FeatureUndistorted& f : cur.features) {
    const MapPoint* p = s_.map.Find(f.id);
    if (!p || p->state == PointState::kRemoved || !ref.Find(f.id)) continue;
    parallax.push_back(geometry::ParallaxDeg(pair, p->position_in_world));
  }
  // Too few points shared with the reference to say: the view has moved on, as far as the start can tell.
  if (parallax.size() < static_cast<size_t>(init_min_points_)) return std::numeric_limits<double>::infinity();
  return UpperMedian(parallax);
}

void Settler::Settle(int slot, std::vector<FrameReport>* out) {
  const InitOptions& io = s_.options.init;
  const double parallax = ParallaxFromReference(slot);
  const bool last = parallax >= io.settle_parallax_deg;  // the settling's last step: it has settled
  // Posed frames since the reference (at most settle_max_frames, evenly spread, with the reference, the
  // initialisation's frame and this one), and every map point seen at least twice among them.
  std::vector<int> posed;
  for (int s = s_.reference_slot; s <= slot; ++s)
    if (s_.map.frames[s].has_pose) posed.push_back(s);
  std::vector<int> window;
  for (int i : EvenlySpread(static_cast<int>(posed.size()), io.settle_max_frames)) window.push_back(posed[i]);
  if (std::find(window.begin(), window.end(), init_slot_) == window.end()) window.push_back(init_slot_);
  std::sort(window.begin(), window.end());
  window.erase(std::unique(window.begin(), window.end()), window.end());
  std::vector<Pose> cams;
  for (int s : window) cams.push_back(s_.map.frames[s].cam_from_world);
  WindowPoints wp = s_.CollectWindowPoints(window);
  std::vector<bool> fixed(window.size(), false);
  fixed.front() = true;  // the reference camera is the world
  geometry::BundleAdjustOptions bo;
  bo.focal_px = s_.focal_px;
  bo.huber_px = io.refine_huber_px;
  bo.cauchy = true;  // tens of frames of tracks hold wrong matches: their pull must fade
  // One thread: Ceres' multi-threaded Schur elimination sums in a varying order, and the same seed must give
  // the same trajectory.
  // Tens to 120 cameras that all see the same few hundred points: the Schur complement is not formed
  // (BundleAdjustOptions::LinearSolver::kIterativeSchur; 7-Scenes' four settling steps of 54-114 frames 5.8 -> 3.1 s
  // against the dense Schur complement, the trajectory the same to 1e-7 m).
  bo.linear_solver = geometry::BundleAdjustOptions::LinearSolver::kIterativeSchur;
  geometry::BundleAdjust(cams, wp.X, wp.obs, fixed, bo);
  std::string reversal;
  if (FlipIfMirrored(window, last, &cams, &wp, &reversal))
    geometry::BundleAdjust(cams, wp.X, wp.obs, fixed, bo);
  // (The radial-tangential k1 only: a fisheye's equidistant model is kept as given, its calibration being part of
  // any fisheye's setup.)
  if (last && io.self_calibrate && !s_.camera.dist.IsFisheye() &&
      !self_calibration_.tried && SelfCalibrate(window, cams, wp, slot)) {
    // The features undistorted again with the refined camera (the same points, in the same order), adjusted again.
    std::vector<Eigen::Vector3d> adjusted = std::move(wp.X);
    wp = s_.CollectWindowPoints(window);
    wp.X = std::move(adjusted);
    geometry::BundleAdjust(cams, wp.X, wp.obs, fixed, bo);
  }
  std::vector<Eigen::Vector3d>& X = wp.X;
  // The scale: the initialisation's baseline keeps its length (1, or the ground truth's with --gt-scale).
  const auto init_it = std::find(window.begin(), window.end(), init_slot_);
  const double b = init_it == window.end()
                       ? 0.0
                       : (cams[init_it - window.begin()].OriginOfTargetInSource() - cams.front().OriginOfTargetInSource()).norm();
  const double s = b > 1e-12 ? init_baseline_ / b : 1.0;
  // Scaled about the reference camera's centre, which stays where it is: the world's origin after the
  // initialisation (the expressions below are then exactly t * s and x * s), the anchor's centre in a provisional
  // map (SystemOptions::bridge). A camera x_c = q X + t seeing the world scaled about c0 sees x_c * s.
  const Eigen::Vector3d c0 = cams.front().OriginOfTargetInSource();
  for (Pose& c : cams) c.t = s * c.t + (s - 1.0) * (c.q * c0);
  for (Eigen::Vector3d& x : X) x = c0 + s * (x - c0);
  std::unordered_map<int, Pose> moved_by;  // window slot -> new * old^-1
  for (size_t w = 0; w < window.size(); ++w) {
    moved_by[window[w]] = cams[w] * s_.map.frames[window[w]].cam_from_world.Inverse();
    s_.map.frames[window[w]].cam_from_world = cams[w];
  }
  const FrameRecord& cur = s_.map.frames[slot];
  s_.StoreAdjustedPoints(cams, wp, cur.index);
  s_.RefreshInlierFlags(slot);  // at the moved current pose
  // The posed frames left out of the adjustment, and those before the reference: each placed again against
  // the adjusted points (PnP from the points it sees; for a frame before the reference, with the agreement it
  // was first placed with, and following the frame after it, which is placed first: Initializer::FollowsFrom), or
  // else moved with its neighbour in the window: for a frame before the reference, which stays the world, only
  // the scale changes.
  std::vector<int> left_out;
  for (int k = s_.reference_slot - 1; k >= s_.posed_from; --k) left_out.push_back(k);
  for (int k : posed)
    if (!std::binary_search(window.begin(), window.end(), k)) left_out.push_back(k);
  for (int k : left_out) {
    FrameRecord& f = s_.map.frames[k];
    const bool before_reference = k < s_.reference_slot;
    const std::optional<Pose> pose =
        s_.PlaceByPnp(k, s_.options.tracker.min_inliers, before_reference ? s_.options.tracker.min_inlier_ratio : 0.0);
    if (pose && (!before_reference || init_.FollowsFrom(k, *pose, k + 1))) {
      f.cam_from_world = *pose;
    } else if (before_reference) {
      f.cam_from_world.t *= s;
    } else {
      f.cam_from_world = moved_by[*(std::upper_bound(window.begin(), window.end(), k) - 1)] * f.cam_from_world;
    }
  }
  std::string note = fmt::format(
      "{}: {} of {} frames and {} points refined together {}",
      last ? "settled" : "settling", window.size(), posed.size(), wp.pts.size(),
      std::isfinite(parallax) ? fmt::format("at a median parallax of {:.1f} deg", parallax)
                              : fmt::format("as the view moved on (fewer than {} of the reference's points in view)",
                                            init_min_points_));
  if (self_calibration_.tried && self_calibration_.frame == cur.index) {
    note += "; " + self_calibration_.note;
    out->front().self_calibration = true;
  }
  if (!reversal.empty()) {
    note += "; " + reversal;
    out->front().depth_reversed = true;
  }
  settling_ = parallax < io.settle_parallax_deg;
  next_settle_parallax_deg_ = std::min(parallax * io.settle_step, io.settle_parallax_deg);
  out->front().cam_from_world = cur.cam_from_world;
  // A flipped map moved every pose far from where the smoother's state is (the 640x480 rotation seed 1: the
  // frame's smoothed pose 7 deg from its flipped one, the next 2 deg): it starts again there, as after a
  // relocalisation.
  if (!reversal.empty()) s_.smoother.Reset(), out->front().smoothed_cam_from_world = s_.smoother.Update(cur.cam_from_world);
  out->front().note = note;
  s_.ResidualStats(slot, &out->front());
  for (int k = s_.posed_from; k <= slot; ++k) {
    if (k == slot || !s_.map.frames[k].has_pose) continue;
    FrameReport r = s_.PosedReport(k);
    r.pose_update = true;
    out->push_back(r);
  }
}

namespace {

// The pixel at which `camera` sees the ray through undistorted normalised coordinates n (distortion applied).
Eigen::Vector2d SeenPixel(const PinholeCamera& camera, const Eigen::Vector2d& n) {
  return camera.NormalizedToPixel(camera.HasDistortion() ? camera.Distort(n) : n);
}

// The pixel that `to` undistorts a feature to, when `from` undistorted it to uv_px (same K, other distortion).
Eigen::Vector2d Reundistort(const PinholeCamera& from, const PinholeCamera& to, const Eigen::Vector2d& uv_px) {
  return to.UndistortPixel(SeenPixel(from, from.PixelToNormalized(uv_px)));
}

}  // namespace

bool Settler::SelfCalibrate(const std::vector<int>& window, const std::vector<Pose>& cams, const WindowPoints& wp,
                           int slot) {
  const InitOptions& io = s_.options.init;
  SelfCalibration& c = self_calibration_;
  c.tried = true;
  c.frame = s_.map.frames[slot].index;
  c.k1_given = c.k1_measured = s_.camera.dist.k1;
  // At most kCalibrationFrames of the window, evenly spread (its first frame, the reference, among them): the
  // adjustment's cost grows with the observations, and neighbouring frames of the same tracks add little.
  std::vector<int> camera_of(window.size(), -1);  // window position -> calibration camera
  std::vector<Pose> sub_cams;
  std::vector<bool> fixed;
  for (int w : EvenlySpread(static_cast<int>(window.size()), kCalibrationFrames)) {
    camera_of[w] = static_cast<int>(sub_cams.size());
    sub_cams.push_back(cams[w]);
    fixed.push_back(sub_cams.size() <= 2);  // the gauge and the scale: the first two frames taken
  }
  // Points seen at least twice among them, and their observations as the camera saw them (distorted pixels).
  const std::vector<int> seen = ViewsAmong(wp.obs, wp.X.size(), camera_of);
  std::vector<int> point_of(wp.X.size(), -1);
  std::vector<Eigen::Vector3d> X;
  std::vector<geometry::PixelObservation> obs;
  for (const geometry::BundleObservation& o : wp.obs) {
    if (camera_of[o.camera] < 0 || seen[o.point] < 2) continue;
    if (point_of[o.point] < 0) point_of[o.point] = static_cast<int>(X.size()), X.push_back(wp.X[o.point]);
    obs.push_back({camera_of[o.camera], point_of[o.point], SeenPixel(s_.camera, o.uv_norm)});
  }
  geometry::IntrinsicsOptions co;
  co.loss_px = io.refine_huber_px;
  co.free_focal = false;
  co.num_threads = 1;  // the same seed, the same result
  // The same fit on each half of the points (alternate ones): a lens bends every point's ray alike, so both
  // halves measure the same k1; a k1 that only absorbs the errors of some tracks does not repeat
  // (InitOptions::calibration_min_half_share).
  std::vector<Eigen::Vector3d> X_half[2];
  std::vector<geometry::PixelObservation> obs_half[2];
  for (int half = 0; half < 2; ++half) {
    std::vector<int> point_in_half(X.size(), -1);
    for (const geometry::PixelObservation& o : obs) {
      if (o.point % 2 != half) continue;
      if (point_in_half[o.point] < 0) {
        point_in_half[o.point] = static_cast<int>(X_half[half].size());
        X_half[half].push_back(X[o.point]);
      }
      obs_half[half].push_back({o.camera, point_in_half[o.point], o.uv_px});
    }
  }
  // The three fits are independent and single-threaded: run side by side (KITTI 06: 210 ms one after the other).
  geometry::IntrinsicsFit fit, fit_half[2];
  tbb::parallel_invoke([&] { fit = geometry::RefineIntrinsics(s_.camera, sub_cams, X, obs, fixed, co); },
                       [&] { fit_half[0] = geometry::RefineIntrinsics(s_.camera, sub_cams, X_half[0], obs_half[0], fixed, co); },
                       [&] { fit_half[1] = geometry::RefineIntrinsics(s_.camera, sub_cams, X_half[1], obs_half[1], fixed, co); });
  for (int half = 0; half < 2; ++half) {
    c.k1_half[half] = fit_half[half].camera.dist.k1;
    c.sigma_k1_half[half] = fit_half[half].sigma_k1;
  }
  c.min_half_z = std::sqrt(std::min(fit_half[0].chi2, fit_half[1].chi2));
  c.frames = static_cast<int>(sub_cams.size());
  c.points = static_cast<int>(X.size());
  c.observations = fit.observations;
  c.k1_measured = fit.camera.dist.k1;
  c.sigma_k1 = fit.sigma_k1;
  c.z = std::sqrt(fit.chi2);
  const double change = c.k1_measured - c.k1_given;
  auto share = [&](int half) { return change == 0 ? 0.0 : (c.k1_half[half] - c.k1_given) / change; };
  c.min_half_share = std::min(share(0), share(1));
  c.max_half_share = std::max(share(0), share(1));
  c.corner_shift_px = 0;
  for (const Eigen::Vector2d& corner : {Eigen::Vector2d(0, 0), Eigen::Vector2d(s_.camera.width - 1, 0),
                                       Eigen::Vector2d(0, s_.camera.height - 1),
                                       Eigen::Vector2d(s_.camera.width - 1, s_.camera.height - 1)})
    c.corner_shift_px = std::max(c.corner_shift_px, (fit.camera.UndistortPixel(corner) - s_.camera.UndistortPixel(corner)).norm());
  c.accepted = SelfCalibrationIsTaken(c, io);
  c.note = fmt::format("lens distortion k1 {} from {} frames, {} points: {:.4f} +- {:.4f} ({:.1f} sigma, {:.1f} px at "
                       "the farthest corner; halves of the points {:.4f} +- {:.4f} and {:.4f} +- {:.4f}, the "
                       "smaller {:.2f} and the larger {:.2f} of the change, the weaker at {:.1f} sigma): {}",
                       c.accepted ? "self-calibrated" : "checked", c.frames, c.points, c.k1_measured, c.sigma_k1, c.z,
                       c.corner_shift_px, c.k1_half[0], c.sigma_k1_half[0], c.k1_half[1], c.sigma_k1_half[1], c.min_half_share,
                       c.max_half_share, c.min_half_z,
                       c.accepted ? fmt::format("k1 {:g} -> {:.4f}", c.k1_given, c.k1_measured)
                                  : fmt::format("k1 {:g} kept", c.k1_given));
  if (!c.accepted) return false;
  const PinholeCamera given = s_.camera;
  s_.camera.dist.k1 = c.k1_measured;
  for (FrameRecord& f : s_.map.frames)
    for (FeatureUndistorted& u : f.features) u.uv_px = Reundistort(given, s_.camera, u.uv_px);
  return true;
}

bool Settler::FlipIfMirrored(const std::vector<int>& window, bool last, std::vector<Pose>* cams, WindowPoints* wp,
                            std::string* why) {
  // A window of two views is explained about as well by the scene's mirror in depth, and one that turns more than
  // it moves (a pan, then the first steps) may even be explained a little better by the mirror: the tracks'
  // errors are correlated along each track, and the test at the initialisation counts every observation as
  // independent (rendered rotation scenario at 640x480, seed 1: the mirror won frames 3-41 by a chi-square of 51
  // and the run was lost from frame 129 on with its orientations 126 deg off). The frames after it tell: three
  // frames later the map as it was explained the settling window with a mean squared residual of 0.041 px^2 and
  // its mirror with 0.019, twenty frames later 0.77 against 0.041.
  if (window.size() < 3 || wp->pts.size() < 3) return false;
  const Pose ref = cams->front();  // cam_from_world of the window's first camera (a copy: cams is rewritten)
  // Judged on at most kFlipCheckFrames of the window, evenly spread (its first and last among them), and the
  // points seen at least twice there: the whole settling window (up to 120 frames) took seconds a test on 7-Scenes.
  std::vector<int> sub;
  std::vector<int> sub_of(window.size(), -1);  // window position -> position among those judged
  for (int w : EvenlySpread(static_cast<int>(window.size()), kFlipCheckFrames))
    sub_of[w] = static_cast<int>(sub.size()), sub.push_back(window[w]);
  const std::vector<int> views = ViewsAmong(wp->obs, wp->X.size(), sub_of);
  std::vector<Eigen::Vector3d> in_ref, sub_in_ref;
  std::vector<int64_t> ids, sub_ids;
  for (size_t i = 0; i < wp->pts.size(); ++i) {
    in_ref.push_back(ref * wp->X[i]), ids.push_back(wp->pts[i]->id);
    if (views[i] >= 2) sub_in_ref.push_back(in_ref.back()), sub_ids.push_back(ids.back());
  }
  if (sub_ids.size() < 3) return false;
  // The map and its mirror placed and refined side by side: two independent single-threaded fits (KITTI 06's
  // 17-frame settling window: 90 and 200 ms one after the other).
  std::optional<Initializer::InitHypothesis> as_is, sub_mirror;
  const std::vector<Eigen::Vector3d> sub_mirrored = MirrorInDepth(sub_in_ref);
  tbb::parallel_invoke(
      [&] { as_is = init_.RefineInitWindow(sub, std::nullopt, sub_in_ref, sub_ids, nullptr, false); },
      [&] { sub_mirror = init_.RefineInitWindow(sub, std::nullopt, sub_mirrored, sub_ids, nullptr, false); });
  if (!as_is || !sub_mirror) return false;
  // The map as it is needs no new placement: the settling's adjustment has just fitted it to the whole window, and
  // its cost over the frames judged is a fit the placement from scratch may miss (PnP through 10 % outliers and a
  // descent from there: 2.98 px^2 on the noisy paper scenario's first 16 frames, where the adjusted map fits them at
  // 2.79). The lower of the two is the map's fit.
  std::vector<double> settled;
  for (const geometry::BundleObservation& o : wp->obs)
    if (sub_of[static_cast<size_t>(o.camera)] >= 0 && views[static_cast<size_t>(o.point)] >= 2)
      settled.push_back(geometry::ReprojectionErrorPx((*cams)[static_cast<size_t>(o.camera)],
                                                      wp->X[static_cast<size_t>(o.point)], o.uv_norm, s_.focal_px));
  const double as_is_cost =
      settled.empty() ? as_is->cost
                      : std::min(as_is->cost, CappedMeanSquarePx2(settled, s_.options.mapping.max_reprojection_px));
  // Counted by tracks, not by observations: a track's errors are correlated along it, so the points are what
  // the window holds independently. Counted by observations, a 5-frame window of the rendered fast scenario
  // (seed 3: 36 points, both fits at 1.2-1.3 px, the mirror's 22 % lower) flipped a right map by a chi-square
  // of 49, and the run ended 60 cm off instead of 6; by its tracks that is 10, and the 640x480 rotation seeds
  // 177 and 230.
  const double chi2 =
      (as_is_cost - sub_mirror->cost) * static_cast<double>(sub_ids.size()) / std::max(sub_mirror->cost, kCostFloorPx2);
  // And by how much: the chi-square is not calibrated where the tracks' errors are correlated and a tenth of them
  // are outliers (the noisy paper scenario, 1 px and 10 %, 16 frames at 5.2 deg under clang's rounding: the
  // adjusted map 2.79 px^2, its mirror 2.47, a chi-square of 22 for a right map; the fast scenario's 5-frame
  // window above: 1.28x). A mirror that is the scene leaves the map's fit far above the noise it fits at itself
  // (the 640x480 rotation seeds: 2.2x and 2.15x, 20 frames later 19x), so the mirror must also fit at most
  // kFlipCostRatio of the map's cost; a smaller lead waits for the next settling step's longer window.
  if (!(chi2 >= s_.options.init.ambiguity_chi2) || !(as_is_cost >= kFlipCostRatio * sub_mirror->cost)) {
    mirror_lead_ = 0;
    return false;
  }
  // And the lead confirmed by a longer window: a mirror that is the scene pulls away as the parallax grows (the
  // rotation scenario at 640x480, seed 1: 2.3x at frame 44, 7.7x at 49, 17x at 56), while two near-equal fits of a
  // plane seen through a narrow view trade a lead the tracks' errors give one of them (the planar scenario at
  // 160x120, seed 5: the mirror ahead by 1.89x at frame 30 and 1.62x at 33, the settling's last step; flipped, its
  // map ended 23 cm and 114 deg off, 0.5 cm and 0.3 deg unflipped). So a lead waits for the next step, is taken
  // there when it grew, and left when it did not; one first found at the settling's last step, which has no later
  // step, is taken.
  const double lead = as_is_cost / sub_mirror->cost;
  const double before = mirror_lead_;
  mirror_lead_ = lead;
  if (before > 0 && lead <= before) return false;  // did not grow with the window
  if (before == 0 && !last) return false;          // to be confirmed by the next step
  mirror_lead_ = 0;
  // Taken: the whole window's mirror, placed and refined (once in a run that needs it).
  const std::optional<Initializer::InitHypothesis> mirror =
      init_.RefineInitWindow(window, std::nullopt, MirrorInDepth(in_ref), ids, nullptr, false);
  if (!mirror) return false;
  const Pose world_from_ref = ref.Inverse();
  for (size_t w = 0; w < window.size(); ++w) (*cams)[w] = mirror->poses[w] * ref;
  // RefineInitWindow keeps the points in the order given, which is wp's.
  for (size_t i = 0; i < wp->X.size(); ++i) wp->X[i] = world_from_ref * mirror->points[i];
  *why = fmt::format(
      "the map was the mirror of the scene in depth: flipped (over {} frames and {} points its mirror explains the "
      "views with a mean squared residual of {:.4f} px^2 against {:.4f}, a chi-square of {:.0f} over the tracks)",
      sub.size(), sub_ids.size(), sub_mirror->cost, as_is_cost, chi2);
  return true;
}

}  // namespace mcslam::slam
