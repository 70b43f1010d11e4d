// Mapping (mapper.h, paper §6.2-6.3): the frame history, new points by triangulation, tracks merged into the points
// they revisit, and after them the Monte Carlo point adjustment (point_adjuster.cc: Algorithm 2), or bundle
// adjustment of the keyframe window (the baseline), and the local bundle adjustment.
#include "slam/mapper.h"

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
#include "slam/point_adjuster.h"
#include "slam/settler.h"
#include "slam/system_internal.h"

namespace mcslam::slam {

using detail::Ms;
using detail::NoiseFromMedianResidualPx;
using detail::ParallaxForDepthNoiseDeg;

// One local bundle adjustment (Mapper::PrepareLocalBa): the problem, copied out of the map so that it can be
// solved on another thread while the map is read, and the keyframe whose report it completes.
struct Mapper::LocalBa {
  int slot = -1;
  std::vector<int> window;    // frame slots, oldest first
  size_t first_adjusted = 0;  // window[first_adjusted..] are adjusted, those before fixed
  WindowPoints wp;            // wp.X and the poses below are what the solve changes
  std::vector<Pose> cams;
  std::vector<bool> fixed, fixed_points;
  geometry::BundleAdjustOptions options;
  double prepare_ms = 0;
  // MappingOptions::local_ba_async: the solve under way (its time, ms) and the keyframe's report as Process
  // returned it.
  std::future<double> solved;
  FrameReport report;
  // Solves the problem in place; returns its time (ms).
  double Solve() {
    const auto t0 = std::chrono::steady_clock::now();
    geometry::BundleAdjust(cams, wp.X, wp.obs, fixed, options, fixed_points);
    return detail::Ms(t0);
  }
};

Mapper::Mapper(SlamState& s, Bridge& bridge, const Settler& settler, PointAdjuster& adjuster)
    : s_(s), bridge_(bridge), settler_(settler), adjuster_(adjuster) {}

Mapper::~Mapper() {
  if (pending_ba_ && pending_ba_->solved.valid()) pending_ba_->solved.wait();  // its thread reads *pending_ba_
}

int Mapper::AddFrame(const FrameObservations& frame) {
  merged_tracks_.clear();
  FrameRecord rec;
  rec.index = frame.index;
  rec.stamp_s = frame.stamp_s;
  rec.blurred = frame.blurred;
  rec.features.reserve(frame.features.size());
  size_t aliased = 0;
  for (const FeatureObservation& f : frame.features) {
    if (!f.uv_px.allFinite()) continue;
    const Eigen::Vector2d uv = s_.camera.UndistortPixel(f.uv_px);
    if (!uv.allFinite()) continue;  // a fisheye's ray too far off the axis for the back end's pinhole pixels
    int64_t id = f.feature_id;
    if (!track_alias_.empty())
      if (auto it = track_alias_.find(id); it != track_alias_.end()) id = it->second, ++aliased;
    rec.features.push_back({id, uv});
  }
  if (aliased < track_alias_.size())  // the tracks that ended: their ids never come again
    std::erase_if(track_alias_, [&](const auto& kv) {
      return std::none_of(frame.features.begin(), frame.features.end(),
                          [&](const FeatureObservation& f) { return f.feature_id == kv.first; });
    });
  std::sort(rec.features.begin(), rec.features.end(), [](const auto& a, const auto& b) { return a.id < b.id; });
  rec.features.erase(std::unique(rec.features.begin(), rec.features.end(),
                                 [](const auto& a, const auto& b) { return a.id == b.id; }),
                     rec.features.end());
  s_.map.frames.push_back(std::move(rec));
  const int slot = static_cast<int>(s_.map.frames.size()) - 1;
  PruneHistory(slot);
  return slot;
}

void Mapper::MapKeyframe(int slot, int inliers, FrameReport* r) {
  const FrameRecord& fr = s_.map.frames[slot];
  s_.map.keyframes.push_back(slot);
  r->keyframe = true;
  const auto t1 = std::chrono::steady_clock::now();
  r->new_points = TriangulateNewPoints(slot, inliers);
  r->map_ms = Ms(t1);
  if (s_.options.mapping.adjust) {
    const auto t2 = std::chrono::steady_clock::now();
    if (s_.options.structure_method == StructureMethod::kBundleAdjustment) {
      BundleAdjustWindow(slot, r);
      r->cam_from_world = fr.cam_from_world;  // the adjustment moved this keyframe too
    } else {
      adjuster_.AdjustPoints(slot, r);
      r->adjust_points_ms = Ms(t2);
      const auto t3 = std::chrono::steady_clock::now();
      std::unique_ptr<LocalBa> ba = PrepareLocalBa(slot);
      if (ba && s_.options.mapping.local_ba_async) {
        // Solved while the caller goes on; the next Process (or Flush) applies it and revises this report.
        LocalBa* solving = ba.get();
        try {
          ba->solved = std::async(std::launch::async, [solving] { return solving->Solve(); });
          pending_ba_ = std::move(ba);
        } catch (const std::system_error&) {  // no thread to be had: solved in place below
        }
      }
      if (ba) {
        ba->Solve();
        ApplyLocalBa(*ba, r);
      }
      r->local_ba_ms = Ms(t3);
      r->cam_from_world = fr.cam_from_world;  // the local adjustment moves this keyframe too
    }
    r->adjust_ms = Ms(t2);
  }
}

std::optional<FrameReport> Mapper::ApplyPending() {
  if (!pending_ba_) return std::nullopt;
  const std::unique_ptr<LocalBa> ba = std::move(pending_ba_);
  const auto t0 = std::chrono::steady_clock::now();
  const double solve_ms = ba->solved.get();  // rethrows what the solve threw
  FrameReport r = ba->report;
  r.local_ba_wait_ms = Ms(t0);
  const auto t1 = std::chrono::steady_clock::now();
  ApplyLocalBa(*ba, &r);
  // What TrackFrame reports after the adjustment when it is solved in place.
  r.cam_from_world = s_.map.frames[ba->slot].cam_from_world;
  s_.ResidualStats(ba->slot, &r);
  r.map_points = s_.MapPoints();
  r.local_ba_ms = ba->prepare_ms + solve_ms + Ms(t1);
  r.adjust_ms = r.adjust_points_ms + r.local_ba_ms;
  return r;
}

void Mapper::SetPendingReport(const FrameReport& r) {
  if (pending_ba_) pending_ba_->report = r;
}

std::optional<double> Mapper::RecentNoisePx() const {
  if (recent_residual_px_.empty()) return std::nullopt;
  return NoiseFromMedianResidualPx(
      UpperMedian(std::vector<double>(recent_residual_px_.begin(), recent_residual_px_.end())));
}

int Mapper::TriangulateNewPoints(int slot, int inliers) {
  const MappingOptions& mo = s_.options.mapping;
  const FrameRecord& cur = s_.map.frames[slot];
  geometry::TriangulationOptions to;
  to.max_reprojection_px = mo.max_reprojection_px;
  to.focal_px = s_.focal_px;
  // The parallax a new point needs: at least min_parallax_deg, and enough for the tracks' noise, measured as
  // the median residual of the map's points in the recent keyframes (1.18 σ for Gaussian noise of σ per
  // coordinate): a point triangulated from a parallax θ has a depth error of about σ / (f θ) of its depth,
  // and new points' depth errors are what a monocular map's scale drifts with.
  {
    FrameReport stats;
    s_.ResidualStats(slot, &stats);
    if (stats.reproj_median_px > 0) recent_residual_px_.push_back(stats.reproj_median_px);
    if (recent_residual_px_.size() > kResidualHistory) recent_residual_px_.pop_front();
  }
  const double noise_px = RecentNoisePx().value_or(0.0);
  noise_parallax_deg_ = std::min(ParallaxForDepthNoiseDeg(noise_px, s_.focal_px, mo.max_relative_depth_noise),
                                 mo.max_noise_parallax_deg);
  const double wanted = std::max(mo.min_parallax_deg, noise_parallax_deg_);
  const bool starving = inliers < mo.starving_inliers;
  to.min_parallax_deg = starving ? std::min(wanted, mo.starving_parallax_deg) : wanted;
  const int min_views = starving ? std::min(mo.min_track_frames, mo.starving_min_track_frames) : mo.min_track_frames;
  // The map points this frame does not observe, where they project into it (merge_revisited_points; always in a
  // loaded map, which is a place this run came back to: docs/map_format.md). Not on a provisional map: the rest of
  // the map is at another scale.
  std::vector<std::pair<int64_t, Eigen::Vector2d>> unseen;
  if (s_.MergesRevisits() && !bridge_.active())
    for (const MapPoint& p : s_.map.points()) {
      Eigen::Vector2d uv;
      if (p.state != PointState::kRemoved && !cur.Find(p.id) &&
          s_.ideal.ProjectWorld(cur.cam_from_world, p.position_in_world, &uv) &&
          s_.ideal.InImage(uv, -mo.max_reprojection_px))
        unseen.emplace_back(p.id, uv);
    }
  std::vector<std::pair<int64_t, int64_t>> merges;  // track, map point
  int added = 0;
  for (const FeatureUndistorted& f : cur.features) {
    MapPoint* existing = s_.map.Find(f.id);
    if (existing && (existing->state != PointState::kRemoved ||
                     cur.index - existing->removed_frame < mo.retriangulate_after_frames))
      continue;
    // Posed keyframes where this feature was seen, oldest first (the track's history).
    std::vector<int> seen;
    for (auto it = std::lower_bound(s_.map.keyframes.begin(), s_.map.keyframes.end(), s_.pruned_until);
         it != s_.map.keyframes.end(); ++it)
      if (s_.map.frames[*it].has_pose && s_.map.frames[*it].Find(f.id)) seen.push_back(*it);
    if (static_cast<int>(seen.size()) < min_views) continue;
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
      const Pose poses2[2] = {s_.map.frames[seen[pr[0]]].cam_from_world, s_.map.frames[seen[pr[1]]].cam_from_world};
      const Eigen::Vector2d uv2[2] = {s_.ideal.PixelToNormalized(s_.map.frames[seen[pr[0]]].Find(f.id)->uv_px),
                                      s_.ideal.PixelToNormalized(s_.map.frames[seen[pr[1]]].Find(f.id)->uv_px)};
      const geometry::Triangulation t2 = geometry::TriangulateDlt(poses2, uv2, pair_opts);
      if (!t2.ok) continue;
      std::vector<int> agree;
      for (int k : seen) {
        Eigen::Vector2d uv;
        if (s_.ideal.ProjectWorld(s_.map.frames[k].cam_from_world, t2.point_in_world, &uv) &&
            (uv - s_.map.frames[k].Find(f.id)->uv_px).norm() <= mo.max_reprojection_px)
          agree.push_back(k);
      }
      if (agree.size() > best_views.size()) best_views = agree;
    }
    if (static_cast<int>(best_views.size()) < min_views) continue;
    std::vector<Pose> poses;
    std::vector<Eigen::Vector2d> uv;
    for (int k : best_views) {
      poses.push_back(s_.map.frames[k].cam_from_world);
      uv.push_back(s_.ideal.PixelToNormalized(s_.map.frames[k].Find(f.id)->uv_px));
    }
    const geometry::Triangulation t = geometry::TriangulateDlt(poses, uv, to);
    if (!t.ok) continue;
    if (!existing && !unseen.empty())
      if (const std::optional<int64_t> old = RevisitedPoint(f, best_views, seen, unseen);
          old && std::none_of(merges.begin(), merges.end(), [&](const auto& m) { return m.second == *old; })) {
        merges.emplace_back(f.id, *old);
        continue;
      }
    MapPoint p;
    p.id = f.id;
    p.position_in_world = t.point_in_world;
    p.last_seen_frame = cur.index;
    if (existing) {
      *existing = p;
      s_.loaded_points.erase(p.id);  // where this run's views put it, no longer where a loaded map did
    } else
      s_.map.Add(p);
    if (bridge_.active()) bridge_.AddPoint(p.id);
    ++added;
  }
  for (const auto& [track, point] : merges) MergeTrack(track, point);
  return added;
}

