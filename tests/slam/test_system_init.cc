// The System's initialisation (paper §6.1) on the synthetic scenario's observations: when it waits, a plane, a
// scene with few features, the window's frames, the frames before a reference that moved on, the settling's
// mirror test.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "core/random.h"
#include "eval/trajectory_eval.h"
#include "sim/paper_scenario.h"
#include "sim/scenarios.h"
#include "slam/settler.h"
#include "slam/system.h"
#include "slam/system_internal.h"
#include "system_test_util.h"

namespace mcslam::slam {
namespace {

using namespace test;  // Scenario, FastOptions, RunSystem

// The rule that takes a self-calibrated k1 (SelfCalibrationIsTaken), on the figures measured (report.json's
// self_calibration): a real lens' widest halves, 0.56 and 1.35 of the whole's change (7-Scenes seed 10 with an
// experimental front end; 0.83-1.27 over seeds 1-10 at d8d6dcb), are taken; the sparse scenario's 24 points once
// measured k1 -0.72 at 12.5 sigma, 38.7 px at the corner, from halves of 0.86 and 2.16 of the change (the same sign:
// only the upper bound tells), and the older case of halves of opposite signs.
TEST(SelfCalibrationRule, EachHalfMustRepeatTheChangeWithinAFactorOfTwo) {
  const InitOptions io;  // calibration_min_half_share 0.5: a factor of two either way
  SelfCalibration lens;
  lens.z = 20.4, lens.corner_shift_px = 10.4, lens.min_half_share = 0.56, lens.max_half_share = 1.35;
  lens.min_half_z = 6.3;  // 7-Scenes' weakest half over seeds 1-10
  EXPECT_TRUE(SelfCalibrationIsTaken(lens, io));
  SelfCalibration few_tracks = lens;
  few_tracks.z = 12.5, few_tracks.corner_shift_px = 38.7;
  few_tracks.min_half_share = 0.86, few_tracks.max_half_share = 2.16;
  EXPECT_FALSE(SelfCalibrationIsTaken(few_tracks, io));
  SelfCalibration opposite = lens;
  opposite.min_half_share = -0.5, opposite.max_half_share = 1.9;
  EXPECT_FALSE(SelfCalibrationIsTaken(opposite, io));
  // Significance and size are still needed: just under each threshold, not taken.
  SelfCalibration weak = lens;
  weak.z = io.calibration_min_z * 0.99;
  EXPECT_FALSE(SelfCalibrationIsTaken(weak, io));
  SelfCalibration small = lens;
  small.corner_shift_px = io.calibration_min_shift_px * 0.99;
  EXPECT_FALSE(SelfCalibrationIsTaken(small, io));
  // Each half must measure the change itself: the rendered planar scenario at 160x120 (seed 2, an exact camera)
  // measured -0.223 at 38.9 sigma, 3.9 px, from halves of 1.16 and 1.58 of the change, one of them at 0 sigma (its
  // k1-free fit did not lower its cost).
  SelfCalibration one_half_silent = lens;
  one_half_silent.z = 38.9, one_half_silent.corner_shift_px = 3.9;
  one_half_silent.min_half_share = 1.16, one_half_silent.max_half_share = 1.58, one_half_silent.min_half_z = 0;
  EXPECT_FALSE(SelfCalibrationIsTaken(one_half_silent, io));
  one_half_silent.min_half_z = io.calibration_min_half_z * 0.99;
  EXPECT_FALSE(SelfCalibrationIsTaken(one_half_silent, io));
  one_half_silent.min_half_z = io.calibration_min_half_z;
  EXPECT_TRUE(SelfCalibrationIsTaken(one_half_silent, io));
  // calibration_min_half_share 0: no bound on the halves' size, only their direction.
  InitOptions no_halves;
  no_halves.calibration_min_half_share = 0;
  EXPECT_TRUE(SelfCalibrationIsTaken(few_tracks, no_halves));
  EXPECT_FALSE(SelfCalibrationIsTaken(opposite, no_halves));
}

// The initialisation's ambiguity test counts a window's observations as n (1 - rho) / (1 + rho), rho the pooled
// lag-1 correlation of the tracks' residuals. 200 tracks of 20 residuals: independent Gaussian noise gives rho
// within 4 standard errors (1 / sqrt(3800)) of 0; an AR(1) sequence with phi = 0.8 (started stationary) gives 0.8
// within 0.05 (its standard error is ~0.01 here); a constant bias gives 1; no pair of consecutive residuals gives 0.
TEST(PooledLag1Correlation, NoiseBiasAndAR1) {
  CounterRng rng(7, 1);
  std::vector<std::vector<Eigen::Vector2d>> noise(200), ar1(200), bias(200);
  for (int t = 0; t < 200; ++t) {
    Eigen::Vector2d last(rng.Normal(), rng.Normal());
    const Eigen::Vector2d b(rng.Normal(), rng.Normal());
    for (int k = 0; k < 20; ++k) {
      const double nu = rng.Normal(), nv = rng.Normal();
      noise[t].emplace_back(nu, nv);
      last = 0.8 * last + std::sqrt(1 - 0.64) * Eigen::Vector2d(rng.Normal(), rng.Normal());
      ar1[t].push_back(last);
      bias[t].push_back(b);
    }
  }
  EXPECT_LT(std::abs(detail::PooledLag1Correlation(noise)), 4.0 / std::sqrt(3800.0));
  EXPECT_NEAR(detail::PooledLag1Correlation(ar1), 0.8, 0.05);
  EXPECT_NEAR(detail::PooledLag1Correlation(bias), 1.0, 1e-12);
  EXPECT_EQ(detail::PooledLag1Correlation({{Eigen::Vector2d(1, 2)}, {}}), 0.0);
}

// A frame placed by PnP before the reference is checked against the posed frame after it (Initializer::FollowsFrom):
// the median angle between a track's ray in that frame and its epipolar plane under the two poses. Two cameras
// 2-5 cm and 0-6 degrees apart (a thirtieth of a second of a fast hand-held camera), 60 points 1-6 m in front seen
// by both through 0.5 px of noise at f = 500 px, 20 seeds, three motions: a random one, an orbit (the turn keeps
// the scene's centre where it was in the image, so the tracks hardly move) and a pure turn. The true poses: under
// 0.06 degrees (0.5 px of noise is 0.057 degrees; the median over the tracks is about 0.7 of it). A wrong one, the
// turn 10 degrees off about any axis (the PnP placement that asked for the check turned 53 degrees from the next
// frame where the camera turned 9): over 0.5 degrees (measured at least 1.1). The check's limit, the pose step's
// inlier threshold of 3 px, is 0.34 degrees here. (An epipolar plane is the same for a move and its opposite: the sign of the move is not judged here,
// and PnP puts its points in front of the camera.)
TEST(EpipolarDisagreement, TheTruePoseFollowsAndAWrongOneDoesNot) {
  double worst_true = 0, best_wrong = 1e9;
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    for (int motion = 0; motion < 3; ++motion) {
      CounterRng rng(seed, 3 + motion);
      const auto unit = [&] { return Eigen::Vector3d(rng.Normal(), rng.Normal(), rng.Normal()).normalized().eval(); };
      Pose b_from_a;
      const Eigen::Vector3d centre(0, 0, 3);  // the scene's centre, in camera a
      if (motion == 0) {  // anything
        b_from_a.q = Eigen::Quaterniond(Eigen::AngleAxisd(rng.Uniform(0, 6) * M_PI / 180, unit()));
        b_from_a.t = rng.Uniform(0.02, 0.05) * unit();
      } else if (motion == 1) {  // an orbit: moved sideways, turned back towards the centre
        const Eigen::Vector3d move(rng.Uniform(0.02, 0.05), rng.Uniform(-0.01, 0.01), 0);
        const double yaw = std::atan2(move.x(), centre.z());
        b_from_a.q = Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()));
        b_from_a.t = -(b_from_a.q * move);  // camera b's centre at `move` in camera a
      } else {  // a pure turn
        b_from_a.q = Eigen::Quaterniond(Eigen::AngleAxisd(rng.Uniform(1, 6) * M_PI / 180, unit()));
      }
      std::vector<Eigen::Vector3d> in_a, in_b;
      const auto noisy_ray = [&](const Eigen::Vector3d& p) {
        return (p.hnormalized() + 0.5 / 500 * Eigen::Vector2d(rng.Normal(), rng.Normal())).homogeneous().normalized().eval();
      };
      while (in_a.size() < 60) {
        const Eigen::Vector3d p(rng.Uniform(-2, 2), rng.Uniform(-1.5, 1.5), rng.Uniform(1, 6));
        const Eigen::Vector3d q = b_from_a * p;
        if (q.z() < 0.5 || std::abs(q.x() / q.z()) > 0.6 || std::abs(q.y() / q.z()) > 0.45) continue;
        in_a.push_back(noisy_ray(p));
        in_b.push_back(noisy_ray(q));
      }
      const double right = detail::EpipolarDisagreementDeg(in_a, in_b, b_from_a);
      worst_true = std::max(worst_true, right);
      EXPECT_LT(right, 0.2) << seed << " motion " << motion;
      Pose turned = b_from_a;
      turned.q = Eigen::Quaterniond(Eigen::AngleAxisd(10 * M_PI / 180, unit())) * b_from_a.q;
      const double wrong = detail::EpipolarDisagreementDeg(in_a, in_b, turned);
      best_wrong = std::min(best_wrong, wrong);
      EXPECT_GT(wrong, 0.5) << seed << " motion " << motion;
    }
  }
  std::printf("epipolar disagreement: true poses at most %.3f deg, wrong ones at least %.3f deg\n", worst_true,
              best_wrong);
  EXPECT_EQ(detail::EpipolarDisagreementDeg({}, {}, Pose()), 0.0);
}

