// The full back end (paper §6) on the synthetic scenario: initialisation, tracking, mapping.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <stdexcept>
#include <cstdio>
#include <set>
#include <unordered_map>

#include "apps/slam_job.h"
#include "core/random.h"
#include "eval/trajectory_eval.h"
#include "sim/paper_scenario.h"
#include "sim/scenarios.h"
#include "slam/pose_tracker.h"
#include "slam/system.h"
#include "slam/system_internal.h"
#include "system_test_util.h"

namespace mcslam::slam {
namespace {

using namespace test;  // Scenario, FastOptions, RunSystem

TEST(System, CleanScenarioFromObservationsAlone) {
  const apps::SequenceInput in = Scenario(120, 0.0, 0.0);
  const apps::SlamRunResult res = RunSystem(in);
  ASSERT_TRUE(res.initialised);
  int tracked = 0;
  for (const FrameReport& r : res.reports) tracked += r.status == FrameStatus::kTracked;
  EXPECT_EQ(tracked, 120);
  const auto err = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(res.reports, false));
  // Measured 2.5 mm / 0.05 deg at 2^16 hypotheses; the bounds leave 2x for other seeds and libraries, and
  // stay well inside the paper's 2 cm / 1 degree.
  EXPECT_LT(err.ate_m.mean, 0.005);
  EXPECT_LT(err.rot_deg.mean, 0.2);
  EXPECT_NEAR(err.alignment_result.gt_world_from_est_world.scale, 1.0, 0.02);  // --gt-scale sets the scale
  EXPECT_GT(res.map.points.size(), 150u);
  // The map matches the ground-truth points after the same alignment: median error under 1 cm.
  std::vector<double> point_err;
  const Pose world_from_cam0 = in.groundtruth.world_from_cam.front();
  const sim::SyntheticSequence seq = [] {
    sim::PaperScenarioOptions so;
    so.frames = 1;
    return sim::MakePaperScenario(so);
  }();
  for (size_t i = 0; i < res.map.points.size(); ++i) {
    const Eigen::Vector3d gt_in_cam0 = world_from_cam0.Inverse() * seq.points_in_world[res.map.ids[i]];
    point_err.push_back((res.map.points[i] - gt_in_cam0).norm());
  }
  std::nth_element(point_err.begin(), point_err.begin() + point_err.size() / 2, point_err.end());
  EXPECT_LT(point_err[point_err.size() / 2], 0.01);
}

// The target on the noisy scenario (σ = 1 px, 10 % wrong matches): mean error ≤ 2 cm and ≤ 1 deg after
// a Sim(3) alignment, here on 150 frames (past the settling, which ends at frames 83-107 on seeds 1-6) and at
// 2^16 hypotheses to keep the test short. Seeds 1 and 5: before the settling, the worst (5: 11.7 cm) and one whose
// first map came out 1.8x too shallow (1).
// Without the settling (settle_parallax_deg 0) the first map's depth errors stay: measured over seeds 1-8
// (`mcslam run --hypotheses 65536 --gt-scale [--settle-parallax-deg 0]`, 2026-11-28): ATE 1.3-4.5 cm against
// 0.9-1.0 cm settled, every seed worse (1.3x-4.5x), the scale 1-52 % off (seed 5: 52 %, seed 1: 4 %; seed 1 was
// 80 % off before the simulator's projection rounded its last bits otherwise: which seed keeps a shallow map is
// chaotic). Bounds: each seed's unsettled ATE above its settled one, and the worse of the two scales > 20 % off.
TEST(System, NoisyScenarioMeetsThePapersPrecisionAfterSettling) {
  double worst_raw_scale_error = 0;
  for (uint64_t seed : {1, 5}) {
    const apps::SequenceInput in = Scenario(150, 1.0, 0.1, seed);
    const apps::SlamRunResult res = RunSystem(in);
    ASSERT_TRUE(res.initialised);
    int settled = 0, lost = 0;
    for (const FrameReport& r : res.reports) {
      settled += r.note.rfind("settled", 0) == 0;
      lost += r.status == FrameStatus::kLost;
    }
    EXPECT_EQ(settled, 1) << "seed " << seed;
    EXPECT_EQ(lost, 0) << "seed " << seed;
    const auto err = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(res.reports, false));
    EXPECT_LT(err.ate_m.mean, 0.02) << "seed " << seed;
    EXPECT_LT(err.rot_deg.mean, 1.0) << "seed " << seed;
    EXPECT_NEAR(err.alignment_result.gt_world_from_est_world.scale, 1.0, 0.1) << "seed " << seed;
    SystemOptions o = FastOptions();
    o.init.settle_parallax_deg = 0;
    const apps::SlamRunResult raw =
        apps::RunSlam(in, o, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel(), true);
    const auto raw_err = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(raw.reports, false));
    std::printf("seed %llu: ATE %.4f m settled, %.4f m without the settling (scale %.3f)\n",
                static_cast<unsigned long long>(seed), err.ate_m.mean, raw_err.ate_m.mean,
                raw_err.alignment_result.gt_world_from_est_world.scale);
    EXPECT_GT(raw_err.ate_m.mean, err.ate_m.mean) << "seed " << seed;
    worst_raw_scale_error =
        std::max(worst_raw_scale_error, std::abs(raw_err.alignment_result.gt_world_from_est_world.scale - 1.0));
  }
  EXPECT_GT(worst_raw_scale_error, 0.2);
}

// The same observations through a lens with barrel distortion k1 that the camera file does not declare.
apps::SequenceInput ThroughAnUndeclaredLens(apps::SequenceInput in, double k1) {
  PinholeCamera lens = in.camera;
  lens.dist.k1 = k1;
  for (FrameObservations& f : in.frames)
    for (FeatureObservation& o : f.features) o.uv_px = lens.NormalizedToPixel(lens.Distort(in.camera.PixelToNormalized(o.uv_px)));
  return in;
}