std::optional<int64_t> Mapper::RevisitedPoint(const FeatureUndistorted& f, const std::vector<int>& views,
                                              const std::vector<int>& seen,
                                              const std::vector<std::pair<int64_t, Eigen::Vector2d>>& unseen) const {
  // An inlier of the point adjustment in every view (Algorithm 2's outlier threshold), and the only one: the
  // views' depth barely constrains (right merges measured up to 11 % of the depth off the track's own
  // triangulation), so two map points that both fit are told apart by nothing here. A point observed in a
  // keyframe beside the track is another point (two tracks at once), whatever it projects to.
  const double r = std::min(s_.options.mapping.max_reprojection_px, s_.options.mapping.adjust_threshold_px);
  std::optional<int64_t> found;
  for (const auto& [id, uv] : unseen) {
    if ((uv - f.uv_px).norm() > r) continue;
    if (std::any_of(seen.begin(), seen.end(), [&, id = id](int k) { return s_.map.frames[k].Find(id) != nullptr; }))
      continue;
    const MapPoint& p = *s_.map.Find(id);
    bool agrees = true;
    for (int k : views) {
      Eigen::Vector2d uv_k;
      agrees = s_.ideal.ProjectWorld(s_.map.frames[k].cam_from_world, p.position_in_world, &uv_k) &&
               (uv_k - s_.map.frames[k].Find(f.id)->uv_px).norm() <= r;
      if (!agrees) break;
    }
    if (!agrees) continue;
    // Where looks are known, the track must look like the point too (a nearby point of a corner-poor patch fits
    // the views as well; its look tells it apart), and only those that do are counted.
    if (s_.same_look && !s_.same_look(f.id, id)) continue;
    if (found) return std::nullopt;
    found = id;
  }
  return found;
}

