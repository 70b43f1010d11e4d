#pragma once
// The only layer that sees pixels and 3D together (docs/design.md): a VisualSlam owns a front end and a System
// and runs one frame through both. Around the paper's per-frame loop it keeps what joins them:
// - remapping (§6.4): the lost map points, projected with the latest pose, are handed to the front end, which
//   looks for them near there by their SIFT descriptors (kept here from the moment their track ended);
// - relocalisation: after a lost frame, or after frames that could not be read, the frame's features are
//   matched by descriptor to the map points whose tracks ended, the System's RANSAC PnP places the frame, the
//   matched tracks go on under their map points' ids, and the Monte Carlo pose step starts from that pose.
// The application around it reads frames, writes files and reports progress; it does no SLAM.
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include <opencv2/core.hpp>

#include "compute/point_kernel.h"
#include "compute/pose_kernel.h"
#include "core/camera.h"
#include "core/pose.h"
#include "frontend/frontend.h"
#include "io/map_file.h"
#include "slam/system.h"

namespace mcslam::pipeline {

struct VisualSlamOptions {
  frontend::FrontendOptions frontend;
  slam::SystemOptions system;
  // After a lost frame (or unreadable ones), relocalise against the map before the pose step.
  bool relocalise = true;
  // Remap requests per frame at most (the most recently seen lost points first): each costs SIFT descriptions
  // of the corners in its window, and a point lost long ago is rarely found again.
  int max_remap_requests = 200;
  // Remapping backs off from lost points that are in view but not found, where that pays: a point is looked
  // for in every frame for its first `remap_tries_every_frame` failed tries since it came into view (out of
  // view and back starts it afresh); past that ("late" tries), while fewer than `remap_backoff_below` of the
  // late tries find their point (measured over the run, the latest frames weighing most, once at least
  // `remap_backoff_evidence` late tries were counted), it is looked for in every `remap_retry_every`-th frame
  // only (staggered by id: those tries go on measuring) and in the frames where a corner that would start a new
  // track appears in its window (the end of an occlusion: the new track would take the corner for good).
  // And only while the map is well fed: the latest pose had at least `remap_backoff_min_inliers` inliers (twice
  // MappingOptions::starving_inliers); a thin map takes back every point it can.
  // Measured over every remap request (docs/timing.md): a first try succeeds 33-35 % of the time on the demo
  // and 7-Scenes (KITTI 1.8 %); after 10 failures 0.1 % (demo), 0.3 % (7-Scenes), none of KITTI's, and those
  // late tries are most requests; on the fast scenario (pose inliers: median 32), where the short tracks of a
  // quick camera block a lost point's corner for a while, about 1.3 % of them succeed, and re-found points keep
  // its drift down: backing off there lost 30 % of the remaps and raised the ATE on 4 of 5 seeds, and with the
  // success rate alone it backed off early in a run and seed 5 ended 46 cm off (6.7 cm without). At 1 %, about
  // 100 tries (a few ms of SIFT) are spent on a point found again.
  int remap_tries_every_frame = 10;
  int remap_retry_every = 8;
  double remap_backoff_below = 0.01;
  double remap_backoff_evidence = 100;
  int remap_backoff_min_inliers = 60;
  // Relocalisation compares each new track with this many lost map points at most, the most recently seen:
  // the cost of a try stays bounded however long the run (at 400 tracks, ~25 ms on 2 cores).
  int max_relocalisation_points = 2000;
  // Relocalisation's descriptor distance cap (remapping's is FrontendOptions::remap_max_distance, 250). A lost
  // frame is usually a view from elsewhere than where the points were last described, and the RANSAC PnP that
  // follows verifies every match: Lowe's test alone (with a cap that only stops the nearest of unrelated
  // points, whose median distance is ~520 on the shared sequences) keeps the matches a changed view pushed
  // past 250.
  double relocalisation_max_distance = 400.0;
  // When the lost frame's upright descriptors place it nowhere, the camera may have turned about its axis since
  // the map saw the place (a phone held the other way up, a drone that banked, a camera put back rolled): SIFT's
  // upright descriptors match up to a few tens of degrees of such a turn only. The frame's new tracks (up to
  // turned_relocalisation_sample of them) are described again with their grids turned by every
  // turned_relocalisation_step_deg, the turn under which most of them match is taken, and all of them are matched
  // again under it before the RANSAC PnP. The Middlebury temple ring seen again upside down (views 0042-0034 after
  // 0013-0030) relocalised nowhere before. false: upright only.
  bool relocalise_turned = true;
  int turned_relocalisation_sample = 64;
  double turned_relocalisation_step_deg = 30.0;
  // The pipelined frame loop (VisualSlam::Push): the front end of each frame runs on a thread of its own while
  // the back end works on the frame before it. What the front end takes from the back end (the lost points to look
  // for, projected with the latest pose) is then one frame older: the back end of the frame before has not ended.
  // The new tracks are then described within their frame's front end (FrontendOptions::describe_async is off).
  // Off by default: on 2 cores both stages already keep both cores busy (TBB), and overlapping them made each
  // slower by more than it saved (docs/timing_pipelined.md: 7-Scenes 22.3 against 24.9 frames/s sequential).
  bool pipelined = false;
  // Only the tracks that are map points are described (SIFT), each once it is one (from the frame it was born in,
  // while that is kept, Frontend::DescribeOnly) and again every FrontendOptions::descriptor_refresh_frames,
  // instead of every new track at its birth: what remapping looks for again is a lost map point's look, and most
  // tracks never become one (KITTI 06: ~1,300 map points of 6,223 tracks born; its description 16.0 -> 4.6 ms a
  // frame, docs/timing_describe.md). Relocalisation describes the frame's other tracks when it needs them
  // (Frontend::DescribeMissing). While the map is lost or a provisional map is tracked, and where a place seen again
  // may be merged (System::merges_revisits: a loaded map), every new track is described at its birth all the same.
  // Off by default: the looks of points whose tracks were older than the refresh period when they became map points
  // differ from those taken every track at its birth, and the rendered rotation and sparse scenarios, which hang on
  // single remaps, came out worse (docs/tuning.md: the robustness matrix 85 -> 83 of 100 cells on AVX2).
  bool describe_map_points_only = false;
  // Throws std::invalid_argument naming the field.
  void Check() const;
};

// The front end does not take this image (its pixel type): the frame is skipped, the run goes on.
class UnusableFrame : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// What one frame did, for the application's per-frame report.
struct VisualSlamStep {
  frontend::FrameResult frontend;           // tracks, lost tracks, front-end counts and times
  std::vector<slam::FrameReport> reports;   // System::Process's reports (this frame, and earlier ones revised)
  bool before_init = false;                 // the map did not exist when the frame came
  double backend_ms = 0;                    // System::Process
  // Relocalisation: tried on this frame, features matched to map points, PnP inliers (0: no pose), time.
  bool reloc_tried = false;
  int reloc_matches = 0;
  int reloc_inliers = 0;
  bool reloc_near_provisional = false;  // Relocalisation::near_provisional_orientation
  // The turn about the camera's axis under which the new tracks matched best (VisualSlamOptions::relocalise_turned;
  // 0: not looked for), and whether the pose came from descriptors so turned.
  double reloc_turn_deg = 0;
  bool reloc_turned = false;
  double reloc_ms = 0;
  // Tracks that went on as the map point of a place seen again in this frame's back end (System::merged_tracks).
  int merged_tracks = 0;
  // The report of this frame among `reports` (nullptr when the System gave none for it).
  const slam::FrameReport* current() const;
};

class VisualSlam {
 public:
  VisualSlam(const PinholeCamera& camera, VisualSlamOptions options, std::unique_ptr<compute::PoseKernel> pose_kernel,
             std::unique_ptr<compute::PointKernel> point_kernel);
  VisualSlam(const VisualSlam&) = delete;  // the System's look check calls back into this object
  VisualSlam& operator=(const VisualSlam&) = delete;