TEST(System, StaticCameraNeverInitialises) {
  apps::SequenceInput in = Scenario(40, 0.5, 0.0);
  for (auto& f : in.frames) f.features = in.frames.front().features;  // the camera does not move
  const apps::SlamRunResult res = RunSystem(in);
  EXPECT_FALSE(res.initialised);
  ASSERT_EQ(res.reports.size(), 40u);
  for (const FrameReport& r : res.reports) EXPECT_EQ(r.status, FrameStatus::kWaitingForInit);
  EXPECT_NE(res.reports.back().note.find("feature motion"), std::string::npos) << res.reports.back().note;
  // Each waiting frame says why in a form a summary can count: the first became the reference, the rest had too
  // little motion; the summary names that as the cause.
  EXPECT_EQ(res.reports.front().init_wait, InitWait::kReference);
  for (size_t k = 1; k < res.reports.size(); ++k) EXPECT_EQ(res.reports[k].init_wait, InitWait::kMotion) << k;
  const NotInitialisedSummary why = WhyNotInitialised(res.reports, "RULE");
  EXPECT_TRUE(why.too_little_motion);
  EXPECT_FALSE(why.too_few_features);
  EXPECT_NE(why.text.find("in 39 the features had not moved enough since the reference frame (RULE)"),
            std::string::npos)
      << why.text;
}

