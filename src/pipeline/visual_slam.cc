#include "pipeline/visual_slam.h"

#include <algorithm>
#include <chrono>
#include <future>
#include <map>
#include <stdexcept>
#include <tuple>
#include <unordered_set>
#include <utility>

#include <fmt/format.h>

#include "frontend/to_observations.h"

namespace mcslam::pipeline {

namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

bool Removed(const slam::MapPoint* p) { return !p || p->state == slam::PointState::kRemoved; }

// The late tries' counts forget with a half-life of ~140 frames (a run that turns from slow to quick motion
// stops backing off within a few seconds).
constexpr double kLateTriesDecay = 0.995;

// Checked; in the pipelined loop the new tracks are described within their frame's front end (which runs beside
// the back end already; a task of its own would be joined from another thread than the one that started it).
VisualSlamOptions Prepared(VisualSlamOptions options) {
  options.Check();
  if (options.pipelined) options.frontend.describe_async = false;
  return options;
}

}  // namespace

void VisualSlamOptions::Check() const {
  system.Check();
  if (max_remap_requests < 0)
    throw std::invalid_argument(fmt::format("max_remap_requests must be >= 0, got {}", max_remap_requests));
  if (remap_tries_every_frame < 0)
    throw std::invalid_argument(fmt::format("remap_tries_every_frame must be >= 0, got {}", remap_tries_every_frame));
  if (remap_retry_every < 1)
    throw std::invalid_argument(fmt::format("remap_retry_every must be >= 1, got {}", remap_retry_every));
  if (!(remap_backoff_below >= 0 && remap_backoff_below <= 1))
    throw std::invalid_argument(fmt::format("remap_backoff_below must be in [0, 1], got {}", remap_backoff_below));
  if (remap_backoff_min_inliers < 0)
    throw std::invalid_argument(
        fmt::format("remap_backoff_min_inliers must be >= 0, got {}", remap_backoff_min_inliers));
  if (!(remap_backoff_evidence >= 0))
    throw std::invalid_argument(fmt::format("remap_backoff_evidence must be >= 0, got {}", remap_backoff_evidence));
  if (max_relocalisation_points < 0)
    throw std::invalid_argument(
        fmt::format("max_relocalisation_points must be >= 0, got {}", max_relocalisation_points));
  if (!(relocalisation_max_distance > 0))
    throw std::invalid_argument(
        fmt::format("relocalisation_max_distance must be > 0, got {}", relocalisation_max_distance));
  if (turned_relocalisation_sample < 1)
    throw std::invalid_argument(
        fmt::format("turned_relocalisation_sample must be >= 1, got {}", turned_relocalisation_sample));
  if (!(turned_relocalisation_step_deg >= 1 && turned_relocalisation_step_deg <= 180))
    throw std::invalid_argument(
        fmt::format("turned_relocalisation_step_deg must be in [1, 180], got {}", turned_relocalisation_step_deg));
}

const slam::FrameReport* VisualSlamStep::current() const {
  for (auto it = reports.rbegin(); it != reports.rend(); ++it)
    if (it->index == frontend.index) return &*it;
  return nullptr;
}

VisualSlam::VisualSlam(const PinholeCamera& camera, VisualSlamOptions options,
                       std::unique_ptr<compute::PoseKernel> pose_kernel,
                       std::unique_ptr<compute::PointKernel> point_kernel)
    : given_camera_(camera),
      options_(Prepared(std::move(options))),
      frontend_(options_.frontend),
      system_(camera, options_.system, std::move(pose_kernel), std::move(point_kernel)) {
  system_.SetLookCheck([this](int64_t track, int64_t point) { return SameLook(track, point); });
}

void VisualSlam::KeepTrackLooks(const FrameObservations& obs) {
  track_looks_.clear();
  if (!system_.merges_revisits() || !system_.initialised()) return;
  for (const FeatureObservation& f : obs.features)
    if (!system_.map().Find(f.feature_id))
      if (std::optional<frontend::Descriptor> d = frontend_.DescriptorIfDone(f.feature_id))  // else: a later frame
        track_looks_.emplace(f.feature_id, *d);
}

bool VisualSlam::SameLook(int64_t track, int64_t point) const {
  const auto look = track_looks_.find(track);
  if (look == track_looks_.end()) return false;
  const double cap = options_.frontend.remap_max_distance;
  for (const auto* looks : {&lost_descriptors_, &first_descriptors_})
    if (const auto it = looks->find(point);
        it != looks->end() && frontend::DescriptorDistance(look->second, it->second) <= cap)
      return true;
  return false;
}