// k1 = -0.25 moves a feature at the corner of the paper's 320x240 image (f = 500 px) by 8-9 px. Measured on seeds
// 1-3 (200 frames, 0.5 px of noise): k1 -0.232 / -0.242 / -0.253 found at 36-61 sigma (the System takes >= 10),
// mean ATE 4.4-6.4 mm against 14-39 mm with the camera kept as given; the undistorted observations: 0.4-0.9
// sigma, kept. Bounds: k1 within 0.04 (twice the worst error), 20 sigma, half the error as given, and 4 sigma
// for a camera that is right (chance: 1 in 16,000).
TEST(System, SelfCalibratesALensTheCameraDoesNotDeclare) {
  for (uint64_t seed : {1, 2}) {
    const apps::SequenceInput clean = Scenario(200, 0.5, 0.0, seed);
    const apps::SequenceInput in = ThroughAnUndeclaredLens(clean, -0.25);
    const apps::SlamRunResult res = RunSystem(in);
    const SelfCalibration& c = res.self_calibration;
    EXPECT_TRUE(c.accepted) << "seed " << seed << ": " << c.note;
    EXPECT_NEAR(c.k1_measured, -0.25, 0.04) << "seed " << seed;
    EXPECT_EQ(res.self_calibration_camera.dist.k1, c.k1_measured);  // the map goes on with it
    EXPECT_GT(c.z, 20.0) << "seed " << seed;
    SystemOptions off = FastOptions();
    off.init.self_calibrate = false;
    const apps::SlamRunResult as_given = RunSystem(in, off, true);
    EXPECT_FALSE(as_given.self_calibration.tried);
    const auto err = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(res.reports, false));
    const auto err_given = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(as_given.reports, false));
    EXPECT_LT(err.ate_m.mean, 0.5 * err_given.ate_m.mean) << "seed " << seed;
    EXPECT_LT(err.ate_m.mean, 0.012) << "seed " << seed;

    const apps::SlamRunResult right = RunSystem(clean);
    EXPECT_TRUE(right.self_calibration.tried);
    EXPECT_FALSE(right.self_calibration.accepted) << "seed " << seed << ": " << right.self_calibration.note;
    EXPECT_LT(right.self_calibration.z, 4.0) << "seed " << seed;
    EXPECT_EQ(right.self_calibration_camera.dist.k1, 0.0);
  }
}

TEST(System, NoisyScenarioIsTrackedThroughout) {
  // sigma = 1 px and 10 % wrong matches, 120 frames: every frame tracked, at the noise level.
  const apps::SequenceInput in = Scenario(120, 1.0, 0.1, 3);
  const apps::SlamRunResult res = RunSystem(in);
  ASSERT_TRUE(res.initialised);
  int lost = 0;
  for (const FrameReport& r : res.reports) lost += r.status == FrameStatus::kLost;
  EXPECT_EQ(lost, 0);
  const auto err = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(res.reports, false));
  EXPECT_LT(err.ate_m.mean, 0.05);
  // The final reprojection error of the inliers is at the noise level (mean |n| of 2-D noise at 1 px: 1.25).
  EXPECT_LT(res.reports.back().reproj_mean_px, 2.0);
}

TEST(System, LostFrameIsCountedAndTrackingResumes) {
  apps::SequenceInput in = Scenario(80, 0.0, 0.0);
  in.frames[60].features.resize(3);  // too few to score: lost
  const apps::SlamRunResult res = RunSystem(in);
  ASSERT_TRUE(res.initialised);
  EXPECT_EQ(res.reports[60].status, FrameStatus::kLost);
  EXPECT_FALSE(res.reports[60].has_pose);
  for (int i = 61; i < 80; ++i) EXPECT_EQ(res.reports[i].status, FrameStatus::kTracked) << i;
}

TEST(System, SameSeedSameResult) {
  const apps::SequenceInput in = Scenario(50, 1.0, 0.1);
  const auto a = RunSystem(in), b = RunSystem(in);
  ASSERT_EQ(a.reports.size(), b.reports.size());
  for (size_t i = 0; i < a.reports.size(); ++i) {
    ASSERT_EQ(a.reports[i].has_pose, b.reports[i].has_pose);
    if (a.reports[i].has_pose) {
      EXPECT_EQ(a.reports[i].cam_from_world.t, b.reports[i].cam_from_world.t) << i;
    }
  }
}

// MappingOptions::local_ba_min_step_of_depth: the local adjustment's keyframes are spaced by what the camera
// moved against the scene's depth, not by their count. The paper scenario (hand-held, 30 Hz, ~2 cm a frame at
// ~3 m) gets windows that reach further back than eight consecutive keyframes; the forward one (10 Hz, 1 m a frame
// at tens of metres) keeps its consecutive ones; with the step 0 both are consecutive.
TEST(System, TheLocalAdjustmentSpacesItsKeyframesByTheMoveAgainstTheDepth) {
  auto median_span = [](const std::string& scenario, double step) {
    sim::ScenarioOptions so;
    so.name = scenario;
    so.noise_px = 0.5;
    so.seed = 1;
    so.frames = 100;
    const apps::SequenceInput in = apps::KnownMapInputFromSequence(sim::MakeScenario(so));
    SystemOptions o = FastOptions();
    o.mapping.local_ba_min_step_of_depth = step;
    const apps::SlamRunResult res = RunSystem(in, o, /*gt_scale=*/false);
    std::vector<int> spans;
    for (const FrameReport& r : res.reports)
      if (r.local_ba) spans.push_back(r.local_ba_span);
    if (spans.empty()) return -1;
    std::nth_element(spans.begin(), spans.begin() + static_cast<long>(spans.size() / 2), spans.end());
    return spans[spans.size() / 2];
  };
  const int adjusted = SystemOptions().mapping.local_ba_keyframes;
  const int paper = median_span("paper", SystemOptions().mapping.local_ba_min_step_of_depth);
  const int paper_consecutive = median_span("paper", 0.0);
  const int forward = median_span("forward", SystemOptions().mapping.local_ba_min_step_of_depth);
  std::printf("[ span ] median frames spanned by the adjusted keyframes: paper %d (step 0: %d), forward %d\n", paper,
              paper_consecutive, forward);
  // Every tracked frame is a keyframe on these inputs: eight consecutive ones span 7 frames.
  EXPECT_EQ(paper_consecutive, adjusted - 1);
  EXPECT_EQ(forward, adjusted - 1);
  // 2 % of ~3 m is ~6 cm, three frames of the paper's path or so: at least twice the consecutive span.
  EXPECT_GE(paper, 2 * (adjusted - 1));
}

// MappingOptions::local_ba_function_tolerance: each keyframe's local adjustment starts from the last one's solution
// with one new view, so it may stop once an iteration lowers its cost by less than 0.1 % instead of Ceres' 1e-6
// (which every call on the paper scene ran to the cap of 10 without reaching). The noisy paper scenario (1 px, 10 %
// outliers; 200 frames: the first map settles until about frame 95, the local adjustments run after it), seeds
// 1-3: ATE at 1e-3 within 10 % of ATE at 1e-6 on every seed (measured here: -3.2 %, -0.1 %, +1.4 %; the bound
// is three times the largest).
TEST(System, TheLocalAdjustmentStopsWhenAnIterationNoLongerLowersItsCost) {
  auto ate = [](uint64_t seed, double tolerance) {
    const apps::SequenceInput in = Scenario(200, 1.0, 0.1, seed);
    SystemOptions o = FastOptions();
    o.seed = seed;
    o.mapping.local_ba_function_tolerance = tolerance;
    const apps::SlamRunResult res = RunSystem(in, o, /*gt_scale=*/false);
    return eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(res.reports, false)).ate_m.rmse;
  };
  EXPECT_EQ(SystemOptions().mapping.local_ba_function_tolerance, 1e-3);
  for (uint64_t seed = 1; seed <= 3; ++seed) {
    const double loose = ate(seed, 1e-3), tight = ate(seed, 1e-6);
    std::printf("[ local BA ] seed %llu: ATE %.5f m at a tolerance of 1e-3, %.5f at 1e-6\n",
                static_cast<unsigned long long>(seed), loose, tight);
    EXPECT_LE(loose, 1.1 * tight) << "seed " << seed;
  }
}