// A scene with fewer features than a two-view initialisation can use (8 points, of which each frame sees at
// most 8, against the floor of 12 shared features, InitOptions::min_count_floor): the camera moves as in the
// paper's scenario, but the frames wait on too few features, and the summary says so rather than blame the motion
// (it said "the sequence never moved enough" before).
TEST(System, TooFewFeaturesAreNamedAsWhatHeldTheFirstMapBack) {
  sim::ScenarioOptions so;
  so.name = "paper";
  so.frames = 60;
  so.num_points = 8;
  so.seed = 3;
  const apps::SequenceInput in = apps::KnownMapInputFromSequence(sim::MakeScenario(so));
  size_t most = 0;
  for (const FrameObservations& f : in.frames) most = std::max(most, f.features.size());
  ASSERT_LT(most, static_cast<size_t>(InitOptions{}.min_count_floor));
  const apps::SlamRunResult res = RunSystem(in, /*gt_scale=*/false);
  ASSERT_FALSE(res.initialised);
  int few_shared = 0;
  int most_shared = -1;
  for (const FrameReport& r : res.reports) {
    EXPECT_EQ(r.status, FrameStatus::kWaitingForInit);
    if (r.init_wait != InitWait::kFewShared) continue;
    ++few_shared;
    most_shared = std::max(most_shared, r.init_count);
    EXPECT_EQ(r.init_needed, InitOptions{}.min_count_floor) << r.index;
    EXPECT_LT(r.init_count, r.init_needed) << r.index;
  }
  EXPECT_EQ(few_shared, 59);  // every frame but the first, which became the reference
  EXPECT_LE(most_shared, static_cast<int>(most));
  const NotInitialisedSummary why = WhyNotInitialised(res.reports, "RULE");
  EXPECT_TRUE(why.too_few_features) << why.text;
  EXPECT_FALSE(why.too_little_motion) << why.text;
  EXPECT_NE(why.text.find(fmt::format("in 59 too few features were shared with the reference frame (at most {}, 12 "
                                      "needed)",
                                      most_shared)),
            std::string::npos)
      << why.text;
  EXPECT_EQ(why.text.find("RULE"), std::string::npos) << why.text;  // the motion rule is not quoted: not the cause
}