  // Runs one readable frame through the front end and the back end. Throws UnusableFrame when the front end
  // does not take the image's pixel type: nothing has changed then but that the next frame counts as coming
  // after a gap. Other exceptions (the System's) propagate.
  VisualSlamStep Process(const cv::Mat& image, int64_t index, double stamp_s);
  // The pipelined frame loop (VisualSlamOptions::pipelined; without it, Process): starts this frame's front end
  // and, meanwhile, runs the back end of the frame before, whose step it returns (nullopt for the first frame).
  // The frame in flight comes back with the next Push or with Flush. Throws UnusableFrame, before anything else,
  // for an image the front end does not take (the frame in flight stays in flight).
  std::optional<VisualSlamStep> Push(const cv::Mat& image, int64_t index, double stamp_s);
  // The back end of the frame in flight, if any: before SkipFrame, Finish, ExportMap or reading the map as of the
  // last frame pushed.
  std::optional<VisualSlamStep> Flush();

  // After the last frame: the reports that the System still holds back (MappingOptions::local_ba_async: the last
  // keyframe's, revised by its local bundle adjustment). Call it before reading the final map.
  std::vector<slam::FrameReport> Finish();
  // A frame that could not be read: the camera may have moved far meanwhile, so the next frame is relocalised.
  // Throws std::logic_error while a frame is in flight (Flush first).
  void SkipFrame();

  // The map as a map file holds it (io/map_file.h; its options are the caller's to fill in): the points in
  // the map, each with its SIFT descriptor when one is known (its live track's, or the one kept since its track
  // ended), and the posed keyframes with the features they kept.
  io::MapFile ExportMap();
  // Starts in a map read from a file, before the first frame: the System holds its points and keyframes, the
  // front end numbers its tracks above the map's ids, and the first frames are relocalised against the map by
  // the points' descriptors. Throws std::invalid_argument when the map was made with another camera (naming
  // what differs), has no point with a descriptor, or relocalisation is off; std::logic_error after a frame.
  void LoadMap(const io::MapFile& map);

