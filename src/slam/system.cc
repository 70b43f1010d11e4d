// The System (system.h): the per-frame loop over the stages (Process), the restarts, and a map to start in.
// The stages, each a unit that owns its state (docs/design.md): initializer.cc (§6.1: the two-view
// initialisation), settler.cc (the first map's settling), frame_tracker.cc (§5: the pose step, rotation-only
// tracking), mapper.cc and point_adjuster.cc (§6.2-6.3: the frame history, triangulation, Monte Carlo point
// adjustment, bundle adjustment), bridge.cc (the provisional map after a turn), relocaliser.cc; what they share:
// slam_state.cc.
#include "slam/system.h"

#include <algorithm>
#include <chrono>
#include <optional>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <utility>

#include <fmt/format.h>

#include "core/median.h"
#include "slam/bridge.h"
#include "slam/frame_tracker.h"
#include "slam/initializer.h"
#include "slam/mapper.h"
#include "slam/point_adjuster.h"
#include "slam/relocaliser.h"
#include "slam/slam_state.h"
#include "slam/system_internal.h"

namespace mcslam::slam {

using detail::Ms;

namespace {

// The frames lost just before `slot`, a frame tracked again (relocalised, found by the pose step from the last pose,
// or by its rotation, or the first one localised in a loaded map), placed now by PnP against the map, newest first,
// as the frames before the first map's reference are (Initializer::PoseFramesBefore: the pose step's least inliers,
// and agreement with the frame after it). Their features are the same tracks as this frame's: the tracks that
// relocalisation matched to map points since the last tracked frame (`renamed`: track id -> point id) are renamed
// to those points in them first. Not keyframes, not smoothed, no point moves; their reports come after this
// frame's. Rendered fast scenario, seed 2: a jolt of 7.1 deg and 31 cm in a frame lost 41 of 63 tracks at frame 18,
// and frames 18-25 stayed lost until 17 new tracks matched the map at frame 26; those tracks were followed through
// frames 19-25.
void PoseLostFramesBefore(SlamState& s, Initializer& init, int slot,
                          const std::unordered_map<int64_t, int64_t>& renamed, std::vector<FrameReport>* out) {
  const auto rename = [&](FrameRecord& f) {
    if (renamed.empty()) return;
    std::vector<std::pair<int64_t, int64_t>> here;  // collected first: a rename moves entries of f.features
    for (const FeatureUndistorted& o : f.features)
      if (const auto it = renamed.find(o.id); it != renamed.end()) here.emplace_back(o.id, it->second);
    for (const auto& [track, point] : here) f.Rename(track, point);
  };
  std::vector<std::pair<int, int>> placed;  // slot, PnP inliers
  init.PoseFramesBefore(slot, s.pruned_until, rename, &placed);
  const int64_t found = s.map.frames[slot].index;
  for (const auto& [k, inliers] : placed) {
    FrameReport r = s.PosedReport(k);
    r.inliers = inliers;
    r.placed_after_loss = true;
    r.smoothed_cam_from_world = r.cam_from_world;
    r.note = fmt::format("lost when it came; posed against the map once frame {} was tracked again", found);
    out->push_back(r);
  }
}

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

struct System::Stages {
  Stages(const PinholeCamera& camera, const SystemOptions& options, std::unique_ptr<compute::PointKernel> point_kernel)
      : state(camera, options),
        adjuster(state, std::move(point_kernel)),
        init(state, settler),
        settler(state, init),
        bridge(state, init, settler, tracker, mapper),
        mapper(state, bridge, settler, adjuster),
        tracker(state, mapper, bridge, settler) {}
  SlamState state;
  PointAdjuster adjuster;
  Initializer init;
  Settler settler;
  Bridge bridge;
  Mapper mapper;
  FrameTracker tracker;
  // FrameObservations::relabelled since the last tracked frame: track id -> map point id.
  std::unordered_map<int64_t, int64_t> renamed_since_tracked;
};

System::System(const PinholeCamera& camera, const SystemOptions& options,
               std::unique_ptr<compute::PoseKernel> pose_kernel, std::unique_ptr<compute::PointKernel> point_kernel)
    : given_camera_(camera) {
  SystemOptions checked = options;
  checked.tracker.seed = checked.seed;  // one seed for every draw of the System
  camera.Check();
  checked.Check();
  if (!pose_kernel || !point_kernel) throw std::invalid_argument("system: compute kernels missing");
  st_ = std::make_unique<Stages>(camera, checked, std::move(point_kernel));
  SlamState& s = st_->state;
  // The pose step (§5) exists from the start; its translation floor is set when the map's scale is known.
  s.pose_step = std::make_unique<PoseTracker>(s.ideal, s.options.tracker, std::move(pose_kernel));
}

System& System::operator=(System&& other) noexcept = default;

System::~System() = default;  // the Mapper waits for a local bundle adjustment still being solved

void System::ApplyPendingAdjustment() {
  if (std::optional<FrameReport> r = st_->mapper.ApplyPending()) held_reports_.push_back(std::move(*r));
}

std::vector<FrameReport> System::Flush() {
  ApplyPendingAdjustment();
  return std::exchange(held_reports_, {});
}

int System::PosedFrames() const {
  const std::vector<FrameRecord>& frames = st_->state.map.frames;
  return static_cast<int>(std::count_if(frames.begin(), frames.end(), [](const FrameRecord& f) { return f.has_pose; }));
}

std::vector<FrameReport> System::Finish() {
  std::vector<FrameReport> out = Flush();
  if (!dropped_map_) return out;
  // The run ended before the map started after a restart outgrew the one before it: that one's poses stand, and
  // the new map's frames lose theirs (one map's frames in the trajectory).
  const std::string note = fmt::format("posed in a map started after the map before it stayed lost; the run ended "
                                       "before it posed more frames than the {} of that map, whose poses stand",
                                       dropped_posed_);
  for (const FrameRecord& f : st_->state.map.frames)
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
  for (const FrameReport& r : now)
    if (r.index == frame.index) st_->mapper.SetPendingReport(r);
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
  const SystemOptions& options = st_->state.options;
  if (!lost || options.restart_min_lost_frames == 0 || !st_->state.loaded_points.empty() ||
      lost_run_ < options.restart_min_lost_frames)
    return now;
  std::vector<const FrameRecord*> posed;
  for (const FrameRecord& f : st_->state.map.frames)
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
    pending_map = std::move(st_->state.map);
    pending_calibration = st_->settler.self_calibration();
  }
  // A new System in this one's place, with its kernels, camera as given, options and baseline oracle.
  std::unique_ptr<compute::PoseKernel> pose_kernel = st_->state.pose_step->ReleaseKernel();
  std::unique_ptr<compute::PointKernel> point_kernel = st_->adjuster.ReleaseKernel();
  auto oracle = std::move(st_->state.oracle);
  const int restarts = restarts_ + 1;
  const SystemOptions kept_options = options;  // (the stages, options included, go with the old System)
  *this = System(given_camera_, kept_options, std::move(pose_kernel), std::move(point_kernel));
  st_->state.oracle = std::move(oracle);
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
  SlamState& s = st_->state;
  if (!s.map.frames.empty() || s.initialised) throw std::logic_error("System::StartInMap: only before the first frame");
  if (camera) {
    camera->Check();
    s.camera = *camera;
  }
  for (MapPoint& p : points) {
    s.loaded_points.insert(p.id);
    p.state = PointState::kLost;
    p.inlier = true;
    p.last_seen_frame = -1;
    p.removed_frame = -1;
    s.map.Add(p);
  }
  for (FrameRecord& f : keyframes) {
    f.has_pose = true;
    s.map.keyframes.push_back(static_cast<int>(s.map.frames.size()));
    s.map.frames.push_back(std::move(f));
  }
  s.initialised = true;
  // The pose step's translation floor, as the initialisation sets it: from the median depth of the points in
  // the first camera.
  std::vector<double> depths;
  if (!s.map.frames.empty())
    for (const MapPoint& p : s.map.points())
      if (const double z = (s.map.frames.front().cam_from_world * p.position_in_world).z(); z > 0) depths.push_back(z);
  if (!depths.empty()) s.pose_step->SetTranslationFloor(s.options.sigma_trans_floor_rel_depth * UpperMedian(depths));
}

// The paper's per-frame loop: the frame into the history; before the map, the two-view initialisation; then the
// pose step (and on a keyframe the mapping after it), or the provisional map's while a turn is bridged; and the
// settling of a new map as its parallax grows.
std::vector<FrameReport> System::ProcessFrame(const FrameObservations& frame) {
  SlamState& s = st_->state;
  const int slot = st_->mapper.AddFrame(frame);
  std::vector<FrameReport> out;
  if (s.initialised && s.last_posed_slot < 0 && !frame.pose_hint) {  // in a loaded map, not localised yet
    FrameReport r;
    r.index = frame.index;
    r.stamp_s = frame.stamp_s;
    r.status = FrameStatus::kLost;
    r.note = "not localised in the loaded map yet";
    r.map_points = static_cast<int>(s.map.points().size());
    out.push_back(r);
    return out;
  }
  if (!s.initialised) {
    const auto t0 = std::chrono::steady_clock::now();
    if (st_->init.TryInitialise(&out)) return out;
    // The initialiser's waiting report (its note, why it waited, a rejection) with this frame's own fields.
    FrameReport r = out.empty() ? FrameReport{} : out.front();
    r.index = frame.index;
    r.stamp_s = frame.stamp_s;
    r.status = FrameStatus::kWaitingForInit;
    r.init_ms = Ms(t0);
    if (out.empty()) r.note = "waiting for enough motion to initialise";
    out.assign(1, r);
    return out;
  }
  std::optional<Pose> hint = frame.pose_hint;
  std::string placed_note;
  if (st_->bridge.waiting()) {
    if (!hint && s.options.bridge_wait_placed_by_map_tracks)
      if (const std::optional<Relocalisation> r = RelocaliseByTracks(s, st_->bridge, slot)) {
        hint = r->cam_from_world;
        placed_note = fmt::format("placed in the map by its own tracks of {} of its points; no provisional map needed",
                                  r->inlier_point_ids.size());
      }
    if (!hint) return st_->bridge.Try(slot);
    st_->bridge.Drop();  // relocalised in the map itself before a provisional map was made: none is needed
  }
  if (st_->bridge.active() && hint) return st_->bridge.Join(slot, *hint);
  out.push_back(st_->tracker.TrackFrame(slot, hint));
  if (!placed_note.empty()) out.front().note += (out.front().note.empty() ? "" : "; ") + placed_note;
  if (out.front().status == FrameStatus::kTracked && st_->settler.Due(slot)) {
    const auto t0 = std::chrono::steady_clock::now();
    st_->settler.Settle(slot, &out);
    out.front().init_ms = Ms(t0);
  }
  // The tracks relocalisation renamed are kept until a frame is tracked: the frame relocalised may itself be lost.
  for (const auto& [track, point] : frame.relabelled) st_->renamed_since_tracked[track] = point;
  if (out.front().status == FrameStatus::kTracked) {
    // Not while a provisional map is tracked (its scale is its own, not the map's).
    if (s.options.pose_lost_frames_when_found && !st_->bridge.active())
      PoseLostFramesBefore(s, st_->init, slot, st_->renamed_since_tracked, &out);
    st_->renamed_since_tracked.clear();
  }
  return out;
}

std::optional<Relocalisation> System::Relocalise(const std::vector<RelocalisationMatch>& matches) const {
  return slam::Relocalise(st_->state, st_->bridge, matches);
}

void System::SetBaselineOracle(std::function<std::optional<double>(double, double)> oracle) {
  st_->state.oracle = std::move(oracle);
}

void System::SetLookCheck(std::function<bool(int64_t track, int64_t point)> check) {
  st_->state.same_look = std::move(check);
}

bool System::merges_revisits() const { return st_->state.MergesRevisits(); }
bool System::initialised() const { return st_->state.initialised; }
bool System::localised() const { return st_->state.last_posed_slot >= 0; }
const Map& System::map() const { return st_->state.map; }
const Map& System::result_map() const {
  return dropped_map_ && (finished_with_dropped_map_ || !initialised()) ? *dropped_map_ : st_->state.map;
}
bool System::bridging() const { return st_->bridge.active(); }
bool System::Provisional(int64_t point_id) const { return st_->bridge.Provisional(point_id); }
bool System::AtCurrentScale(int64_t point_id) const { return st_->bridge.AtCurrentScale(point_id); }
bool System::Loaded(int64_t point_id) const { return st_->state.IsLoaded(point_id); }
const std::vector<std::pair<int64_t, int64_t>>& System::merged_tracks() const { return st_->mapper.merged_tracks(); }
const PinholeCamera& System::camera() const { return st_->state.camera; }
const SelfCalibration& System::self_calibration() const {
  return &result_map() != &st_->state.map && dropped_self_calibration_ ? *dropped_self_calibration_
                                                                         : st_->settler.self_calibration();
}

}  // namespace mcslam::slam