// The summary's ranking, on reports made by hand: the cause that held the most frames back leads; too few
// features (shared, or fitting one motion, counted together) against too little motion; another reason that held
// more frames back than either (rejections) takes the advice; no waiting frame, no summary.
TEST(WhyNotInitialised, TheReasonThatHeldMostFramesBackLeads) {
  auto waiting = [](InitWait w, int count = 0, int needed = 0) {
    FrameReport r;
    r.init_wait = w;
    r.init_count = count;
    r.init_needed = needed;
    return r;
  };
  std::vector<FrameReport> reports = {waiting(InitWait::kReference)};
  for (int k = 0; k < 5; ++k) reports.push_back(waiting(InitWait::kMotion));
  for (int k = 0; k < 3; ++k) reports.push_back(waiting(InitWait::kFewShared, 9 + k, 12));
  for (int k = 0; k < 3; ++k) reports.push_back(waiting(InitWait::kFewInliers, 13, 15));
  NotInitialisedSummary why = WhyNotInitialised(reports, "RULE");
  EXPECT_TRUE(why.too_few_features);  // 6 frames against the motion's 5
  EXPECT_FALSE(why.too_little_motion);
  EXPECT_EQ(why.text.find("of the 12 frames waiting for the first map, in 5 the features had not moved enough since "
                          "the reference frame (RULE), in 3 too few features were shared with the reference frame (at "
                          "most 11, 12 needed), in 3 too few correspondences fit one motion between two views (at "
                          "most 13, 15 needed) and 1 became the reference frame. The scene offers too few features"),
            0u)
      << why.text;
  reports.push_back(waiting(InitWait::kMotion));
  reports.push_back(waiting(InitWait::kMotion));
  why = WhyNotInitialised(reports, "RULE");  // 7 against 6
  EXPECT_TRUE(why.too_little_motion);
  EXPECT_FALSE(why.too_few_features);
  EXPECT_NE(why.text.find("Move the camera sideways"), std::string::npos) << why.text;
  for (int k = 0; k < 8; ++k) reports.push_back(waiting(InitWait::kRejected));
  why = WhyNotInitialised(reports, "RULE");  // 8 rejections lead
  EXPECT_FALSE(why.too_little_motion);
  EXPECT_FALSE(why.too_few_features);
  EXPECT_NE(why.text.find("of the 22 frames waiting for the first map, in 8 an initialisation was found and rejected"),
            std::string::npos)
      << why.text;
  EXPECT_NE(why.text.find("need a wider sideways move"), std::string::npos) << why.text;
  // Tracked frames and frames with no reason recorded are not counted.
  std::vector<FrameReport> none = {FrameReport{}};
  none.front().status = FrameStatus::kTracked;
  none.front().init_wait = InitWait::kMotion;
  none.push_back(FrameReport{});
  EXPECT_TRUE(WhyNotInitialised(none, "RULE").text.empty());
}

// Points on one plane (a table top under the box's place), seen by the scenario's moving camera: the essential
// matrix is not determined (a homography explains the views), so the initialisation decomposes the homography
// and lets the window of frames choose between its two motions (issue #16: planar scenes). Without that path
// the system waited for ever.
TEST(System, PlanarSceneInitialisesFromTheHomography) {
  sim::PaperScenarioOptions so;
  so.frames = 60;
  const sim::SyntheticSequence seq = sim::MakePaperScenario(so);
  apps::SequenceInput in;
  in.camera = seq.camera;
  in.groundtruth = sim::ToTrajectory(seq);
  CounterRng rng(5, 0);
  std::vector<Eigen::Vector3d> plane;
  for (int i = 0; i < 300; ++i) {
    // y first: the order in which GCC evaluated emplace_back(Uniform(), Uniform(), 0.3) (unspecified in C++;
    // clang goes left to right), so both compilers make the same plane.
    const double y = rng.Uniform(-0.6, 0.6), x = rng.Uniform(-0.6, 0.6);
    plane.emplace_back(x, y, 0.3);
  }
  for (size_t k = 0; k < seq.cam_from_world.size(); ++k) {
    FrameObservations f;
    f.index = static_cast<int64_t>(k);
    f.stamp_s = seq.stamps_s[k];
    for (size_t i = 0; i < plane.size(); ++i) {
      Eigen::Vector2d uv;
      if (seq.camera.ProjectWorld(seq.cam_from_world[k], plane[i], &uv) && seq.camera.InImage(uv))
        f.features.push_back({static_cast<int64_t>(i), uv});
    }
    in.frames.push_back(f);
  }
  apps::SlamRunResult res;
  ASSERT_NO_THROW(res = RunSystem(in, /*gt_scale=*/false));
  ASSERT_EQ(res.reports.size(), 60u);
  ASSERT_TRUE(res.initialised);
  int tracked = 0, init_frame = -1;
  for (const FrameReport& r : res.reports) {
    tracked += r.status == FrameStatus::kTracked;
    if (r.initialisation && !r.note.empty() && init_frame < 0) init_frame = static_cast<int>(r.index);
  }
  // Measured: initialised at frame 12 (frames 7-11 wait: the plane's second motion explains the window as
  // well), every frame tracked.
  EXPECT_LE(init_frame, 30);
  EXPECT_EQ(tracked, 60);
  const auto err = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(res.reports, false));
  EXPECT_FALSE(err.mirrored);
  std::printf("[ planar   ] initialised at frame %d, ATE mean %.5f m, rotation mean %.3f deg\n", init_frame,
              err.ate_m.mean, err.rot_deg.mean);
  // Clean data: measured 0.7 mm mean (0.2 deg); the noisy scenario's bound, 2 cm, is far above that and far below
  // the wrong motion of the homography's pair (centimetres to decimetres off).
  EXPECT_LT(err.ate_m.mean, 0.02);
  EXPECT_LT(err.rot_deg.mean, 1.0);
}