// MappingOptions::local_ba_async: the local bundle adjustment solved on its own thread and applied at the start of
// the next Process gives the very poses, reports and map of the adjustment solved in place (nothing reads the map
// between two calls here), and each keyframe's report comes back revised at the next call, first.
TEST(System, TheLocalBundleAdjustmentOnItsOwnThreadChangesNothingButWhenItIsApplied) {
  const apps::SequenceInput in = Scenario(120, 1.0, 0.1);
  SystemOptions sync = FastOptions(), async = FastOptions();
  sync.mapping.local_ba_async = false;
  async.mapping.local_ba_async = true;
  const auto a = RunSystem(in, sync, true), b = RunSystem(in, async, true);
  ASSERT_EQ(a.reports.size(), b.reports.size());
  int adjusted = 0;
  for (size_t i = 0; i < a.reports.size(); ++i) {
    const FrameReport &ra = a.reports[i], &rb = b.reports[i];
    ASSERT_EQ(ra.index, rb.index);
    ASSERT_EQ(ra.status, rb.status) << ra.index;
    ASSERT_EQ(ra.has_pose, rb.has_pose) << ra.index;
    EXPECT_EQ(ra.removed, rb.removed) << ra.index;
    EXPECT_EQ(ra.map_points, rb.map_points) << ra.index;
    EXPECT_EQ(ra.reproj_median_px, rb.reproj_median_px) << ra.index;
    if (ra.has_pose) {
      EXPECT_EQ(ra.cam_from_world.t, rb.cam_from_world.t) << ra.index;
      EXPECT_EQ(ra.cam_from_world.q.coeffs(), rb.cam_from_world.q.coeffs()) << ra.index;
    }
    EXPECT_EQ(ra.local_ba, rb.local_ba) << ra.index;
    adjusted += ra.local_ba;
  }
  // Not vacuous: the frames after the settling (which ends near frame 95 here) are keyframes with a local
  // adjustment (measured: 25).
  EXPECT_GE(adjusted, 15);
  ASSERT_EQ(a.map.points.size(), b.map.points.size());
  for (size_t i = 0; i < a.map.points.size(); ++i) EXPECT_EQ(a.map.points[i], b.map.points[i]) << i;

  // Call by call: a keyframe's report is returned at once, and again, revised, first among the next call's.
  System system(in.camera, async, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
  system.SetBaselineOracle(apps::BaselineOracle(in.groundtruth));
  int revised = 0;
  int64_t previous = -1;
  for (const FrameObservations& f : in.frames) {
    const std::vector<FrameReport> out = system.Process(f);
    ASSERT_FALSE(out.empty());
    EXPECT_TRUE(std::any_of(out.begin(), out.end(), [&](const FrameReport& r) { return r.index == f.index; }));
    for (size_t i = 0; i < out.size(); ++i) {
      if (!out[i].local_ba) continue;
      EXPECT_EQ(i, 0u);  // first
      EXPECT_EQ(out[i].index, previous);
      ++revised;
    }
    previous = f.index;
  }
  // The last frame's adjustment, when it had one (here it has: every frame after the settling is adjusted).
  const std::vector<FrameReport> tail = system.Flush();
  ASSERT_EQ(tail.size(), a.reports.back().local_ba ? 1u : 0u);
  for (const FrameReport& r : tail) {
    EXPECT_EQ(r.index, previous);
    EXPECT_TRUE(r.local_ba);
  }
  EXPECT_TRUE(system.Flush().empty());
  EXPECT_EQ(revised + static_cast<int>(tail.size()), adjusted);
}

// One seed: SystemOptions::seed drives the pose step too, whatever the tracker options' own seed says; a different
// System seed gives other draws (the noisy scenario: some pose differs).
TEST(System, OneSeedDrivesEveryDraw) {
  const apps::SequenceInput in = Scenario(40, 1.0, 0.1);
  SystemOptions a = FastOptions(), b = FastOptions(), c = FastOptions();
  a.seed = b.seed = 7;
  a.tracker.seed = 1;
  b.tracker.seed = 99;
  c.seed = 8;
  c.tracker.seed = 1;
  const auto ra = RunSystem(in, a, true), rb = RunSystem(in, b, true), rc = RunSystem(in, c, true);
  ASSERT_EQ(ra.reports.size(), rb.reports.size());
  bool differs = ra.reports.size() != rc.reports.size();
  for (size_t i = 0; i < ra.reports.size(); ++i) {
    ASSERT_EQ(ra.reports[i].has_pose, rb.reports[i].has_pose) << i;
    if (ra.reports[i].has_pose) {
      EXPECT_EQ(ra.reports[i].cam_from_world.t, rb.reports[i].cam_from_world.t) << i;
    }
    if (!differs && ra.reports[i].has_pose && rc.reports[i].has_pose)
      differs = ra.reports[i].cam_from_world.t != rc.reports[i].cam_from_world.t;
  }
  EXPECT_TRUE(differs) << "seed 8 drew the same as seed 7";
}

TEST(PoseTrackerFloor, OnlyAPositiveTranslationFloorIsTaken) {
  PoseTracker t(sim::PaperCamera(), PoseTrackerOptions{}, compute::MakeCpuPoseKernel());
  t.SetTranslationFloor(0.002);
  EXPECT_EQ(t.options().sigma_trans_floor_m, 0.002);
  EXPECT_THROW(t.SetTranslationFloor(0.0), std::invalid_argument);
  EXPECT_THROW(t.SetTranslationFloor(std::nan("")), std::invalid_argument);
  EXPECT_EQ(t.options().sigma_trans_floor_m, 0.002);  // a refused value changes nothing
}

TEST(System, BaselinesRunEndToEndAndAreExactOnCleanData) {
  // The paper's comparison (§8): PnP for the pose step, local bundle adjustment for the structure step.
  // On exact observations both solve their least-squares problems exactly (Monte Carlo sampling cannot:
  // it stops at the resolution of its samples, ~2 mm here).
  const apps::SequenceInput in = Scenario(60, 0.0, 0.0);
  for (auto [pose, structure] : {std::pair{PoseMethod::kPnp, StructureMethod::kMonteCarlo},
                                 std::pair{PoseMethod::kMonteCarlo, StructureMethod::kBundleAdjustment},
                                 std::pair{PoseMethod::kPnp, StructureMethod::kBundleAdjustment}}) {
    SystemOptions o = FastOptions();
    o.pose_method = pose;
    o.structure_method = structure;
    const auto res = apps::RunSlam(in, o, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel(), true);
    ASSERT_TRUE(res.initialised);
    int tracked = 0;
    for (const FrameReport& r : res.reports) tracked += r.status == FrameStatus::kTracked;
    EXPECT_EQ(tracked, 60);
    const auto err = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(res.reports, false));
    if (pose == PoseMethod::kPnp) {
      // Measured ~1e-8 m: least squares on exact data; 1e-5 m leaves room for solver tolerances.
      EXPECT_LT(err.ate_m.mean, 1e-5);
    } else {
      EXPECT_LT(err.ate_m.mean, 0.005);  // the Monte Carlo pose step's sampling resolution dominates
    }
  }
  EXPECT_THROW(ParsePoseMethod("icp"), std::invalid_argument);
  EXPECT_THROW(ParseStructureMethod("lm"), std::invalid_argument);
}