void Mapper::MergeTrack(int64_t track, int64_t point) {
  for (size_t i = static_cast<size_t>(s_.pruned_until); i < s_.map.frames.size(); ++i)  // older ones have no features
    s_.map.frames[i].Rename(track, point);
  MapPoint& p = *s_.map.Find(point);
  p.state = PointState::kActive;
  p.inlier = true;
  p.last_seen_frame = s_.map.frames.back().index;
  track_alias_[track] = point;
  merged_tracks_.emplace_back(track, point);
}

void Mapper::PruneHistory(int slot) {
  int keep_from = slot - s_.options.mapping.history_frames;
  // The oldest keyframe the Fibonacci window can still reach.
  const long reach = FibonacciReach(s_.options.mapping.window);
  const long nkf = static_cast<long>(s_.map.keyframes.size());
  if (nkf > 0) keep_from = std::min(keep_from, s_.map.keyframes[static_cast<size_t>(std::max(0L, nkf - 1 - reach))]);
  // The initialisation and the settling work on every frame since the reference (or the first frame posed
  // before it).
  if ((!s_.initialised || settler_.active()) && s_.reference_slot >= 0)
    keep_from = std::min(keep_from, s_.posed_from >= 0 ? s_.posed_from : s_.reference_slot);  // s_.posed_from <= reference
  for (; s_.pruned_until < keep_from; ++s_.pruned_until) {
    std::vector<FeatureUndistorted>().swap(s_.map.frames[static_cast<size_t>(s_.pruned_until)].features);
  }
}