// A scene with little texture (the sparse scenario: 26-35 points in view, against the 40 shared features the
// initialisation asks for on a textured scene): the counts are lowered to 60 % of the features the frame tracks
// (down to 12), so that it initialises instead of waiting for ever (issue #16).
TEST(System, SparseSceneInitialisesFromTheFewFeaturesItHas) {
  for (uint64_t seed = 1; seed <= 4; ++seed) {
    sim::ScenarioOptions so;
    so.name = "sparse";
    so.frames = 150;
    so.noise_px = 0.5;
    so.seed = seed;
    const apps::SequenceInput in = apps::KnownMapInputFromSequence(sim::MakeScenario(so));
    size_t most = 0;
    for (const FrameObservations& f : in.frames) most = std::max(most, f.features.size());
    ASSERT_LT(most, static_cast<size_t>(InitOptions{}.min_common_features));  // the old gate could never pass
    apps::SlamRunResult res;
    ASSERT_NO_THROW(res = RunSystem(in, /*gt_scale=*/false));
    ASSERT_TRUE(res.initialised) << "seed " << seed;
    int tracked = 0, init_frame = -1;
    for (const FrameReport& r : res.reports) {
      tracked += r.status == FrameStatus::kTracked;
      if (r.initialisation && !r.note.empty() && init_frame < 0) init_frame = static_cast<int>(r.index);
    }
    const auto err = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(res.reports, false));
    std::printf("[ sparse   ] seed %d: %zu features at most, initialised at frame %d, %d of 150 tracked, ATE mean "
                "%.4f m, rotation mean %.3f deg\n",
                static_cast<int>(seed), most, init_frame, tracked, err.ate_m.mean, err.rot_deg.mean);
    // Measured over seeds 1-8 (CLI, the same options but 2^18 hypotheses): initialised at frames 14-44,
    // every frame tracked, 0.9-1.2 cm and 0.25-1.0 deg mean. Bounds: the robustness matrix's 30 % of the
    // frames for the start; twice the largest measured error.
    EXPECT_LE(init_frame, 45) << "seed " << seed;
    EXPECT_EQ(tracked, 150) << "seed " << seed;
    EXPECT_FALSE(err.mirrored) << "seed " << seed;
    EXPECT_LT(err.ate_m.mean, 0.024) << "seed " << seed;
    EXPECT_LT(err.rot_deg.mean, 2.0) << "seed " << seed;
  }
}

// Fast motion (the fast scenario, observations only): two frames already hold enough motion and parallax to
// initialise. Two views leave the depth reversal open (and a window of two fits its own noise), so the
// initialisation waits for a third frame (InitOptions::min_window_frames); allowed two, it takes frames 0
// and 1 (the rendered seed 6 came out mirrored so).
TEST(System, InitialisationWindowHoldsAtLeastThreeFrames) {
  sim::ScenarioOptions so;
  so.name = "fast";
  so.frames = 40;
  so.noise_px = 0.2;
  so.seed = 6;
  const apps::SequenceInput in = apps::KnownMapInputFromSequence(sim::MakeScenario(so));
  for (int min_window : {3, 2}) {
    SystemOptions o = FastOptions();
    o.init.min_window_frames = min_window;
    std::string note;
    const apps::SlamRunResult res =
        apps::RunSlam(in, o, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel(), /*gt_scale=*/false,
                      [&](const FrameReport& r) {
                        if (r.initialisation && !r.note.empty() && note.empty()) note = r.note;
                      });
    ASSERT_TRUE(res.initialised) << min_window;
    const size_t at = note.find("window of ");
    ASSERT_NE(at, std::string::npos) << note;
    const int window = std::atoi(note.c_str() + at + 10);
    std::printf("[ window   ] min_window_frames %d: %s\n", min_window, note.c_str());
    if (min_window == 3) {
      EXPECT_GE(window, 3) << note;
    } else {
      EXPECT_EQ(window, 2) << note;  // the gate is what made the difference
    }
  }
}