void VisualSlam::KeepFirstLooks(const FrameObservations& obs) {
  if (!system_.initialised()) return;
  for (const FeatureObservation& f : obs.features)
    if (!first_descriptors_.count(f.feature_id) && !Removed(system_.map().Find(f.feature_id)))
      if (std::optional<frontend::Descriptor> d = frontend_.DescriptorIfDone(f.feature_id))  // else: next frame
        first_descriptors_.emplace(f.feature_id, *d);
}

std::vector<slam::FrameReport> VisualSlam::Finish() {
  if (in_flight_) throw std::logic_error("VisualSlam::Finish: a frame is in flight (Flush first)");
  return system_.Finish();
}

io::MapFile VisualSlam::ExportMap() {
  if (in_flight_) throw std::logic_error("VisualSlam::ExportMap: a frame is in flight (Flush first)");
  system_.Flush();  // nothing is pending after Finish; a caller that did not call it loses only the report
  io::MapFile out;
  out.camera = system_.camera();  // with its k1 self-calibrated, if it was
  for (const slam::MapPoint& p : system_.map().points()) {
    if (p.state == slam::PointState::kRemoved) continue;
    io::MapFilePoint mp;
    mp.id = p.id;
    mp.position_in_world = p.position_in_world;
    if (auto it = lost_descriptors_.find(p.id); it != lost_descriptors_.end())
      mp.descriptor = it->second;
    else if (std::optional<frontend::Descriptor> d = frontend_.GetDescriptor(p.id))
      mp.descriptor = *d;
    if (auto it = first_descriptors_.find(p.id); it != first_descriptors_.end()) mp.first_descriptor = it->second;
    out.points.push_back(std::move(mp));
  }
  const slam::Map& map = system_.map();
  for (int slot : map.keyframes) {
    const slam::FrameRecord& f = map.frames[static_cast<size_t>(slot)];
    if (!f.has_pose) continue;
    io::MapFileKeyframe k;
    k.index = f.index;
    k.stamp_s = f.stamp_s;
    k.cam_from_world = f.cam_from_world;
    for (const slam::FeatureUndistorted& feature : f.features) {
      k.feature_ids.push_back(feature.id);
      k.uv_px.push_back(feature.uv_px);
    }
    out.keyframes.push_back(std::move(k));
  }
  return out;
}

void VisualSlam::LoadMap(const io::MapFile& map) {
  if (!system_.map().frames.empty()) throw std::logic_error("VisualSlam::LoadMap: only before the first frame");
  // A map made by a run that self-calibrated its lens' k1 (InitOptions::self_calibrate) goes on with its k1.
  PinholeCamera given_k1 = map.camera;
  given_k1.dist.k1 = given_camera_.dist.k1;
  if (const std::string diff = io::CameraDifference(given_k1, given_camera_); !diff.empty())
    throw std::invalid_argument(fmt::format("the map was made with another camera than this run's ({})", diff));
  if (!options_.relocalise)
    throw std::invalid_argument("a run in a loaded map starts by relocalising in it: relocalisation cannot be off");
  if (std::none_of(map.points.begin(), map.points.end(), [](const io::MapFilePoint& p) { return p.descriptor.has_value(); }))
    throw std::invalid_argument(fmt::format("the map has {} points but none with a descriptor to relocalise by",
                                            map.points.size()));
  std::vector<slam::MapPoint> points;
  int64_t next_id = 0;
  lost_descriptors_.clear();
  first_descriptors_.clear();
  for (const io::MapFilePoint& mp : map.points) {
    slam::MapPoint p;
    p.id = mp.id;
    p.position_in_world = mp.position_in_world;
    points.push_back(p);
    if (mp.descriptor) lost_descriptors_[mp.id] = *mp.descriptor;
    if (mp.first_descriptor) first_descriptors_[mp.id] = *mp.first_descriptor;
    next_id = std::max(next_id, mp.id + 1);
  }
  std::vector<slam::FrameRecord> keyframes;
  for (const io::MapFileKeyframe& k : map.keyframes) {
    slam::FrameRecord f;
    f.index = k.index;
    f.stamp_s = k.stamp_s;
    f.cam_from_world = k.cam_from_world;
    for (size_t i = 0; i < k.feature_ids.size(); ++i) {
      f.features.push_back({k.feature_ids[i], k.uv_px[i]});
      next_id = std::max(next_id, k.feature_ids[i] + 1);
    }
    keyframes.push_back(std::move(f));
  }
  system_.StartInMap(std::move(points), std::move(keyframes), map.camera);
  frontend_.ReserveIdsBelow(next_id);
  was_lost_ = true;  // the first frame is relocalised
}

