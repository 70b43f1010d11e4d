#pragma once
// The options of the SLAM back end (System, system.h): the initialisation's (InitOptions), the mapping's
// (MappingOptions) and the System's own with the pose step's (SystemOptions). Each Check() throws
// std::invalid_argument naming the bad field and its value (system.cc).
#include <cstdint>
#include <string>

#include "geometry/two_view.h"
#include "slam/pose_smoother.h"
#include "slam/pose_tracker.h"

namespace mcslam::slam {

struct InitOptions {
  // Start trying once the features moved this much (median angle between a feature's two rays, the rotation
  // not removed): 2.3 degrees is 20 px at f = 500 px. An angle, so one value serves every focal length.
  double min_median_motion_deg = 2.3;
  // ... or once the part of that motion that no rotation explains reaches this many pixels (median over the
  // features; Initializer::NonRotationalMotionPx). A camera that circles what it looks at (an object scanned, a
  // turntable, a hand-held orbit) keeps its features nearly still in the image while the parallax grows: the
  // Middlebury temple ring, 8 degrees of orbit a view, moved its features 0.2-0.6 degrees in 2 views (16 degrees
  // of parallax; 7.6-11.5 px that no turn explains) and waited 7 views for 2.3 or never got there; the rendered
  // paper scenario, seed 2, waited until frame 44 (9.9 degrees of parallax). A turn about the camera's centre
  // leaves the tracks' noise (about a pixel at 1 px of noise), a still camera less. 5 px: more than a motion that
  // is no orbit leaves by the time its median motion reaches 2.3 degrees (the rendered still-start scenario, seed
  // 3: 4.4 px then), so that such a motion starts as before; at 3 px two still-start seeds made their first map
  // from 4 degrees of parallax instead of 7 and ended at 0.33-0.37 % of their path instead of 0.09-0.16 %.
  // 0: the median motion alone.
  double min_nonrotational_motion_px = 5.0;
  int min_common_features = 40;              // fewer shared with the reference: the reference moves on
  int min_inliers = 40;                      // epipolar inliers needed
  int min_points = 30;                       // triangulated points needed
  // A scene with little texture offers fewer features than those counts ask for, and would never initialise:
  // each count is lowered to at most min_shared_fraction of the features the current frame tracks, down to
  // min_count_floor. A frame tracking >= 67 features (40 / 0.6) keeps the counts above. The floor is what the
  // window's ambiguity test still decides on. Rendered sparse scenario (21-35 corners a frame), seeds 1-30: a
  // floor of 20 left 11 never initialised and 7 initialised within the first 30 % of the frames; 12 left 3 and
  // 17, 15 left 1 and 16; none mirrored at any of them (at 15, 3 of 10 had come out mirrored with an earlier
  // initialisation, issue #16's notes). The two-view geometry's own minima (geometry::TwoViewOptions: 15 epipolar
  // inliers, 15 points) bind below 15: the floor lowers the shared features to 12, the inliers and points to 15.
  // Lowering those too (the rendered sparse scenario through a 65-degree camera, 11-17 corners a frame, seeds
  // 1-10, which never initialise) initialised every seed but made one map mirrored and one run succeed.
  double min_shared_fraction = 0.6;
  int min_count_floor = 12;
  // Frames from the reference to the initialising one, at least. Two views of a narrow field of view are
  // explained about as well by the depth-reversed structure and by the true one (and a window of two fits
  // its own noise: 0.02 px), so the ambiguity test below cannot tell them apart; a third view can. At 15x
  // the paper's speed a two-frame window initialised mirrored (fast scenario, seed 6).
  int min_window_frames = 3;
  // Median parallax of those points, before and after the window's refinement, at least this; and after the
  // refinement at least what the tracks' noise asks for: two views of a parallax θ fix a depth to about
  // σ / (f θ) of itself (σ the features' noise, measured as the refined window's residual), which must not
  // exceed max_relative_depth_noise. At σ = 1 px and f = 500 px that is 4.6 degrees (a near pure-rotation
  // solution explains such views about as well as the true one under ~3 degrees: issue #4's note found 5
  // the best of 3, 5, 7 there); real tracks at 0.2-0.5 px need the floor only.
  double min_median_parallax_deg = 3.0;
  double max_relative_depth_noise = 0.02;
  // Ambiguity: another refined solution with another structure (the best one's depth-reversed twin, a plane's
  // second motion) must explain the window worse by at least this chi-square (its summed squared residuals
  // minus the best one's, over the best one's mean squared residual), or the initialisation waits for more
  // motion. 25: a difference that noise alone gives with odds of about one in a million (1 dof).
  double ambiguity_chi2 = 25.0;
  geometry::EssentialMethod method = geometry::EssentialMethod::kEightPoint;
  double ransac_threshold_px = 1.5;
  // Every frame from the reference to the initialising one is placed by PnP against the two-view points and
  // the whole window refined by one bundle adjustment (Levenberg-Marquardt, Huber), for each two-view
  // hypothesis; the hypothesis that explains the window best is kept. Two views of a narrow field of view
  // leave the bas-relief direction nearly free; the window pins it down.
  bool refine_window = true;
  double refine_huber_px = 2.0;
  // Settling: after the initialisation, while the median parallax between the reference camera and the
  // current one (over the map points both see) is below settle_parallax_deg, every posed frame since the
  // reference and the map are refined together by one bundle adjustment each time that parallax has grown by
  // settle_step (and once more on reaching settle_parallax_deg); the scale stays that of the first baseline.
  // The first map is made from a few degrees of parallax, so that a user gets a pose early, but at σ = 1 px
  // and a narrow field of view a few degrees leave the bas-relief direction nearly free: the paper scenario's
  // first map came out 1.8x too shallow on seed 1, and every later point inherited it. Waiting for 16 degrees
  // before initialising fixes that too, at the cost of no pose for the first ~90 frames. 0 turns it off.
  double settle_parallax_deg = 16.0;
  double settle_step = 1.5;
  // Frames in one settling adjustment (evenly spread); the others are placed again by PnP against its points.
  // The paper scenario settles at ~100 frames: all of them (keeping a third of them cost 0.5 cm of mean
  // error over six seeds, the map's points being seen fewer times).
  int settle_max_frames = 120;
  // Frames before the reference: when the reference moved on while waiting (min_common_features), the
  // frames before it were never posed. After the initialisation each is placed by RANSAC PnP against the
  // new map, newest first, for as long as one is (at least the tracker's min_inliers agreeing, and at least
  // half of the map points it sees, and following the frame after it: Initializer::FollowsFrom), and placed again
  // after every settling adjustment.
  bool pose_frames_before_reference = true;
  // Self-calibration of the lens' first radial distortion coefficient, once, at the settling's last adjustment
  // (geometry/self_calibration.h, docs/self_calibration.md): at most 40 of the window's frames and their points
  // adjusted again with k1 free and as given. The focal length stays as given: over a settling window it trades
  // with k1 (correlation ~0.9), and two halves of 7-Scenes gave focal lengths 10 % apart. The measured k1 replaces
  // the given one when the change is both significant and material: a likelihood ratio of at least
  // calibration_min_z standard deviations, and a shift of at least calibration_min_shift_px of a feature seen at
  // the image's farthest corner. Tracks err together, so the ratio over-states real tracks' evidence: the
  // rendered scenarios' exact cameras gave up to 6.5 (1.5 px), KITTI's rectified one 1.1, 7-Scenes' nominal
  // camera 14.1-16.6 (6-8 px; robustness matrix, seeds 1-10). Every stored feature is then undistorted again and
  // the window adjusted with the new camera; the map and the caller go on with it (System::camera). Needs the
  // settling (settle_parallax_deg > 0).
  bool self_calibrate = true;
  double calibration_min_z = 10.0;
  double calibration_min_shift_px = 3.0;
  // ... and the same fit on each half of the window's points (alternate ones) measures the change too: each
  // half's change of k1 in the same direction, at least calibration_min_half_share of the whole's and at most its
  // inverse (a factor of two either way at 0.5). A lens
  // bends every ray alike, so its k1 repeats in both halves (7-Scenes seed 1: -0.0318 from -0.0340 and -0.0309;
  // a rendered lens of -0.2, CliRun.ImagesThroughALens*: -0.215 from -0.184 and -0.288); a k1 that absorbs the
  // errors of some tracks does not (the sparse scenario's seed 3, whose -0.353 at 10.3 sigma bent its map: -0.666
  // and +0.173). The halves' own standard deviations understate their spread as the whole's does (the rendered
  // lens' halves are 4.7 of them apart), so the test is on the shares, not on a z. The upper bound: the sparse
  // scenario's seed 3 (24 points) once measured -0.718 at 12.5 sigma, 38.7 px at the corner, from halves of -1.553
  // and -0.620 (the same sign, the smaller 0.86 of the whole's, the larger 2.16; an experimental front end's tracks);
  // the lenses taken measure at most 1.35 (7-Scenes seeds 1-10: 0.83-1.27, 1.35 with that front end; the rendered
  // lens 1.34).
  double calibration_min_half_share = 0.5;
  // ... and each half's own fit measures it significantly: its likelihood ratio at least calibration_min_half_z
  // standard deviations. Half the points measure a lens with about 1 / sqrt(2) of the whole's z (7-Scenes seeds
  // 1-10: the weaker half at 6.3-11.3 sigma, wholes at 13.9-17.7); a half whose k1-free fit does not lower its cost
  // at all (z 0) measured nothing, whatever k1 it ended at: the rendered planar scenario at 160x120, seed 2, took
  // -0.223 at 38.9 sigma from halves of -0.258 (8.0 sigma) and -0.353 (0 sigma), a camera that is exact, and its
  // map ended 6.3 % of the path off (1.1 % with the camera kept).
  double calibration_min_half_z = 3.0;
  void Check() const;
};

struct MappingOptions {
  // New points (linear triangulation between posed frames).
  int min_track_frames = 3;                  // posed frames a feature must be seen in
  double min_parallax_deg = 2.0;
  // ... and at least what the tracks' noise asks for (Mapper::TriangulateNewPoints): a depth error of at most
  // this fraction of the depth, capped at max_noise_parallax_deg.
  double max_relative_depth_noise = 0.03;
  double max_noise_parallax_deg = 12.0;
  // A map running dry: when fewer inliers than this support a keyframe's pose, its new points need only
  // starving_parallax_deg (if lower): points from less parallax are less accurate, but a pose with none to
  // score is lost, and a larger min_parallax_deg with tracks that end early can starve the map.
  int starving_inliers = 30;
  double starving_parallax_deg = 2.0;
  // ... and need only this many posed frames (if fewer than min_track_frames): under fast motion most tracks
  // live three or four frames, and a track seen in three posed keyframes is one that is nearly gone (fast
  // scenario, seed 2: half of the 65 tracks were map points when a 7 deg jolt left 7 of those in view, and the
  // camera was lost for 14 frames; with two views it tracks all 150).
  int starving_min_track_frames = 2;
  double max_reprojection_px = 3.0;
  // A point removed as an outlier may be triangulated again from its track this many frames later (its
  // first triangulation is often what was wrong: low parallax early in the track).
  int retriangulate_after_frames = 10;
  // A place seen again: a new track whose point, triangulated, is where one map point not seen in this frame
  // projects (within min(max_reprojection_px, adjust_threshold_px) in every view it is triangulated from, not seen
  // beside the track, and no other such point) goes on as that map point instead of making a second one
  // (Mapper::RevisitedPoint, MergeTrack; the front end is told through System::merged_tracks). Without it, every return to a mapped place whose
  // lost points the remapping does not find adds the place's points again (a 10,000-frame orbit: 354 map points
  // after 1,000 frames, 1,671 at the end). Off by default until two end-to-end runs it changes are understood: the
  // rendered rotation scenario, seed 15 (a provisional map after a pan), went from 2.2 to 4.1 cm, and after
  // CliRun's 30-frame gap the pose step's second try alone no longer reached across (0 frames tracked after it).
  // In a loaded map (System::StartInMap) it is on whatever this says: there the run is in a place mapped before,
  // and on 7-Scenes seeds 1-8 it cut the points a second run adds to its loaded map from 268-371 to 51-81 at the same
  // accuracy (docs/map_seeds.md). Where the caller knows the looks (System::SetLookCheck: an image run's
  // descriptors), a merge also needs the track to look like the point; with that, on the robustness matrix, it is
  // still no gain worth a default (docs/tuning.md, 2026-12-07).
  bool merge_revisited_points = false;
  // Frames whose features are kept (their poses are always kept): older ones drop theirs, so that memory and
  // the triangulation's search through the track history stay bounded on a run of any length. Never less
  // than the Fibonacci window reaches back, nor the frames since the reference while initialising/settling.
  int history_frames = 1000;
  // Monte Carlo point adjustment (PointAdjuster::AdjustPoints).
  bool adjust = true;
  double adjust_threshold_px = 2.5;          // a point whose residual stays above this is an outlier (the paper's threshold)
  // Points with a residual above this are re-sampled (the paper uses adjust_threshold_px for both). Lower
  // values also refine points that are still inside the outlier threshold but biased (a depth error that
  // a short window cannot show yet); the best sample replaces such a point only when it lowers the residual.
  double candidate_threshold_px = 2.5;
  int samples = 4096;                        // per point
  int window = 12;                           // keyframes (current and current - Fib(n))
  double sigma_scale = 1.0;                  // Sigma_j = diag(scale * |dz| + floor), dz from Eqs. 8-9
  double sigma_floor_rel_depth = 0.01;       // floor, as a fraction of the point's depth
  double max_distance_px = 20.0;             // cap of one observation's contribution to a sample's score
  // Local bundle adjustment (Mapper::PrepareLocalBa), after each keyframe's Monte Carlo point adjustment:
  // the poses of the newest local_ba_keyframes keyframes and every point they see, refined together; the
  // twice as many keyframes before them and the Fibonacci window's older ones held fixed (they hold the gauge
  // and the scale). The paper's estimators never move a pose and a point together: each new point is
  // triangulated from poses that were themselves found from older points, so where the map renews itself
  // quickly (a car, a fast pan, a turn) the scale and the heading drift with each generation of points.
  // Robustness matrix, 2 cores, seeds 1-10: rendered forward from 0.32-5.3 m to 3-24 cm over a 119 m path,
  // fast 2-6 cm, 7-Scenes 7.0-8.3 -> 6.9-7.2 cm (docs/tuning.md). 0: off (the paper's back end).
  int local_ba_keyframes = 8;
  // Its robust loss: Cauchy with this scale in units of the tracks' noise sigma (measured: the map's recent
  // median residual), never under local_ba_min_loss_px. 2.385 sigma is the Cauchy scale of 95 % efficiency
  // under Gaussian noise (Holland and Welsch): sub-pixel drift of a few tracks, which a least-squares pose
  // would follow, weighs little.
  double local_ba_loss_sigmas = 2.385;
  double local_ba_min_loss_px = 0.3;
  // Its keyframes, adjusted and held, are taken walking back from the newest one, each at least this fraction of
  // the newest keyframe's median depth from the one taken before it (a keyframe nearer is left out): the window
  // then spans a baseline that fixes depths whatever the frame rate and speed. Every posed frame is a keyframe
  // here, and a hand-held camera at 30 Hz moves ~0.5 % of the depth a frame: eight consecutive ones made a window
  // of 4 % that let 7-Scenes' scale drift (ATE 6.9-7.2 cm; 4.9-5.3 cm with 0.02, seeds 1-10). A car at 1 m a frame is
  // already further apart than this: its windows are unchanged. 0: the newest keyframes, consecutive.
  double local_ba_min_step_of_depth = 0.02;
  // Its convergence test: an adjustment ends when a Levenberg-Marquardt iteration lowers its robust cost by less than
  // this fraction of it, or after SystemOptions::ba_iterations. Every posed frame is a keyframe, so each adjustment
  // starts from the last one's solution with one new view, and at Ceres' default (1e-6) every call on the rendered
  // paper scene ran to the cap of 10, creeping by amounts no frame's pose shows. At 1e-3 a call takes 2-6 iterations
  // where the views agree, and the cap where fixed points hold the solution far from where the poses put it (a run
  // in a loaded map). A fixed cap of 3 instead let such a run leave the loaded map's frame (7-Scenes, seed 1: 12 cm
  // and 6 % of scale off it, against 1 cm at 10 iterations and 3 cm at 1e-3). docs/tuning.md.
  double local_ba_function_tolerance = 1e-3;
  // The local bundle adjustment of a keyframe solved on a thread of its own while the caller goes on to the next
  // frame (reads it, runs its front end), and applied at the start of the next System::Process (or Flush): the
  // next frame's pose step and mapping see the adjusted map as they would without it, so a folder of
  // observations gives the same result to the last bit; only what the caller reads between the two calls (an
  // image run's remap requests, its overlay) sees the map before the adjustment. The keyframe's report comes
  // first in the next call's reports, revised (its adjusted pose, residuals and times). Off by default: a
  // caller that turns it on must call Flush after its last frame. `mcslam run` turns it on.
  bool local_ba_async = false;
  void Check() const;
};

// The estimators of each step: the paper's Monte Carlo ones, or the baselines it compares with (§8).
enum class PoseMethod { kMonteCarlo, kPnp };                    // PnP: OpenCV RANSAC EPnP + LM refinement
enum class StructureMethod { kMonteCarlo, kBundleAdjustment };  // BA: Ceres over the same keyframe window
PoseMethod ParsePoseMethod(const std::string& name);            // "mc" | "pnp"
StructureMethod ParseStructureMethod(const std::string& name);  // "mc" | "ba"

struct SystemOptions {
  PoseMethod pose_method = PoseMethod::kMonteCarlo;
  StructureMethod structure_method = StructureMethod::kMonteCarlo;
  int ba_iterations = 10;    // Levenberg-Marquardt iteration cap of the local bundle adjustment
  int ba_fixed_keyframes = 2;  // the oldest keyframes of the window held fixed (gauge, including scale)
  // The pose step's options; its seed is `seed` below and its sigma_trans_floor_m comes from
  // sigma_trans_floor_rel_depth at initialisation (what these two fields say here is not used).
  PoseTrackerOptions tracker;
  InitOptions init;
  MappingOptions mapping;
  PoseSmootherOptions smoother;
  // The tracker's translation-spread floor, as a fraction of the median scene depth at initialisation
  // (the map's scale is arbitrary, so an absolute floor would mean nothing).
  double sigma_trans_floor_rel_depth = 0.0007;
  // Every random draw of the System: the pose step's table, the point adjustment's, the initialisation's RANSAC.
  uint64_t seed = 1;
  // Relocalisation (System::Relocalise): a pose is accepted when at least this many of the matches agree
  // with it (RANSAC PnP, the tracker's inlier threshold).
  int relocalise_min_inliers = 15;
  // When the map leaves the view while the camera only turns (a pan away from what was mapped), no point can be
  // triangulated and the pose step runs out of points. The frame is then posed by its rotation about the last
  // well-posed camera centre, from the bearings of the tracks (Wahba's problem; the rotation-only model of a
  // panorama), while fewer than rotation_only_min_tracks of the map points it tracks are in view, at least that
  // many tracks and rotation_only_min_ratio of those shared agree within 3 sigma of the tracks' measured noise, and their
  // residual has not grown (FrameTracker::TrackRotationOnly): a camera that also moves makes the tracks disagree with
  // any rotation, and the frame is lost as before. No keyframe, no point is made from such frames; the map's pose
  // step takes over as soon as it has points again (lost ones found again by remapping near where the turn
  // projects them). docs/rotation_only.md.
  bool rotation_only = true;
  int rotation_only_min_tracks = 20;
  double rotation_only_min_ratio = 0.7;
  // ... and when the pose step does find a pose, but from fewer than rotation_only_min_tracks inliers, the turn
  // is tried too and taken when it holds: the same tests, its tracks within their noise from the turn's first
  // frame on, and not in a provisional map (docs/rotation_only.md). Six degrees of freedom fitted to ten or fifteen points
  // at one edge of the image trade a turn for a move: the rendered rotation scenario, seed 5, panning back to the
  // map with 10-15 inliers, had its centres jump by centimetres while the camera stood still, and the 54 points
  // triangulated from that phantom baseline sent the frames after it 3-5 deg and up to 27 cm off (ATE 3.5 cm;
  // with the turn 0.6 cm).
  bool rotation_only_over_weak_pose = true;
  // A turn under way whose residual jumps past the move test's bound on one frame is kept for the next frame to
  // tell a move (it grows) from noise (it falls back): that frame is lost, the turn and a provisional map being
  // tracked are kept, and the next frame turns on about the same centre or ends the turn. Through noisy images
  // single frames of a pure turn jump so (rotation scenario with noise of 6 grey levels: 0.46 px against 0.32,
  // the turn ended, 80 frames lost after it; docs/rotation_only.md). false: the first such frame ends the turn.
  bool rotation_only_keep_turn_over_a_jump = true;
  // A bridge over the unmapped: when a turn that took the map out of view ends in a move (the rotation-only
  // tracking above refuses the frame), the camera goes on where nothing is mapped and would stay lost until the
  // map comes back into view. A provisional map is made instead from two views, as the initialisation makes the
  // first one, anchored at the turn's last pure-rotation frame (its pose is known, so only the scale is free):
  // its scale is guessed so that its points lie as deep as the map's did before the turn. Tracking and mapping go
  // on in it; when the caller relocalises a frame against the rest of the map (it tries each frame while
  // bridging()), the provisional map and the frames posed in it are scaled about the anchor's centre so that the
  // frame's two poses agree, then adjusted between the anchor and that frame (the map's points held), and it
  // becomes part of the map. A provisional map whose tracking fails first leaves the map (its frames keep their
  // poses). docs/rotation_only.md.
  bool bridge = true;
  // A frame that finds the map again while its turn is kept over a jump of the turn's residual (it has no pose in
  // the provisional map being tracked) leaves the join to the next frame, which turns on and joins from its pose in
  // the provisional map, or loses it. false: the provisional map is given up at that frame, the turn with it.
  // docs/rotation_only.md.
  bool bridge_join_waits_over_a_jump = true;
  // While a provisional map is waited for (the map out of view, the turn ended in a move), a frame whose own tracks
  // follow as many of the map's points as the pose step needs (tracker.min_inliers), agreeing on a pose (RANSAC
  // PnP, as a relocalisation), is placed in the map by them and the provisional map is not made. The map's points
  // come back into the tracks by a relocalisation whose frame could not join (it had no pose in the provisional
  // map, which the next frame then lost): no descriptor relocalises them again, and the pose step takes no point
  // that was no inlier of the frame before. false: the frames wait for the provisional map's two views.
  // docs/rotation_only.md.
  bool bridge_wait_placed_by_map_tracks = true;
  // A map that stays lost (the camera went where no relocalisation finds it, right after a weak initialisation,
  // or after a long blackout) is replaced by a new one initialised from the frames that follow, once the frames
  // lost in a row reach restart_min_lost_frames and outnumber the frames the map posed: the run then keeps the
  // larger share of its frames posed, in one map. When the new map initialises, the old one's frames are reported
  // again without a pose (FrameReport::map_dropped); a run that ends before keeps them. A map read from a file is
  // never replaced. 0: never. (The rendered fast scenario
  // with two of every ten frames blurred, seed 1, initialised on frames 1-3 and was lost from frame 4 to its
  // end, 146 of 150 frames.)
  int restart_min_lost_frames = 10;
  // When a frame is tracked again after frames were lost (relocalised, found by the pose step or by its rotation,
  // or the first one localised in a loaded map; not while a provisional map is tracked), the lost frames just before
  // it are placed by PnP against the map through the tracks they share with it (those relocalisation matched to map
  // points renamed to them first), newest first, while each agrees with the frame after it; they are reported then
  // (FrameReport::placed_after_loss; not keyframes, no point moves). false: they stay lost.
  bool pose_lost_frames_when_found = true;
  void Check() const;
};

}  // namespace mcslam::slam