// The reference moves on while waiting (frame 10 keeps one feature fewer than the floor, min_count_floor, that
// the lowered min_common_features asks of a frame tracking so few, and frame 11 then shares those with frame 10,
// fewer than the 40 it asks of a frame tracking ~190): the map is made from frame 11 on. The
// frames before it see the same points and are placed against the first map: every frame has a pose, those
// as accurate as the rest. Without it they stay unposed.
TEST(System, FramesBeforeAMovedReferenceArePosedAgainstTheFirstMap) {
  apps::SequenceInput in = Scenario(120, 0.0, 0.0);
  in.frames[10].features.resize(static_cast<size_t>(InitOptions{}.min_count_floor - 1));
  for (bool pose_before : {true, false}) {
    SystemOptions o = FastOptions();
    o.init.pose_frames_before_reference = pose_before;
    std::string first_init_note;  // what the CLI logs and report.json keeps as the initialisation's
    const apps::SlamRunResult res =
        apps::RunSlam(in, o, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel(), /*gt_scale=*/true,
                      [&](const FrameReport& r) {
                        if (r.initialisation && !r.note.empty() && first_init_note.empty()) first_init_note = r.note;
                      });
    ASSERT_TRUE(res.initialised);
    ASSERT_EQ(res.reports.size(), 120u);
    EXPECT_EQ(first_init_note.rfind("initialised from frames 11 and", 0), 0u) << first_init_note;
    int reference = -1;  // the first frame the initialisation's window holds
    for (const FrameReport& r : res.reports)
      if (r.initialisation && r.keyframe) {
        reference = static_cast<int>(r.index);
        break;
      }
    ASSERT_EQ(reference, 11) << "the reference did not move on as this test needs";
    for (int i = 0; i < reference; ++i) {
      const FrameReport& r = res.reports[i];
      if (pose_before) {
        EXPECT_EQ(r.status, FrameStatus::kTracked) << i;
        EXPECT_NE(r.note.find("before its reference frame"), std::string::npos) << i << ": " << r.note;
      } else {
        EXPECT_EQ(r.status, FrameStatus::kWaitingForInit) << i;
        EXPECT_FALSE(r.has_pose) << i;
      }
    }
    for (int i = reference; i < 120; ++i) EXPECT_EQ(res.reports[i].status, FrameStatus::kTracked) << i;
    if (!pose_before) continue;
    // Clean data. Measured: frames 0-10 within 0.10-0.14 mm of the truth, the whole run 0.39 mm on average.
    // Bounds: 2 mm for those frames (a pose copied from a neighbour would be off by a frame's motion), and the
    // clean scenario test's 5 mm for the run.
    const auto err = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(res.reports, false));
    ASSERT_EQ(err.matched(), 120u);
    for (const eval::FrameError& e : err.frames)
      if (e.est_index < static_cast<size_t>(reference)) {
        EXPECT_LT(e.trans_err_m, 0.002) << "frame " << e.est_index;
      }
    EXPECT_LT(err.ate_m.mean, 0.005);
  }
}

// A reference whose shared tracks cannot give the epipolar inliers a solution needs moves on (low texture: few
// tracks, a couple of them bad). 60 frames of the clean paper scenario cut to 23 tracks a frame: 15 seen from frame
// 0 on, two of them swapped from frame 1 on (outliers of every two-view geometry with frame 0), and 8
// more born at frame 3. Each frame tracks 23, so the lowered counts ask 14 shared tracks (0.6 of 23) and the
// two-view geometry its own 15 inliers: frame 0 shares 15 and gives at most 14 inliers (13, and one of the swapped
// pair by chance) while the camera moves on. Before, the reference stayed at frame 0 until frame 28, where both
// swapped tracks happened to fit the two views, and the map was made there from a window left at 0.61 px (the clean
// tracks fit to 0.00 px). Now it moves on to the oldest frame that shares enough tracks (frame 3: 23) and the map
// is made from there.
TEST(System, AReferenceThatCannotGiveTheInliersNeededMovesOn) {
  apps::SequenceInput in = Scenario(60, 0.0, 0.0);
  auto seen_in = [&](int64_t id, int from, int to) {
    for (int k = from; k <= to; ++k) {
      const auto& fs = in.frames[static_cast<size_t>(k)].features;
      if (std::none_of(fs.begin(), fs.end(), [&](const FeatureObservation& f) { return f.feature_id == id; }))
        return false;
    }
    return true;
  };
  std::vector<int64_t> old_ids, new_ids;
  for (const FeatureObservation& f : in.frames.front().features)
    if (old_ids.size() < 15 && seen_in(f.feature_id, 0, 59)) old_ids.push_back(f.feature_id);
  for (const FeatureObservation& f : in.frames[3].features)
    if (new_ids.size() < 8 && std::find(old_ids.begin(), old_ids.end(), f.feature_id) == old_ids.end() &&
        seen_in(f.feature_id, 3, 59))
      new_ids.push_back(f.feature_id);
  ASSERT_EQ(old_ids.size(), 15u);
  ASSERT_EQ(new_ids.size(), 8u);
  for (FrameObservations& fr : in.frames) {
    std::vector<FeatureObservation> kept;
    for (FeatureObservation f : fr.features) {
      const bool old = std::find(old_ids.begin(), old_ids.end(), f.feature_id) != old_ids.end();
      const bool born = fr.index >= 3 && std::find(new_ids.begin(), new_ids.end(), f.feature_id) != new_ids.end();
      if (!old && !born) continue;
      // From frame 1 on the first two tracks follow each other's point (a tracker that jumped).
      if (fr.index >= 1 && f.feature_id == old_ids[0])
        f.feature_id = old_ids[1];
      else if (fr.index >= 1 && f.feature_id == old_ids[1])
        f.feature_id = old_ids[0];
      kept.push_back(f);
    }
    fr.features = kept;
  }
  ASSERT_EQ(in.frames[10].features.size(), 23u);
  std::string first_init_note, moved_note;
  const apps::SlamRunResult res = apps::RunSlam(
      in, FastOptions(), compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel(), /*gt_scale=*/true,
      [&](const FrameReport& r) {
        if (r.initialisation && !r.note.empty() && first_init_note.empty()) first_init_note = r.note;
        if (moved_note.empty() && r.note.find("the reference moves on") != std::string::npos) moved_note = r.note;
      });
  std::printf("[ moved    ] %s\n[ init     ] %s\n", moved_note.c_str(), first_init_note.c_str());
  ASSERT_TRUE(res.initialised) << "the reference at frame 0 gives 13 inliers of the 15 needed";
  EXPECT_NE(moved_note.find(" of 15 fit, 15 needed"), std::string::npos) << moved_note;
  EXPECT_NE(moved_note.find("moves on to frame 3"), std::string::npos) << moved_note;
  EXPECT_EQ(first_init_note.rfind("initialised from frames 3 and", 0), 0u) << first_init_note;
  // Clean tracks but for the two bad ones (left out as outliers): every frame from the reference on posed within
  // the clean scenario test's 5 mm on average (the map holds 21 points).
  const auto err = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(res.reports, false));
  std::printf("[ ate      ] %zu frames matched, mean %.5f m\n", err.matched(), err.ate_m.mean);
  EXPECT_GE(err.matched(), 57u);
  EXPECT_LT(err.ate_m.mean, 0.005);
}

