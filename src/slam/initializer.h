#pragma once
// The two-view initialisation (paper §6.1): the reference frame, the two-view solutions between it and the current
// frame refined over every frame between them, the depth-reversal ambiguity test, and the frames before the
// reference placed once the map exists. A map made here settles next (Settler).
#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"
#include "slam/frame_report.h"
#include "slam/map.h"

namespace mcslam::slam {

struct SlamState;
class Settler;

class Initializer {
 public:
  Initializer(SlamState& s, Settler& settler) : s_(s), settler_(settler) {}

  // Tries to make the map from the reference frame to the newest frame. True when it did (*out: the reports of
  // the frames it posed); false with *out holding one report whose note says why not yet (init_rejected when an
  // ambiguity refused a solution).
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
                                                 std::string* failure, bool check_parallax = true) const;
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
  // The features a frame shares with an earlier one that are no map point: their normalised coordinates in each,
  // their ids, and the angle between each one's two rays (degrees, the rotation not removed).
  struct Correspondences {
    std::vector<Eigen::Vector2d> n1, n2;
    std::vector<int64_t> ids;
    std::vector<double> motion_deg;
  };
  Correspondences Correspond(int ref_slot, int cur_slot) const;
  // Whether the features moved enough since the reference for the two views to be tried: a median motion of at
  // least InitOptions::min_median_motion_deg, or a median motion that no rotation explains of at least
  // min_nonrotational_motion_px (a camera that circles what it looks at). nullopt when they did, else why not (the
  // frame's note).
  std::optional<std::string> MotionShort(const Correspondences& c) const;
  // The part of the features' motion that no turn of the camera explains (geometry::NonRotationalMotionRad), in
  // pixels at the focal length.
  double NonRotationalMotionPx(const Correspondences& c) const;
  // InitOptions' shared features, inliers and points, each lowered where the frame tracks few features
  // (min_shared_fraction of them, down to min_count_floor).
  struct InitCounts {
    int common, inliers, points;
  };
  InitCounts NeededCounts(int cur_slot) const;
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
  // Places frames before_slot-1, before_slot-2, ... (not before first_slot) by PnP against the map while each can
  // be (the pose step's least inliers and share of the points seen) and follows from the frame after it
  // (FollowsFrom); the walk ends at a frame already posed or without features. `prepare` (when given) is called on
  // each frame before it is placed. The ones placed get poses; `placed` (when given) receives each one's slot and
  // PnP inliers, newest first. Returns the first slot placed (before_slot: none). Used for the frames before the
  // first map's reference (InitOptions::pose_frames_before_reference) and for frames lost before a frame tracked
  // again (SystemOptions::pose_lost_frames_when_found).
  int PoseFramesBefore(int before_slot, int first_slot, const std::function<void(FrameRecord&)>& prepare = {},
                       std::vector<std::pair<int, int>>* placed = nullptr);

 private:
  // The other minima of the two views' cost in the bas-relief valley around `winner` (geometry::RelativePoseMinima,
  // over the winner's inliers), those that might compete with it, each refined over the window (eligible when it
  // has the parallax asked for).
  std::vector<InitHypothesis> ValleyNeighbours(const std::vector<int>& window, const std::vector<Eigen::Vector2d>& n1,
                                               const std::vector<Eigen::Vector2d>& n2, const std::vector<int64_t>& ids,
                                               const InitHypothesis& winner) const;
  // After a failed try from the reference: it moves on when its shared tracks could not give the inliers needed.
  void MoveStarvedReference(int cur_slot, size_t shared, const InlierSupply& supply, std::vector<FrameReport>* out);
  // How many of frame cur_slot's features frame s saw too.
  int SharedFeatures(int s, int cur_slot) const;

  SlamState& s_;
  Settler& settler_;
};

}  // namespace mcslam::slam
