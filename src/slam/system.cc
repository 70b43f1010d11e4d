#include "slam/system.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <unordered_map>

#include <Eigen/Dense>
#include <fmt/format.h>

#include "core/median.h"
#include "geometry/bundle_adjust.h"
#include "geometry/pnp.h"
#include "geometry/rotation_only.h"
#include "geometry/triangulation.h"
#include "slam/fibonacci.h"

namespace mcslam::slam {

namespace {

// The noise σ of a feature (px, per coordinate) from a median reprojection residual: 1.1774 σ for Gaussian noise.
double NoiseFromMedianResidualPx(double median_residual_px) { return median_residual_px / 1.1774; }

// The parallax (degrees) at which two views fix a point's depth to `relative_depth_noise` of itself: a parallax
// θ fixes it to about σ / (f θ). Used for the first map and for new points alike.
double ParallaxForDepthNoiseDeg(double noise_px, double focal_px, double relative_depth_noise) {
  return RadToDeg(noise_px / (focal_px * relative_depth_noise));
}

double Ms(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

void Fail(const std::string& what) { throw std::invalid_argument(what); }

}  // namespace

PoseMethod ParsePoseMethod(const std::string& name) {
  if (name == "mc") return PoseMethod::kMonteCarlo;
  if (name == "pnp") return PoseMethod::kPnp;
  throw std::invalid_argument(fmt::format("pose method must be 'mc' or 'pnp', got '{}'", name));
}

StructureMethod ParseStructureMethod(const std::string& name) {
  if (name == "mc") return StructureMethod::kMonteCarlo;
  if (name == "ba") return StructureMethod::kBundleAdjustment;
  throw std::invalid_argument(fmt::format("structure method must be 'mc' or 'ba', got '{}'", name));
}

const char* ToString(FrameStatus s) {
  switch (s) {
    case FrameStatus::kWaitingForInit: return "waiting";
    case FrameStatus::kTracked: return "tracked";
    case FrameStatus::kLost: return "lost";
  }
  return "?";
}

void InitOptions::Check() const {
  if (!(min_median_motion_deg > 0 && min_median_motion_deg < 90))
    Fail(fmt::format("init: min_median_motion_deg must be in (0, 90), got {}", min_median_motion_deg));
  if (!(max_relative_depth_noise > 0)) Fail(fmt::format("init: max_relative_depth_noise must be > 0, got {}", max_relative_depth_noise));
  if (!(ambiguity_chi2 >= 0)) Fail(fmt::format("init: ambiguity_chi2 must be >= 0, got {}", ambiguity_chi2));
  if (min_common_features < 8) Fail(fmt::format("init: min_common_features must be >= 8, got {}", min_common_features));
  if (min_inliers < 8) Fail(fmt::format("init: min_inliers must be >= 8, got {}", min_inliers));
  if (min_points < 3) Fail(fmt::format("init: min_points must be >= 3, got {}", min_points));
  if (!(min_shared_fraction > 0 && min_shared_fraction <= 1))
    Fail(fmt::format("init: min_shared_fraction must be in (0, 1], got {}", min_shared_fraction));
  if (min_window_frames < 2) Fail(fmt::format("init: min_window_frames must be >= 2, got {}", min_window_frames));
  if (min_count_floor < 8) Fail(fmt::format("init: min_count_floor must be >= 8, got {}", min_count_floor));
  if (!(min_median_parallax_deg >= 0)) Fail(fmt::format("init: min_median_parallax_deg must be >= 0, got {}", min_median_parallax_deg));
  if (!(ransac_threshold_px > 0)) Fail(fmt::format("init: ransac_threshold_px must be > 0, got {}", ransac_threshold_px));
  if (!(settle_parallax_deg >= 0 && settle_parallax_deg < 90))
    Fail(fmt::format("init: settle_parallax_deg must be in [0, 90), got {}", settle_parallax_deg));
  if (settle_max_frames < 3) Fail(fmt::format("init: settle_max_frames must be >= 3, got {}", settle_max_frames));
  if (!(settle_step > 1)) Fail(fmt::format("init: settle_step must be > 1, got {}", settle_step));
}

void MappingOptions::Check() const {
  if (history_frames < 1) Fail(fmt::format("mapping: history_frames must be >= 1, got {}", history_frames));
  if (retriangulate_after_frames < 1)
    Fail(fmt::format("mapping: retriangulate_after_frames must be >= 1, got {}", retriangulate_after_frames));
  if (min_track_frames < 2) Fail(fmt::format("mapping: min_track_frames must be >= 2, got {}", min_track_frames));
  if (!(min_parallax_deg >= 0)) Fail(fmt::format("mapping: min_parallax_deg must be >= 0, got {}", min_parallax_deg));
  if (!(max_relative_depth_noise > 0))
    Fail(fmt::format("mapping: max_relative_depth_noise must be > 0, got {}", max_relative_depth_noise));
  if (!(max_noise_parallax_deg >= 0 && max_noise_parallax_deg < 90))
    Fail(fmt::format("mapping: max_noise_parallax_deg must be in [0, 90), got {}", max_noise_parallax_deg));
  if (starving_inliers < 0) Fail(fmt::format("mapping: starving_inliers must be >= 0, got {}", starving_inliers));
  if (!(starving_parallax_deg >= 0))
    Fail(fmt::format("mapping: starving_parallax_deg must be >= 0, got {}", starving_parallax_deg));
  if (!(max_reprojection_px > 0)) Fail(fmt::format("mapping: max_reprojection_px must be > 0, got {}", max_reprojection_px));
  if (!(adjust_threshold_px > 0)) Fail(fmt::format("mapping: adjust_threshold_px must be > 0, got {}", adjust_threshold_px));
  if (!(candidate_threshold_px >= 0))
    Fail(fmt::format("mapping: candidate_threshold_px must be >= 0, got {}", candidate_threshold_px));
  if (samples < 1) Fail(fmt::format("mapping: samples must be >= 1, got {}", samples));
  if (window < 2) Fail(fmt::format("mapping: window must be >= 2 keyframes, got {}", window));
  if (!(sigma_scale >= 0)) Fail(fmt::format("mapping: sigma_scale must be >= 0, got {}", sigma_scale));
  if (!(sigma_floor_rel_depth > 0)) Fail(fmt::format("mapping: sigma_floor_rel_depth must be > 0, got {}", sigma_floor_rel_depth));
  if (!(max_distance_px > 0 && max_distance_px <= 1e6))
    Fail(fmt::format("mapping: max_distance_px must be in (0, 1e6], got {}", max_distance_px));
}

void SystemOptions::Check() const {
  if (ba_iterations < 1) Fail(fmt::format("ba_iterations must be >= 1, got {}", ba_iterations));
  if (ba_fixed_keyframes < 1) Fail(fmt::format("ba_fixed_keyframes must be >= 1, got {}", ba_fixed_keyframes));
  if (rotation_only_min_tracks < 3)
    Fail(fmt::format("rotation_only_min_tracks must be >= 3, got {}", rotation_only_min_tracks));
  if (!(rotation_only_min_ratio > 0 && rotation_only_min_ratio <= 1))
    Fail(fmt::format("rotation_only_min_ratio must be in (0, 1], got {}", rotation_only_min_ratio));
  if (relocalise_min_inliers < 6)
    Fail(fmt::format("relocalise_min_inliers must be >= 6, got {}", relocalise_min_inliers));
  tracker.Check();
  init.Check();
  mapping.Check();
  smoother.Check();
  if (!(sigma_trans_floor_rel_depth > 0))
    Fail(fmt::format("sigma_trans_floor_rel_depth must be > 0, got {}", sigma_trans_floor_rel_depth));
}

System::System(const PinholeCamera& camera, const SystemOptions& options,
               std::unique_ptr<compute::PoseKernel> pose_kernel, std::unique_ptr<compute::PointKernel> point_kernel)
    : camera_(camera),
      ideal_(camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height),
      focal_px_(0.5 * (camera.fx + camera.fy)),
      options_(options),
      pose_kernel_(std::move(pose_kernel)),
      point_kernel_(std::move(point_kernel)),
      smoother_(options.smoother) {
  camera_.Check();
  options_.Check();
  if (!pose_kernel_ || !point_kernel_) throw std::invalid_argument("system: compute kernels missing");
  point_normals_ = compute::NormalTable(options_.mapping.samples, options_.seed, /*stream=*/2);
}

std::vector<FrameReport> System::Process(const FrameObservations& frame) {
  FrameRecord rec;
  rec.index = frame.index;
  rec.stamp_s = frame.stamp_s;
  rec.features.reserve(frame.features.size());
  for (const FeatureObservation& f : frame.features) {
    if (!f.uv_px.allFinite()) continue;
    const Eigen::Vector2d uv = camera_.UndistortPixel(f.uv_px);
    if (uv.allFinite()) rec.features.push_back({f.feature_id, uv});
  }
  std::sort(rec.features.begin(), rec.features.end(), [](const auto& a, const auto& b) { return a.id < b.id; });
  rec.features.erase(std::unique(rec.features.begin(), rec.features.end(),
                                 [](const auto& a, const auto& b) { return a.id == b.id; }),
                     rec.features.end());
  map_.frames.push_back(std::move(rec));
  const int slot = static_cast<int>(map_.frames.size()) - 1;
  PruneHistory(slot);

  std::vector<FrameReport> out;
  if (!initialised_) {
    const auto t0 = std::chrono::steady_clock::now();
    if (TryInitialise(&out)) return out;
    FrameReport r;
    r.index = frame.index;
    r.stamp_s = frame.stamp_s;
    r.status = FrameStatus::kWaitingForInit;
    r.init_ms = Ms(t0);
    r.note = out.empty() ? "waiting for enough motion to initialise" : out.front().note;
    r.init_rejected = !out.empty() && out.front().init_rejected;
    out.assign(1, r);
    return out;
  }
  out.push_back(TrackFrame(slot, frame.pose_hint));
  if (settling_ && out.front().status == FrameStatus::kTracked &&
      ParallaxFromReference(slot) >= next_settle_parallax_deg_) {
    const auto t0 = std::chrono::steady_clock::now();
    Settle(slot, &out);
    out.front().init_ms = Ms(t0);
  }
  return out;
}

System::WindowPoints System::CollectWindowPoints(const std::vector<int>& window) {
  WindowPoints wp;
  std::unordered_map<int64_t, int> count, index;
  for (int s : window)
    for (const FeatureUndistorted& f : map_.frames[s].features)
      if (const MapPoint* p = map_.Find(f.id); p && p->state != PointState::kRemoved) ++count[f.id];
  for (size_t w = 0; w < window.size(); ++w)
    for (const FeatureUndistorted& f : map_.frames[window[w]].features) {
      MapPoint* p = map_.Find(f.id);
      if (!p || p->state == PointState::kRemoved || count[f.id] < 2) continue;
      auto [it, fresh] = index.try_emplace(f.id, static_cast<int>(wp.pts.size()));
      if (fresh) wp.pts.push_back(p), wp.X.push_back(p->position_in_world);
      wp.obs.push_back({static_cast<int>(w), it->second, ideal_.PixelToNormalized(f.uv_px)});
    }
  return wp;
}

int System::StoreAdjustedPoints(const std::vector<Pose>& cams, const WindowPoints& wp, int64_t frame_index) {
  std::vector<std::vector<double>> residuals(wp.pts.size());
  for (const geometry::BundleObservation& o : wp.obs)
    residuals[o.point].push_back(geometry::ReprojectionErrorPx(cams[o.camera], wp.X[o.point], o.uv_norm, focal_px_));
  int removed = 0;
  for (size_t i = 0; i < wp.pts.size(); ++i) {
    wp.pts[i]->position_in_world = wp.X[i];
    if (residuals[i].size() >= 3 && UpperMedian(residuals[i]) > options_.mapping.adjust_threshold_px) {
      wp.pts[i]->state = PointState::kRemoved;
      wp.pts[i]->removed_frame = frame_index;
      ++removed;
    }
  }
  return removed;
}

double System::ParallaxFromReference(int slot) const {
  const FrameRecord& ref = map_.frames[reference_slot_];
  const FrameRecord& cur = map_.frames[slot];
  const Pose pair[2] = {ref.cam_from_world, cur.cam_from_world};
  std::vector<double> parallax;
  for (const FeatureUndistorted& f : cur.features) {
    const MapPoint* p = map_.Find(f.id);
    if (!p || p->state == PointState::kRemoved || !ref.Find(f.id)) continue;
    parallax.push_back(geometry::ParallaxDeg(pair, p->position_in_world));
  }
  // Too few points shared with the reference to say: the view has moved on, as far as the start can tell.
  if (parallax.size() < static_cast<size_t>(init_min_points_)) return std::numeric_limits<double>::infinity();
  return UpperMedian(parallax);
}

void System::Settle(int slot, std::vector<FrameReport>* out) {
  const InitOptions& io = options_.init;
  const double parallax = ParallaxFromReference(slot);
  // Posed frames since the reference (at most settle_max_frames, evenly spread, with the reference, the
  // initialisation's frame and this one), and every map point seen at least twice among them.
  std::vector<int> posed;
  for (int s = reference_slot_; s <= slot; ++s)
    if (map_.frames[s].has_pose) posed.push_back(s);
  std::vector<int> window;
  const int n = static_cast<int>(posed.size()), m = std::min(n, io.settle_max_frames);
  for (int i = 0; i < m; ++i) window.push_back(posed[static_cast<int64_t>(i) * (n - 1) / std::max(m - 1, 1)]);
  if (std::find(window.begin(), window.end(), init_slot_) == window.end()) window.push_back(init_slot_);
  std::sort(window.begin(), window.end());
  window.erase(std::unique(window.begin(), window.end()), window.end());
  std::vector<Pose> cams;
  for (int s : window) cams.push_back(map_.frames[s].cam_from_world);
  WindowPoints wp = CollectWindowPoints(window);
  std::vector<Eigen::Vector3d>& X = wp.X;
  const std::vector<geometry::BundleObservation>& obs = wp.obs;
  std::vector<bool> fixed(window.size(), false);
  fixed.front() = true;  // the reference camera is the world
  geometry::BundleAdjustOptions bo;
  bo.focal_px = focal_px_;
  bo.huber_px = io.refine_huber_px;
  bo.cauchy = true;  // tens of frames of tracks hold wrong matches: their pull must fade
  // One thread: Ceres' multi-threaded Schur elimination sums in a varying order, and the same seed must give
  // the same trajectory.
  bo.dense_schur = true;  // tens of cameras that all see the same few hundred points
  geometry::BundleAdjust(cams, X, obs, fixed, bo);
  // The scale: the initialisation's baseline keeps its length (1, or the ground truth's with --gt-scale).
  const auto init_it = std::find(window.begin(), window.end(), init_slot_);
  const double b = init_it == window.end()
                       ? 0.0
                       : (cams[init_it - window.begin()].OriginOfTargetInSource() - cams.front().OriginOfTargetInSource()).norm();
  const double s = b > 1e-12 ? init_baseline_ / b : 1.0;
  for (Pose& c : cams) c.t *= s;
  for (Eigen::Vector3d& x : X) x *= s;
  std::unordered_map<int, Pose> moved_by;  // window slot -> new * old^-1
  for (size_t w = 0; w < window.size(); ++w) {
    moved_by[window[w]] = cams[w] * map_.frames[window[w]].cam_from_world.Inverse();
    map_.frames[window[w]].cam_from_world = cams[w];
  }
  const FrameRecord& cur = map_.frames[slot];
  StoreAdjustedPoints(cams, wp, cur.index);
  RefreshInlierFlags(slot);  // at the moved current pose
  // The posed frames left out of the adjustment, and those before the reference: each placed again against
  // the adjusted points (PnP from the points it sees; for a frame before the reference, with the agreement it
  // was first placed with), or else moved with its neighbour in the window: for a frame before the
  // reference, which stays the world, only the scale changes.
  std::vector<int> left_out;
  for (int k = posed_from_; k < reference_slot_; ++k) left_out.push_back(k);
  for (int k : posed)
    if (!std::binary_search(window.begin(), window.end(), k)) left_out.push_back(k);
  for (int k : left_out) {
    FrameRecord& f = map_.frames[k];
    const bool before_reference = k < reference_slot_;
    if (const std::optional<Pose> pose = PlaceByPnp(k, options_.tracker.min_inliers,
                                                    before_reference ? options_.tracker.min_inlier_ratio : 0.0)) {
      f.cam_from_world = *pose;
    } else if (before_reference) {
      f.cam_from_world.t *= s;
    } else {
      f.cam_from_world = moved_by[*(std::upper_bound(window.begin(), window.end(), k) - 1)] * f.cam_from_world;
    }
  }
  const std::string note = fmt::format(
      "{}: {} of {} frames and {} points refined together at a median parallax of {:.1f} deg",
      parallax >= io.settle_parallax_deg ? "settled" : "settling", window.size(), posed.size(), wp.pts.size(), parallax);
  settling_ = parallax < io.settle_parallax_deg;
  next_settle_parallax_deg_ = std::min(parallax * io.settle_step, io.settle_parallax_deg);
  out->front().cam_from_world = cur.cam_from_world;
  out->front().note = note;
  ResidualStats(slot, &out->front());
  for (int k = posed_from_; k <= slot; ++k) {
    if (k == slot || !map_.frames[k].has_pose) continue;
    FrameReport r = PosedReport(k);
    r.pose_update = true;
    out->push_back(r);
  }
}

geometry::PnpOptions System::TrackerPnpOptions(int min_inliers) const {
  geometry::PnpOptions po;
  po.focal_px = focal_px_;
  po.threshold_px = options_.tracker.inlier_threshold_px;
  po.min_inliers = min_inliers;
  return po;
}

std::optional<Pose> System::PlaceByPnp(int slot, int min_inliers, double min_inlier_ratio) const {
  std::vector<Eigen::Vector3d> P;
  std::vector<Eigen::Vector2d> uv;
  for (const FeatureUndistorted& o : map_.frames[slot].features)
    if (const MapPoint* p = map_.Find(o.id); p && p->state != PointState::kRemoved)
      P.push_back(p->position_in_world), uv.push_back(ideal_.PixelToNormalized(o.uv_px));
  int inliers = 0;
  std::optional<Pose> pose = geometry::SolvePnp(P, uv, TrackerPnpOptions(min_inliers), &inliers);
  if (pose && inliers < min_inlier_ratio * static_cast<double>(P.size())) return std::nullopt;
  return pose;
}

int System::PoseFramesBefore(int before_slot, int first_slot) {
  int first = before_slot;
  for (int k = before_slot - 1; k >= std::max(first_slot, 0); --k) {
    FrameRecord& f = map_.frames[k];
    if (f.has_pose || f.features.empty()) break;
    const std::optional<Pose> pose =
        PlaceByPnp(k, options_.tracker.min_inliers, options_.tracker.min_inlier_ratio);
    if (!pose) break;
    f.has_pose = true;
    f.cam_from_world = *pose;
    first = k;
  }
  return first;
}

namespace {

// The points mirrored in depth about their median depth along the reference camera's axis, each kept on its
// ray (so the reference view is unchanged): the start of the depth-reversed twin of a two-view solution.
std::vector<Eigen::Vector3d> MirrorInDepth(const std::vector<Eigen::Vector3d>& points_in_ref) {
  std::vector<double> z;
  for (const Eigen::Vector3d& X : points_in_ref) z.push_back(X.z());
  const double z0 = UpperMedian(z);
  std::vector<Eigen::Vector3d> out;
  out.reserve(points_in_ref.size());
  for (const Eigen::Vector3d& X : points_in_ref) {
    const double zm = std::max(2.0 * z0 - X.z(), 0.1 * z0);
    out.push_back(X * (zm / X.z()));
  }
  return out;
}

// Two refined initialisations are the same solution when their points' depths correlate at least this much
// and their last cameras' orientations agree within kSameRotationDeg; the noise variance of the ambiguity test
// is at least kCostFloorPx2 (a residual of 0.03 px), so that two exact fits of clean data do not count as a
// clear winner and loser.
constexpr double kSameStructureCorrelation = 0.9;
constexpr double kSameRotationDeg = 2.0;
constexpr double kCostFloorPx2 = 1e-3;

// Pearson correlation of the depths (z) of the points two reconstructions share (by id): about -1 for a
// depth-reversed pair, about +1 for the same structure; 1 when they share fewer than 3 points.
double DepthCorrelation(const std::vector<Eigen::Vector3d>& a, const std::vector<int64_t>& a_ids,
                        const std::vector<Eigen::Vector3d>& b, const std::vector<int64_t>& b_ids) {
  std::unordered_map<int64_t, double> zb;
  for (size_t i = 0; i < b.size() && i < b_ids.size(); ++i) zb[b_ids[i]] = b[i].z();
  std::vector<std::pair<double, double>> z;
  for (size_t i = 0; i < a.size() && i < a_ids.size(); ++i)
    if (auto it = zb.find(a_ids[i]); it != zb.end()) z.emplace_back(a[i].z(), it->second);
  if (z.size() < 3) return 1.0;
  double ma = 0, mb = 0;
  for (const auto& [x, y] : z) ma += x, mb += y;
  ma /= static_cast<double>(z.size()), mb /= static_cast<double>(z.size());
  double sab = 0, saa = 0, sbb = 0;
  for (const auto& [x, y] : z) sab += (x - ma) * (y - mb), saa += (x - ma) * (x - ma), sbb += (y - mb) * (y - mb);
  return saa > 0 && sbb > 0 ? sab / std::sqrt(saa * sbb) : 1.0;
}

}  // namespace

std::optional<System::InitHypothesis> System::RefineInitWindow(const std::vector<int>& window,
                                                               const std::optional<Pose>& last_from_ref,
                                                               std::vector<Eigen::Vector3d> points,
                                                               std::vector<int64_t> point_ids,
                                                               std::string* failure, bool check_parallax) const {
  const InitOptions& io = options_.init;
  const double focal = focal_px_;
  auto fail = [&](std::string why) -> std::optional<InitHypothesis> {
    if (failure) *failure = std::move(why);
    return std::nullopt;
  };
  InitHypothesis h;
  h.points = std::move(points);
  h.point_ids = std::move(point_ids);
  std::unordered_map<int64_t, int> index;
  for (size_t i = 0; i < h.point_ids.size(); ++i) index[h.point_ids[i]] = static_cast<int>(i);
  h.poses.assign(window.size(), Pose());
  if (last_from_ref) h.poses.back() = *last_from_ref;
  std::vector<bool> fixed(window.size(), false);
  fixed.front() = true;
  geometry::PnpOptions po;
  po.focal_px = focal;
  po.threshold_px = options_.mapping.max_reprojection_px;
  std::vector<geometry::BundleObservation> obs;
  for (size_t w = 0; w < window.size(); ++w) {
    std::vector<Eigen::Vector3d> P;
    std::vector<Eigen::Vector2d> uv;
    for (const FeatureUndistorted& f : map_.frames[window[w]].features)
      if (auto it = index.find(f.id); it != index.end()) {
        const Eigen::Vector2d n = ideal_.PixelToNormalized(f.uv_px);
        obs.push_back({static_cast<int>(w), it->second, n});
        P.push_back(h.points[it->second]);
        uv.push_back(n);
      }
    if (w == 0 || (last_from_ref && w + 1 == window.size())) continue;
    const std::optional<Pose> pose = geometry::SolvePnp(P, uv, po);
    h.poses[w] = pose ? *pose : h.poses[w - 1];
  }
  geometry::BundleAdjustOptions bo;
  bo.focal_px = focal;
  bo.huber_px = io.refine_huber_px;
  if (io.refine_window) geometry::BundleAdjust(h.poses, h.points, obs, fixed, bo);
  std::vector<double> res;
  double cost = 0;
  const double cap_sq = options_.mapping.max_reprojection_px * options_.mapping.max_reprojection_px;
  for (const geometry::BundleObservation& o : obs) {
    res.push_back(geometry::ReprojectionErrorPx(h.poses[o.camera], h.points[o.point], o.uv_norm, focal));
    cost += std::min(res.back() * res.back(), cap_sq);
  }
  h.median_px = UpperMedian(res);
  h.cost = obs.empty() ? std::numeric_limits<double>::infinity() : cost / static_cast<double>(obs.size());
  h.observations = static_cast<int>(obs.size());
  std::vector<double> z;
  for (const Eigen::Vector3d& X : h.points) z.push_back(X.z());
  if (!(UpperMedian(z) > 0)) return fail("refined window: the points ended behind the reference camera");
  // The refined window must still have the parallax asked for (between the first and the last camera), and
  // enough for the tracks' noise: two views of a parallax θ fix a depth to about σ / (f θ) of itself, σ the
  // noise of a feature (the window's median residual is 1.18 σ for Gaussian noise, σ per coordinate).
  std::vector<double> parallax;
  const Pose ends[2] = {h.poses.front(), h.poses.back()};
  for (const Eigen::Vector3d& X : h.points) parallax.push_back(geometry::ParallaxDeg(ends, X));
  const double refined_parallax = UpperMedian(parallax);
  const double noise_px = NoiseFromMedianResidualPx(h.median_px);
  const double needed =
      std::max(io.min_median_parallax_deg, ParallaxForDepthNoiseDeg(noise_px, focal, io.max_relative_depth_noise));
  h.parallax_ok = refined_parallax >= needed;
  if (check_parallax && !h.parallax_ok)
    return fail(fmt::format("refined window: median parallax {:.2f} deg < {:.2f} deg (the tracks' noise, {:.2f} px, "
                            "asks for it)",
                            refined_parallax, needed, noise_px));
  return h;
}

bool System::TryInitialise(std::vector<FrameReport>* out) {
  const InitOptions& io = options_.init;
  const int cur_slot = static_cast<int>(map_.frames.size()) - 1;
  auto note = [&](std::string s) {
    FrameReport r;
    r.note = std::move(s);
    out->assign(1, r);
    return false;
  };
  if (reference_slot_ < 0) {
    reference_slot_ = cur_slot;
    return note("reference frame for initialisation");
  }
  // Correspondences between the reference and this frame. Forward motion (a car) and fast turns lose features
  // quickly: when too few are shared, the reference moves on to the oldest frame since it that still shares
  // enough with this one, so that the motion gathered since is kept (moving it to this frame would start over).
  std::vector<Eigen::Vector2d> n1, n2;
  std::vector<int64_t> ids;
  std::vector<double> motion_deg;  // angle between the two rays of a feature, the rotation not removed
  auto correspond = [&](int ref_slot) {
    n1.clear(), n2.clear(), ids.clear(), motion_deg.clear();
    const FrameRecord& r = map_.frames[ref_slot];
    for (const FeatureUndistorted& f : map_.frames[cur_slot].features) {
      const FeatureUndistorted* g = r.Find(f.id);
      if (!g) continue;
      n1.push_back(ideal_.PixelToNormalized(g->uv_px));
      n2.push_back(ideal_.PixelToNormalized(f.uv_px));
      ids.push_back(f.id);
      const Eigen::Vector3d a = n1.back().homogeneous().normalized(), b = n2.back().homogeneous().normalized();
      motion_deg.push_back(std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / M_PI);
    }
  };
  // The counts asked for, lowered where the frame tracks few features (InitOptions::min_shared_fraction).
  const int offered = static_cast<int>(std::ceil(io.min_shared_fraction *
                                                 static_cast<double>(map_.frames[cur_slot].features.size())));
  auto lowered = [&](int count) { return std::min(count, std::max(io.min_count_floor, offered)); };
  const int need_common = lowered(io.min_common_features), need_inliers = lowered(io.min_inliers),
            need_points = lowered(io.min_points);
  correspond(reference_slot_);
  if (static_cast<int>(ids.size()) < need_common) {
    int next = cur_slot;
    for (int s = reference_slot_ + 1; s < cur_slot && next == cur_slot; ++s) {
      int shared = 0;
      for (const FeatureUndistorted& f : map_.frames[cur_slot].features) shared += map_.frames[s].Find(f.id) != nullptr;
      if (shared >= need_common) next = s;
    }
    const size_t had = ids.size();
    reference_slot_ = next;
    if (next == cur_slot) return note(fmt::format("only {} features shared with the reference: new reference", had));
    correspond(reference_slot_);
  }
  const FrameRecord& ref = map_.frames[reference_slot_];
  const FrameRecord& cur = map_.frames[cur_slot];
  const double med_motion = UpperMedian(motion_deg);
  if (med_motion < io.min_median_motion_deg)
    return note(fmt::format("median feature motion {:.2f} deg < {:.2f} deg", med_motion, io.min_median_motion_deg));

  // Two-view hypotheses: the 8-point method with two RANSAC seeds, OpenCV's 5-point method, and, when a
  // homography explains the views (a dominant plane), the motions of its decomposition. Each places every
  // frame of the window by PnP against its points and is refined by one bundle adjustment over the whole
  // window; the one that explains the window best is kept. With a narrow field of view two views leave a
  // near-free bas-relief direction and sometimes a twisted pair; a wrong basin cannot explain tens of views
  // as well as the right one.
  std::vector<int> window;
  for (int s = reference_slot_; s <= cur_slot; ++s) window.push_back(s);
  if (static_cast<int>(window.size()) < io.min_window_frames)
    return note(fmt::format("{} frames since the reference (the window needs {}: two views leave the depth "
                            "reversal open)",
                            window.size(), io.min_window_frames));
  const double focal = focal_px_;
  std::string last_failure;
  geometry::TwoViewOptions tv;
  tv.ransac_threshold_px = io.ransac_threshold_px;
  tv.focal_px = focal;
  tv.max_reprojection_px = options_.mapping.max_reprojection_px;
  std::vector<geometry::TwoViewResult> seeds;
  const std::pair<geometry::EssentialMethod, uint64_t> tries[] = {{io.method, options_.seed},
                                                                   {io.method, options_.seed + 1},
                                                                   {geometry::EssentialMethod::kFivePointOpenCV, 0},
                                                                   {geometry::EssentialMethod::kEightPoint, options_.seed + 2}};
  bool eight_point_failed = false;  // the data refused the 8-point method: other seeds will not help
  bool five_point_tried = false;  // OpenCV's 5-point RANSAC has a fixed seed: one try is all it gives
  bool planar = false;            // a homography explains the views
  for (const auto& [method, seed] : tries) {
    if (eight_point_failed && method == geometry::EssentialMethod::kEightPoint) continue;
    if (method == geometry::EssentialMethod::kFivePointOpenCV) {
      if (five_point_tried) continue;
      five_point_tried = true;
    }
    tv.method = method;
    tv.seed = seed;
    geometry::TwoViewResult tvr = geometry::EstimateTwoView(n1, n2, tv);
    if (!tvr.ok) {
      last_failure = "two-view geometry failed: " + tvr.failure;
      planar |= tvr.status == geometry::TwoViewStatus::kPlanarOrRotation;
      // Only a refusal of the data itself (too few, NaN, planar or pure rotation) holds for every seed.
      const bool data_refused = tvr.status == geometry::TwoViewStatus::kBadInput ||
                                tvr.status == geometry::TwoViewStatus::kTooFewCorrespondences ||
                                tvr.status == geometry::TwoViewStatus::kPlanarOrRotation;
      eight_point_failed |= method == geometry::EssentialMethod::kEightPoint && data_refused;
      continue;
    }
    seeds.push_back(std::move(tvr));
  }
  const size_t num_essential_seeds = seeds.size();
  if (planar)
    for (geometry::TwoViewResult& tvr : geometry::EstimateTwoViewPlanar(n1, n2, tv)) seeds.push_back(std::move(tvr));

  std::vector<InitHypothesis> refined;
  for (size_t k = 0; k < seeds.size(); ++k) {
    const geometry::TwoViewResult& tvr = seeds[k];
    const bool passes = tvr.num_inliers >= need_inliers && tvr.num_triangulated >= need_points &&
                        tvr.median_parallax_deg >= io.min_median_parallax_deg;
    if (!passes)
      last_failure = fmt::format("two-view: {} inliers, {} points, median parallax {:.2f} deg (need {}, {}, {:.2f})",
                                 tvr.num_inliers, tvr.num_triangulated, tvr.median_parallax_deg, need_inliers,
                                 need_points, io.min_median_parallax_deg);
    // A plane's motions are judged together: one short of the gates still stands against the other.
    const bool planar_seed = k >= num_essential_seeds;
    if (!passes && !planar_seed) continue;
    std::vector<Eigen::Vector3d> points;
    std::vector<int64_t> point_ids;
    for (size_t i = 0; i < ids.size(); ++i)
      if (tvr.triangulated[i]) points.push_back(tvr.points_in_cam1[i]), point_ids.push_back(ids[i]);
    std::string why;
    std::optional<InitHypothesis> h = RefineInitWindow(window, tvr.cam2_from_cam1, points, point_ids, &why, passes);
    if (!h) {
      if (passes) last_failure = why;
      continue;
    }
    h->two_view_inliers = tvr.num_inliers;
    h->two_view_parallax_deg = tvr.median_parallax_deg;
    h->eligible = passes;
    refined.push_back(std::move(*h));
  }
  auto cheapest = [&] {
    auto best_it = refined.end();
    for (auto it = refined.begin(); it != refined.end(); ++it)
      if (it->eligible && (best_it == refined.end() || it->cost < best_it->cost)) best_it = it;
    return best_it;
  };
  if (cheapest() == refined.end()) return note(last_failure);
  // The depth-reversal (Necker) ambiguity: seen through a narrow field of view, a scene and its mirror image
  // in depth, with the cameras turned the other way, project nearly alike. The mirror of the winner is refined
  // too and competes with the rest.
  {
    const InitHypothesis& winner = *cheapest();
    // Refined whatever its parallax: short of it, it still stands against the winner.
    if (std::optional<InitHypothesis> mirror = RefineInitWindow(window, std::nullopt, MirrorInDepth(winner.points),
                                                                winner.point_ids, nullptr, /*check_parallax=*/false)) {
      mirror->two_view_inliers = winner.two_view_inliers;
      mirror->two_view_parallax_deg = winner.two_view_parallax_deg;
      mirror->mirrored = true;
      mirror->eligible = mirror->parallax_ok;
      refined.push_back(std::move(*mirror));
    }
  }
  // Ambiguity: another solution with another structure (its points' depths not in step with the winner's: the
  // depth-reversed mirror, the plane's twin) explains the window about as well. The views cannot tell them
  // apart yet: wait for more motion rather than risk a wrong (mirrored, twisted) map.
  std::optional<InitHypothesis> best = *cheapest();
  for (const InitHypothesis& h : refined) {
    const bool distinct = DepthCorrelation(best->points, best->point_ids, h.points, h.point_ids) < kSameStructureCorrelation ||
                          AngularDistanceDeg(best->poses.back().q, h.poses.back().q) > kSameRotationDeg;
    // How much worse it explains the window, as a chi-square: the summed squared residuals' difference over
    // the window's noise variance (the best solution's mean squared residual, at least the floor's).
    const double chi2 = (h.cost - best->cost) * best->observations / std::max(best->cost, kCostFloorPx2);
    if (distinct && chi2 < io.ambiguity_chi2) {
      note(fmt::format("ambiguous initialisation: {} explains the window about as well as the best solution (mean "
                       "squared residual {:.4f} against {:.4f} px^2): waiting for more motion",
                       h.mirrored ? "its mirror in depth" : "another solution with another structure", h.cost,
                       best->cost));
      out->front().init_rejected = true;
      return false;
    }
  }

  // Gauge: the reference camera is the world; the first baseline has length 1, or the true length when
  // the ground truth is offered (--gt-scale, as the paper sets the scale by hand for its precision test).
  double baseline = 1.0;
  if (oracle_) {
    const std::optional<double> d = oracle_(ref.stamp_s, cur.stamp_s);
    if (!d || !std::isfinite(*d) || !(*d > 0))
      throw std::runtime_error(fmt::format(
          "--gt-scale: the ground truth gives no baseline between frames {} (t = {:.6f} s) and {} (t = {:.6f} s): "
          "no pose near those stamps, or the camera did not move",
          ref.index, ref.stamp_s, cur.index, cur.stamp_s));
    baseline = *d;
  }
  const double b = (best->poses.back().OriginOfTargetInSource() - best->poses.front().OriginOfTargetInSource()).norm();
  const double s = b > 1e-12 ? baseline / b : 1.0;
  std::vector<double> depths;
  for (size_t i = 0; i < best->points.size(); ++i) {
    MapPoint p;
    p.id = best->point_ids[i];
    p.position_in_world = best->points[i] * s;
    p.last_seen_frame = cur.index;
    map_.Add(p);
    depths.push_back(p.position_in_world.z());
  }
  for (size_t w = 0; w < window.size(); ++w) {
    FrameRecord& f = map_.frames[window[w]];
    f.has_pose = true;
    f.cam_from_world = best->poses[w];
    f.cam_from_world.t *= s;
    map_.keyframes.push_back(window[w]);
  }
  last_posed_slot_ = cur_slot;
  init_slot_ = cur_slot;
  init_baseline_ = baseline;
  settling_ = io.settle_parallax_deg > 0;
  next_settle_parallax_deg_ = io.settle_step * std::max(best->two_view_parallax_deg, 1e-3);
  MarkSeen(cur_slot);
  RefreshInlierFlags(cur_slot);
  PoseTrackerOptions topts = options_.tracker;
  topts.sigma_trans_floor_m = options_.sigma_trans_floor_rel_depth * UpperMedian(depths);
  tracker_ = std::make_unique<PoseTracker>(ideal_, topts, std::move(pose_kernel_));
  initialised_ = true;
  init_min_points_ = need_points;
  posed_from_ = io.pose_frames_before_reference ? PoseFramesBefore(reference_slot_, pruned_until_) : reference_slot_;

  out->clear();
  smoother_.Reset();
  for (size_t w = 0; w < window.size(); ++w) {
    FrameReport r = PosedReport(window[w]);
    r.keyframe = true;
    r.initialisation = true;
    r.smoothed_cam_from_world = smoother_.Update(r.cam_from_world);
    if (w + 1 == window.size()) {
      r.new_points = static_cast<int>(depths.size());
      r.note = fmt::format(
          "initialised from frames {} and {}: {} inliers, {} points, median parallax {:.2f} deg, window of {} frames "
          "refined to a median reprojection error of {:.2f} px{}",
          ref.index, cur.index, best->two_view_inliers, depths.size(), best->two_view_parallax_deg,
          window.size(), best->median_px,
          best->mirrored ? " (the depth-reversed twin of the two-view solution, which explained the window better)" : "");
    }
    r.map_points = map_.CountInState(PointState::kActive) + map_.CountInState(PointState::kLost);
    out->push_back(r);
  }
  // The frames before the reference: poses, unsmoothed (the smoother runs forward from the reference). After
  // the window's reports, so that the first report with a note is the one that says how the map was made.
  for (int k = posed_from_; k < reference_slot_; ++k) {
    FrameReport r = PosedReport(k);
    r.initialisation = true;
    r.smoothed_cam_from_world = r.cam_from_world;
    r.note = fmt::format("posed at the initialisation (frame {}), before its reference frame", cur.index);
    out->push_back(r);
  }
  return true;
}

FrameReport System::TrackFrame(int slot, const std::optional<Pose>& pose_hint) {
  FrameReport r;
  FrameRecord& fr = map_.frames[slot];
  r.index = fr.index;
  r.stamp_s = fr.stamp_s;
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<PointObservation> obs;
  std::vector<MapPoint*> pts;
  obs.reserve(fr.features.size());
  for (const FeatureUndistorted& f : fr.features) {
    MapPoint* p = map_.Find(f.id);
    if (!p || p->state == PointState::kRemoved) continue;
    obs.push_back({p->position_in_world, f.uv_px, p->inlier});
    pts.push_back(p);
  }
  std::vector<double> res;
  std::vector<uint8_t> inl;
  const Pose prev = pose_hint ? *pose_hint : map_.frames[last_posed_slot_].cam_from_world;
  // After relocalisation the inlier flags are those of the last tracked frame, long ago: the points that
  // score are those that agree with the hint instead.
  if (pose_hint) {
    tracker_->ClassifyInliers(*pose_hint, obs, &res, &inl);
    for (size_t i = 0; i < obs.size(); ++i) obs[i].was_inlier = inl[i] != 0;
  }
  const PoseEstimate est = options_.pose_method == PoseMethod::kPnp
                               ? EstimatePosePnp(obs, &res, &inl)
                               : tracker_->Track(prev, obs, static_cast<uint64_t>(fr.index), &res, &inl);
  r.track_ms = Ms(t0);
  r.scored = est.scored;
  r.inliers = est.inliers;
  if (!est.tracked) {
    for (MapPoint* p : pts) p->inlier = true;  // everyone gets another chance in the next frame
    if (!pose_hint && options_.rotation_only && TrackRotationOnly(slot, &r)) {
      r.track_ms = Ms(t0);
      MarkSeen(slot);
      r.map_points = map_.CountInState(PointState::kActive) + map_.CountInState(PointState::kLost);
      return r;
    }
    r.status = FrameStatus::kLost;
    r.note = est.lost_reason + (r.note.empty() ? "" : "; " + r.note);
    MarkSeen(slot);
    r.map_points = map_.CountInState(PointState::kActive) + map_.CountInState(PointState::kLost);
    return r;
  }
  for (size_t i = 0; i < pts.size(); ++i) pts[i]->inlier = inl[i] != 0;
  fr.has_pose = true;
  fr.cam_from_world = est.cam_from_world;
  fr.pose_inliers = est.inliers;
  last_posed_slot_ = slot;
  panorama_bearings_.clear();  // the pose step has points again: a later turn starts afresh
  r.status = FrameStatus::kTracked;
  r.has_pose = true;
  r.cam_from_world = est.cam_from_world;
  // A relocalised pose may be far from where the smoother's state is: it starts again there.
  if (pose_hint) smoother_.Reset();
  r.smoothed_cam_from_world = smoother_.Update(est.cam_from_world);
  if (est.keyframe) {
    map_.keyframes.push_back(slot);
    r.keyframe = true;
    const auto t1 = std::chrono::steady_clock::now();
    r.new_points = TriangulateNewPoints(slot, est.inliers);
    r.map_ms = Ms(t1);
    if (options_.mapping.adjust) {
      const auto t2 = std::chrono::steady_clock::now();
      if (options_.structure_method == StructureMethod::kBundleAdjustment) {
        BundleAdjustWindow(slot, &r);
        r.cam_from_world = fr.cam_from_world;  // the adjustment moved this keyframe too
      } else {
        AdjustPoints(slot, &r);
      }
      r.adjust_ms = Ms(t2);
    }
  }
  MarkSeen(slot);
  ResidualStats(slot, &r);
  r.map_points = map_.CountInState(PointState::kActive) + map_.CountInState(PointState::kLost);
  return r;
}

std::optional<double> System::RecentNoisePx() const {
  if (recent_residual_px_.empty()) return std::nullopt;
  return NoiseFromMedianResidualPx(
      UpperMedian(std::vector<double>(recent_residual_px_.begin(), recent_residual_px_.end())));
}

bool System::TrackRotationOnly(int slot, FrameReport* r) {
  // Only right after a posed frame: its centre is where the camera still is if it only turned.
  if (last_posed_slot_ != slot - 1 || last_posed_slot_ < 0) {
    panorama_bearings_.clear();
    return false;
  }
  auto bearing = [&](const FeatureUndistorted& f) {
    return Eigen::Vector3d(ideal_.PixelToNormalized(f.uv_px).homogeneous().normalized());
  };
  if (panorama_bearings_.empty()) {  // a new turn starts from the last posed frame
    const FrameRecord& prev = map_.frames[last_posed_slot_];
    // The centre: that of the latest frame of the tracked run before whose pose at least half as many points
    // agreed as at the best of the run's recent frames. The last frames before the map left the view hold few
    // points, all at one edge of the image, and their centres wander (rotation scenario, seed 6: 6.2 cm off with
    // 23 inliers, 0.9 cm two frames earlier with 45; the run's best had 77).
    int first = last_posed_slot_, most = 0;
    while (first - 1 >= 0 && first - 1 > last_posed_slot_ - kPanoramaCentreLookback && map_.frames[first - 1].has_pose)
      --first;
    for (int s = first; s <= last_posed_slot_; ++s) most = std::max(most, map_.frames[s].pose_inliers);
    panorama_centre_ = prev.cam_from_world.OriginOfTargetInSource();
    for (int s = last_posed_slot_; s >= first; --s)
      if (2 * map_.frames[s].pose_inliers >= most && map_.frames[s].pose_inliers > 0) {
        panorama_centre_ = map_.frames[s].cam_from_world.OriginOfTargetInSource();
        break;
      }
    panorama_bearings_.clear();
    const Eigen::Quaterniond world_from_cam = prev.cam_from_world.q.conjugate();
    for (const FeatureUndistorted& f : prev.features) panorama_bearings_[f.id] = world_from_cam * bearing(f);
    panorama_min_rms_px_ = std::numeric_limits<double>::infinity();
  }
  FrameRecord& fr = map_.frames[slot];
  std::vector<Eigen::Vector3d> in_world, in_cam;
  for (const FeatureUndistorted& f : fr.features)
    if (auto it = panorama_bearings_.find(f.id); it != panorama_bearings_.end())
      in_world.push_back(it->second), in_cam.push_back(bearing(f));
  geometry::RotationOnlyOptions ro;
  // Agreement within the tracks' noise: 3 σ of the difference of two noisy positions (σ √2 per coordinate),
  // σ as the map's recent residuals measure it; never over the pose step's inlier threshold, never under half a
  // pixel (a camera that moves shows as parallax that grows frame after frame, so the bound needs no more).
  const double noise_px = RecentNoisePx().value_or(options_.tracker.inlier_threshold_px);
  ro.threshold_px = std::clamp(3.0 * std::sqrt(2.0) * noise_px, 0.5, options_.tracker.inlier_threshold_px);
  ro.focal_px = focal_px_;
  ro.min_inliers = options_.rotation_only_min_tracks;
  ro.seed = options_.seed ^ (static_cast<uint64_t>(fr.index) * 0x9E3779B97F4A7C15ull);
  const geometry::RotationOnlyResult rot = geometry::EstimateRotationOnly(in_world, in_cam, ro);
  const double ratio = in_world.empty() ? 0.0 : static_cast<double>(rot.inliers) / in_world.size();
  // A camera that starts to move again while the turn goes on shows first as a residual that grows: the rotation
  // absorbs most of a sideways move, the depths' spread does not. The frames of a pure turn measure the tracks'
  // noise (the least rms so far); an rms beyond 3 standard errors of it (sqrt(2 n) inliers' worth) is a move.
  // Rotation scenario, 0.5 px noise: 0.95-1.03 px while turning, 1.14 px 2.7 cm into the move. Below a quarter
  // pixel (a KLT tracker's precision on real images) the rms is the images' own (texture, interpolation), not
  // Gaussian noise, and wanders more than that: rendered, 0.08-0.12 px while turning, 0.39 px 1 cm into the move.
  const double noise_rms = std::max(panorama_min_rms_px_, 0.25);
  const bool moved = rot.ok && std::isfinite(panorama_min_rms_px_) &&
                     rot.rms_px > noise_rms * (1.0 + 3.0 / std::sqrt(2.0 * rot.inliers));
  if (!rot.ok || ratio < options_.rotation_only_min_ratio || moved) {
    r->note = !rot.ok ? fmt::format("no turn about the last centre: {}", rot.failure)
              : moved ? fmt::format("no turn about the last centre: the tracks' residual grew to {:.2f} px from {:.2f} "
                                    "(the camera moves)", rot.rms_px, panorama_min_rms_px_)
                      : fmt::format("no turn about the last centre: {} of {} tracks agree on one", rot.inliers,
                                    in_world.size());
    panorama_bearings_.clear();
    return false;
  }
  // Only when the map is out of view: had the turn kept map points in the image, the pose step failed for
  // another reason (a jolt, wrong tracks), and a turn would hide it (fast scenario, seed 3: a frame posed so,
  // 22 of 30 tracks agreeing, sent what followed 0.7 m astray).
  const Eigen::Quaterniond q(rot.cam_from_ref);
  const Pose turned(q, -(q * panorama_centre_));
  int in_view = 0;
  for (const MapPoint& p : map_.points()) {
    Eigen::Vector2d uv;
    if (p.state != PointState::kRemoved && ideal_.ProjectWorld(turned, p.position_in_world, &uv) && ideal_.InImage(uv))
      ++in_view;
  }
  if (in_view >= options_.rotation_only_min_tracks) {
    r->note = fmt::format("no turn about the last centre: {} map points would be in view", in_view);
    panorama_bearings_.clear();
    return false;
  }
  panorama_min_rms_px_ = std::min(panorama_min_rms_px_, rot.rms_px);
  fr.has_pose = true;
  fr.cam_from_world = turned;
  last_posed_slot_ = slot;
  // Tracks born during the turn join the panorama as seen from here.
  const Eigen::Quaterniond world_from_cam = q.conjugate();
  for (const FeatureUndistorted& f : fr.features) panorama_bearings_.try_emplace(f.id, world_from_cam * bearing(f));
  r->status = FrameStatus::kTracked;
  r->has_pose = true;
  r->rotation_only = true;
  r->cam_from_world = fr.cam_from_world;
  r->smoothed_cam_from_world = smoother_.Update(fr.cam_from_world);
  r->note = fmt::format("rotation only: the map is out of view; {} of {} tracks agree on a turn about the last "
                        "centre ({:.2f} px rms)",
                        rot.inliers, in_world.size(), rot.rms_px);
  ResidualStats(slot, r);
  return true;
}

void System::MarkSeen(int slot) {
  const FrameRecord& fr = map_.frames[slot];
  for (const FeatureUndistorted& f : fr.features)
    if (MapPoint* p = map_.Find(f.id); p && p->state != PointState::kRemoved) {
      p->last_seen_frame = fr.index;
      p->state = PointState::kActive;
    }
  for (MapPoint& p : map_.points())
    if (p.state == PointState::kActive && p.last_seen_frame < fr.index) p.state = PointState::kLost;
}

int System::TriangulateNewPoints(int slot, int inliers) {
  const MappingOptions& mo = options_.mapping;
  const FrameRecord& cur = map_.frames[slot];
  geometry::TriangulationOptions to;
  to.max_reprojection_px = mo.max_reprojection_px;
  to.focal_px = focal_px_;
  // The parallax a new point needs: at least min_parallax_deg, and enough for the tracks' noise, measured as
  // the median residual of the map's points in the recent keyframes (1.18 σ for Gaussian noise of σ per
  // coordinate): a point triangulated from a parallax θ has a depth error of about σ / (f θ) of its depth,
  // and new points' depth errors are what a monocular map's scale drifts with.
  {
    FrameReport stats;
    ResidualStats(slot, &stats);
    if (stats.reproj_median_px > 0) recent_residual_px_.push_back(stats.reproj_median_px);
    if (recent_residual_px_.size() > kResidualHistory) recent_residual_px_.pop_front();
  }
  const double noise_px = RecentNoisePx().value_or(0.0);
  noise_parallax_deg_ = std::min(ParallaxForDepthNoiseDeg(noise_px, focal_px_, mo.max_relative_depth_noise),
                                 mo.max_noise_parallax_deg);
  const double wanted = std::max(mo.min_parallax_deg, noise_parallax_deg_);
  to.min_parallax_deg = inliers < mo.starving_inliers ? std::min(wanted, mo.starving_parallax_deg) : wanted;
  int added = 0;
  for (const FeatureUndistorted& f : cur.features) {
    MapPoint* existing = map_.Find(f.id);
    if (existing && (existing->state != PointState::kRemoved ||
                     cur.index - existing->removed_frame < mo.retriangulate_after_frames))
      continue;
    // Posed keyframes where this feature was seen, oldest first (the track's history).
    std::vector<int> seen;
    for (auto it = std::lower_bound(map_.keyframes.begin(), map_.keyframes.end(), pruned_until_);
         it != map_.keyframes.end(); ++it)
      if (map_.frames[*it].has_pose && map_.frames[*it].Find(f.id)) seen.push_back(*it);
    if (static_cast<int>(seen.size()) < mo.min_track_frames) continue;
    // Robust linear triangulation: a point from each of a few view pairs (first-current, and pairs that
    // skip the first or the current view in case a wrong match sits there), the views that agree with it
    // within the reprojection threshold counted, and the best pair's agreeing views triangulated together.
    // A wrong match or one noisy view then costs a view, not the point.
    const int n = static_cast<int>(seen.size());
    const int first = 0, last = n - 1, mid = n / 2;
    const int pairs[4][2] = {{first, last}, {std::min(1, last), last}, {first, std::max(last - 1, 0)}, {first, mid}};
    geometry::TriangulationOptions pair_opts = to;
    std::vector<int> best_views;
    for (const auto& pr : pairs) {
      if (pr[0] >= pr[1]) continue;
      const Pose poses2[2] = {map_.frames[seen[pr[0]]].cam_from_world, map_.frames[seen[pr[1]]].cam_from_world};
      const Eigen::Vector2d uv2[2] = {ideal_.PixelToNormalized(map_.frames[seen[pr[0]]].Find(f.id)->uv_px),
                                      ideal_.PixelToNormalized(map_.frames[seen[pr[1]]].Find(f.id)->uv_px)};
      const geometry::Triangulation t2 = geometry::TriangulateDlt(poses2, uv2, pair_opts);
      if (!t2.ok) continue;
      std::vector<int> agree;
      for (int k : seen) {
        Eigen::Vector2d uv;
        if (ideal_.ProjectWorld(map_.frames[k].cam_from_world, t2.point_in_world, &uv) &&
            (uv - map_.frames[k].Find(f.id)->uv_px).norm() <= mo.max_reprojection_px)
          agree.push_back(k);
      }
      if (agree.size() > best_views.size()) best_views = agree;
    }
    if (static_cast<int>(best_views.size()) < mo.min_track_frames) continue;
    std::vector<Pose> poses;
    std::vector<Eigen::Vector2d> uv;
    for (int k : best_views) {
      poses.push_back(map_.frames[k].cam_from_world);
      uv.push_back(ideal_.PixelToNormalized(map_.frames[k].Find(f.id)->uv_px));
    }
    const geometry::Triangulation t = geometry::TriangulateDlt(poses, uv, to);
    if (!t.ok) continue;
    MapPoint p;
    p.id = f.id;
    p.position_in_world = t.point_in_world;
    p.last_seen_frame = cur.index;
    if (existing)
      *existing = p;
    else
      map_.Add(p);
    ++added;
  }
  return added;
}

void System::PruneHistory(int slot) {
  int keep_from = slot - options_.mapping.history_frames;
  // The oldest keyframe the Fibonacci window can still reach.
  const long reach = FibonacciReach(options_.mapping.window);
  const long nkf = static_cast<long>(map_.keyframes.size());
  if (nkf > 0) keep_from = std::min(keep_from, map_.keyframes[static_cast<size_t>(std::max(0L, nkf - 1 - reach))]);
  // The initialisation and the settling work on every frame since the reference (or the first frame posed
  // before it).
  if ((!initialised_ || settling_) && reference_slot_ >= 0)
    keep_from = std::min(keep_from, posed_from_ >= 0 ? posed_from_ : reference_slot_);  // posed_from_ <= reference
  for (; pruned_until_ < keep_from; ++pruned_until_) {
    std::vector<FeatureUndistorted>().swap(map_.frames[static_cast<size_t>(pruned_until_)].features);
  }
}

std::vector<int> System::WindowSlots() const {
  std::vector<int> window;  // frame slots, newest first
  for (int wi : FibonacciWindow(static_cast<int>(map_.keyframes.size()), options_.mapping.window))
    if (map_.frames[map_.keyframes[wi]].has_pose) window.push_back(map_.keyframes[wi]);
  return window;
}

std::optional<Relocalisation> System::Relocalise(const std::vector<RelocalisationMatch>& matches) const {
  if (!initialised_) return std::nullopt;
  std::vector<PointObservation> obs;
  std::vector<Eigen::Vector3d> P;
  std::vector<Eigen::Vector2d> uv;
  std::vector<int64_t> ids;
  for (const RelocalisationMatch& m : matches) {
    const MapPoint* p = map_.Find(m.point_id);
    if (!p || p->state == PointState::kRemoved || !m.uv_px.allFinite()) continue;
    const Eigen::Vector2d u = camera_.UndistortPixel(m.uv_px);
    if (!u.allFinite()) continue;
    obs.push_back({p->position_in_world, u, true});
    P.push_back(p->position_in_world);
    uv.push_back(ideal_.PixelToNormalized(u));
    ids.push_back(m.point_id);
  }
  if (static_cast<int>(P.size()) < options_.relocalise_min_inliers) return std::nullopt;
  geometry::PnpOptions po = TrackerPnpOptions(options_.relocalise_min_inliers);
  po.iterations = 500;  // no prior and maybe half the matches wrong
  const std::optional<Pose> pose = geometry::SolvePnp(P, uv, po);
  if (!pose) return std::nullopt;
  Relocalisation r;
  r.cam_from_world = *pose;
  r.matches = static_cast<int>(P.size());
  // Inliers as the pose step counts them.
  std::vector<double> res;
  std::vector<uint8_t> inl;
  tracker_->ClassifyInliers(*pose, obs, &res, &inl);
  for (size_t i = 0; i < ids.size(); ++i)
    if (inl[i]) r.inlier_point_ids.push_back(ids[i]);
  if (static_cast<int>(r.inlier_point_ids.size()) < options_.relocalise_min_inliers) return std::nullopt;
  return r;
}

PoseEstimate System::EstimatePosePnp(const std::vector<PointObservation>& obs, std::vector<double>* res,
                                     std::vector<uint8_t>* inl) const {
  // The pose baseline (§8): RANSAC EPnP on every observed map point, refined by Levenberg-Marquardt on the
  // inliers; inliers and keyframes decided as for the Monte Carlo estimate.
  PoseEstimate est;
  std::vector<Eigen::Vector3d> P;
  std::vector<Eigen::Vector2d> uv;
  for (const PointObservation& o : obs) P.push_back(o.point_in_world), uv.push_back(ideal_.PixelToNormalized(o.uv_undistorted_px));
  // Scored as in the Monte Carlo estimate: the points that were inliers at the last pose (the keyframe rule
  // compares the inliers with these; counting every observed point made PnP stop making keyframes).
  est.scored = static_cast<int>(
      std::count_if(obs.begin(), obs.end(), [](const PointObservation& o) { return o.was_inlier; }));
  const std::optional<Pose> pose = geometry::SolvePnp(P, uv, TrackerPnpOptions(options_.tracker.min_inliers));
  res->assign(obs.size(), std::numeric_limits<double>::infinity());
  inl->assign(obs.size(), 0);
  if (!pose) {
    est.lost_reason = fmt::format("PnP failed on {} points", P.size());
    return est;
  }
  est.cam_from_world = *pose;
  est.inliers = tracker_->ClassifyInliers(*pose, obs, res, inl);
  if (est.lost_reason = options_.tracker.LostReason(est.inliers, ScoringInliers(obs, *inl), est.scored);
      !est.lost_reason.empty())
    return est;
  est.tracked = true;
  est.keyframe = est.inliers >= options_.tracker.keyframe_min_inlier_ratio * est.scored;
  return est;
}

void System::BundleAdjustWindow(int slot, FrameReport* r) {
  // The structure baseline (§8): Levenberg-Marquardt bundle adjustment (Ceres, Huber) of the poses of the
  // same Fibonacci keyframe window the Monte Carlo adjustment scores over, and of every point seen at least
  // twice in it; the oldest keyframes stay fixed (gauge and scale). Outliers leave the map by the same rule
  // as in the Monte Carlo adjustment: median residual over the window above the threshold.
  const std::vector<int> adjustable_slots = WindowSlots();
  if (adjustable_slots.size() < 3) return;
  // The cameras: every posed keyframe from the oldest of the window to this one. The window's keyframes are
  // adjusted (but for the oldest, which fix the gauge and the scale); the keyframes between them are held
  // fixed, so that a point moved here stays consistent with every view of it that a later window may use.
  std::vector<int> window;  // oldest first
  std::vector<bool> fixed;
  const int oldest = adjustable_slots.back();
  for (int k : map_.keyframes) {
    if (k < oldest || !map_.frames[k].has_pose) continue;
    const bool in_window = std::find(adjustable_slots.begin(), adjustable_slots.end(), k) != adjustable_slots.end();
    const int rank = static_cast<int>(adjustable_slots.end() - std::find(adjustable_slots.begin(), adjustable_slots.end(), k));
    window.push_back(k);
    fixed.push_back(!in_window || rank <= options_.ba_fixed_keyframes);
  }
  std::vector<Pose> cams;
  for (int k : window) cams.push_back(map_.frames[k].cam_from_world);
  WindowPoints wp = CollectWindowPoints(window);
  if (wp.pts.empty()) return;
  std::vector<Eigen::Vector3d>& X = wp.X;
  const std::vector<geometry::BundleObservation>& obs = wp.obs;
  geometry::BundleAdjustOptions bo;
  bo.focal_px = focal_px_;
  bo.huber_px = options_.init.refine_huber_px;
  bo.max_iterations = options_.ba_iterations;
  bo.cauchy = true;  // wrong matches of tens of pixels must stop pulling (Huber's pull never fades)
  geometry::BundleAdjust(cams, X, obs, fixed, bo);
  for (size_t w = 0; w < window.size(); ++w) map_.frames[window[w]].cam_from_world = cams[w];
  const int removed = StoreAdjustedPoints(cams, wp, map_.frames[slot].index);
  r->removed += removed;
  r->adjusted += static_cast<int>(wp.pts.size()) - removed;
}

void System::AdjustPoints(int slot, FrameReport* r) {
  const MappingOptions& mo = options_.mapping;
  const FrameRecord& cur = map_.frames[slot];
  std::vector<int> window;  // frame slots
  std::vector<compute::ScaledPose> poses;
  for (int ws : WindowSlots()) {
    const FrameRecord& k = map_.frames[ws];
    window.push_back(ws);
    const Eigen::Quaterniond q = k.cam_from_world.q.normalized();
    const float qf[4] = {float(q.w()), float(q.x()), float(q.y()), float(q.z())};
    const float tf[3] = {float(k.cam_from_world.t.x()), float(k.cam_from_world.t.y()), float(k.cam_from_world.t.z())};
    poses.push_back(compute::MakeScaledPose(qf, tf, float(camera_.fx), float(camera_.fy)));
  }
  if (window.size() < 2) return;

  // The residual of a point (Algorithm 2) is read robustly: the median of its reprojection distances over
  // the window's keyframes, so that one wrong match (a feature on the wrong spot in one frame) neither makes
  // a good point a candidate nor condemns it.
  auto median_residual = [&](const std::vector<std::pair<int, Eigen::Vector2d>>& views, const Eigen::Vector3d& X) {
    std::vector<double> d;
    for (const auto& [w, uv_obs] : views) {
      Eigen::Vector2d uv;
      d.push_back(ideal_.ProjectWorld(map_.frames[window[w]].cam_from_world, X, &uv) ? (uv - uv_obs).norm() : 1e9);
    }
    return UpperMedian(d);
  };

  // Candidates: points seen in this keyframe whose residual is above the threshold.
  std::vector<MapPoint*> cand;
  std::vector<double> before_residual;
  std::vector<std::vector<std::pair<int, Eigen::Vector2d>>> cand_views;
  std::vector<float> cx, cy, cz, sx, sy, sz, ou, ov;
  std::vector<int> obs_begin{0}, obs_pose;
  std::vector<std::pair<int, Eigen::Vector2d>> views;
  for (const FeatureUndistorted& f : cur.features) {
    MapPoint* p = map_.Find(f.id);
    if (!p || p->state == PointState::kRemoved) continue;
    views.clear();
    for (size_t w = 0; w < window.size(); ++w)
      if (const FeatureUndistorted* o = map_.frames[window[w]].Find(f.id)) views.emplace_back(static_cast<int>(w), o->uv_px);
    // Fewer than 3 views: one view cannot tell a point from its ray, and the median of two residuals is not
    // robust to one wrong match, so no verdict is passed on this point yet.
    if (views.size() < 3) continue;
    const double before = median_residual(views, p->position_in_world);
    if (before <= mo.candidate_threshold_px) continue;
    // Eqs. 8-9: the point displacement dz that the linearised projection model says would move its
    // projections onto the features, stacked over the window's views (Huber-weighted, so that a wrong
    // match does not drive it): unlike one view, several see the point's depth error too. The spread is
    // |dz| per axis plus a floor.
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    for (const auto& [w, uv_obs] : views) {
      Eigen::Vector2d uv;
      Eigen::Matrix<double, 2, 3> J;
      if (!ideal_.ProjectWorld(map_.frames[window[w]].cam_from_world, p->position_in_world, &uv, &J)) continue;
      const Eigen::Vector2d res = uv_obs - uv;
      const double e = res.norm(), k = 2.0 * mo.adjust_threshold_px;
      const double wgt = e <= k ? 1.0 : k / e;
      A += wgt * J.transpose() * J;
      b += wgt * J.transpose() * res;
    }
    A += 1e-6 * A.trace() * Eigen::Matrix3d::Identity();  // a ridge: a short baseline leaves depth nearly free
    Eigen::Vector3d dz = A.ldlt().solve(b);
    if (!dz.allFinite()) dz.setZero();
    const double depth = (cur.cam_from_world * p->position_in_world).z();
    if (!(depth > 0)) continue;  // behind this keyframe: no spread can be derived from it
    const Eigen::Vector3d sigma = (mo.sigma_scale * dz.cwiseAbs()).array() + mo.sigma_floor_rel_depth * depth;
    for (const auto& [w, uv_obs] : views) {
      obs_pose.push_back(w);
      ou.push_back(float(uv_obs.x() - camera_.cx));
      ov.push_back(float(uv_obs.y() - camera_.cy));
    }
    cand.push_back(p);
    before_residual.push_back(before);
    cand_views.push_back(views);
    cx.push_back(float(p->position_in_world.x())), cy.push_back(float(p->position_in_world.y()));
    cz.push_back(float(p->position_in_world.z()));
    sx.push_back(float(sigma.x())), sy.push_back(float(sigma.y())), sz.push_back(float(sigma.z()));
    obs_begin.push_back(static_cast<int>(obs_pose.size()));
  }
  if (cand.empty()) return;

  compute::PointAdjustProblem pr;
  pr.poses = poses.data();
  pr.num_poses = static_cast<int>(poses.size());
  pr.cx = cx.data(), pr.cy = cy.data(), pr.cz = cz.data();
  pr.sx = sx.data(), pr.sy = sy.data(), pr.sz = sz.data();
  pr.obs_begin = obs_begin.data();
  pr.num_points = static_cast<int>(cand.size());
  pr.obs_pose = obs_pose.data();
  pr.obs_u = ou.data(), pr.obs_v = ov.data();
  pr.params.fx = float(camera_.fx), pr.params.fy = float(camera_.fy);
  pr.params.max_distance_px = float(mo.max_distance_px);
  std::vector<compute::PointBest> best(cand.size());
  point_kernel_->Score(pr, point_normals_, mo.samples, best.data());

  // The best sample replaces the point when its residual is lower than before and under the threshold;
  // otherwise the point is an outlier and leaves the map.
  for (size_t p = 0; p < cand.size(); ++p) {
    const Eigen::Vector3d X(best[p].position[0], best[p].position[1], best[p].position[2]);
    const double after = best[p].index >= 0 ? median_residual(cand_views[p], X) : before_residual[p];
    if (after < before_residual[p] && after < mo.adjust_threshold_px) {
      cand[p]->position_in_world = X;
      ++r->adjusted;
    } else if (before_residual[p] < mo.adjust_threshold_px) {
      // A candidate below the outlier threshold that no sample improves stays as it is.
    } else {
      cand[p]->state = PointState::kRemoved;
      cand[p]->removed_frame = cur.index;
      ++r->removed;
    }
  }
}

void System::RefreshInlierFlags(int slot) {
  const FrameRecord& fr = map_.frames[slot];
  for (const FeatureUndistorted& f : fr.features)
    if (MapPoint* p = map_.Find(f.id); p && p->state != PointState::kRemoved) {
      Eigen::Vector2d uv;
      p->inlier = ideal_.ProjectWorld(fr.cam_from_world, p->position_in_world, &uv) &&
                  (uv - f.uv_px).norm() < options_.tracker.inlier_threshold_px;
    }
}

FrameReport System::PosedReport(int slot) const {
  const FrameRecord& f = map_.frames[slot];
  FrameReport r;
  r.index = f.index;
  r.stamp_s = f.stamp_s;
  r.status = FrameStatus::kTracked;
  r.has_pose = true;
  r.cam_from_world = f.cam_from_world;
  ResidualStats(slot, &r);
  return r;
}

void System::ResidualStats(int slot, FrameReport* r) const {
  const FrameRecord& fr = map_.frames[slot];
  if (!fr.has_pose) return;
  std::vector<double> all;
  double sum = 0;
  int n = 0;
  for (const FeatureUndistorted& f : fr.features) {
    const MapPoint* p = map_.Find(f.id);
    if (!p || p->state == PointState::kRemoved) continue;
    Eigen::Vector2d uv;
    if (!ideal_.ProjectWorld(fr.cam_from_world, p->position_in_world, &uv)) continue;
    const double d = (uv - f.uv_px).norm();
    all.push_back(d);
    if (d < options_.tracker.inlier_threshold_px) sum += d, ++n;
  }
  r->reproj_mean_px = n > 0 ? sum / n : 0.0;
  r->reproj_median_px = UpperMedian(all);
}

}  // namespace mcslam::slam