// The settling's depth-reversal test (Settler::FlipIfMirrored) leaves a right map alone on noisy tracks: the noisy
// paper scenario (1 px, 10 % outliers) initialises on the scene, not its mirror, and at the first settling steps
// (16-30 frames, ~5 deg) its mirror fits the window about as well. Under clang's rounding seed 1's first step had
// the mirror ahead by a chi-square of 22-35 (2.79 or 2.98 px^2 against 2.47): flipped, the run ended with every
// orientation ~176 deg off. Seeds whose first settling step comes within 60 frames here; a flipped map's
// orientations are >= 90 deg off, a right one's < 2 (bound 10 deg).
TEST(System, ARightMapIsNotFlippedByTheSettlingsMirrorTest) {
  for (uint64_t seed : {1, 3, 5, 16}) {
    const apps::SequenceInput in = Scenario(60, 1.0, 0.1, seed);
    const apps::SlamRunResult res = RunSystem(in);
    ASSERT_TRUE(res.initialised) << "seed " << seed;
    int settling_steps = 0;
    for (const FrameReport& r : res.reports) {
      EXPECT_FALSE(r.depth_reversed) << "seed " << seed << " frame " << r.index << ": " << r.note;
      settling_steps += r.note.find("settling:") != std::string::npos || r.note.rfind("settled", 0) == 0;
    }
    EXPECT_GE(settling_steps, 1) << "seed " << seed;  // the test ran
    const auto err = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(res.reports, false));
    EXPECT_LT(err.rot_deg.mean, 10.0) << "seed " << seed;
  }
}

// A map that stays lost is replaced by a new one (SystemOptions::restart_min_lost_frames): the paper scenario's
// observations with a blackout at frames 30-79 (no feature: every frame lost), and from frame 80 on features the
// first map never saw (new ids: a place where nothing can be relocalised). Without the restart every frame from 30
// on stays lost. With it, once the frames lost in a row outnumber those the map posed, a new map is started; once
// that one has posed more frames than the first, the first one's frames are reported again without a pose.
// Measured: the first map posed frames 0-29; the restart at frame 60 (31 frames lost in a row); the new map posed
// all of frames 80-199 (those before its initialisation placed when it came), ATE 4.3 mm mean after its Sim(3)
// alignment, 0.17 deg. Bounds: at least 100 of frames 80-199 posed (the initialisation needs its motion, which a
// later start of the orbit may take longer to give), and the noisy scenario's ATE bound, 2 cm.
// When the run ends first (100 frames: the new map posed 20 or fewer), the first map's poses stand and the new
// map's frames lose theirs: the trajectory stays one map's.
TEST(System, AMapLostForLongerThanItPosedIsReplacedByANewOne) {
  apps::SequenceInput in = Scenario(200, 0.5, 0.0);
  for (size_t i = 30; i < 80; ++i) in.frames[i].features.clear();
  for (size_t i = 80; i < in.frames.size(); ++i)
    for (FeatureObservation& f : in.frames[i].features) f.feature_id += 1000000;
  SystemOptions never = FastOptions();
  never.restart_min_lost_frames = 0;
  const apps::SlamRunResult with = RunSystem(in), without = RunSystem(in, never, true);
  ASSERT_EQ(with.reports.size(), 200u);
  ASSERT_EQ(without.reports.size(), 200u);
  int dropped = 0, posed_after = 0, posed_after_without = 0;
  for (const FrameReport& r : with.reports) {
    if (r.map_dropped) {
      ++dropped;
      EXPECT_LT(r.index, 30) << "only the first map's frames are dropped";
      EXPECT_FALSE(r.has_pose);
      EXPECT_EQ(r.status, FrameStatus::kLost);
    }
    posed_after += r.index >= 80 && r.has_pose;
  }
  for (const FrameReport& r : without.reports) posed_after_without += r.index >= 80 && r.has_pose;
  std::printf("[ restart  ] %d frames dropped, %d of frames 80-199 posed (without: %d)\n", dropped, posed_after,
              posed_after_without);
  EXPECT_GT(dropped, 20);
  EXPECT_EQ(posed_after_without, 0);
  EXPECT_GE(posed_after, 100);
  const auto err = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(with.reports, false));
  std::printf("[ restart  ] ATE mean %.5f m over %zu frames, rotation mean %.3f deg\n", err.ate_m.mean,
              err.ate_m.count, err.rot_deg.mean);
  EXPECT_FALSE(err.mirrored);
  EXPECT_LT(err.ate_m.mean, 0.02);

  // The run ends at frame 99: the new map never posed more than the first one's 30 frames.
  in.frames.resize(100);
  const apps::SlamRunResult short_run = RunSystem(in);
  int posed_before = 0, posed_new = 0, dropped_new = 0;
  for (const FrameReport& r : short_run.reports) {
    posed_before += r.index < 30 && r.has_pose;
    posed_new += r.index >= 80 && r.has_pose;
    dropped_new += r.index >= 80 && r.map_dropped;
  }
  std::printf("[ restart  ] run ending at frame 99: %d of frames 0-29 posed, %d of 80-99, %d dropped\n", posed_before,
              posed_new, dropped_new);
  EXPECT_EQ(posed_before, 30);
  EXPECT_EQ(posed_new, 0);
  EXPECT_TRUE(short_run.initialised);
  EXPECT_GT(short_run.map.points.size(), 20u) << "the first map's points are the result";
}