void Mapper::BundleAdjustWindow(int slot, FrameReport* r) {
  // The structure baseline (§8): Levenberg-Marquardt bundle adjustment (Ceres, Huber) of the poses of the
  // same Fibonacci keyframe window the Monte Carlo adjustment scores over, and of every point seen at least
  // twice in it; the oldest keyframes stay fixed (gauge and scale). Outliers leave the map by the same rule
  // as in the Monte Carlo adjustment: median residual over the window above the threshold.
  const std::vector<int> adjustable_slots = s_.WindowSlots();
  if (adjustable_slots.size() < 3) return;
  // The cameras: every posed keyframe from the oldest of the window to this one. The window's keyframes are
  // adjusted (but for the oldest, which fix the gauge and the scale); the keyframes between them are held
  // fixed, so that a point moved here stays consistent with every view of it that a later window may use.
  std::vector<int> window;  // oldest first
  std::vector<bool> fixed;
  const int oldest = adjustable_slots.back();
  for (int k : s_.map.keyframes) {
    if (k < oldest || !s_.map.frames[k].has_pose) continue;
    const bool in_window = std::find(adjustable_slots.begin(), adjustable_slots.end(), k) != adjustable_slots.end();
    const int rank = static_cast<int>(adjustable_slots.end() - std::find(adjustable_slots.begin(), adjustable_slots.end(), k));
    window.push_back(k);
    fixed.push_back(!in_window || rank <= s_.options.ba_fixed_keyframes);
  }
  std::vector<Pose> cams;
  for (int k : window) cams.push_back(s_.map.frames[k].cam_from_world);
  WindowPoints wp = s_.CollectWindowPoints(window);
  if (wp.pts.empty()) return;
  std::vector<Eigen::Vector3d>& X = wp.X;
  const std::vector<geometry::BundleObservation>& obs = wp.obs;
  geometry::BundleAdjustOptions bo;
  bo.focal_px = s_.focal_px;
  bo.huber_px = s_.options.init.refine_huber_px;
  bo.max_iterations = s_.options.ba_iterations;
  bo.cauchy = true;  // wrong matches of tens of pixels must stop pulling (Huber's pull never fades)
  geometry::BundleAdjust(cams, X, obs, fixed, bo, s_.HeldPoints(wp));  // a loaded map's points held
  for (size_t w = 0; w < window.size(); ++w) s_.map.frames[window[w]].cam_from_world = cams[w];
  const int removed = s_.StoreAdjustedPoints(cams, wp, s_.map.frames[slot].index);
  r->removed += removed;
  r->adjusted += static_cast<int>(wp.pts.size()) - removed;
}

