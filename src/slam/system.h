#pragma once
// The SLAM back end (paper §5-6): from feature observations alone, it initialises from two views (§6.1),
// tracks every frame by Monte Carlo pose estimation (§5), and on keyframes adds points by linear
// triangulation and refines points by Monte Carlo adjustment over Fibonacci-spaced keyframes (§6.2-6.3).
#include <deque>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include "compute/point_kernel.h"
#include "compute/pose_kernel.h"
#include "core/camera.h"
#include "geometry/bundle_adjust.h"
#include "geometry/pnp.h"
#include "geometry/two_view.h"
#include "slam/map.h"
#include "slam/pose_smoother.h"
#include "slam/pose_tracker.h"
#include "slam/system_options.h"
#include "core/observations.h"

namespace mcslam::slam {

// A feature of the current frame matched (by descriptor) to a map point: an input of System::Relocalise.
struct RelocalisationMatch {
  int64_t point_id = 0;
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();  // as the camera saw it (distorted pixels)
};
struct Relocalisation {
  Pose cam_from_world;
  std::vector<int64_t> inlier_point_ids;  // the matches that agree with it
  int matches = 0;
  // Found among the poses near a provisional map's orientation, the free search having found none or one
  // that disagreed with it (System::Relocalise).
  bool near_provisional_orientation = false;
};

enum class FrameStatus { kWaitingForInit, kTracked, kLost };
const char* ToString(FrameStatus s);

struct FrameReport {
  int64_t index = 0;
  double stamp_s = 0;
  FrameStatus status = FrameStatus::kWaitingForInit;
  bool has_pose = false;
  Pose cam_from_world;
  Pose smoothed_cam_from_world;
  bool keyframe = false;
  bool initialisation = false;  // the pose came from the two-view initialisation
  bool self_calibration = false;  // the lens' k1 was measured on this frame (InitOptions::self_calibrate): the note says
  // A later correction of an earlier frame's pose (the settling after initialisation): only cam_from_world
  // (and the residual statistics) replace those of that frame's report; the rest of it stands.
  bool pose_update = false;
  int scored = 0, inliers = 0;
  // The pose step's best score (the capped reprojection distances summed, px) and the translation spread it sampled
  // with (m): zero when the frame was not posed by the pose step.
  double score = 0;
  Eigen::Vector3d sigma_t = Eigen::Vector3d::Zero();
  int map_points = 0;           // active + lost
  int new_points = 0, adjusted = 0, removed = 0;
  double reproj_mean_px = 0;    // mean residual of the inlier observations of map points in this frame
  double reproj_median_px = 0;  // median residual of all observations of map points in this frame
  double track_ms = 0, map_ms = 0, adjust_ms = 0, init_ms = 0;
  // adjust_ms's two parts on a keyframe: the Monte Carlo point adjustment and the local bundle
  // adjustment after it (MappingOptions::local_ba_keyframes; with local_ba_async its preparation, solve and
  // application, and local_ba_wait_ms what the next frame's Process waited for the solve to end).
  double adjust_points_ms = 0, local_ba_ms = 0, local_ba_wait_ms = 0;
  bool local_ba = false;  // a local bundle adjustment refined this keyframe's window (not skipped)
  int local_ba_span = 0;  // frames from the oldest keyframe it adjusted to this one (local_ba_min_step_of_depth)
  std::string note;             // why lost / waiting; how posed when not by the pose step
  bool rotation_only = false;   // tracked by its rotation about the last centre (SystemOptions::rotation_only)
  bool provisional = false;     // posed in a provisional map whose scale was guessed (SystemOptions::bridge)
  // That provisional map joined the map later (its frames scaled to the map's and adjusted: pose updates carry it).
  bool joined = false;
  // The pose's scale is still the provisional map's guess: it never joined the map (lost, or the run ended first),
  // so its frames are in a frame of their own, not the map's (a Sim(3) apart).
  bool guessed_scale() const { return provisional && !joined; }
  // Waiting: an initialisation was found and rejected in this frame (its note says why: a depth-reversal
  // ambiguity), as opposed to no initialisation being possible yet.
  bool init_rejected = false;
  // The map was found, while it settled, to be the mirror of the scene in depth and was flipped (note says by
  // how much the mirror explained the settling window better).
  bool depth_reversed = false;
  // A revised report: the frame had been posed in a map that was dropped (SystemOptions::restart_min_lost_frames);
  // it has no pose now (returned when the new map initialises). The report of the frame that started the new map
  // says so in its note, with map_restarted set.
  bool map_dropped = false;
  bool map_restarted = false;
};

// The System's bridge over the unmapped (SystemOptions::bridge), from a turn's last frame to where the map is
// found again. (Outside System: clang 14 cannot construct a nested struct with member initialisers in an optional.)
struct BridgeState {
  int anchor_slot = -1;    // the turn's last frame: its pose is the provisional map's reference
  double depth_prior = 0;  // the map's median depth before the turn: the guessed scale
  bool built = false;      // the provisional map exists (before: waiting for two views that make one)
  std::unordered_set<int64_t> points;  // its points
};

// What the self-calibration (InitOptions::self_calibrate) measured, and whether it replaced the camera's k1.
struct SelfCalibration {
  bool tried = false;
  bool accepted = false;
  int64_t frame = -1;          // the frame whose settling measured it
  double k1_given = 0;         // the camera's k1 before
  double k1_measured = 0;      // the window's best k1 (the camera's k1 after, when accepted)
  double sigma_k1 = 0;         // the standard deviation its likelihood ratio implies
  double z = 0;                // |k1_measured - k1_given| / sigma_k1: the square root of the likelihood ratio
  double corner_shift_px = 0;  // how far the change moves a feature seen at the image's farthest corner
  double k1_half[2] = {0, 0}, sigma_k1_half[2] = {0, 0};  // the same fit on each half of the points (alternate)
  double min_half_share = 0;   // the smaller of the halves' changes of k1 over the whole's (negative: opposite)
  int frames = 0, points = 0, observations = 0;
  std::string note;            // one line: what was measured and what was done
};

class System {
 public:
  ~System();  // waits for a local bundle adjustment still being solved (MappingOptions::local_ba_async)
  System& operator=(System&& other) noexcept;  // (a restart: SystemOptions::restart_min_lost_frames)
  System(const PinholeCamera& camera, const SystemOptions& options, std::unique_ptr<compute::PoseKernel> pose_kernel,
         std::unique_ptr<compute::PointKernel> point_kernel);

