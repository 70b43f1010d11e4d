// The System: its options' checks and the per-frame loop (Process). The stages live in their own files:
// system_init.cc (§6.1: two-view initialisation), system_settle.cc (the first map's settling), system_track.cc
// (§5: the pose step, rotation-only tracking, relocalisation), system_map.cc (§6.2-6.3: triangulation, Monte
// Carlo point adjustment, bundle adjustment, the frame history), system_bridge.cc (the provisional map after a
// turn).
#include "slam/system.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <unordered_map>
#include <utility>

#include <Eigen/Dense>
#include <fmt/format.h>

#include "core/median.h"
#include "geometry/bundle_adjust.h"
#include "geometry/pnp.h"
#include "geometry/rotation_only.h"
#include "geometry/triangulation.h"
#include "slam/fibonacci.h"
#include "slam/system_internal.h"

namespace mcslam::slam {

using detail::Ms;
using detail::NoiseFromMedianResidualPx;
using detail::ParallaxForDepthNoiseDeg;

namespace {

void Fail(const std::string& what) { throw std::invalid_argument(what); }

// The report of a frame that loses its pose with its map (SystemOptions::restart_min_lost_frames).
FrameReport DroppedReport(const FrameRecord& f, std::string note) {
  FrameReport r;
  r.index = f.index;
  r.stamp_s = f.stamp_s;
  r.status = FrameStatus::kLost;
  r.map_dropped = true;
  r.note = std::move(note);
  return r;
}

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
  if (!(calibration_min_z > 0)) Fail(fmt::format("init: calibration_min_z must be > 0, got {}", calibration_min_z));
  if (!(calibration_min_shift_px >= 0))
    Fail(fmt::format("init: calibration_min_shift_px must be >= 0, got {}", calibration_min_shift_px));
  if (!(calibration_min_half_share >= 0 && calibration_min_half_share <= 1))
    Fail(fmt::format("init: calibration_min_half_share must be in [0, 1], got {}", calibration_min_half_share));
}

void MappingOptions::Check() const {
  if (history_frames < 1) Fail(fmt::format("mapping: history_frames must be >= 1, got {}", history_frames));
  if (local_ba_keyframes < 0 || local_ba_keyframes == 1 || local_ba_keyframes > 64)
    Fail(fmt::format("mapping: local_ba_keyframes must be 0 (off) or in [2, 64], got {}", local_ba_keyframes));
  if (!(local_ba_loss_sigmas > 0 && local_ba_loss_sigmas <= 100))
    Fail(fmt::format("mapping: local_ba_loss_sigmas must be in (0, 100], got {}", local_ba_loss_sigmas));
  if (!(local_ba_min_loss_px > 0 && local_ba_min_loss_px <= 100))
    Fail(fmt::format("mapping: local_ba_min_loss_px must be in (0, 100], got {}", local_ba_min_loss_px));
  if (!(local_ba_min_step_of_depth >= 0 && local_ba_min_step_of_depth <= 1))
    Fail(fmt::format("mapping: local_ba_min_step_of_depth must be in [0, 1], got {}", local_ba_min_step_of_depth));
  if (retriangulate_after_frames < 1)
    Fail(fmt::format("mapping: retriangulate_after_frames must be >= 1, got {}", retriangulate_after_frames));
  if (min_track_frames < 2) Fail(fmt::format("mapping: min_track_frames must be >= 2, got {}", min_track_frames));
  if (!(min_parallax_deg >= 0)) Fail(fmt::format("mapping: min_parallax_deg must be >= 0, got {}", min_parallax_deg));
  if (!(max_relative_depth_noise > 0))
    Fail(fmt::format("mapping: max_relative_depth_noise must be > 0, got {}", max_relative_depth_noise));
  if (!(max_noise_parallax_deg >= 0 && max_noise_parallax_deg < 90))
    Fail(fmt::format("mapping: max_noise_parallax_deg must be in [0, 90), got {}", max_noise_parallax_deg));
  if (starving_inliers < 0) Fail(fmt::format("mapping: starving_inliers must be >= 0, got {}", starving_inliers));
  if (starving_min_track_frames < 2)
    Fail(fmt::format("mapping: starving_min_track_frames must be >= 2, got {}", starving_min_track_frames));
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
  if (restart_min_lost_frames < 0)
    Fail(fmt::format("restart_min_lost_frames must be >= 0 (0: never), got {}", restart_min_lost_frames));
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
      point_kernel_(std::move(point_kernel)),
      smoother_(options.smoother) {
  options_.tracker.seed = options_.seed;  // one seed for every draw of the System
  camera_.Check();
  options_.Check();
  if (!pose_kernel || !point_kernel_) throw std::invalid_argument("system: compute kernels missing");
  // The pose step (§5) exists from the start; its translation floor is set when the map's scale is known.
  tracker_ = std::make_unique<PoseTracker>(ideal_, options_.tracker, std::move(pose_kernel));
  point_normals_ = compute::NormalTable(options_.mapping.samples, options_.seed, /*stream=*/2);
  given_camera_ = camera_;
}

System& System::operator=(System&& other) noexcept = default;

System::~System() {
  if (pending_ba_ && pending_ba_->solved.valid()) pending_ba_->solved.wait();  // its thread reads *pending_ba_
}

void System::ApplyPendingAdjustment() {
  if (!pending_ba_) return;
  const std::unique_ptr<LocalBa> ba = std::move(pending_ba_);
  const auto t0 = std::chrono::steady_clock::now();
  const double solve_ms = ba->solved.get();  // rethrows what the solve threw
  FrameReport r = ba->report;
  r.local_ba_wait_ms = Ms(t0);
  const auto t1 = std::chrono::steady_clock::now();
  ApplyLocalBa(*ba, &r);
  // What TrackFrame reports after the adjustment when it is solved in place.
  r.cam_from_world = map_.frames[ba->slot].cam_from_world;
  ResidualStats(ba->slot, &r);
  r.map_points = map_.CountInState(PointState::kActive) + map_.CountInState(PointState::kLost);
  r.local_ba_ms = ba->prepare_ms + solve_ms + Ms(t1);
  r.adjust_ms = r.adjust_points_ms + r.local_ba_ms;
  held_reports_.push_back(std::move(r));
}

std::vector<FrameReport> System::Flush() {
  ApplyPendingAdjustment();
  return std::exchange(held_reports_, {});
}

int System::PosedFrames() const {
  return static_cast<int>(std::count_if(map_.frames.begin(), map_.frames.end(), [](const FrameRecord& f) { return f.has_pose; }));
}

std::vector<FrameReport> System::Finish() {
  std::vector<FrameReport> out = Flush();
  if (!dropped_map_) return out;
  // The run ended before the map started after a restart outgrew the one before it: that one's poses stand, and
  // the new map's frames lose theirs (one map's frames in the trajectory).
  const std::string note = fmt::format("posed in a map started after the map before it stayed lost; the run ended "
                                       "before it posed more frames than the {} of that map, whose poses stand",
                                       dropped_posed_);
  for (const FrameRecord& f : map_.frames)
    if (f.has_pose) out.push_back(DroppedReport(f, note));
  finished_with_dropped_map_ = true;
  return out;
}

std::vector<FrameReport> System::Process(const FrameObservations& frame) {
  std::vector<FrameReport> out = Flush();
  std::vector<FrameReport> now;
  try {
    now = ProcessFrame(frame);
  } catch (...) {
    held_reports_ = std::move(out);  // applied to the map already: the next Flush returns them
    throw;
  }
  // An adjustment this frame started completes the frame's report as ProcessFrame returns it (with what the
  // paths after TrackFrame added, e.g. a relocalisation's note).
  if (pending_ba_)
    for (const FrameReport& r : now)
      if (r.index == frame.index) pending_ba_->report = r;
  now = MaybeRestart(frame, std::move(now));
  // A new map after a restart: once it has posed more frames than the map before it, that map's frames lose their
  // poses (before the new map's reports of this frame).
  if (dropped_map_ && PosedFrames() > dropped_posed_) {
    std::vector<FrameReport> dropped = std::exchange(dropped_reports_, {});
    dropped_map_.reset();
    dropped_self_calibration_.reset();
    out.insert(out.end(), std::make_move_iterator(dropped.begin()), std::make_move_iterator(dropped.end()));
  }
  out.insert(out.end(), std::make_move_iterator(now.begin()), std::make_move_iterator(now.end()));
  return out;
}

std::vector<FrameReport> System::MaybeRestart(const FrameObservations& frame, std::vector<FrameReport> now) {
  const auto current = std::find_if(now.begin(), now.end(), [&](const FrameReport& r) { return r.index == frame.index; });
  const bool lost = current != now.end() && current->status == FrameStatus::kLost;
  lost_run_ = lost ? lost_run_ + 1 : 0;
  if (!lost || options_.restart_min_lost_frames == 0 || !loaded_points_.empty() || lost_run_ < options_.restart_min_lost_frames)
    return now;
  std::vector<const FrameRecord*> posed;
  for (const FrameRecord& f : map_.frames)
    if (f.has_pose) posed.push_back(&f);
  if (posed.empty() || lost_run_ <= static_cast<int>(posed.size())) return now;
  // Its pending adjustment is applied first (its thread reads the map); its revised report goes with the map.
  ApplyPendingAdjustment();
  held_reports_.clear();
  const std::string why = fmt::format("lost for {} frames in a row, more than the {} frames the map posed ({}-{}): a "
                                      "new map is started, which replaces this one once it has posed more frames",
                                      lost_run_, posed.size(), posed.front()->index, posed.back()->index);
  // This map's frames, reported again without a pose: once the new map has posed more frames than this one (until
  // then this map's poses stand, and a run that ends first keeps them: Finish).
  const std::string note = fmt::format(
      "its map was replaced: lost at frame {} for {} frames in a row, more than the {} it posed", frame.index, lost_run_,
      posed.size());
  std::vector<FrameReport> dropped;
  for (const FrameRecord* f : posed) dropped.push_back(DroppedReport(*f, note));
  std::vector<FrameReport> out;
  std::vector<FrameReport> pending;
  std::optional<Map> pending_map;
  std::optional<SelfCalibration> pending_calibration;
  int pending_posed = 0;
  if (dropped_map_) {
    // A map before this one still waits to be replaced (this one never posed more than it): it stays the one a new
    // map must outgrow, and this one's frames lose their poses now.
    out = std::move(dropped);
    pending = std::move(dropped_reports_);
    pending_map = std::move(dropped_map_);
    pending_calibration = std::move(dropped_self_calibration_);
    pending_posed = dropped_posed_;
  } else {
    pending = std::move(dropped);
    pending_posed = static_cast<int>(posed.size());
    pending_map = std::move(map_);
    pending_calibration = self_calibration_;
  }
  // A new System in this one's place, with its kernels, camera as given, options and baseline oracle.
  std::unique_ptr<compute::PoseKernel> pose_kernel = tracker_->ReleaseKernel();
  std::unique_ptr<compute::PointKernel> point_kernel = std::move(point_kernel_);
  auto oracle = std::move(oracle_);
  const int restarts = restarts_ + 1;
  *this = System(given_camera_, options_, std::move(pose_kernel), std::move(point_kernel));
  oracle_ = std::move(oracle);
  restarts_ = restarts;
  dropped_reports_ = std::move(pending);
  dropped_map_ = std::move(pending_map);
  dropped_self_calibration_ = std::move(pending_calibration);
  dropped_posed_ = pending_posed;
  std::vector<FrameReport> again = ProcessFrame(frame);
  for (FrameReport& r : again)
    if (r.index == frame.index) {
      r.map_restarted = true;
      r.note = why + (r.note.empty() ? "" : "; " + r.note);
    }
  out.insert(out.end(), std::make_move_iterator(again.begin()), std::make_move_iterator(again.end()));
  return out;
}

void System::StartInMap(std::vector<MapPoint> points, std::vector<FrameRecord> keyframes,
                        const std::optional<PinholeCamera>& camera) {
  if (!map_.frames.empty() || initialised_) throw std::logic_error("System::StartInMap: only before the first frame");
  if (camera) {
    camera->Check();
    camera_ = *camera;
  }
  for (MapPoint& p : points) {
    loaded_points_.insert(p.id);
    p.state = PointState::kLost;
    p.inlier = true;
    p.last_seen_frame = -1;
    p.removed_frame = -1;
    map_.Add(p);
  }
  for (FrameRecord& f : keyframes) {
    f.has_pose = true;
    map_.keyframes.push_back(static_cast<int>(map_.frames.size()));
    map_.frames.push_back(std::move(f));
  }
  initialised_ = true;
  // The pose step's translation floor, as the initialisation sets it: from the median depth of the points in
  // the first camera.
  std::vector<double> depths;
  if (!map_.frames.empty())
    for (const MapPoint& p : map_.points())
      if (const double z = (map_.frames.front().cam_from_world * p.position_in_world).z(); z > 0) depths.push_back(z);
  if (!depths.empty()) tracker_->SetTranslationFloor(options_.sigma_trans_floor_rel_depth * UpperMedian(depths));
}

std::vector<FrameReport> System::ProcessFrame(const FrameObservations& frame) {
  merged_tracks_.clear();
  FrameRecord rec;
  rec.index = frame.index;
  rec.stamp_s = frame.stamp_s;
  rec.blurred = frame.blurred;
  rec.features.reserve(frame.features.size());
  size_t aliased = 0;
  for (const FeatureObservation& f : frame.features) {
    if (!f.uv_px.allFinite()) continue;
    const Eigen::Vector2d uv = camera_.UndistortPixel(f.uv_px);
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
  map_.frames.push_back(std::move(rec));
  const int slot = static_cast<int>(map_.frames.size()) - 1;
  PruneHistory(slot);

  std::vector<FrameReport> out;
  if (initialised_ && last_posed_slot_ < 0 && !frame.pose_hint) {  // in a loaded map, not localised yet
    FrameReport r;
    r.index = frame.index;
    r.stamp_s = frame.stamp_s;
    r.status = FrameStatus::kLost;
    r.note = "not localised in the loaded map yet";
    r.map_points = static_cast<int>(map_.points().size());
    out.push_back(r);
    return out;
  }
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
  if (bridge_ && !bridge_->built) {
    if (!frame.pose_hint) return TryBridge(slot);
    bridge_.reset();  // relocalised in the map itself before a provisional map was made: none is needed
  }
  if (bridging() && frame.pose_hint) return JoinBridge(slot, *frame.pose_hint);
  out.push_back(TrackFrame(slot, frame.pose_hint));
  if (settling_ && out.front().status == FrameStatus::kTracked &&
      ParallaxFromReference(slot) >= next_settle_parallax_deg_) {
    const auto t0 = std::chrono::steady_clock::now();
    Settle(slot, &out);
    out.front().init_ms = Ms(t0);
  }
  return out;
}

}  // namespace mcslam::slam