  const slam::System& system() const { return system_; }
  slam::System& system() { return system_; }
  const frontend::Frontend& frontend() const { return frontend_; }
  const VisualSlamOptions& options() const { return options_; }

 private:
  // The lost points to look for in this frame (remap_tries_ updated for which are in view).
  std::vector<frontend::RemapRequest> RemapRequests();
  // Tells the front end which tracks to describe in its next frame (describe_map_points_only), from the map as
  // it is now: called where no back end runs.
  void ChooseDescriptions();
  // After the front end: the requests not re-attached count as failed tries.
  void CountRemapTries(std::span<const frontend::RemapRequest> requests, const frontend::FrameResult& fr);
  // turned: also look for the map through descriptors turned about the camera's axis when upright ones place
  // nothing (after a lost frame or a gap, not while a provisional map holds the map's orientation).
  void Relocalise(const frontend::FrameResult& fr, FrameObservations* obs, VisualSlamStep* step, bool turned);
  // The stages of one frame, in the order Process runs them; Push runs the front end of the next frame between
  // BeforeBackend and the System's Process, and AfterBackend renames the tracks the System merged in that frame's
  // result too (`next`).
  frontend::FrameResult RunFrontend(const cv::Mat& image, int64_t index, double stamp_s,
                                    std::span<const frontend::RemapRequest> requests);
  void AfterFrontend(const frontend::FrameResult& fr, std::span<const frontend::RemapRequest> requests);
  FrameObservations BeforeBackend(bool after_gap, VisualSlamStep* step);
  void RunBackend(const FrameObservations& obs, VisualSlamStep* step);
  void AfterBackend(const FrameObservations& obs, VisualSlamStep* step, frontend::FrameResult* next);
  // The checks of Push on a new image (UnusableFrame).
  void CheckImage(const cv::Mat& image, int64_t index);
  struct InFlight;
  // The back end of a frame whose front end ran (Process, Flush): AfterFrontend to AfterBackend.
  VisualSlamStep Complete(InFlight frame);
  // Keeps the descriptor of each feature of the frame that is a map point without a first look yet.
  void KeepFirstLooks(const FrameObservations& obs);
  // A place seen again is merged into its map points (MappingOptions::merge_revisited_points, and always in a loaded
  // map) only where it looks like them: a new track's SIFT descriptor within FrontendOptions::remap_max_distance of
  // the point's last or first look, as remapping accepts a match (System::SetLookCheck). By projection alone, a
  // nearby point of the same corner-poor patch was taken for the point (docs/tuning.md). The looks of the frame's
  // tracks that are no map point yet are taken before the back end runs (the front end may run beside it).
  void KeepTrackLooks(const FrameObservations& obs);
  bool SameLook(int64_t track, int64_t point) const;

  PinholeCamera given_camera_;  // as given (the System's may have its k1 self-calibrated)
  VisualSlamOptions options_;
  frontend::Frontend frontend_;
  slam::System system_;
  std::unordered_map<int64_t, frontend::Descriptor> lost_descriptors_;  // map points whose track ended
  // Every map point's look when it joined the map (its track's descriptor then): relocalisation's second look.
  std::unordered_map<int64_t, frontend::Descriptor> first_descriptors_;
  std::unordered_map<int64_t, frontend::Descriptor> track_looks_;  // KeepTrackLooks: this frame's new tracks
  std::optional<Pose> latest_cam_from_world_;
  // Remapping's failed tries of each lost map point in view since it came into view (VisualSlamOptions'
  // remap_tries_every_frame), and the last frame in which it was lost and in view; only points in view now.
  struct RemapTries {
    int failures = 0;
    int64_t in_view_at = -2;
  };
  std::unordered_map<int64_t, RemapTries> remap_tries_;
  // Late tries (remap_tries_every_frame failures or more) made in full, and those that found their point,
  // both decayed a frame (visual_slam.cc: kLateTriesDecay); the ids of this frame's late requests.
  double late_tries_ = 0, late_found_ = 0;
  int latest_inliers_ = 0;  // of the latest posed frame
  std::unordered_set<int64_t> late_requested_;
  int64_t frames_processed_ = 0;  // Process and SkipFrame calls: remap_tries_' clock
  bool was_lost_ = false;
  int restarts_seen_ = 0;  // System::restarts() after the last Process
  bool after_gap_ = false;  // frames were skipped since the last one processed
  cv::Size image_size_;     // of the first frame taken
  // The frame whose front end ran and whose back end has not (Push).
  struct InFlight {
    VisualSlamStep step;  // with its front end's result
    std::vector<frontend::RemapRequest> requests;
    bool after_gap = false;
  };
  std::optional<InFlight> in_flight_;
};

}  // namespace mcslam::pipeline