  // Processes the next frame. Returns the reports of the frames that became final: normally this frame;
  // when the map is initialised, also the frames from the reference frame on, and those before it that
  // could be placed (their reports replace the earlier 'waiting' ones).
  std::vector<FrameReport> Process(const FrameObservations& frame);
  // MappingOptions::local_ba_async: waits for the last keyframe's local bundle adjustment, applies it and returns
  // that keyframe's revised report (none when nothing is pending; also those a Process that threw had flushed).
  // Process does it first; call it after the last frame, before reading the final map.
  std::vector<FrameReport> Flush();
  // After the last frame: Flush, and when the map started after a restart (SystemOptions::restart_min_lost_frames)
  // has not yet posed more frames than the map before it, that map's poses stand and the new map's frames are
  // reported again without a pose (FrameReport::map_dropped); result_map() is then that map.
  std::vector<FrameReport> Finish();
  // The same wait and application, the revised report held for the next Process or Flush to return: for a caller
  // that reads the map (relocalisation) before it processes the frame.
  void ApplyPendingAdjustment();

  // After the track is lost: the pose of a frame from features matched to map points by their look alone
  // (no pose prior), by RANSAC PnP on the points that are in the map. nullopt when fewer than
  // relocalise_min_inliers matches agree, or before initialisation. Changes nothing; the caller passes the
  // pose as the frame's pose_hint with the inlier features under their map points' ids.
  std::optional<Relocalisation> Relocalise(const std::vector<RelocalisationMatch>& matches) const;