// A long run must not keep every frame's features: beyond history_frames (and the window's reach) a frame
// keeps only its pose. Here a short history (20 frames, window 6: reach 8) over 150 clean frames: the old
// frames are emptied, the recent ones not, and the trajectory is as good as with the whole history.
TEST(System, HistoryIsBoundedAndTrackingDoesNotNeedMore) {
  const apps::SequenceInput in = Scenario(150, 0.0, 0.0);
  auto run = [&](int history) {
    SystemOptions o = FastOptions();
    o.mapping.window = 6;
    o.mapping.history_frames = history;
    System system(in.camera, o, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
    std::vector<FrameReport> reports(in.frames.size());
    for (const FrameObservations& f : in.frames)
      for (const FrameReport& r : system.Process(f)) reports[static_cast<size_t>(r.index)] = r;
    int emptied = 0;
    for (const FrameRecord& f : system.map().frames) emptied += f.features.empty();
    // The last `history` frames keep their features (each has ~190 here).
    for (size_t k = system.map().frames.size() - static_cast<size_t>(std::min(history, 150)); k < 150; ++k)
      EXPECT_FALSE(system.map().frames[k].features.empty()) << k;
    io::Trajectory est;
    for (const FrameReport& r : reports)
      if (r.has_pose) est.stamps_s.push_back(r.stamp_s), est.world_from_cam.push_back(r.cam_from_world.Inverse());
    return std::pair{emptied, eval::EvaluateTrajectory(in.groundtruth, est)};
  };
  const auto [emptied_short, err_short] = run(20);
  const auto [emptied_all, err_all] = run(1000);
  std::printf("history 20: %d frames emptied, ATE mean %.4f m; whole history: %.4f m\n", emptied_short, err_short.ate_m.mean, err_all.ate_m.mean);
  EXPECT_EQ(emptied_all, 0);
  // Frames 0-128 dropped theirs (150 - 20 - 1 = 129; the initialisation's reference is among them: it ends early).
  EXPECT_GE(emptied_short, 120);
  EXPECT_EQ(err_short.matched(), 150u);
  // Clean data: both measured 0.9 mm; the short history may differ by the Monte Carlo noise only.
  EXPECT_LT(err_short.ate_m.mean, 0.005);
  EXPECT_LT(err_short.ate_m.mean, 2.0 * err_all.ate_m.mean + 0.001);
}

// Relocalisation: a pose from features matched to map points with no prior (RANSAC PnP), then given to the
// pose step as the frame's hint. Here the frames jump by a second (frames 60-89 never come): the Monte Carlo
// search around the last pose cannot reach the new one.
TEST(System, RelocalisesAfterAJumpFromMatchesAlone) {
  const apps::SequenceInput in = Scenario(120, 0.0, 0.0);
  SystemOptions o = FastOptions();
  // The pose step's second try, 4x wider in rotation (PoseTrackerOptions::retry_rot_scale), reaches across this
  // jump on clean data (measured: frame 90 tracked): off, so that the frame needs relocalising.
  o.tracker.retry_rot_scale = 0;
  System system(in.camera, o, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
  EXPECT_FALSE(system.Relocalise({}).has_value());  // no map yet
  FrameReport last;
  std::vector<Eigen::Vector3d> est_centres, gt_centres;  // of the frames tracked before the jump
  for (int i = 0; i < 60; ++i)
    for (const FrameReport& r : system.Process(in.frames[static_cast<size_t>(i)])) {
      last = r;
      if (!r.has_pose) continue;
      est_centres.push_back(r.cam_from_world.Inverse().t);
      gt_centres.push_back(in.groundtruth.world_from_cam[static_cast<size_t>(r.index)].t);
    }
  ASSERT_EQ(last.status, FrameStatus::kTracked);
  ASSERT_GE(est_centres.size(), 30u);
  // The observations of map points in a frame, as matches (the synthetic features carry their point's id).
  auto matches_of = [&](const FrameObservations& f) {
    std::vector<RelocalisationMatch> m;
    for (const FeatureObservation& x : f.features)
      if (const MapPoint* p = system.map().Find(x.feature_id); p && p->state != PointState::kRemoved)
        m.push_back({x.feature_id, x.uv_px});
    return m;
  };
  const FrameObservations& after = in.frames[90];
  std::vector<RelocalisationMatch> m = matches_of(after);
  ASSERT_GE(m.size(), 40u);
  // A third of the matches wrong (anywhere in the image): they are left out of the inliers.
  CounterRng rng(5, 0);
  std::set<int64_t> wrong;
  for (size_t k = 0; k < m.size(); k += 3) {
    const double v = rng.Uniform(0, 240), u = rng.Uniform(0, 320);  // v first: GCC's order for Vector2d(U(), U())
    m[k].uv_px = Eigen::Vector2d(u, v);
    wrong.insert(m[k].point_id);
  }
  const std::optional<Relocalisation> reloc = system.Relocalise(m);
  ASSERT_TRUE(reloc.has_value());
  EXPECT_EQ(reloc->matches, static_cast<int>(m.size()));
  // A random pixel lands within the 3 px inlier threshold of its point's projection with odds ~1e-3.
  for (int64_t id : reloc->inlier_point_ids) EXPECT_FALSE(wrong.count(id)) << id;
  EXPECT_GE(reloc->inlier_point_ids.size() + 2, m.size() - wrong.size());  // a point or two may be off
  // Fewer matches than relocalise_min_inliers: nothing.
  EXPECT_FALSE(system.Relocalise(std::vector<RelocalisationMatch>(m.begin(), m.begin() + 14)).has_value());

  // The map's frame is the truth's up to a similarity, fixed by the frames before the jump.
  const eval::Similarity3 s = eval::AlignPositions(est_centres, gt_centres, eval::Alignment::kSim3).gt_world_from_est_world;
  auto off_m = [&](const FrameReport& r) {
    return (s * r.cam_from_world.Inverse().t - in.groundtruth.world_from_cam[static_cast<size_t>(r.index)].t).norm();
  };
  // Without the hint the frame is lost (its first try is not widened by the turn the tracks measured across the
  // jump: at that spread it came out 10 cm off, FrameTracker::TrackFrame); the next one, with the relocalised pose
  // as its hint, is tracked, and as accurately as the frames before the jump.
  const std::vector<FrameReport> jumped = system.Process(after);
  ASSERT_EQ(jumped.size(), 1u);
  EXPECT_EQ(jumped[0].status, FrameStatus::kLost) << jumped[0].note;
  FrameObservations next = in.frames[91];
  const std::optional<Relocalisation> r91 = system.Relocalise(matches_of(next));
  ASSERT_TRUE(r91.has_value());
  next.pose_hint = r91->cam_from_world;
  const std::vector<FrameReport> resumed = system.Process(next);
  // Frame 91's report, then frame 90's: lost when it came, placed against the map through the tracks it shares
  // with frame 91 once that one was tracked (SystemOptions::pose_lost_frames_when_found).
  ASSERT_EQ(resumed.size(), 2u);
  EXPECT_EQ(resumed[0].status, FrameStatus::kTracked) << resumed[0].note;
  EXPECT_GT(resumed[0].inliers, 30);
  EXPECT_EQ(resumed[1].index, 90);
  EXPECT_EQ(resumed[1].status, FrameStatus::kTracked) << resumed[1].note;
  // The resumed camera is where the truth says, within 1 cm (the paper's scene is ~3 m away; the clean run's
  // frames are within 1-2 mm), and so is the frame placed after it.
  EXPECT_LT(off_m(resumed[0]), 0.01);
  EXPECT_LT(off_m(resumed[1]), 0.01);
}

// A jolt that loses most tracks: frames 60-64 keep 5 of their map points' tracks (fewer than the pose step
// scores: lost), the rest of their points are followed as new tracks (new ids), and at frame 65 relocalisation
// matches those new tracks to their map points (as the pipeline does: the tracks renamed to the points from frame
// 65 on, FrameObservations::relabelled). One kept point's own track ends at frame 61 while a new track of it runs
// from frame 60 (a corner detected again beside a track that is about to fail): in frames 60-61 the renamed track
// meets the point's own observation and is dropped. Frame 65 is tracked; frames 60-64 are placed after it through
// the renamed tracks, newest first, each where the truth is, their features still in id order, each id once.
// Without the renaming they keep 4-5 points (PnP needs 8): lost; with pose_lost_frames_when_found off, lost too.
TEST(System, FramesLostBeforeARelocalisationArePlacedThroughTheTracksItMatched) {
  const apps::SequenceInput in = Scenario(70, 0.0, 0.0);
  constexpr int64_t kNewTrack = 1'000'000'000;
  struct Outcome {
    std::vector<FrameReport> found;                  // frame 65's reports
    std::map<int64_t, FrameStatus> when_they_came;   // frames 60-64
    std::vector<Eigen::Vector3d> est_centres, gt_centres;  // frames 0-59 tracked
    std::map<int64_t, std::vector<int64_t>> ids;     // frames 60-64: their features' ids after frame 65
    int64_t twice = -1;                              // the point seen by its own track and a new one
  };
  auto run = [&](bool pose_lost, bool relabel) {
    SystemOptions o = FastOptions();
    o.pose_lost_frames_when_found = pose_lost;
    System system(in.camera, o, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
    Outcome out;
    for (int i = 0; i < 60; ++i)
      for (const FrameReport& r : system.Process(in.frames[static_cast<size_t>(i)]))
        if (r.has_pose && r.index < 60) {
          out.est_centres.push_back(r.cam_from_world.Inverse().t);
          out.gt_centres.push_back(in.groundtruth.world_from_cam[static_cast<size_t>(r.index)].t);
        }
    // The points frame 59 saw as map points: 5 of them keep their tracks, the others are new tracks from frame 60.
    std::set<int64_t> kept;
    for (const FeatureObservation& x : in.frames[59].features)
      if (const MapPoint* p = system.map().Find(x.feature_id); p && p->state != PointState::kRemoved && kept.size() < 5)
        kept.insert(x.feature_id);
    out.twice = *kept.begin();
    auto jolted = [&](int i) {
      FrameObservations f = in.frames[static_cast<size_t>(i)];
      std::vector<FeatureObservation> extra;
      for (FeatureObservation& x : f.features) {
        if (x.feature_id == out.twice && i <= 61) {
          extra.push_back({x.feature_id + kNewTrack, x.uv_px});  // its new track, beside its own
          continue;
        }
        if (!kept.count(x.feature_id) || x.feature_id == out.twice) x.feature_id += kNewTrack;
      }
      f.features.insert(f.features.end(), extra.begin(), extra.end());
      return f;
    };
    for (int i = 60; i < 65; ++i)
      for (const FrameReport& r : system.Process(jolted(i)))
        if (r.index == i) out.when_they_came[i] = r.status;
    FrameObservations f65 = jolted(65);
    std::vector<RelocalisationMatch> matches;
    for (const FeatureObservation& x : f65.features) {
      const int64_t point = x.feature_id >= kNewTrack ? x.feature_id - kNewTrack : x.feature_id;
      if (const MapPoint* p = system.map().Find(point); p && p->state != PointState::kRemoved)
        matches.push_back({point, x.uv_px});
    }
    const std::optional<Relocalisation> reloc = system.Relocalise(matches);
    if (!reloc) return out;
    f65.pose_hint = reloc->cam_from_world;
    for (FeatureObservation& x : f65.features)
      if (x.feature_id >= kNewTrack && system.map().Find(x.feature_id - kNewTrack)) {
        if (relabel) f65.relabelled.emplace_back(x.feature_id, x.feature_id - kNewTrack);
        x.feature_id -= kNewTrack;
      }
    out.found = system.Process(f65);
    for (const FrameRecord& f : system.map().frames)
      if (f.index >= 60 && f.index < 65)
        for (const FeatureUndistorted& x : f.features) out.ids[f.index].push_back(x.id);
    return out;
  };

  const Outcome placed = run(true, true);
  ASSERT_EQ(placed.when_they_came.size(), 5u);
  for (const auto& [i, st] : placed.when_they_came) EXPECT_EQ(st, FrameStatus::kLost) << "frame " << i;
  ASSERT_GE(placed.found.size(), 1u);
  EXPECT_EQ(placed.found[0].index, 65);
  ASSERT_EQ(placed.found[0].status, FrameStatus::kTracked) << placed.found[0].note;
  ASSERT_EQ(placed.found.size(), 6u);
  const eval::Similarity3 s =
      eval::AlignPositions(placed.est_centres, placed.gt_centres, eval::Alignment::kSim3).gt_world_from_est_world;
  for (size_t k = 1; k < placed.found.size(); ++k) {
    const FrameReport& r = placed.found[k];
    EXPECT_EQ(r.index, static_cast<int64_t>(65 - k));  // newest first
    EXPECT_EQ(r.status, FrameStatus::kTracked);
    EXPECT_TRUE(r.placed_after_loss);
    EXPECT_FALSE(r.keyframe);
    // PnP's inliers, of the ~200 map points each frame sees once renamed (measured 200-201); bound 3/4 of them.
    EXPECT_GE(r.inliers, 150);
    // Clean data: measured 0.52-0.56 mm from the truth (the frames tracked before the jolt: 1-2 mm); bound 1 cm.
    const double off =
        (s * r.cam_from_world.Inverse().t - in.groundtruth.world_from_cam[static_cast<size_t>(r.index)].t).norm();
    EXPECT_LT(off, 0.01) << "frame " << r.index;
  }
  // The renamed frames' features: in id order, each id once, the twice-seen point once, no renamed track left.
  ASSERT_EQ(placed.ids.size(), 5u);
  for (const auto& [i, ids] : placed.ids) {
    EXPECT_TRUE(std::is_sorted(ids.begin(), ids.end())) << "frame " << i;
    EXPECT_EQ(std::adjacent_find(ids.begin(), ids.end()), ids.end()) << "frame " << i;
    EXPECT_EQ(std::count(ids.begin(), ids.end(), placed.twice), 1) << "frame " << i;
    EXPECT_EQ(std::count(ids.begin(), ids.end(), placed.twice + kNewTrack), 0) << "frame " << i;
  }
  // Not renamed: 4-5 map points in each lost frame, fewer than PnP takes.
  const Outcome unnamed = run(true, false);
  ASSERT_GE(unnamed.found.size(), 1u);
  EXPECT_EQ(unnamed.found[0].status, FrameStatus::kTracked);
  EXPECT_EQ(unnamed.found.size(), 1u);
  // Off: only frame 65's report.
  const Outcome off = run(false, true);
  ASSERT_GE(off.found.size(), 1u);
  EXPECT_EQ(off.found[0].status, FrameStatus::kTracked);
  EXPECT_EQ(off.found.size(), 1u);
}

// Track ids as a KLT front end gives them: a point that leaves the view and comes back is a new track (only
// remapping, which observations alone do not have, would give it its map point again).
// scene_of (when given): each track id's scene point.
void NewIdsAfterEveryGap(apps::SequenceInput* in, std::unordered_map<int64_t, int64_t>* scene_of = nullptr) {
  std::unordered_map<int64_t, std::pair<size_t, int64_t>> last;  // scene id -> (last frame seen, track id)
  int64_t next = 1'000'000'000;
  for (size_t i = 0; i < in->frames.size(); ++i)
    for (FeatureObservation& f : in->frames[i].features) {
      auto [it, fresh] = last.try_emplace(f.feature_id, i, f.feature_id);
      if (!fresh && it->second.first + 1 != i) it->second.second = next++;
      it->second.first = i;
      if (scene_of) (*scene_of)[it->second.second] = f.feature_id;
      f.feature_id = it->second.second;
    }
}

// The rotation scenario's observations (noise 0.5 px; `frames` of them, or the scenario's when 0) with track ids
// renewed after every gap (NewIdsAfterEveryGap, which fills scene_of when given).
apps::KnownMapInput RotationTracks(uint64_t seed, int frames,
                                   std::unordered_map<int64_t, int64_t>* scene_of = nullptr) {
  sim::ScenarioOptions so;
  so.name = "rotation";
  so.noise_px = 0.5;
  so.seed = seed;
  if (frames > 0) so.frames = frames;
  apps::KnownMapInput in = apps::KnownMapInputFromSequence(sim::MakeScenario(so));
  NewIdsAfterEveryGap(&in, scene_of);
  return in;
}

// The paper's orbit from tracks that a point leaving the view (or hidden for a frame) ends: each return makes a
// new track at a mapped place. With MappingOptions::merge_revisited_points such a track goes on as the map point
// that is there, and the map keeps about one point per scene point; without, each return adds one.
TEST(System, APlaceSeenAgainGoesOnAsItsMapPointInsteadOfANewOne) {
  for (uint64_t seed = 1; seed <= 2; ++seed) {
    sim::PaperScenarioOptions so;
    so.frames = 450;
    so.speed = 2.0;
    so.noise_px = 1.0;
    so.seed = seed;
    apps::KnownMapInput in = apps::KnownMapInputFromSequence(sim::MakePaperScenario(so));
    std::unordered_map<int64_t, int64_t> scene_of;
    NewIdsAfterEveryGap(&in, &scene_of);
    struct Run {
      int points = 0, merges = 0, wrong = 0;
      std::set<int64_t> scene_points;  // the scene points the map holds
      std::vector<FrameReport> reports;
    };
    auto run = [&](bool merge) {
      SystemOptions o = FastOptions();
      o.mapping.merge_revisited_points = merge;
      System system(in.camera, o, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
      Run r;
      r.reports.resize(in.frames.size());
      for (const FrameObservations& f : in.frames) {
        for (const FrameReport& rep : system.Process(f)) r.reports[static_cast<size_t>(rep.index)] = rep;
        for (const auto& [track, point] : system.merged_tracks()) {
          ++r.merges;
          r.wrong += scene_of.at(track) != scene_of.at(point);
        }
      }
      for (const FrameReport& rep : system.Flush()) r.reports[static_cast<size_t>(rep.index)] = rep;
      for (const MapPoint& p : system.map().points())
        if (p.state != PointState::kRemoved) ++r.points, r.scene_points.insert(scene_of.at(p.id));
      return r;
    };
    const Run with = run(true), without = run(false);
    const auto err_with = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(with.reports, false));
    const auto err_without =
        eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(without.reports, false));
    std::printf("[ revisits ] seed %d: with merging %d map points for %zu scene points, %d merges (%d wrong), ATE "
                "%.4f m; without %d for %zu, ATE %.4f m\n",
                static_cast<int>(seed), with.points, with.scene_points.size(), with.merges, with.wrong,
                err_with.ate_m.rmse, without.points, without.scene_points.size(), err_without.ate_m.rmse);
    // Measured (seeds 1-3, 450 frames at twice the paper's speed: 1.5 orbits): 75 / 51 / 73 merges, of them 2 / 4 / 2
    // into the map point of another scene point (one that projects within 2.5 px of the track in every view: the
    // views cannot tell them apart); 298 / 302 / 281 map points against 373 / 353 /
    // 354 without; the ATE the same to 0.1 mm. Bounds: at least 30 merges, at most 10 % of them joining two scene
    // points, at most 90 % of the points without, the ATE within 10 % + 1 mm.
    EXPECT_GE(with.merges, 30) << "seed " << seed;
    EXPECT_LE(with.wrong, 0.1 * with.merges) << "seed " << seed;
    EXPECT_LT(with.points, 0.9 * without.points) << "seed " << seed;
    EXPECT_EQ(err_with.matched(), in.frames.size()) << "seed " << seed;
    EXPECT_LT(err_with.ate_m.rmse, 1.1 * err_without.ate_m.rmse + 0.001) << "seed " << seed;
  }
}

// System::SetLookCheck: where the caller can tell whether a new track looks like a map point (VisualSlam: their SIFT
// descriptors), a place seen again is merged only where it does. Here the look is an oracle (the scene point behind
// each id), so every merge it lets through must join one scene point.
TEST(System, APlaceSeenAgainIsMergedOnlyWhereItLooksAlike) {
  sim::PaperScenarioOptions so;
  so.frames = 450;
  so.speed = 2.0;
  so.noise_px = 1.0;
  so.seed = 1;
  apps::KnownMapInput in = apps::KnownMapInputFromSequence(sim::MakePaperScenario(so));
  std::unordered_map<int64_t, int64_t> scene_of;
  NewIdsAfterEveryGap(&in, &scene_of);
  struct Run {
    int merges = 0, wrong = 0, looks_asked = 0;
  };
  auto run = [&](bool looks_alike_only_if_same_scene_point) {
    SystemOptions o = FastOptions();
    o.mapping.merge_revisited_points = true;
    System system(in.camera, o, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
    Run r;
    system.SetLookCheck([&](int64_t track, int64_t point) {
      ++r.looks_asked;
      return looks_alike_only_if_same_scene_point && scene_of.at(track) == scene_of.at(point);
    });
    for (const FrameObservations& f : in.frames) {
      system.Process(f);
      for (const auto& [track, point] : system.merged_tracks()) {
        ++r.merges;
        r.wrong += scene_of.at(track) != scene_of.at(point);
      }
    }
    system.Flush();
    return r;
  };
  const Run oracle = run(true), never = run(false);
  std::printf("[ revisits ] look check: %d merges (%d wrong) of %d asked; a check that never agrees: %d of %d asked\n",
              oracle.merges, oracle.wrong, oracle.looks_asked, never.merges, never.looks_asked);
  // By projection alone seeds 1-3 merged 51-75 times, 2-4 of them wrongly (the test above); with the oracle seed 1
  // merged 87 times, none wrongly (a candidate that does not look alike no longer makes a right one ambiguous). The
  // check must decide every merge (none without its yes, none it refused) and leave the right ones: at least 30, as
  // the test above asks of projection alone.
  EXPECT_GE(oracle.merges, 30);
  EXPECT_EQ(oracle.wrong, 0);
  EXPECT_GT(never.looks_asked, 0);
  EXPECT_EQ(never.merges, 0);
}

// The rotation scenario up to just after its first pure turn: the camera pans 45 degrees in place, its field of
// view (35 degrees) leaves everything mapped, and no point can be made without parallax. With
// SystemOptions::rotation_only the frames of the turn are posed by their rotation about the last centre instead
// of being lost; no frame is so posed while the camera really moves, and the trajectory is no worse for them.
TEST(System, APanAwayFromTheMapIsTrackedAsATurnAboutTheLastCentre) {
  for (uint64_t seed = 1; seed <= 2; ++seed) {
    const apps::SequenceInput in =
        RotationTracks(seed, static_cast<int>(std::lround(sim::kRotationPureSegmentsS[0].second * 30.0)) + 20);
    SystemOptions with = FastOptions(), without = FastOptions();
    without.rotation_only = false;
    const apps::SlamRunResult on = RunSystem(in, with, /*gt_scale=*/false);
    const apps::SlamRunResult off = RunSystem(in, without, /*gt_scale=*/false);
    ASSERT_TRUE(on.initialised && off.initialised) << "seed " << seed;
    int tracked_on = 0, tracked_off = 0, turned = 0;
    double worst_move = 0;
    for (size_t i = 0; i < on.reports.size(); ++i) {
      tracked_on += on.reports[i].status == FrameStatus::kTracked;
      tracked_off += off.reports[i].status == FrameStatus::kTracked;
      if (!on.reports[i].rotation_only) continue;
      ++turned;
      EXPECT_TRUE(on.reports[i].has_pose);
      EXPECT_FALSE(on.reports[i].keyframe);
      // How far the true camera is from where it was on the last frame the pose step tracked.
      size_t last = i;
      while (last > 0 && on.reports[last].rotation_only) --last;
      const Eigen::Vector3d c = in.groundtruth.world_from_cam[i].t, c0 = in.groundtruth.world_from_cam[last].t;
      worst_move = std::max(worst_move, (c - c0).norm());
    }
    const auto err_on = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(on.reports, false));
    const auto err_off = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(off.reports, false));
    std::printf("[ rotation ] seed %d: %d of %zu frames tracked with turns about the last centre (%d of them), %d "
                "without; true centre at most %.4f m from the last tracked one; ATE %.4f m with, %.4f m without\n",
                static_cast<int>(seed), tracked_on, on.reports.size(), turned, tracked_off, worst_move,
                err_on.ate_m.rmse, err_off.ate_m.rmse);
    // Measured (2^16 hypotheses): seeds 1 and 2 gain 12 and 10 frames, the turns end 1.7 and 0.5 cm into the
    // move that follows, ATE 2.42 / 1.13 cm with against 1.88 / 1.17 cm without. Bounds: at least 5 frames
    // gained; 5 cm of move (3x); the ATE at most 1.5x that without + 2 mm (the 28 % of seed 1, with room).
    EXPECT_GE(turned, 5) << "seed " << seed;
    EXPECT_GE(tracked_on, tracked_off + turned) << "seed " << seed;  // the turns are frames gained, none lost
    EXPECT_LT(worst_move, 0.05) << "seed " << seed;
    EXPECT_LT(err_on.ate_m.rmse, 1.5 * err_off.ate_m.rmse + 0.002) << "seed " << seed;
  }
}

// While a provisional map is waited for (the turn away from the map ended in a move, and its two views lack
// parallax yet), a frame that follows enough of the map's points by its own tracks is placed in the map by them:
// a relocalisation whose frame could not join brings the map's points back into the tracks, and no descriptor
// finds them again after that (rendered rotation scenario with noise of 6 grey levels, seed 14 on an AVX2 build:
// 11 frames lost so, 16.8 cm). Here the rotation scenario's observations up to the first frame that waits, then
// the next frame turned back to the orientation of the last frame the pose step tracked before the turn, at its
// true centre, seeing 12 of the map's points where the truth puts them. Measured (seeds 1 and 2, waiting at frame
// 127): placed 0.62 and 1.02 cm from the truth on the AVX-512 build, 0.41 and 1.02 on the AVX2 one (the last frame
// tracked before the turn: 0.59-0.79 cm); with the old rule (SystemOptions::bridge_wait_placed_by_map_tracks
// false) lost. Bound: 2 cm (2x the worse; the scenario's 1 %-of-path rule is 3.3 cm). One test a seed (the sanitized
// suite runs the first: 66 s there each).
void ExpectAWaitingFramePlacedByItsOwnTracks(uint64_t seed) {
  std::unordered_map<int64_t, int64_t> scene_of;
  const apps::KnownMapInput in = RotationTracks(seed, 0, &scene_of);
  for (const bool placed : {true, false}) {
    SystemOptions o = FastOptions();
    o.bridge_wait_placed_by_map_tracks = placed;
    System system(in.camera, o, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
    std::vector<Eigen::Vector3d> est_centres, gt_centres;  // of the frames the pose step tracked
    int waiting = -1, last_tracked = -1;
    for (size_t i = 0; i < in.frames.size() && waiting < 0; ++i)
      for (const FrameReport& r : system.Process(in.frames[i])) {
        if (r.note.rfind("the map is out of view; a provisional map from", 0) == 0)
          waiting = static_cast<int>(r.index);
        if (!r.has_pose || r.rotation_only || r.inliers < 30) continue;
        last_tracked = std::max(last_tracked, static_cast<int>(r.index));
        est_centres.push_back(r.cam_from_world.Inverse().t);
        gt_centres.push_back(in.groundtruth.world_from_cam[static_cast<size_t>(r.index)].t);
      }
    ASSERT_GE(waiting, 0) << "seed " << seed;
    ASSERT_GE(last_tracked, 0) << "seed " << seed;
    const size_t k = static_cast<size_t>(waiting) + 1;
    Pose world_from_cam = in.groundtruth.world_from_cam[k];
    world_from_cam.q = in.groundtruth.world_from_cam[static_cast<size_t>(last_tracked)].q;
    const Pose cam_from_world = world_from_cam.Inverse();
    FrameObservations back = in.frames[k];
    back.features.clear();
    for (const MapPoint& p : system.map().points()) {
      Eigen::Vector2d uv;
      if (p.state != PointState::kRemoved &&
          in.camera.ProjectWorld(cam_from_world, in.map.at(scene_of.at(p.id)), &uv) && in.camera.InImage(uv))
        back.features.push_back({p.id, uv});
    }
    std::sort(back.features.begin(), back.features.end(),
              [](const FeatureObservation& a, const FeatureObservation& b) { return a.feature_id < b.feature_id; });
    ASSERT_GE(back.features.size(), 40u) << "seed " << seed;
    // As few as a relocalisation brings back (seed 14 above: 15 of 18, of them 13 still tracked two frames on):
    // 12, spread over the ids, fewer than a relocalisation by look takes (SystemOptions::relocalise_min_inliers).
    std::vector<FeatureObservation> few;
    for (size_t j = 0; j < 12; ++j) few.push_back(back.features[j * back.features.size() / 12]);
    back.features = few;
    const std::vector<FrameReport> out = system.Process(back);
    ASSERT_EQ(out.size(), 1u) << "seed " << seed;
    std::printf("[ placed ] seed %d, %s: waiting at frame %d, frame %zu sees %zu map points: %s\n",
                static_cast<int>(seed), placed ? "on" : "off", waiting, k, back.features.size(), out[0].note.c_str());
    if (!placed) {  // the old rule: the frame waits for the provisional map's two views, lost
      EXPECT_EQ(out[0].status, FrameStatus::kLost) << out[0].note;
      continue;
    }
    const eval::Similarity3 sim =
        eval::AlignPositions(est_centres, gt_centres, eval::Alignment::kSim3).gt_world_from_est_world;
    const Eigen::Vector3d centre = sim * out[0].cam_from_world.Inverse().t;
    const double off = (centre - world_from_cam.t).norm();
    const double before = (sim * est_centres.back() - gt_centres.back()).norm();
    std::printf("[ placed ] centre %.4f m from the truth (the last tracked frame: %.4f m)\n", off, before);
    EXPECT_EQ(out[0].status, FrameStatus::kTracked) << out[0].note;
    EXPECT_NE(out[0].note.find("placed in the map by its own tracks"), std::string::npos) << out[0].note;
    EXPECT_FALSE(system.bridging());
    EXPECT_LT(off, 0.02) << "seed " << seed << ": " << centre.transpose() << " vs " << world_from_cam.t.transpose();
  }
}
TEST(System, AFrameWaitingForAProvisionalMapIsPlacedByItsOwnTracksOfTheMapSeed1) {
  ExpectAWaitingFramePlacedByItsOwnTracks(1);
}
TEST(System, AFrameWaitingForAProvisionalMapIsPlacedByItsOwnTracksOfTheMapSeed2) {
  ExpectAWaitingFramePlacedByItsOwnTracks(2);
}

TEST(SystemOptions, CheckNamesTheField) {
  SystemOptions o;
  o.mapping.window = 1;
  try {
    o.Check();
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("window"), std::string::npos);
  }
  o = {};
  o.init.min_inliers = 3;
  EXPECT_THROW(o.Check(), std::invalid_argument);
  for (const double bad : {-0.01, 1.5, std::nan("")}) {
    o = {};
    o.mapping.local_ba_min_step_of_depth = bad;
    try {
      o.Check();
      ADD_FAILURE() << bad;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("local_ba_min_step_of_depth"), std::string::npos) << e.what();
    }
  }
  const std::pair<const char*, std::function<void(SystemOptions&)>> calibration[] = {
      {"calibration_min_z", [](SystemOptions& x) { x.init.calibration_min_z = 0; }},
      {"calibration_min_z", [](SystemOptions& x) { x.init.calibration_min_z = std::nan(""); }},
      {"calibration_min_shift_px", [](SystemOptions& x) { x.init.calibration_min_shift_px = -1; }},
      {"calibration_min_half_share", [](SystemOptions& x) { x.init.calibration_min_half_share = 1.5; }},
      {"calibration_min_half_z", [](SystemOptions& x) { x.init.calibration_min_half_z = -1; }},
      {"local_ba_function_tolerance", [](SystemOptions& x) { x.mapping.local_ba_function_tolerance = -1e-3; }}};
  for (const auto& [field, spoil] : calibration) {
    o = {};
    spoil(o);
    try {
      o.Check();
      ADD_FAILURE() << field;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace mcslam::slam
