// The two-view initialisation (initializer.h, paper §6.1): two views, the window refined by bundle adjustment, the
// depth-reversal ambiguity test and frames before the reference. The settling of the first map: settler.cc.
#include "slam/initializer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <unordered_map>

#include <Eigen/Dense>
#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include "core/median.h"
#include "geometry/bundle_adjust.h"
#include "geometry/essential.h"
#include "geometry/pnp.h"
#include "geometry/rotation_only.h"
#include "geometry/self_calibration.h"
#include "geometry/triangulation.h"
#include "slam/fibonacci.h"
#include "slam/settler.h"
#include "slam/slam_state.h"
#include "slam/system_internal.h"

namespace mcslam::slam {

using detail::Ms;
using detail::NoiseFromMedianResidualPx;
using detail::kCostFloorPx2;
using detail::MirrorInDepth;
using detail::ParallaxForDepthNoiseDeg;

Initializer::Correspondences Initializer::Correspond(int ref_slot, int cur_slot) const {
  Correspondences c;
  const FrameRecord& ref = s_.map.frames[ref_slot];
  for (const FeatureUndistorted& f : s_.map.frames[cur_slot].features) {
    const FeatureUndistorted* g = ref.Find(f.id);
    if (!g) continue;
    if (const MapPoint* p = s_.map.Find(f.id); p && p->state != PointState::kRemoved) continue;
    c.n1.push_back(s_.ideal.PixelToNormalized(g->uv_px));
    c.n2.push_back(s_.ideal.PixelToNormalized(f.uv_px));
    c.ids.push_back(f.id);
    const Eigen::Vector3d a = c.n1.back().homogeneous().normalized(), b = c.n2.back().homogeneous().normalized();
    c.motion_deg.push_back(AngleBetween(a, b) * 180.0 / M_PI);
  }
  return c;
}

double Initializer::NonRotationalMotionPx(const Correspondences& c) const {
  std::vector<Eigen::Vector3d> ref, cur;
  for (size_t i = 0; i < c.n1.size(); ++i) {
    ref.push_back(c.n1[i].homogeneous().normalized());
    cur.push_back(c.n2[i].homogeneous().normalized());
  }
  return geometry::NonRotationalMotionRad(ref, cur) * s_.focal_px;
}

std::optional<std::string> Initializer::MotionShort(const Correspondences& c) const {
  const InitOptions& io = s_.options.init;
  const double med_motion = UpperMedian(c.motion_deg);
  if (med_motion >= io.min_median_motion_deg) return std::nullopt;
  if (!(io.min_nonrotational_motion_px > 0))
    return fmt::format("median feature motion {:.2f} deg < {:.2f} deg", med_motion, io.min_median_motion_deg);
  const double nonrot_px = NonRotationalMotionPx(c);
  if (nonrot_px >= io.min_nonrotational_motion_px) return std::nullopt;
  return fmt::format("median feature motion {:.2f} deg < {:.2f} deg, {:.2f} px of it no turn explains < {:.2f} px",
                     med_motion, io.min_median_motion_deg, nonrot_px, io.min_nonrotational_motion_px);
}

Initializer::InitCounts Initializer::NeededCounts(int cur_slot) const {
  const InitOptions& io = s_.options.init;
  const int offered = static_cast<int>(std::ceil(io.min_shared_fraction *
                                                 static_cast<double>(s_.map.frames[cur_slot].features.size())));
  auto lowered = [&](int count) { return std::min(count, std::max(io.min_count_floor, offered)); };
  return {lowered(io.min_common_features), lowered(io.min_inliers), lowered(io.min_points)};
}

bool Initializer::FollowsFrom(int k, const Pose& k_from_world, int next) const {
  const FrameRecord& fk = s_.map.frames[k];
  const FrameRecord& fn = s_.map.frames[next];
  std::vector<Eigen::Vector3d> in_k, in_next;
  detail::SharedBearings(fk, fn, s_.ideal, &in_k, &in_next);
  if (in_k.size() < kMinTracksToFollow) return true;  // nothing to judge by: as PnP placed it
  const double limit_deg = std::atan(s_.options.tracker.inlier_threshold_px / s_.focal_px) * 180.0 / M_PI;
  return detail::EpipolarDisagreementDeg(in_k, in_next, fn.cam_from_world * k_from_world.Inverse()) <= limit_deg;
}

int Initializer::PoseFramesBefore(int before_slot, int first_slot, const std::function<void(FrameRecord&)>& prepare,
                                  std::vector<std::pair<int, int>>* placed) {
  int first = before_slot;
  for (int k = before_slot - 1; k >= std::max(first_slot, 0); --k) {
    FrameRecord& f = s_.map.frames[k];
    if (f.has_pose || f.features.empty()) break;
    if (prepare) prepare(f);
    int inliers = 0;
    const std::optional<Pose> pose =
        s_.PlaceByPnp(k, s_.options.tracker.min_inliers, s_.options.tracker.min_inlier_ratio, &inliers);
    if (!pose) break;
    if (!FollowsFrom(k, *pose, k + 1)) break;
    f.has_pose = true;
    f.cam_from_world = *pose;
    if (placed) placed->emplace_back(k, inliers);
    first = k;
  }
  return first;
}

namespace {

// Two refined initialisations are the same solution when their points' depths correlate at least this much
// and their last cameras' orientations agree within kSameRotationDeg.
constexpr double kSameStructureCorrelation = 0.9;
constexpr double kSameRotationDeg = 2.0;

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

std::optional<Initializer::InitHypothesis> Initializer::RefineInitWindow(const std::vector<int>& window,
                                                               const std::optional<Pose>& last_from_ref,
                                                               std::vector<Eigen::Vector3d> points,
                                                               std::vector<int64_t> point_ids,
                                                               std::string* failure, bool check_parallax) const {
  const InitOptions& io = s_.options.init;
  const double focal = s_.focal_px;
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
  po.threshold_px = s_.options.mapping.max_reprojection_px;
  std::vector<geometry::BundleObservation> obs;
  std::vector<std::vector<Eigen::Vector3d>> P(window.size());
  std::vector<std::vector<Eigen::Vector2d>> uv(window.size());
  for (size_t w = 0; w < window.size(); ++w)
    for (const FeatureUndistorted& f : s_.map.frames[window[w]].features)
      if (auto it = index.find(f.id); it != index.end()) {
        const Eigen::Vector2d n = s_.ideal.PixelToNormalized(f.uv_px);
        obs.push_back({static_cast<int>(w), it->second, n});
        P[w].push_back(h.points[it->second]);
        uv[w].push_back(n);
      }
  // Every frame placed against the points on its own (in parallel: a placement that finds no consensus, as a
  // mirror's often does, runs all its RANSAC iterations, 8 ms a frame on KITTI 06), then one that failed takes its
  // predecessor's pose, in the window's order.
  auto given = [&](size_t w) { return last_from_ref && w + 1 == window.size(); };  // the last frame's pose, given
  std::vector<std::optional<Pose>> placed(window.size());
  tbb::parallel_for(size_t{1}, window.size(), [&](size_t w) {
    if (!given(w)) placed[w] = geometry::SolvePnp(P[w], uv[w], po);
  });
  for (size_t w = 1; w < window.size(); ++w)
    if (!given(w)) h.poses[w] = placed[w] ? *placed[w] : h.poses[w - 1];
  geometry::BundleAdjustOptions bo;
  bo.focal_px = focal;
  bo.huber_px = io.refine_huber_px;
  // Tens of frames that all see the same points: the Schur complement is not formed (7-Scenes' initialisation
  // over 48 frames: 747 -> 398 ms, the same trajectory to 1e-7 m).
  bo.linear_solver = geometry::BundleAdjustOptions::LinearSolver::kIterativeSchur;
  if (io.refine_window) geometry::BundleAdjust(h.poses, h.points, obs, fixed, bo);
  std::vector<double> res;
  std::vector<std::vector<Eigen::Vector2d>> along(h.points.size());  // each track's residuals in window order (px)
  for (const geometry::BundleObservation& o : obs) {
    res.push_back(geometry::ReprojectionErrorPx(h.poses[o.camera], h.points[o.point], o.uv_norm, focal));
    const Eigen::Vector3d X = h.poses[o.camera] * h.points[o.point];
    if (X.z() > 0) along[o.point].push_back((X.head<2>() / X.z() - o.uv_norm) * focal);
  }
  h.residual_correlation = detail::PooledLag1Correlation(along);
  h.median_px = UpperMedian(res);
  h.cost = detail::CappedMeanSquarePx2(res, s_.options.mapping.max_reprojection_px);
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
  h.median_parallax_deg = refined_parallax;
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

std::vector<Initializer::InitHypothesis> Initializer::ValleyNeighbours(const std::vector<int>& window,
                                                              const std::vector<Eigen::Vector2d>& n1,
                                                              const std::vector<Eigen::Vector2d>& n2,
                                                              const std::vector<int64_t>& ids,
                                                              const InitHypothesis& winner) const {
  std::unordered_map<int64_t, int> at;
  for (size_t i = 0; i < ids.size(); ++i) at[ids[i]] = static_cast<int>(i);
  std::vector<int> used;  // the winner's points: its inliers
  for (int64_t id : winner.point_ids)
    if (auto it = at.find(id); it != at.end()) used.push_back(it->second);
  const Pose& last = winner.poses.back();
  if (used.size() < 8 || !(last.t.norm() > 0)) return {};
  // The valley's extent in rotation is about the angle the baseline subtends: the window's median parallax.
  const double radius_deg = winner.median_parallax_deg;
  if (!(radius_deg > 0)) return {};
  geometry::RefineOptions ro;
  ro.scale = s_.focal_px;
  ro.max_iterations = 100;  // the valley is flat: some starts crawl along it before they converge
  const std::vector<geometry::RelativePoseMinimum> minima =
      geometry::RelativePoseMinima(Pose(last.q, last.t.normalized()), n1, n2, used, radius_deg, ro);
  if (minima.empty()) return {};
  // The winner's own basin: the minimum nearest its rotation (its cost the bar the others are measured by).
  auto own = std::min_element(minima.begin(), minima.end(), [&](const auto& a, const auto& b) {
    return AngularDistanceDeg(a.cam2_from_cam1.q, last.q) < AngularDistanceDeg(b.cam2_from_cam1.q, last.q);
  });
  // The noise variance of one correspondence's Sampson distance, from the cheapest minimum; a minimum competes
  // when it is cheaper than the winner's, or worse by less than the ambiguity test's chi-square.
  const double variance = std::max(minima.front().cost / static_cast<double>(used.size()), kCostFloorPx2);
  std::vector<InitHypothesis> out;
  for (auto m = minima.begin(); m != minima.end(); ++m) {
    if (m == own || (m->cost - own->cost) / variance >= s_.options.init.ambiguity_chi2) continue;
    // Cheirality decides the translation's sign: the points of the winner's inliers in front of both views.
    geometry::InFrontOfBoth best;
    Pose best_pose;
    for (const Pose& pose : {m->cam2_from_cam1, Pose(m->cam2_from_cam1.q, -m->cam2_from_cam1.t)})
      if (geometry::InFrontOfBoth in_front = geometry::TriangulateInFrontOfBoth(pose, n1, n2, used);
          in_front.indices.size() > best.indices.size())
        best = std::move(in_front), best_pose = pose;
    std::vector<int64_t> best_ids;
    for (int i : best.indices) best_ids.push_back(ids[i]);
    if (2 * best.indices.size() < used.size()) continue;
    // Refined whatever its parallax: short of it, it still stands against the winner in the ambiguity test.
    std::optional<InitHypothesis> h = RefineInitWindow(window, best_pose, std::move(best.points_in_cam1), std::move(best_ids),
                                                       nullptr, /*check_parallax=*/false);
    if (!h) continue;
    h->two_view_inliers = winner.two_view_inliers;
    h->two_view_parallax_deg = winner.two_view_parallax_deg;
    h->eligible = h->parallax_ok;
    out.push_back(std::move(*h));
  }
  return out;
}

std::optional<Initializer::InitHypothesis> Initializer::SolveInitWindow(const std::vector<int>& window,
                                                              const std::vector<Eigen::Vector2d>& n1,
                                                              const std::vector<Eigen::Vector2d>& n2,
                                                              const std::vector<int64_t>& ids, int need_inliers,
                                                              int need_points, std::string* why, bool* rejected,
                                                              InlierSupply* most_inliers) const {
  const InitOptions& io = s_.options.init;
  auto fail = [&](std::string s, bool ambiguous) -> std::optional<InitHypothesis> {
    *why = std::move(s);
    *rejected = ambiguous;
    return std::nullopt;
  };
  // Two-view hypotheses: the 8-point method with two RANSAC seeds, OpenCV's 5-point method, and, when a
  // homography explains the views (a dominant plane), the motions of its decomposition. Each places every
  // frame of the window by PnP against its points and is refined by one bundle adjustment over the whole
  // window; the one that explains the window best is kept. With a narrow field of view two views leave a
  // near-free bas-relief direction and sometimes a twisted pair; a wrong basin cannot explain tens of views
  // as well as the right one.
  const double focal = s_.focal_px;
  std::string last_failure;
  geometry::TwoViewOptions tv;
  tv.ransac_threshold_px = io.ransac_threshold_px;
  tv.focal_px = focal;
  tv.max_reprojection_px = s_.options.mapping.max_reprojection_px;
  if (most_inliers) *most_inliers = {-1, std::max(need_inliers, tv.min_inliers)};
  std::vector<geometry::TwoViewResult> seeds;
  const std::pair<geometry::EssentialMethod, uint64_t> tries[] = {{io.method, s_.options.seed},
                                                                   {io.method, s_.options.seed + 1},
                                                                   {geometry::EssentialMethod::kFivePointOpenCV, 0},
                                                                   {geometry::EssentialMethod::kEightPoint, s_.options.seed + 2}};
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
    // Every try that got as far as counting its inliers (a model was found) counts; the later checks keep the count.
    const bool counted = tvr.ok || (tvr.status != geometry::TwoViewStatus::kBadInput &&
                                    tvr.status != geometry::TwoViewStatus::kTooFewCorrespondences &&
                                    tvr.status != geometry::TwoViewStatus::kNoModel);
    if (most_inliers && counted) most_inliers->found = std::max(most_inliers->found, tvr.num_inliers);
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

  // Each seed that passes the gates (and a plane's motions, judged together: one short of the gates still stands
  // against the other) refined over the window; the refinements are independent single-threaded fits, run side by
  // side (KITTI 06's start: 5 of 14 ms each), and read in the seeds' order.
  struct Refinement {
    bool passes = false, refine = false;
    std::optional<InitHypothesis> h;
    std::string failure;
  };
  std::vector<Refinement> refinements(seeds.size());
  for (size_t k = 0; k < seeds.size(); ++k) {
    const geometry::TwoViewResult& tvr = seeds[k];
    refinements[k].passes = tvr.num_inliers >= need_inliers && tvr.num_triangulated >= need_points &&
                            tvr.median_parallax_deg >= io.min_median_parallax_deg;
    refinements[k].refine = refinements[k].passes || k >= num_essential_seeds;
  }
  tbb::parallel_for(size_t{0}, seeds.size(), [&](size_t k) {
    Refinement& r = refinements[k];
    if (!r.refine) return;
    const geometry::TwoViewResult& tvr = seeds[k];
    std::vector<Eigen::Vector3d> points;
    std::vector<int64_t> point_ids;
    for (size_t i = 0; i < ids.size(); ++i)
      if (tvr.triangulated[i]) points.push_back(tvr.points_in_cam1[i]), point_ids.push_back(ids[i]);
    r.h = RefineInitWindow(window, tvr.cam2_from_cam1, std::move(points), std::move(point_ids), &r.failure, r.passes);
  });
  std::vector<InitHypothesis> refined;
  for (size_t k = 0; k < seeds.size(); ++k) {
    const geometry::TwoViewResult& tvr = seeds[k];
    Refinement& r = refinements[k];
    if (!r.passes)
      last_failure = fmt::format("two-view: {} inliers, {} points, median parallax {:.2f} deg (need {}, {}, {:.2f})",
                                 tvr.num_inliers, tvr.num_triangulated, tvr.median_parallax_deg, need_inliers,
                                 need_points, io.min_median_parallax_deg);
    if (!r.refine) continue;
    if (!r.h) {
      if (r.passes) last_failure = r.failure;
      continue;
    }
    r.h->two_view_inliers = tvr.num_inliers;
    r.h->two_view_parallax_deg = tvr.median_parallax_deg;
    r.h->eligible = r.passes;
    refined.push_back(std::move(*r.h));
  }
  auto cheapest = [&] {
    auto best_it = refined.end();
    for (auto it = refined.begin(); it != refined.end(); ++it)
      if (it->eligible && (best_it == refined.end() || it->cost < best_it->cost)) best_it = it;
    return best_it;
  };
  if (cheapest() == refined.end()) return fail(last_failure, false);
  // The bas-relief valley: through a narrow field of view the two views' cost is nearly flat along a trade of
  // rotation for sideways translation and may hold more than one minimum there; every seed above may have
  // stopped in the wrong one. The other minima near the winner that might compete with it (cheaper by the two
  // views, or within the ambiguity test's reach) are refined over the window too; the window decides.
  {
    const InitHypothesis winner = *cheapest();
    for (InitHypothesis& h : ValleyNeighbours(window, n1, n2, ids, winner)) refined.push_back(std::move(h));
  }
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
  // A track's residuals are correlated along it where its error is not the tracker's noise but a bias that
  // changes smoothly with the view (a corner that is an edge's T-junction or a silhouette): then its observations
  // are not independent and the chi-square below, summed over them, overstates what the window tells. With the
  // lag-1 correlation rho of consecutive residuals along the tracks (of the best solution), n observations count
  // as n (1 - rho) / (1 + rho), the effective size of an AR(1) sample; rho < 0 counts as 0 (never bolder).
  const double rho = std::clamp(best->residual_correlation, 0.0, 1.0);
  const double effective = (1.0 - rho) / (1.0 + rho);
  for (const InitHypothesis& h : refined) {
    const bool distinct = DepthCorrelation(best->points, best->point_ids, h.points, h.point_ids) < kSameStructureCorrelation ||
                          AngularDistanceDeg(best->poses.back().q, h.poses.back().q) > kSameRotationDeg;
    // How much worse it explains the window, as a chi-square: the summed squared residuals' difference over
    // the window's noise variance (the best solution's mean squared residual, at least the floor's), over the
    // effective number of observations.
    const double chi2 =
        (h.cost - best->cost) * best->observations * effective / std::max(best->cost, kCostFloorPx2);
    if (distinct && chi2 < io.ambiguity_chi2) {
      // An ineligible solution (short of parallax, a plane's second motion) may even explain it better.
      return fail(fmt::format("ambiguous initialisation: {} explains the window {} the best solution that may be "
                              "taken (mean squared residual {:.4f} against {:.4f} px^2): waiting for more motion",
                              h.mirrored ? "its mirror in depth" : "another solution with another structure",
                              h.cost < best->cost ? "better than" : "about as well as", h.cost, best->cost),
                  true);
    }
  }
  return best;
}

int Initializer::SharedFeatures(int s, int cur_slot) const {
  int n = 0;
  for (const FeatureUndistorted& f : s_.map.frames[cur_slot].features) n += s_.map.frames[s].Find(f.id) != nullptr;
  return n;
}

void Initializer::MoveStarvedReference(int cur_slot, size_t shared, const InlierSupply& supply,
                                  std::vector<FrameReport>* out) {
  // The tracks a reference shares with later frames only ever get fewer (a track that ends never comes back), so
  // a reference whose shared tracks gave fewer epipolar inliers than a solution needs will not give them later:
  // it moves on to the oldest frame since it that shares enough tracks with this one to give them, at the share of
  // outliers just measured (or, short of any, to the one that shares the most, if more than it), keeping as much
  // of the motion gathered as it can. Before, a low-texture scene could wait for good: the rendered sparse
  // scenario, seed 1, kept frame 0 as its reference for 190 frames, 15 tracks shared and 12-14 of them inliers
  // against the 15 the two-view geometry needs.
  const int outliers = static_cast<int>(shared) - supply.found;
  const int wanted = supply.needed + std::max(outliers, 0);
  int best_slot = -1, best_shared = static_cast<int>(shared);
  for (int s = s_.reference_slot + 1; s < cur_slot; ++s) {
    const int n = SharedFeatures(s, cur_slot);
    if (n >= wanted) {
      best_slot = s;
      break;
    }
    if (n > best_shared) best_slot = s, best_shared = n;
  }
  if (best_slot < 0) return;
  s_.reference_slot = best_slot;
  out->front().note += fmt::format("; the reference shares too few tracks to give them ({} of {} fit, {} needed): "
                                   "the reference moves on to frame {}",
                                   supply.found, shared, supply.needed, s_.map.frames[best_slot].index);
}

bool Initializer::TryInitialise(std::vector<FrameReport>* out) {
  const InitOptions& io = s_.options.init;
  const int cur_slot = static_cast<int>(s_.map.frames.size()) - 1;
  auto note = [&](std::string s, InitWait wait, int count = 0, int needed = 0) {
    FrameReport r;
    r.note = std::move(s);
    r.init_wait = wait;
    r.init_count = count;
    r.init_needed = needed;
    out->assign(1, r);
    return false;
  };
  if (s_.reference_slot < 0) {
    s_.reference_slot = cur_slot;
    return note("reference frame for initialisation", InitWait::kReference);
  }
  // Correspondences between the reference and this frame. Forward motion (a car) and fast turns lose features
  // quickly: when too few are shared, the reference moves on to the oldest frame since it that still shares
  // enough with this one, so that the motion gathered since is kept (moving it to this frame would start over).
  const InitCounts need = NeededCounts(cur_slot);
  Correspondences c = Correspond(s_.reference_slot, cur_slot);
  if (static_cast<int>(c.ids.size()) < need.common) {
    int next = cur_slot;
    for (int s = s_.reference_slot + 1; s < cur_slot && next == cur_slot; ++s) {
      if (SharedFeatures(s, cur_slot) >= need.common) next = s;
    }
    const size_t had = c.ids.size();
    s_.reference_slot = next;
    if (next == cur_slot)
      return note(fmt::format("only {} features shared with the reference ({} needed): new reference", had, need.common),
                  InitWait::kFewShared, static_cast<int>(had), need.common);
    c = Correspond(s_.reference_slot, cur_slot);
  }
  const FrameRecord& ref = s_.map.frames[s_.reference_slot];
  const FrameRecord& cur = s_.map.frames[cur_slot];
  // A blurred frame's corners lie off where the sharp frames see them: the first map, which every later pose
  // builds on, waits for a sharp one (the rendered fast scenario with two of every ten frames blurred, seed 1,
  // initialised on its blurred frame 3 and lost the 23-point map in the next).
  if (cur.blurred) return note("a blurred frame: the initialisation waits for a sharp one", InitWait::kBlurred);
  if (std::optional<std::string> short_of = MotionShort(c)) return note(std::move(*short_of), InitWait::kMotion);

  // The window: every frame from the reference to this one but the blurred ones (posed after the map is made, below).
  // A blurred frame's corners lie off where the sharp frames see them, in a direction the blur sets, so they bias
  // the refined window where a sharp frame's only add noise: the rendered planar scenario with two of every ten
  // frames blurred and exposure steps, seed 8, initialised on a window holding six blurred frames, its first 40
  // frames 3.4 deg off in orientation and the run 26 cm off (8 % of the path) as its scale drifted through a
  // 34-point map; without them 0.7 cm. The reference stays, blurred or not: it is the world and one of the two views.
  std::vector<int> window, blurred;
  for (int s = s_.reference_slot; s <= cur_slot; ++s)
    (s == s_.reference_slot || !s_.map.frames[s].blurred ? window : blurred).push_back(s);
  if (static_cast<int>(window.size()) < io.min_window_frames)
    return note(fmt::format("{} frames since the reference{} (the window needs {}: two views leave the depth "
                            "reversal open)",
                            window.size(), blurred.empty() ? "" : " not blurred", io.min_window_frames),
                InitWait::kWindow);
  std::string why;
  bool rejected = false;
  InlierSupply supply;
  std::optional<InitHypothesis> best =
      SolveInitWindow(window, c.n1, c.n2, c.ids, need.inliers, need.points, &why, &rejected, &supply);
  if (!best) {
    const bool starved = supply.found >= 0 && supply.found < supply.needed;  // too few inliers for any solution
    if (rejected)
      note(why, InitWait::kRejected);
    else if (starved)
      note(why, InitWait::kFewInliers, supply.found, supply.needed);
    else
      note(why, InitWait::kGeometry);
    out->front().init_rejected = rejected;
    if (starved) MoveStarvedReference(cur_slot, c.ids.size(), supply, out);
    return false;
  }

  // Gauge: the reference camera is the world; the first baseline has length 1, or the true length when
  // the ground truth is offered (--gt-scale, as the paper sets the scale by hand for its precision test).
  double baseline = 1.0;
  if (s_.oracle) {
    const std::optional<double> d = s_.oracle(ref.stamp_s, cur.stamp_s);
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
    s_.map.Add(p);
    depths.push_back(p.position_in_world.z());
  }
  for (size_t w = 0; w < window.size(); ++w) {
    FrameRecord& f = s_.map.frames[window[w]];
    f.has_pose = true;
    f.cam_from_world = best->poses[w];
    f.cam_from_world.t *= s;
    s_.map.keyframes.push_back(window[w]);
  }
  s_.last_posed_slot = cur_slot;
  settler_.BeginSettling(cur_slot, baseline, best->two_view_parallax_deg, need.points);
  s_.MarkSeen(cur_slot);
  s_.RefreshInlierFlags(cur_slot);
  s_.pose_step->SetTranslationFloor(s_.options.sigma_trans_floor_rel_depth * UpperMedian(depths));
  s_.initialised = true;
  s_.posed_from = io.pose_frames_before_reference ? PoseFramesBefore(s_.reference_slot, s_.pruned_until) : s_.reference_slot;

  out->clear();
  s_.smoother.Reset();
  for (size_t w = 0; w < window.size(); ++w) {
    FrameReport r = s_.PosedReport(window[w]);
    r.keyframe = true;
    r.initialisation = true;
    r.smoothed_cam_from_world = s_.smoother.Update(r.cam_from_world);
    if (w + 1 == window.size()) {
      r.new_points = static_cast<int>(depths.size());
      r.note = fmt::format(
          "initialised from frames {} and {}: {} inliers, {} points, median parallax {:.2f} deg, window of {} frames "
          "refined to a median reprojection error of {:.2f} px{}",
          ref.index, cur.index, best->two_view_inliers, depths.size(), best->two_view_parallax_deg,
          window.size(), best->median_px,
          best->mirrored ? " (the depth-reversed twin of the two-view solution, which explained the window better)" : "");
    }
    r.map_points = s_.MapPoints();
    out->push_back(r);
  }
  // The blurred frames of the window: each placed by PnP against the new map where it can be (not a keyframe: its
  // features make no point), reported after the window's; one that cannot be keeps its waiting report.
  for (int k : blurred) {
    const std::optional<Pose> pose = s_.PlaceByPnp(k, s_.options.tracker.min_inliers, s_.options.tracker.min_inlier_ratio);
    if (!pose) continue;
    FrameRecord& f = s_.map.frames[k];
    f.has_pose = true;
    f.cam_from_world = *pose;
    FrameReport r = s_.PosedReport(k);
    r.initialisation = true;
    r.smoothed_cam_from_world = r.cam_from_world;
    r.note = fmt::format("a blurred frame of the initialisation's window (frame {}): posed against its map, not "
                         "refined with it", cur.index);
    r.map_points = s_.MapPoints();
    out->push_back(r);
  }
  // The frames before the reference: poses, unsmoothed (the smoother runs forward from the reference). After
  // the window's reports, so that the first report with a note is the one that says how the map was made.
  for (int k = s_.posed_from; k < s_.reference_slot; ++k) {
    FrameReport r = s_.PosedReport(k);
    r.initialisation = true;
    r.smoothed_cam_from_world = r.cam_from_world;
    r.note = fmt::format("posed at the initialisation (frame {}), before its reference frame", cur.index);
    out->push_back(r);
  }
  return true;
}

}  // namespace mcslam::slam