  // For --gt-scale: the true distance between the camera centres at two stamps, when known. The first
  // baseline is then scaled to it instead of to 1.
  void SetBaselineOracle(std::function<std::optional<double>(double, double)> oracle) { oracle_ = std::move(oracle); }

  // Starts in a map made before (a map file): its points and its keyframes (poses and features). Only before
  // the first frame; throws std::logic_error after one. The System is then initialised but not localised: a
  // frame without a pose hint is lost until one is relocalised against the map (Relocalise, then Process with
  // the pose as its hint); tracking and mapping go on from there, in the map's frame and scale.
  // `camera`, when given, replaces the System's: a map made by a run that self-calibrated its k1 carries the
  // refined camera (its features are undistorted with it). The caller checks that it differs only in k1.
  void StartInMap(std::vector<MapPoint> points, std::vector<FrameRecord> keyframes,
                  const std::optional<PinholeCamera>& camera = std::nullopt);
  bool initialised() const { return initialised_; }
  // Some map was initialised in this run: this one, or one dropped since (SystemOptions::restart_min_lost_frames),
  // whose frames keep their poses until a new map initialises.
  bool made_a_map() const { return initialised_ || restarts_ > 0; }
  // The map a run's outputs hold (map.ply): this one, or the one before a restart while the new one is not
  // initialised, and after Finish when it had posed more frames than the new one.
  const Map& result_map() const { return dropped_map_ && (finished_with_dropped_map_ || !initialised_) ? *dropped_map_ : map_; }
  // Some frame has a pose: false before the initialisation, and in a loaded map before its first relocalisation.
  bool localised() const { return last_posed_slot_ >= 0; }
  // A provisional map is being tracked (SystemOptions::bridge): the caller should try to relocalise every frame
  // against the rest of the map (Relocalise leaves the provisional points out) and pass the pose as its hint.
  bool bridging() const { return bridge_ && bridge_->built; }
  bool Provisional(int64_t point_id) const { return bridging() && bridge_->points.count(point_id) > 0; }
  // A point the pose step and the remapping may use now: any, or while a provisional map is tracked only its own
  // (the rest of the map is at another scale).
  bool AtCurrentScale(int64_t point_id) const { return !bridging() || Provisional(point_id); }
  const Map& map() const { return map_; }
  // The tracks that went on as an older map point in the last Process (MappingOptions::merge_revisited_points):
  // (track id, map point id) pairs. The System already takes the track's features under the point's id; a
  // front end should relabel the track (the System otherwise renames its features frame by frame).
  const std::vector<std::pair<int64_t, int64_t>>& merged_tracks() const { return merged_tracks_; }
  // The camera the map is made with: the given one, or with its k1 self-calibrated (InitOptions::self_calibrate).
  const PinholeCamera& camera() const { return camera_; }
  // (Of result_map()'s map: after a restart that kept the old map, the old map's measure.)
  const SelfCalibration& self_calibration() const {
    return &result_map() != &map_ && dropped_self_calibration_ ? *dropped_self_calibration_ : self_calibration_;
  }
  // How many times the map was dropped and started again (SystemOptions::restart_min_lost_frames).
  int restarts() const { return restarts_; }