// Two restarts before a map outgrows the first: the first map (frames 0-29, 30 posed) is lost in a blackout, a
// second map is made from frames 80-104 (new ids) and lost in a second blackout before it posed more than 30
// frames, and a third map from frame 160 on (other ids again). The second map is dropped at the second restart (it
// never outgrew the first), the first once the third has posed more than 30 frames: the trajectory is the third
// map's alone. Measured: the second map posed 25 frames (80-104) before it was dropped; the third all of 160-299.
TEST(System, ASecondRestartDropsTheMapThatNeverOutgrewTheFirst) {
  apps::SequenceInput in = Scenario(300, 0.5, 0.0);
  for (size_t i = 0; i < in.frames.size(); ++i) {
    if ((i >= 30 && i < 80) || (i >= 105 && i < 160)) in.frames[i].features.clear();
    const int64_t offset = i >= 160 ? 2000000 : i >= 80 ? 1000000 : 0;
    for (FeatureObservation& f : in.frames[i].features) f.feature_id += offset;
  }
  const apps::SlamRunResult res = RunSystem(in);
  int posed_first = 0, posed_second = 0, dropped_second = 0, posed_third = 0;
  for (const FrameReport& r : res.reports) {
    posed_first += r.index < 30 && r.has_pose;
    posed_second += r.index >= 80 && r.index < 105 && r.has_pose;
    dropped_second += r.index >= 80 && r.index < 105 && r.map_dropped;
    posed_third += r.index >= 160 && r.has_pose;
  }
  std::printf("[ restart  ] posed: first map %d, second %d (dropped %d), third %d\n", posed_first, posed_second,
              dropped_second, posed_third);
  EXPECT_EQ(posed_first, 0);
  EXPECT_EQ(posed_second, 0);
  EXPECT_GT(dropped_second, 0) << "the second map initialised and was dropped";
  EXPECT_GE(posed_third, 100);
  const auto err = eval::EvaluateTrajectory(in.groundtruth, apps::ReportsToTrajectory(res.reports, false));
  EXPECT_FALSE(err.mirrored);
  EXPECT_LT(err.ate_m.mean, 0.02);  // one map's frames: the noisy scenario's bound
}

// The first map waits for a sharp frame: a frame the front end measured as blurred (FrameObservations::blurred)
// does not end the initialisation. The scenario's frames 0-39 flagged blurred: the initialisation, which comes at
// frame 14 on these observations (measured), waits for frame 40 (the waiting frames' notes are replaced when the
// map places them).
TEST(System, TheInitialisationWaitsForASharpFrame) {
  apps::SequenceInput in = Scenario(60, 0.5, 0.0);
  const auto init_frame = [](const apps::SlamRunResult& res) {
    for (const FrameReport& r : res.reports)
      if (r.initialisation && r.note.rfind("initialised from", 0) == 0) return static_cast<int>(r.index);
    return -1;
  };
  const int sharp = init_frame(RunSystem(in));
  for (size_t i = 0; i < 40; ++i) in.frames[i].blurred = true;
  const apps::SlamRunResult res = RunSystem(in);
  std::printf("[ blurred  ] initialised at frame %d (all sharp: %d)\n", init_frame(res), sharp);
  ASSERT_GE(sharp, 0);
  EXPECT_LT(sharp, 40);
  EXPECT_GE(init_frame(res), 40);
}

}  // namespace
}  // namespace mcslam::slam