std::unique_ptr<Mapper::LocalBa> Mapper::PrepareLocalBa(int slot) {
  const auto t0 = std::chrono::steady_clock::now();
  const MappingOptions& mo = s_.options.mapping;
  if (mo.local_ba_keyframes == 0 || settler_.active() || bridge_.active()) return nullptr;
  // Posed keyframes whose features are kept, newest first, each at least local_ba_min_step_of_depth of the
  // newest one's median depth from the one taken before it: the first local_ba_keyframes are adjusted.
  const double min_step = mo.local_ba_min_step_of_depth * s_.MedianDepthSeenBy(slot).value_or(0.0);
  std::vector<int> recent;
  Eigen::Vector3d last_centre = Eigen::Vector3d::Zero();
  for (auto it = s_.map.keyframes.rbegin(); it != s_.map.keyframes.rend() && *it >= s_.pruned_until &&
                                          static_cast<int>(recent.size()) < 3 * mo.local_ba_keyframes;
       ++it) {
    if (!s_.map.frames[*it].has_pose) continue;
    const Eigen::Vector3d centre = s_.map.frames[*it].cam_from_world.OriginOfTargetInSource();
    if (!recent.empty() && (centre - last_centre).norm() < min_step) continue;
    recent.push_back(*it);
    last_centre = centre;
  }
  const int n_adjusted = std::min<int>(mo.local_ba_keyframes, static_cast<int>(recent.size()));
  if (n_adjusted < 3) return nullptr;
  // Held fixed: the next twice as many keyframes (they see most of the same points: the gauge and the scale
  // pass through them; with only the Fibonacci keyframes fixed, KITTI 06's scale slid 5 % in its last 17
  // frames with 4 adjusted), then the Fibonacci window's older keyframes (the long-lived points).
  std::vector<int> window(recent.begin(), recent.end());  // newest first
  for (int ws : s_.WindowSlots())
    if (ws < window.back() && ws >= s_.pruned_until) window.push_back(ws);
  std::reverse(window.begin(), window.end());
  const size_t first_adjusted = window.size() - static_cast<size_t>(n_adjusted);
  std::vector<bool> fixed(window.size(), true);
  std::fill(fixed.begin() + static_cast<long>(first_adjusted), fixed.end(), false);
  // Without older keyframes (the start of the map) the oldest two adjusted ones hold the gauge.
  if (first_adjusted == 0) fixed[0] = fixed[1] = true;
  // The points seen by an adjusted keyframe (and at least twice in all), with all their views in the window.
  const WindowPoints all = s_.CollectWindowPoints(window);
  std::vector<int> keep(all.pts.size(), -1);
  for (const geometry::BundleObservation& o : all.obs)
    if (!fixed[static_cast<size_t>(o.camera)]) keep[static_cast<size_t>(o.point)] = 0;
  WindowPoints wp;
  for (size_t i = 0; i < all.pts.size(); ++i)
    if (keep[i] == 0) keep[i] = static_cast<int>(wp.pts.size()), wp.pts.push_back(all.pts[i]), wp.X.push_back(all.X[i]);
  for (const geometry::BundleObservation& o : all.obs)
    if (keep[static_cast<size_t>(o.point)] >= 0) wp.obs.push_back({o.camera, keep[static_cast<size_t>(o.point)], o.uv_norm});
  if (wp.pts.empty()) return nullptr;
  // Fewer points than the adjusted poses have parameters (6 each): the poses are held by too few views to
  // be refined together with their points. The rendered sparse scenario (16-25 points here) drifted in
  // orientation three times as fast with the adjustment as without (seed 4: 62 deg against 18 over 170 frames,
  // and 2 of 10 seeds came out mirrored). The textured scenarios and the real sequences have 60-140 and skip
  // it only in the odd frame (a turn's end, a fast jolt).
  if (static_cast<int>(wp.pts.size()) < 6 * n_adjusted) return nullptr;
  std::vector<Pose> cams;
  for (int k : window) cams.push_back(s_.map.frames[k].cam_from_world);
  geometry::BundleAdjustOptions bo;
  bo.focal_px = s_.focal_px;
  bo.cauchy = true;
  bo.huber_px = std::max(mo.local_ba_min_loss_px, mo.local_ba_loss_sigmas * RecentNoisePx().value_or(1.0));
  bo.max_iterations = s_.options.ba_iterations;
  bo.function_tolerance = mo.local_ba_function_tolerance;
  // A few tens of cameras: the dense Schur complement solves the same steps as the sparse one, 5-12 % faster
  // on the shared sequences (the same trajectories to the printed digit; docs/timing.md).
  bo.linear_solver = geometry::BundleAdjustOptions::LinearSolver::kDenseSchur;
  // A loaded map is the frame this run localises in: its points are held where it put them.
  std::vector<bool> fixed_points = s_.HeldPoints(wp);
  auto ba = std::make_unique<LocalBa>();
  ba->slot = slot;
  ba->window = std::move(window);
  ba->first_adjusted = first_adjusted;
  ba->wp = std::move(wp);
  ba->cams = std::move(cams);
  ba->fixed = std::move(fixed);
  ba->fixed_points = std::move(fixed_points);
  ba->options = bo;
  ba->prepare_ms = Ms(t0);
  return ba;
}

void Mapper::ApplyLocalBa(const LocalBa& ba, FrameReport* r) {
  for (size_t w = ba.first_adjusted; w < ba.window.size(); ++w) s_.map.frames[ba.window[w]].cam_from_world = ba.cams[w];
  r->removed += s_.StoreAdjustedPoints(ba.cams, ba.wp, s_.map.frames[ba.slot].index);
  r->local_ba = true;
  r->local_ba_span = static_cast<int>(s_.map.frames[ba.slot].index - s_.map.frames[ba.window[ba.first_adjusted]].index);
}

}  // namespace mcslam::slam