// Lost map points projected with the latest pose, the most recently seen first: the front end looks for them
// near there (§6.4). Those it failed to find many times since they came into view are backed off while such late
// tries rarely succeed (VisualSlamOptions::remap_tries_every_frame): looked for now and then, or where a new
// corner appears near them (RemapRequest::only_near_new_corner).
std::vector<frontend::RemapRequest> VisualSlam::RemapRequests() {
  std::vector<frontend::RemapRequest> requests;
  late_requested_.clear();
  if (!system_.initialised() || !latest_cam_from_world_) return requests;
  const int64_t now = frames_processed_;
  std::vector<std::pair<int64_t, const slam::MapPoint*>> lost_points;
  // While a provisional map is tracked, the latest pose is at its scale: the rest of the map would be looked for
  // in the wrong places (and found there, wrongly); it is found by relocalisation instead.
  for (const slam::MapPoint& p : system_.map().points())
    if (p.state == slam::PointState::kLost && lost_descriptors_.count(p.id) && system_.AtCurrentScale(p.id))
      lost_points.emplace_back(p.last_seen_frame, &p);
  std::sort(lost_points.begin(), lost_points.end(), [](const auto& a, const auto& b) {
    return a.first > b.first || (a.first == b.first && a.second->id < b.second->id);
  });
  const bool back_off = latest_inliers_ >= options_.remap_backoff_min_inliers &&
                        late_tries_ >= options_.remap_backoff_evidence &&
                        late_found_ < options_.remap_backoff_below * late_tries_;
  for (const auto& [seen, p] : lost_points) {
    Eigen::Vector2d uv;
    if (!system_.camera().ProjectWorld(*latest_cam_from_world_, p->position_in_world, &uv) ||
        !system_.camera().InImage(uv, options_.frontend.border_px))
      continue;
    // Every point in view is noted, requested or not: one that was out of view (or tracked) in the frame
    // before came back and is tried afresh.
    RemapTries& tries = remap_tries_[p->id];
    if (tries.in_view_at != now - 1) tries.failures = 0;
    tries.in_view_at = now;
    if (requests.size() >= static_cast<size_t>(options_.max_remap_requests)) continue;
    const bool late = tries.failures >= options_.remap_tries_every_frame;
    const bool deferred = late && back_off && (now + p->id) % options_.remap_retry_every != 0;
    if (late && !deferred) late_requested_.insert(p->id);
    const frontend::Descriptor& last = lost_descriptors_.at(p->id);
    const auto first = first_descriptors_.find(p->id);  // tried too where it differs from the last look
    requests.push_back({p->id, last, uv, deferred,
                        first != first_descriptors_.end() && first->second != last ? std::optional(first->second)
                                                                                   : std::nullopt});
  }
  // Only the points in view now keep their count (the map's size stays that of the view).
  std::erase_if(remap_tries_, [&](const auto& kv) { return kv.second.in_view_at != now; });
  return requests;
}

void VisualSlam::CountRemapTries(std::span<const frontend::RemapRequest> requests, const frontend::FrameResult& fr) {
  const std::unordered_set<int64_t> found(fr.remapped_ids.begin(), fr.remapped_ids.end());
  late_tries_ *= kLateTriesDecay;
  late_found_ *= kLateTriesDecay;
  for (int64_t id : late_requested_) {  // the deferred ones tried near a new corner are not counted: biased
    late_tries_ += 1;
    late_found_ += found.count(id);
  }
  for (const frontend::RemapRequest& r : requests) {
    if (found.count(r.feature_id))
      remap_tries_.erase(r.feature_id);
    else if (auto it = remap_tries_.find(r.feature_id); it != remap_tries_.end())
      ++it->second.failures;
  }
}

void VisualSlam::SkipFrame() {
  if (in_flight_) throw std::logic_error("VisualSlam::SkipFrame: a frame is in flight (Flush first)");
  after_gap_ = true;
  ++frames_processed_;  // and remapping tries the points in view afresh
}