 private:
  bool TryInitialise(std::vector<FrameReport>* out);
  // A two-view solution refined over the initialisation's window (reference .. current frame).
  struct InitHypothesis {
    std::vector<Pose> poses;  // per window slot, cam_from_reference
    std::vector<Eigen::Vector3d> points;  // in the reference camera
    std::vector<int64_t> point_ids;
    double median_px = std::numeric_limits<double>::infinity();  // over the window's observations
    double cost = std::numeric_limits<double>::infinity();       // mean squared residual, each capped (px^2)
    int observations = 0;                                          // in the window, over which cost is the mean
    int two_view_inliers = 0;
    double two_view_parallax_deg = 0;
    bool mirrored = false;  // the depth-reversed twin of the two-view solution
    // May become the map: it passed every gate. Others (a plane's second motion, short of parallax) only stand
    // in the ambiguity test: while one explains the window as well, no solution is taken.
    bool eligible = true;
    bool parallax_ok = false;  // the refined window has the parallax asked for
    double median_parallax_deg = 0;  // of the points, between the window's first and last cameras
    // The lag-1 correlation of the tracks' residuals between a track's consecutive observations in the window
    // (frames where it is missing or behind the camera skipped), pooled over the tracks
    // (detail::PooledLag1Correlation): about 0 for a tracker's independent noise, towards 1 for a bias that
    // changes smoothly with the view.
    double residual_correlation = 0;
  };
  // Places every frame of `window` by PnP against `points` (the last one at last_from_ref when given), refines
  // the window by one bundle adjustment and checks it (points in front, parallax for the tracks' noise).
  // nullopt with *failure (when given) saying why.
  std::optional<InitHypothesis> RefineInitWindow(const std::vector<int>& window, const std::optional<Pose>& last_from_ref,
                                                 std::vector<Eigen::Vector3d> points, std::vector<int64_t> point_ids,
                                                 std::string* failure, bool check_parallax = true,
                                                 bool dense_schur = false) const;
  // The other minima of the two views' cost in the bas-relief valley around `winner` (geometry::RelativePoseMinima,
  // over the winner's inliers), those that might compete with it, each refined over the window (eligible when it
  // has the parallax asked for).
  std::vector<InitHypothesis> ValleyNeighbours(const std::vector<int>& window, const std::vector<Eigen::Vector2d>& n1,
                                               const std::vector<Eigen::Vector2d>& n2, const std::vector<int64_t>& ids,
                                               const InitHypothesis& winner) const;
  // The two-view solutions between the first and the last frame of `window` (n1, n2: normalised coordinates of
  // their shared features `ids`), each refined over the window, and the depth-reversal ambiguity test: the best
  // one, in the first frame's camera, or nullopt with *why (*rejected when an ambiguity refused a solution).
  // *most_inliers (when given): the most epipolar inliers any two-view try that found a model counted (-1: none
  // found one), and the fewest a solution needs.
  struct InlierSupply {
    int found = -1, needed = 0;
  };
  std::optional<InitHypothesis> SolveInitWindow(const std::vector<int>& window, const std::vector<Eigen::Vector2d>& n1,
                                                const std::vector<Eigen::Vector2d>& n2, const std::vector<int64_t>& ids,
                                                int need_inliers, int need_points, std::string* why, bool* rejected,
                                                InlierSupply* most_inliers = nullptr) const;
  // After a failed try from the reference: it moves on when its shared tracks could not give the inliers needed.
  void MoveStarvedReference(int cur_slot, size_t shared, const InlierSupply& supply, std::vector<FrameReport>* out);
  // How many of frame cur_slot's features frame s saw too.
  int SharedFeatures(int s, int cur_slot) const;
  // The features a frame shares with an earlier one that are no map point: their normalised coordinates in each,
  // their ids, and the angle between each one's two rays (degrees, the rotation not removed).
  struct Correspondences {
    std::vector<Eigen::Vector2d> n1, n2;
    std::vector<int64_t> ids;
    std::vector<double> motion_deg;
  };
  Correspondences Correspond(int ref_slot, int cur_slot) const;
  // InitOptions' shared features, inliers and points, each lowered where the frame tracks few features
  // (min_shared_fraction of them, down to min_count_floor).
  struct InitCounts {
    int common, inliers, points;
  };
  InitCounts NeededCounts(int cur_slot) const;
  // Settling (InitOptions::settle_parallax_deg) of a map just made from two views ending at init_slot, whose first
  // baseline is `baseline` long, from the reference frame reference_slot_.
  void BeginSettling(int init_slot, double baseline, double two_view_parallax_deg, int min_points);
  double ParallaxFromReference(int slot) const;
  // The points seen at least twice among some frames (slots), and their observations, for a bundle adjustment.
  struct WindowPoints {
    std::vector<MapPoint*> pts;
    std::vector<Eigen::Vector3d> X;
    std::vector<geometry::BundleObservation> obs;  // camera: index into the window
  };
  WindowPoints CollectWindowPoints(const std::vector<int>& window);
  // Writes the adjusted positions back; a point whose median residual over the window (at least 3 views)
  // is above the outlier threshold leaves the map. Returns how many left.
  int StoreAdjustedPoints(const std::vector<Pose>& cams, const WindowPoints& wp, int64_t frame_index);
  void Settle(int slot, std::vector<FrameReport>* out);
  // The depth-reversal test of the initialisation, again over a settling window: the map as it is and its
  // mirror in depth (in the window's first camera), each placed and refined over the window (the map's own
  // adjusted fit counted too); when the mirror explains the window clearly better (InitOptions::ambiguity_chi2
  // and kFlipCostRatio), *cams and wp->X become the mirror's (in the world frame, the first camera where it was)
  // and *why says so.
  bool FlipIfMirrored(const std::vector<int>& window, std::vector<Pose>* cams, WindowPoints* wp, std::string* why) const;
  static constexpr int kFlipCheckFrames = 20;
  static constexpr double kFlipCostRatio = 1.6;  // the map's cost over its mirror's needed to flip (and chi-square)
  // InitOptions::self_calibrate, on the settling's last window after its adjustment (cams, wp.X: adjusted): true
  // when the camera's k1 was replaced (every stored feature then undistorted again with it).
  static constexpr int kCalibrationFrames = 40;
  bool SelfCalibrate(const std::vector<int>& window, const std::vector<Pose>& cams, const WindowPoints& wp, int slot);
  // InitOptions::pose_frames_before_reference: places frames before_slot-1, before_slot-2, ... (not before
  // first_slot) while each can be; the ones placed get poses. Returns the first slot placed (before_slot:
  // none).
  int PoseFramesBefore(int before_slot, int first_slot);
  // A frame placed by PnP from a few points of the map (before the reference, or again after a settling) agrees
  // with the posed frame `next` beside it: at the median over the tracks they share, the track's ray in `next` is
  // within the pose step's inlier threshold (PoseTrackerOptions::inlier_threshold_px, as an angle) of its epipolar
  // plane under the two poses (of the turned ray itself where the two poses share their centre). PnP fits a few
  // points of one face in more than one way: the rendered fast scenario at 640x480 through 65 degrees with
  // photometric noise (docs/robustness_webcam.md), seed 2, had frames 0-6 placed again after the settling
  // 2.9-4.2 m off from 16-19 points, 13-15 of them PnP inliers (frame 6 turned 53 degrees from frame 7, where the
  // camera turned 9): the run's ATE 75 cm, the frames from the reference on 1-1.5 cm. Those placements were
  // 0.62-1.85 degrees from the planes at the median, right ones 0.004-0.07 (the rendered fast scenario at 320x240,
  // seeds 1-6, and that run), the limit 0.34 at f = 500 px. True with fewer than kMinTracksToFollow tracks shared
  // (nothing to judge by).
  bool FollowsFrom(int k, const Pose& k_from_world, int next) const;
  static constexpr size_t kMinTracksToFollow = 8;
  // RANSAC PnP as the pose step judges a point: its inlier threshold, this many inliers at least.
  geometry::PnpOptions TrackerPnpOptions(int min_inliers) const;
  std::optional<Pose> PlaceByPnp(int slot, int min_inliers, double min_inlier_ratio) const;
  FrameReport TrackFrame(int slot, const std::optional<Pose>& pose_hint);
  // SystemOptions::rotation_only: poses `slot` by its rotation about the last tracked centre when the tracks
  // agree on one; true when it did (r then says so).
  // over_pose: in place of a pose the pose step found from few points (SystemOptions::rotation_only_over_weak_pose),
  // which asks the tracks to agree on the turn within their noise from the first frame of the turn on.
  bool TrackRotationOnly(int slot, FrameReport* r, bool over_pose = false);
  // The tracks' noise sigma (px, per coordinate) from the map's residuals in the recent keyframes; nullopt before
  // any keyframe has measured one.
  std::optional<double> RecentNoisePx() const;
  int TriangulateNewPoints(int slot, int inliers);
  // MappingOptions::merge_revisited_points: the map point not observed in `slot` that the new track `f`
  // triangulated from `views` is, if any; `unseen` holds those points and their projections into `slot`.
  // `seen`: the keyframes the track is seen in (a point seen there too is another point).
  std::optional<int64_t> RevisitedPoint(const FeatureUndistorted& f, const std::vector<int>& views,
                                        const std::vector<int>& seen,
                                        const std::vector<std::pair<int64_t, Eigen::Vector2d>>& unseen) const;
  // The track's features in every frame go under the point's id (dropped where that frame has the point too).
  void MergeTrack(int64_t track, int64_t point);
  void AdjustPoints(int slot, FrameReport* r);
  void BundleAdjustWindow(int slot, FrameReport* r);
  // MappingOptions::local_ba_keyframes: the newest keyframes' poses and their points by one bundle
  // adjustment, the keyframes before them fixed (MappingOptions says which), a loaded map's points fixed. Not
  // while settling (the settling adjusts the whole window), on a provisional map (its scale is not the older
  // keyframes'), nor over fewer points than the adjusted poses have parameters. In three parts: the problem
  // (nullptr when it is skipped), copied out of the map; its solve (LocalBa::Solve, on another thread with
  // local_ba_async); the solution written back to the map.
  struct LocalBa;
  std::unique_ptr<LocalBa> PrepareLocalBa(int slot);
  void ApplyLocalBa(const LocalBa& ba, FrameReport* r);
  std::vector<FrameReport> ProcessFrame(const FrameObservations& frame);
  PoseEstimate EstimatePosePnp(const std::vector<PointObservation>& obs, std::vector<double>* res,
                               std::vector<uint8_t>* inl) const;
  std::vector<int> WindowSlots() const;
  void ResidualStats(int slot, FrameReport* r) const;
  FrameReport PosedReport(int slot) const;
  // Each point seen in this posed frame is an inlier when it projects within the inlier threshold of its
  // feature: the flags gate the next frame's score (§5.2).
  void RefreshInlierFlags(int slot);  // a tracked frame's report: its pose and residual statistics
  void MarkSeen(int slot);
  void PruneHistory(int slot);