void VisualSlam::CheckImage(const cv::Mat& image, int64_t index) {
  try {
    frontend::CheckImage(image, index);
    if (!image_size_.empty() && image.size() != image_size_)
      throw std::invalid_argument(fmt::format("frame {}: image is {}x{} but the previous frames were {}x{}", index,
                                              image.cols, image.rows, image_size_.width, image_size_.height));
  } catch (const std::invalid_argument& e) {
    after_gap_ = true;
    throw UnusableFrame(e.what());
  }
  image_size_ = image.size();
}

frontend::FrameResult VisualSlam::RunFrontend(const cv::Mat& image, int64_t index, double stamp_s,
                                              std::span<const frontend::RemapRequest> requests) {
  try {
    return frontend_.Process(image, index, stamp_s, requests);
  } catch (const std::invalid_argument& e) {  // a pixel type the front end does not take: this frame only
    after_gap_ = true;
    throw UnusableFrame(e.what());
  }
}

void VisualSlam::AfterFrontend(const frontend::FrameResult& fr, std::span<const frontend::RemapRequest> requests) {
  for (const frontend::LostTrack& t : fr.lost)
    if (t.descriptor && !Removed(system_.map().Find(t.feature_id))) lost_descriptors_[t.feature_id] = *t.descriptor;
  for (int64_t id : fr.remapped_ids) lost_descriptors_.erase(id);
  CountRemapTries(requests, fr);
}

FrameObservations VisualSlam::BeforeBackend(bool after_gap, VisualSlamStep* step) {
  // The last keyframe's local bundle adjustment (local_ba_async) was solved while the front end ran: applied
  // before the map is matched or tracked against (its revised report comes with the System's next reports).
  system_.ApplyPendingAdjustment();
  step->before_init = !system_.initialised();
  FrameObservations obs = frontend::ToObservations(step->frontend);
  // While the System tracks a provisional map (a bridge over the unmapped), every frame is also matched against
  // the map it must join.
  if (options_.relocalise && (was_lost_ || after_gap || system_.bridging()) && system_.initialised()) {
    const auto t_reloc = Clock::now();
    Relocalise(step->frontend, &obs, step, was_lost_ || after_gap);
    step->reloc_ms = MsSince(t_reloc);
  }
  KeepTrackLooks(obs);
  return obs;
}

void VisualSlam::RunBackend(const FrameObservations& obs, VisualSlamStep* step) {
  const auto t_backend = Clock::now();
  step->reports = system_.Process(obs);
  step->backend_ms = MsSince(t_backend);
}

void VisualSlam::AfterBackend(const FrameObservations& obs, VisualSlamStep* step, frontend::FrameResult* next) {
  if (system_.restarts() != restarts_seen_) {  // the map was dropped: what was kept of its points goes with it
    restarts_seen_ = system_.restarts();
    lost_descriptors_.clear();
    first_descriptors_.clear();
    remap_tries_.clear();
    late_requested_.clear();
    late_tries_ = late_found_ = 0;
    latest_cam_from_world_.reset();
    latest_inliers_ = 0;
  }
  // Tracks the System took as older map points (a place seen again): they go on under the points' ids, with
  // their own descriptors (this view's). A next frame already through the front end reports them under their
  // tracks' ids: renamed there too (a track that ended in it leaves its descriptor to the point).
  step->merged_tracks = static_cast<int>(system_.merged_tracks().size());
  for (const auto& [track, point] : system_.merged_tracks()) {
    bool ended_next = false;
    if (next) {
      for (frontend::TrackedFeature& f : next->features)
        if (f.feature_id == track) f.feature_id = point;
      for (frontend::LostTrack& t : next->lost)
        if (t.feature_id == track) t.feature_id = point, ended_next = true;
    }
    if (frontend_.Relabel(track, point) || ended_next) {  // else the System goes on renaming the track's features
      lost_descriptors_.erase(point);
      remap_tries_.erase(point);
    }
  }
  KeepFirstLooks(obs);
  if (const slam::FrameReport* current = step->current()) {
    if (current->has_pose) latest_cam_from_world_ = current->cam_from_world, latest_inliers_ = current->inliers;
    was_lost_ = current->status == slam::FrameStatus::kLost;
  }
}

void VisualSlam::ChooseDescriptions() {
  // While the map is lost, or a provisional map is tracked beside it, every frame's new tracks are what
  // relocalisation matches: each is described at its birth, as where it came into view is how the map's points
  // were last seen when they left it there (a camera that pans away and back).
  if (!options_.describe_map_points_only || system_.merges_revisits() || was_lost_ || system_.bridging()) {
    frontend_.DescribeEveryTrack();
    return;
  }
  const slam::Map& map = system_.map();
  frontend_.DescribeOnly([&map](int64_t id) { return !Removed(map.Find(id)); });
}

VisualSlamStep VisualSlam::Complete(InFlight frame) {
  AfterFrontend(frame.step.frontend, frame.requests);
  const FrameObservations obs = BeforeBackend(frame.after_gap, &frame.step);
  RunBackend(obs, &frame.step);
  AfterBackend(obs, &frame.step, nullptr);
  return std::move(frame.step);
}

VisualSlamStep VisualSlam::Process(const cv::Mat& image, int64_t index, double stamp_s) {
  if (in_flight_) throw std::logic_error("VisualSlam::Process: a frame is in flight (Flush first)");
  InFlight frame;
  ++frames_processed_;
  frame.requests = RemapRequests();
  ChooseDescriptions();
  frame.step.frontend = RunFrontend(image, index, stamp_s, frame.requests);
  frame.after_gap = std::exchange(after_gap_, false);
  return Complete(std::move(frame));
}

std::optional<VisualSlamStep> VisualSlam::Push(const cv::Mat& image, int64_t index, double stamp_s) {
  if (!options_.pipelined) return Process(image, index, stamp_s);
  CheckImage(image, index);
  std::optional<InFlight> done = std::move(in_flight_);
  in_flight_.reset();
  FrameObservations obs;
  if (done) {
    AfterFrontend(done->step.frontend, done->requests);
    obs = BeforeBackend(done->after_gap, &done->step);
  }
  InFlight next;
  ++frames_processed_;
  next.requests = RemapRequests();  // as of the back end of the frame before the one in flight
  ChooseDescriptions();             // the same
  next.after_gap = std::exchange(after_gap_, false);
  // The front end touches only the Frontend; the back end only the System and this object's remapping state.
  std::future<frontend::FrameResult> front = std::async(std::launch::async, [&] {
    return frontend_.Process(image, index, stamp_s, next.requests);
  });
  try {
    if (done) RunBackend(obs, &done->step);
  } catch (...) {
    front.wait();
    throw;
  }
  next.step.frontend = front.get();
  if (done) AfterBackend(obs, &done->step, &next.step.frontend);
  in_flight_ = std::move(next);
  if (!done) return std::nullopt;
  return std::move(done->step);
}

std::optional<VisualSlamStep> VisualSlam::Flush() {
  if (!in_flight_) return std::nullopt;
  InFlight done = std::move(*in_flight_);
  in_flight_.reset();
  return Complete(std::move(done));
}