  PinholeCamera camera_;
  PinholeCamera ideal_;  // same intrinsics, no distortion: observations are undistorted on arrival
  double focal_px_;      // mean focal length: converts pixel thresholds to normalised units
  SystemOptions options_;
  std::unique_ptr<compute::PointKernel> point_kernel_;
  std::unique_ptr<PoseTracker> tracker_;  // from construction; its translation floor set at initialisation
  compute::NormalTable point_normals_;
  PoseSmoother smoother_;
  std::function<std::optional<double>(double, double)> oracle_;

  Map map_;
  bool initialised_ = false;
  int reference_slot_ = -1;
  int init_min_points_ = 0;  // the point count the initialisation asked for (InitOptions::min_points, lowered)
  int last_posed_slot_ = -1;
  // Settling (InitOptions::settle_parallax_deg).
  bool settling_ = false;
  double next_settle_parallax_deg_ = 0;
  int init_slot_ = -1;             // the frame the initialisation ended on
  int posed_from_ = -1;            // the first posed slot: the reference, or a frame before it (pose_frames_before_reference)
  int pruned_until_ = 0;           // frames before this slot have dropped their features (history_frames)
  double init_baseline_ = 1.0;     // its distance from the reference camera: the scale, kept by every settling
  SelfCalibration self_calibration_;
  // The median residual of the map's points in the last keyframes (MappingOptions::max_relative_depth_noise).
  static constexpr size_t kResidualHistory = 15;
  std::deque<double> recent_residual_px_;
  double noise_parallax_deg_ = 0;
  // Rotation-only tracking (SystemOptions::rotation_only), under way while panorama_bearings_ holds any: the
  // centre all its frames share (a well-posed frame of the tracked run before), and each track's bearing in the
  // world as first seen from there.
  static constexpr int kPanoramaCentreLookback = 10;  // frames searched back for a well-posed centre
  // The first frame of the current run of poses that follow from one another: a relocalised frame starts one (its
  // pose does not follow from the frame before, which may have been posed in a provisional map given up since).
  // A turn's centre is looked for from there on.
  int pose_run_start_slot_ = 0;
  Eigen::Vector3d panorama_centre_ = Eigen::Vector3d::Zero();
  double panorama_min_rms_px_ = 0;  // the least residual of its frames so far: the tracks' noise
  std::vector<std::pair<int, double>> panorama_rms_px_;  // each of its frames (slot) and its residual, in order
  std::unordered_map<int64_t, Eigen::Vector3d> panorama_bearings_;
  // The bridge over the unmapped (SystemOptions::bridge), from a turn's last frame to where the map is found again.
  std::optional<BridgeState> bridge_;
  // The points of a map this run started in (StartInMap): the local bundle adjustment holds them fixed.
  std::unordered_set<int64_t> loaded_points_;
  // MappingOptions::local_ba_async: the adjustment being solved, and the report of its keyframe.
  std::unique_ptr<LocalBa> pending_ba_;
  // Tracks merged into a map point (MergeTrack): their features are taken under the point's id until a frame comes
  // without them (a front end never reuses an id); and those merged in the last Process.
  std::unordered_map<int64_t, int64_t> track_alias_;
  std::vector<std::pair<int64_t, int64_t>> merged_tracks_;
  std::vector<FrameReport> held_reports_;  // revised, not yet returned (ApplyPendingAdjustment, a Process that threw)
  // Restarts (SystemOptions::restart_min_lost_frames): the camera as given (before any self-calibration), the
  // frames lost in a row, and the restarts so far.
  PinholeCamera given_camera_;
  int lost_run_ = 0;
  int restarts_ = 0;
  // A map replaced by a restart: its frames' reports without a pose (returned once the new map has posed more
  // frames than its dropped_posed_), and the map itself until then (result_map).
  std::vector<FrameReport> dropped_reports_;
  std::optional<Map> dropped_map_;
  std::optional<SelfCalibration> dropped_self_calibration_;
  int dropped_posed_ = 0;
  bool finished_with_dropped_map_ = false;  // Finish kept it
  int PosedFrames() const;
  // After this frame's reports: drops the map and starts again with this frame when it has stayed lost long
  // enough; returns the reports to return instead (the dropped frames', then this frame's in the new start).
  std::vector<FrameReport> MaybeRestart(const FrameObservations& frame, std::vector<FrameReport> now);
  // After a turn ended in a move at `slot`: a bridge anchored at the turn's last pure-rotation frame; false (and no bridge)
  // when the map's depth before the turn cannot be measured.
  bool StartBridge(int slot);
  // Waiting for the provisional map: its two-view solution between the anchor and `slot`. The reports of the
  // frames it poses, or this frame's 'lost' report saying why not yet.
  std::vector<FrameReport> TryBridge(int slot);
  // A frame relocalised against the map while bridging: tracked in the provisional map, which is then scaled to
  // agree and joins the map.
  std::vector<FrameReport> JoinBridge(int slot, const Pose& cam_from_world);
  // After the scaling of a join: the bridge's keyframes (and the joining frame) and its points adjusted together,
  // the anchor and the map's points fixed. Returns how many keyframes were adjusted (0: too few points).
  int AdjustJoinedBridge(int slot, FrameReport* r);
  void AbandonBridge(int64_t frame_index);
  // The upper median depth of the map points that frame `slot` sees (in front of it), at its pose; none when it
  // sees none.
  std::optional<double> MedianDepthSeenBy(int slot) const;
};

}  // namespace mcslam::slam