// The features of this frame that are no map point (tracks born since the loss) matched by their descriptors
// to the map points whose tracks ended (nearest, Lowe's ratio and a distance cap; one feature for a map point,
// the closest), together with the map points still tracked, then the System's RANSAC PnP. The matched tracks
// that agree with the pose go on under their map points' ids, in this frame's observations too.
void VisualSlam::Relocalise(const frontend::FrameResult& fr, FrameObservations* obs, VisualSlamStep* step,
                            bool turned) {
  step->reloc_tried = true;
  // Map points that left the map need no descriptor any more.
  std::erase_if(lost_descriptors_, [&](const auto& kv) { return Removed(system_.map().Find(kv.first)); });
  std::erase_if(first_descriptors_, [&](const auto& kv) { return Removed(system_.map().Find(kv.first)); });

  std::vector<std::tuple<int64_t, int64_t, const frontend::Descriptor*>> recent;  // last seen, id, look
  for (const auto& [id, d] : lost_descriptors_)
    if (const slam::MapPoint* p = system_.map().Find(id); !Removed(p) && !system_.Provisional(id))
      recent.emplace_back(p->last_seen_frame, id, &d);
  std::sort(recent.begin(), recent.end(), [](const auto& a, const auto& b) {
    return std::get<0>(a) != std::get<0>(b) ? std::get<0>(a) > std::get<0>(b) : std::get<1>(a) < std::get<1>(b);
  });
  // In a loaded map before its first relocalisation no point was seen yet (all tie, by id): all of them, or a
  // map of more than the cap would be searched only where its first points were made.
  if (system_.localised() && recent.size() > static_cast<size_t>(options_.max_relocalisation_points))
    recent.resize(options_.max_relocalisation_points);
  std::vector<std::pair<int64_t, const frontend::Descriptor*>> map_side;
  for (const auto& [seen, id, d] : recent) map_side.emplace_back(id, d);
  std::sort(map_side.begin(), map_side.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<const frontend::Descriptor*> looks;
  for (const auto& [id, d] : map_side) looks.push_back(d);
  // When the points' last looks place no frame, they are looked for also by how they looked when they joined
  // the map: a place seen again from where it was first mapped (a map loaded in a new session, the start of a
  // loop) looks like that more than like the end of its tracks. Only then: where the last looks do place the
  // frame, the first ones add matches from views long ago (KITTI 06 after a 2-frame gap: 2 more matches, and the
  // run's ATE 4.0-6.6 cm became 5.4-11.0 cm over seeds 1-6). The first looks are matched as a set of their own:
  // Lowe's test against another point's look, not the same point's other one.
  std::vector<const frontend::Descriptor*> first_looks;
  std::vector<size_t> first_of;  // the map_side entry of each first look
  for (size_t i = 0; i < map_side.size(); ++i)
    if (auto it = first_descriptors_.find(map_side[i].first); it != first_descriptors_.end())
      first_looks.push_back(&it->second), first_of.push_back(i);
  frontend::FrontendOptions match_options = frontend_.options();
  match_options.remap_max_distance = options_.relocalisation_max_distance;
  struct Match {
    float distance;
    int64_t track;
    Eigen::Vector2d uv;
  };
  // The frame's tracks that are no map point: each one's descriptor and its match among the last looks, found
  // once for both passes below.
  struct Candidate {
    const frontend::TrackedFeature* feature;
    frontend::Descriptor descriptor;
    std::optional<frontend::DescriptorMatch> last;
  };
  std::vector<Candidate> candidates;
  const auto candidate = [&](const frontend::TrackedFeature& f, const frontend::Descriptor& d) {
    return Candidate{&f, d, frontend::MatchDescriptor(d, looks, match_options)};
  };
  std::vector<slam::RelocalisationMatch> tracked;  // tracks that are map points: matched by their ids
  // The new tracks' looks, which describe_map_points_only leaves undescribed.
  if (options_.describe_map_points_only && map_side.size() >= 2) {
    std::vector<int64_t> unmapped;
    for (const frontend::TrackedFeature& f : fr.features)
      if (Removed(system_.map().Find(f.feature_id))) unmapped.push_back(f.feature_id);
    frontend_.DescribeMissing(unmapped);
  }
  for (const frontend::TrackedFeature& f : fr.features) {
    if (!Removed(system_.map().Find(f.feature_id))) {
      tracked.push_back({f.feature_id, f.uv_px});
      continue;
    }
    if (map_side.size() < 2) continue;
    if (const std::optional<frontend::Descriptor> d = frontend_.GetDescriptor(f.feature_id))
      candidates.push_back(candidate(f, *d));
  }
  std::vector<slam::RelocalisationMatch> matches;
  std::vector<std::pair<int64_t, int64_t>> relabel;  // track id, map point id
  auto match = [&](bool with_first_looks) {
    std::map<int64_t, Match> best_for_point;  // ordered: the same matches in the same order every run
    matches = tracked;
    relabel.clear();
    for (const Candidate& c : candidates) {
      std::optional<frontend::DescriptorMatch> m = c.last;
      size_t point = m ? m->index : 0;
      if (with_first_looks)
        if (const std::optional<frontend::DescriptorMatch> m_first = frontend::MatchDescriptor(c.descriptor, first_looks, match_options);
            m_first && (!m || m_first->distance < m->distance))
          m = m_first, point = first_of[m_first->index];
      if (!m) continue;
      const frontend::TrackedFeature& f = *c.feature;
      const auto [it, fresh] = best_for_point.try_emplace(map_side[point].first, Match{m->distance, f.feature_id, f.uv_px});
      if (!fresh && m->distance < it->second.distance) it->second = {m->distance, f.feature_id, f.uv_px};
    }
    for (const auto& [point_id, m] : best_for_point) {
      matches.push_back({point_id, m.uv});
      relabel.emplace_back(m.track, point_id);
    }
    step->reloc_matches = static_cast<int>(matches.size());
    return system_.Relocalise(matches);
  };
  // The last looks first, then the first looks as well.
  const auto match_looks = [&] {
    std::optional<slam::Relocalisation> r = match(false);
    if (!r && first_looks.size() >= 2) r = match(true);
    return r;
  };
  std::optional<slam::Relocalisation> reloc = match_looks();
  if (!reloc && turned && options_.relocalise_turned && candidates.size() >= 2) {
    // The turn about the camera's axis under which the most of a sample of the new tracks match the last looks
    // (upright excluded: it was just tried), then every new track matched again under it.
    std::vector<float> angles;
    for (double a = options_.turned_relocalisation_step_deg; a < 360.0 - 1e-9; a += options_.turned_relocalisation_step_deg)
      angles.push_back(static_cast<float>(a));
    const size_t sample = std::min(candidates.size(), static_cast<size_t>(options_.turned_relocalisation_sample));
    std::vector<int64_t> ids;
    for (size_t i = 0; i < sample; ++i) ids.push_back(candidates[i].feature->feature_id);
    const std::vector<std::optional<frontend::Descriptor>> d = frontend_.DescribeTurned(ids, angles);
    const auto matched = [&](const std::vector<std::optional<frontend::Descriptor>>& turned_d, size_t a) {
      int count = 0;
      for (size_t i = 0; i < sample; ++i)
        if (const std::optional<frontend::Descriptor>& di = turned_d[a * sample + i])
          count += frontend::MatchDescriptor(*di, looks, match_options).has_value();
      return count;
    };
    int best_count = 0;
    float best = 0.f;
    for (size_t a = 0; a < angles.size() && !d.empty(); ++a)
      if (const int count = matched(d, a); count > best_count) best_count = count, best = angles[a];
    // Half a step either side of the best: a turn between two steps is then at most a quarter step off (SIFT's
    // descriptors are half as far from an unrelated point's 15 degrees off, SiftDescriber's tests).
    if (best_count > 0) {
      const float half = static_cast<float>(options_.turned_relocalisation_step_deg / 2.0);
      const float sides[2] = {best - half, best + half};
      const std::vector<std::optional<frontend::Descriptor>> ds = frontend_.DescribeTurned(ids, sides);
      for (size_t a = 0; a < 2 && !ds.empty(); ++a)
        if (const int count = matched(ds, a); count > best_count) best_count = count, best = sides[a];
    }
    step->reloc_turn_deg = best;  // 0 when no turn matched any
    // Fewer matches than PnP could ever take in the whole frame's share of the sample: nothing to look at again.
    const double share = static_cast<double>(sample) / static_cast<double>(candidates.size());
    if (best_count > 0 && best_count >= share * options_.system.relocalise_min_inliers) {
      std::vector<int64_t> all;
      for (const Candidate& c : candidates) all.push_back(c.feature->feature_id);
      const std::vector<std::optional<frontend::Descriptor>> turned_d =
          frontend_.DescribeTurned(all, std::span<const float>(&best, 1));
      std::vector<Candidate> upright = std::move(candidates);
      candidates.clear();
      for (size_t i = 0; i < upright.size() && !turned_d.empty(); ++i)
        if (turned_d[i]) candidates.push_back(candidate(*upright[i].feature, *turned_d[i]));
      reloc = match_looks();
      step->reloc_turned = reloc.has_value();
    }
  }
  if (!reloc) return;
  step->reloc_inliers = static_cast<int>(reloc->inlier_point_ids.size());
  step->reloc_near_provisional = reloc->near_provisional_orientation;
  const std::unordered_set<int64_t> inliers(reloc->inlier_point_ids.begin(), reloc->inlier_point_ids.end());
  for (const auto& [track_id, point_id] : relabel) {
    if (!inliers.count(point_id) || !frontend_.Relabel(track_id, point_id, lost_descriptors_.at(point_id))) continue;
    for (FeatureObservation& f : obs->features)
      if (f.feature_id == track_id) f.feature_id = point_id;
    obs->relabelled.emplace_back(track_id, point_id);
    lost_descriptors_.erase(point_id);
  }
  obs->pose_hint = reloc->cam_from_world;
}

}  // namespace mcslam::pipeline
