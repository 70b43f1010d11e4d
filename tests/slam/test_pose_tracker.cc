#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "apps/known_map_job.h"
#include "core/random.h"
#include "eval/trajectory_eval.h"
#include "sim/paper_scenario.h"
#include "slam/pose_smoother.h"
#include "slam/pose_tracker.h"

namespace mcslam::slam {
namespace {

std::unique_ptr<PoseTracker> MakeTracker(PoseTrackerOptions o = {}) {
  return std::make_unique<PoseTracker>(sim::PaperCamera(), o, compute::MakeCpuPoseKernel());
}

std::vector<PointObservation> ObservationsAt(const Pose& cam_from_world, const std::vector<Eigen::Vector3d>& pts) {
  const PinholeCamera cam = sim::PaperCamera();
  std::vector<PointObservation> obs;
  for (const auto& p : pts) {
    Eigen::Vector2d uv;
    if (cam.ProjectWorld(cam_from_world, p, &uv) && cam.InImage(uv)) obs.push_back({p, uv, true});
  }
  return obs;
}

// ObservationsAt with Gaussian noise of sigma_px per axis (seeded).
std::vector<PointObservation> NoisyObservationsAt(const Pose& cam_from_world, const std::vector<Eigen::Vector3d>& pts,
                                                  double sigma_px, uint64_t seed, uint64_t stream) {
  std::vector<PointObservation> obs = ObservationsAt(cam_from_world, pts);
  CounterRng rng(seed, stream);
  for (PointObservation& o : obs) {
    const double du = sigma_px * rng.Normal(), dv = sigma_px * rng.Normal();
    o.uv_undistorted_px += Eigen::Vector2d(du, dv);
  }
  return obs;
}

std::vector<Eigen::Vector3d> Cloud() {
  std::vector<Eigen::Vector3d> pts;
  CounterRng rng(4, 0);
  for (int i = 0; i < 150; ++i) {
    // One draw a statement, z first: the order in which GCC evaluated emplace_back(Uniform(), Uniform(),
    // 3 + Uniform()) (unspecified in C++; clang goes left to right), so both compilers make the same cloud.
    const double z = 3 + rng.Uniform(-0.3, 0.3), y = rng.Uniform(-0.4, 0.4), x = rng.Uniform(-0.5, 0.5);
    pts.emplace_back(x, y, z);
  }
  return pts;
}

TEST(PoseTracker, OptionsCheckNamesTheField) {
  PoseTrackerOptions o;
  o.hypotheses = 0;
  try {
    o.Check();
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("hypotheses"), std::string::npos);
  }
  o = {};
  o.rounds = 0;
  EXPECT_THROW(o.Check(), std::invalid_argument);
  EXPECT_THROW(ParseRandomMode("gaussian"), std::invalid_argument);
}

TEST(PoseTracker, LinearisedTranslationRecoversASmallTranslation) {
  const auto pts = Cloud();
  const Pose moved(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.01, -0.005, 0.02));
  const auto obs = ObservationsAt(moved, pts);
  const Eigen::Vector3d dt = MakeTracker()->LinearisedTranslation(Pose(), obs);
  // One Gauss-Newton step of a nearly linear model for mm-cm motions at 3 m: within 10 % of each component.
  EXPECT_NEAR(dt.x(), 0.01, 0.001);
  EXPECT_NEAR(dt.y(), -0.005, 0.0005);
  EXPECT_NEAR(dt.z(), 0.02, 0.002);
}

// The linearised translation's prior (PoseTrackerOptions::translation_prior_steps). Points spread over the view
// fix all three directions: a prior of 3 cm moves the estimate by a hair (the test above's 10 % still holds). 20
// points in one small patch (a map just coming into view at the image's edge) fix two: the translation-only model
// leaves a mix of the sideways and the forward move free, and 1 px of noise decides it. For a true move of 1 cm,
// the worst of seeds 1-10 ran 33 cm off without the prior (bound: more than 10 cm) and 2.4 cm off with it (bound
// 3 cm, the prior's deviation; the data's last bits, which differ between CPUs, cannot move it by millimetres).
TEST(PoseTracker, TheTranslationPriorHoldsADirectionThePointsLeaveFree) {
  const Pose moved(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.01, -0.005, 0.02));
  const Eigen::Vector3d dt = MakeTracker()->LinearisedTranslation(Pose(), ObservationsAt(moved, Cloud()), 0.03);
  EXPECT_NEAR(dt.x(), 0.01, 0.001);
  EXPECT_NEAR(dt.y(), -0.005, 0.0005);
  EXPECT_NEAR(dt.z(), 0.02, 0.002);

  std::vector<Eigen::Vector3d> patch;
  CounterRng rng(5, 0);
  for (int i = 0; i < 20; ++i) {
    const double z = 3 + rng.Uniform(-0.05, 0.05), y = rng.Uniform(-0.05, 0.05), x = 0.7 + rng.Uniform(-0.05, 0.05);
    patch.emplace_back(x, y, z);
  }
  const Eigen::Vector3d truth(0.01, 0.0, 0.0);
  const Pose shifted(Eigen::Quaterniond::Identity(), truth);
  double worst_free = 0, worst_prior = 0;
  for (uint64_t seed = 1; seed <= 10; ++seed) {
    const std::vector<PointObservation> obs = NoisyObservationsAt(shifted, patch, 1.0, seed, 0);
    ASSERT_EQ(obs.size(), patch.size());
    const auto tracker = MakeTracker();
    worst_free = std::max(worst_free, (tracker->LinearisedTranslation(Pose(), obs) - truth).norm());
    worst_prior = std::max(worst_prior, (tracker->LinearisedTranslation(Pose(), obs, 0.03) - truth).norm());
  }
  std::printf("[ patch    ] worst error over seeds 1-10: %.4f m without the prior, %.4f m with it\n", worst_free,
              worst_prior);
  EXPECT_GT(worst_free, 0.10);
  EXPECT_LT(worst_prior, 0.03);
}

TEST(PoseTracker, LostWhenNothingToScoreOrNoInliers) {
  auto tracker = MakeTracker();
  std::vector<double> res;
  std::vector<uint8_t> inl;
  PoseEstimate e = tracker->Track(Pose(), {}, 1, &res, &inl);
  EXPECT_FALSE(e.tracked);
  EXPECT_FALSE(e.lost_reason.empty());
  // Features that fit no pose near the previous one: every observation is far from its point's projection.
  auto obs = ObservationsAt(Pose(), Cloud());
  CounterRng rng(9, 0);
  for (auto& o : obs) {
    const double v = rng.Uniform(0, 240), u = rng.Uniform(0, 320);  // v first: GCC's order, as in Cloud()
    o.uv_undistorted_px = Eigen::Vector2d(u, v);
  }
  e = tracker->Track(Pose(), obs, 2, &res, &inl);
  EXPECT_FALSE(e.tracked);
  EXPECT_EQ(res.size(), obs.size());
}

// A pose that only a minority of the scoring points agree with is no pose (min_inlier_ratio): after a gap in
// the frames most surviving tracks are wrong, and such a pose was taken as tracking, 0.8 m off.
TEST(PoseTracker, LostWhenMostScoringPointsDisagree) {
  auto obs = ObservationsAt(Pose(), Cloud());
  ASSERT_GT(obs.size(), 100u);
  // Two in five exact, the rest anywhere in the image.
  CounterRng rng(11, 0);
  int exact = 0;
  for (size_t i = 0; i < obs.size(); ++i) {
    if (i % 5 < 2) {
      ++exact;
      continue;
    }
    const double v = rng.Uniform(0, 240), u = rng.Uniform(0, 320);  // v first: GCC's order, as in Cloud()
    obs[i].uv_undistorted_px = Eigen::Vector2d(u, v);
  }
  std::vector<double> res;
  std::vector<uint8_t> inl;
  PoseEstimate e = MakeTracker()->Track(Pose(), obs, 1, &res, &inl);
  EXPECT_FALSE(e.tracked);
  // The exact two fifths (and the odd random feature near its point) agree with the best pose: well above
  // min_inliers, well under half.
  EXPECT_GE(e.inliers, exact);
  EXPECT_LT(e.inliers, static_cast<int>(obs.size()) / 2);
  EXPECT_NE(e.lost_reason.find("scoring points (< 50 %)"), std::string::npos) << e.lost_reason;
  // Asking for a third is satisfied by the same estimate.
  PoseTrackerOptions third;
  third.min_inlier_ratio = 0.3;
  e = MakeTracker(third)->Track(Pose(), obs, 1, &res, &inl);
  EXPECT_TRUE(e.tracked) << e.lost_reason;
  EXPECT_LT(e.cam_from_world.t.norm(), 0.01);  // the exact points' pose; 1 cm at 3 m is ~1.7 px
  // The counts alone.
  const PoseTrackerOptions o;
  EXPECT_EQ(o.LostReason(30, 30, 37), "");
  EXPECT_EQ(o.LostReason(10, 10, 37), "10 inliers of 37 scoring points (< 50 %)");
  // Inliers among the points that did not score do not make up for the scoring ones.
  EXPECT_EQ(o.LostReason(20, 10, 37), "10 inliers of 37 scoring points (< 50 %)");
  EXPECT_EQ(o.LostReason(7, 7, 7), "7 inliers (< 8)");
  PoseTrackerOptions bad;
  bad.min_inlier_ratio = 1.5;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

TEST(PoseTracker, ExactDataGivesAnAccuratePoseAndKeyframe) {
  const auto pts = Cloud();
  const Pose truth(QuaternionFromRotationVector(Eigen::Vector3d(0.004, -0.006, 0.003)), Eigen::Vector3d(0.01, 0.004, -0.01));
  PoseTrackerOptions o;
  o.hypotheses = 1 << 16;
  o.rounds = 3;
  std::vector<double> res;
  std::vector<uint8_t> inl;
  const PoseEstimate e = MakeTracker(o)->Track(Pose(), ObservationsAt(truth, pts), 1, &res, &inl);
  ASSERT_TRUE(e.tracked);
  EXPECT_TRUE(e.keyframe);
  EXPECT_EQ(e.inliers, static_cast<int>(res.size()));
  // The estimate explains the exact features to well under a pixel (sampling resolution of 2^16 x 3 rounds).
  EXPECT_LT(e.mean_inlier_residual_px, 0.5);
  // From one frame, a 35-degree field of view on a 1 m object at 3 m leaves a shallow valley along which a
  // yaw of theta is nearly cancelled by a sideways shift of 3 m * theta: the pose is found to within that
  // valley (about 2 cm / 0.4 degrees here), which a sequence then narrows (see KnownMapTracking below).
  EXPECT_LT((e.cam_from_world.t - truth.t).norm(), 0.03);
  EXPECT_LT(AngularDistanceDeg(e.cam_from_world.q, truth.q), 0.6);
  const double valley_deg = RadToDeg((e.cam_from_world.t - truth.t).norm() / 3.0);
  EXPECT_NEAR(AngularDistanceDeg(e.cam_from_world.q, truth.q), valley_deg, 0.15);
}

// The first frame of a turn: the rotation spread follows the last frame's rotation (none), so an 8-degree roll
// (16 sigma of the 0.5-degree spread; a roll no translation can mimic) is out of the first try's reach. The
// second try, with a 4x wider spread (4 sigma), finds it; without it the frame is lost.
TEST(PoseTracker, AFrameLostAtTheFirstSpreadIsScoredAgainWider) {
  const auto pts = Cloud();
  const Pose truth(QuaternionFromRotationVector(Eigen::Vector3d(0, 0, DegToRad(8.0))), Eigen::Vector3d(0.01, 0, 0));
  const auto obs = ObservationsAt(truth, pts);
  ASSERT_GT(obs.size(), 100u);
  std::vector<double> res;
  std::vector<uint8_t> inl;
  PoseTrackerOptions once;
  once.retry_rot_scale = 0;
  const PoseEstimate lost = MakeTracker(once)->Track(Pose(), obs, 1, &res, &inl);
  EXPECT_FALSE(lost.tracked);
  EXPECT_FALSE(lost.widened);
  EXPECT_LT(lost.inliers, static_cast<int>(obs.size()) / 3) << lost.lost_reason;  // not near the 50 % line
  const PoseEstimate e = MakeTracker()->Track(Pose(), obs, 1, &res, &inl);
  ASSERT_TRUE(e.tracked) << e.lost_reason;
  EXPECT_TRUE(e.widened);
  EXPECT_TRUE(e.lost_reason.empty());
  // Exact features: the second try is as good as a first one (ExactDataGivesAnAccuratePoseAndKeyframe's
  // bounds: the yaw/sideways valley of one frame, 0.6 degrees).
  EXPECT_LT(AngularDistanceDeg(e.cam_from_world.q, truth.q), 0.6);
  // Sampled 4x coarser, the pose sits a little further along that valley: nearly all within the 3 px threshold
  // (150 of 150 measured), far above the half that tracking asks.
  EXPECT_GE(e.inliers, static_cast<int>(obs.size()) * 9 / 10);
  // A frame the first try tracks takes no second.
  const PoseEstimate near = MakeTracker()->Track(truth, obs, 2, &res, &inl);
  ASSERT_TRUE(near.tracked);
  EXPECT_FALSE(near.widened);
  PoseTrackerOptions bad;
  bad.retry_rot_scale = 0.5;  // narrower is no retry
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

// Right after a relocalised frame the tracker has no rate of turn of its own; the turn the tracks measured
// (FrameTracker::TrackFrame) is the least spread of the first try. An 8-degree roll is out of the first try's reach at the
// least spread (16 sigma of 0.5 degrees, as in AFrameLostAtTheFirstSpreadIsScoredAgainWider; the second try off
// here) and within it when the measured turn sets the spread: found without a second try, as a first try finds a
// pose near its centre (ExactDataGivesAnAccuratePoseAndKeyframe's 0.6 degrees).
TEST(PoseTracker, TheTurnTheTracksMeasuredSetsTheLeastSpread) {
  const auto pts = Cloud();
  const Pose truth(QuaternionFromRotationVector(Eigen::Vector3d(0, 0, DegToRad(8.0))), Eigen::Vector3d(0.01, 0, 0));
  const auto obs = ObservationsAt(truth, pts);
  std::vector<double> res;
  std::vector<uint8_t> inl;
  PoseTrackerOptions once;
  once.retry_rot_scale = 0;
  EXPECT_FALSE(MakeTracker(once)->Track(Pose(), obs, 1, &res, &inl, 1, 0.0).tracked);
  const PoseEstimate e = MakeTracker(once)->Track(Pose(), obs, 1, &res, &inl, 1, 8.0);
  ASSERT_TRUE(e.tracked) << e.lost_reason;
  EXPECT_FALSE(e.widened);
  EXPECT_LT(AngularDistanceDeg(e.cam_from_world.q, truth.q), 0.6);
}

// A turn the tracks measured that is mostly parallax (a camera moving sideways fast: TUM fr3 at 1 Hz) must not
// coarsen the pose of a frame the usual spread finds: both spreads are searched (the wide one refined at the usual
// spread about its winner) and the lower score wins. Sampled at the measured turn alone (f02088b), the same
// hypotheses spread over a 16x wider rotation and the pose came out coarser (TUM seeds 1 and 2: 1.6 -> 2.4 and
// 1.5 -> 2.5 cm). Measured here: the usual spread alone 0.029 deg and 1.6 mm off (score 2.25), the measured turn
// alone 0.116 deg and 4.2 mm (26.9), both 0.006 deg (the refined wide search scored lower). Bounds: the usual
// search's errors plus 0.02 deg and 1 mm (a lower score on other hypotheses, other vector widths, need not be
// closer to the bit), a quarter of what the wide search alone lost.
TEST(PoseTracker, ATurnTheTracksMeasuredThatIsMostlyParallaxDoesNotCoarsenThePose) {
  const auto pts = Cloud();
  const Pose truth(QuaternionFromRotationVector(Eigen::Vector3d(0, DegToRad(0.3), 0)), Eigen::Vector3d(0.05, 0, 0));
  const auto obs = ObservationsAt(truth, pts);
  std::vector<double> res;
  std::vector<uint8_t> inl;
  PoseTrackerOptions once;
  once.retry_rot_scale = 0;
  const PoseEstimate usual = MakeTracker(once)->Track(Pose(), obs, 1, &res, &inl, 1, 0.0);
  const PoseEstimate turned = MakeTracker(once)->Track(Pose(), obs, 1, &res, &inl, 1, 8.0);
  ASSERT_TRUE(usual.tracked) << usual.lost_reason;
  ASSERT_TRUE(turned.tracked) << turned.lost_reason;
  EXPECT_LE(turned.score, usual.score);
  const double usual_deg = AngularDistanceDeg(usual.cam_from_world.q, truth.q);
  const double turned_deg = AngularDistanceDeg(turned.cam_from_world.q, truth.q);
  std::printf("[ parallax ] rotation error: usual spread %.4f deg, with the tracks' 8-degree turn %.4f deg\n", usual_deg,
              turned_deg);
  EXPECT_LE(turned_deg, usual_deg + 0.02);
  EXPECT_LE((turned.cam_from_world.t - truth.t).norm(), (usual.cam_from_world.t - truth.t).norm() + 0.001);
}

// The next frame's spread follows the rotation of the last estimate from the pose it started from, per frame
// between them: 8 degrees of roll found over one frame widen the next frame's spread to 8 degrees, and it finds
// another 8 to within 0.6 degrees; found over 8 frames (after 7 lost ones) they widen it to 1 degree, and the same
// next frame is out of the first try's reach (8 sigma).
TEST(PoseTracker, AMotionOverFramesWithoutAPoseCountsPerFrameInTheNextSpread) {
  const auto pts = Cloud();
  const Pose once_turned(QuaternionFromRotationVector(Eigen::Vector3d(0, 0, DegToRad(8.0))), Eigen::Vector3d::Zero());
  const Pose twice_turned(QuaternionFromRotationVector(Eigen::Vector3d(0, 0, DegToRad(16.0))), Eigen::Vector3d::Zero());
  auto next_after = [&](uint64_t frames_since_prev) {
    PoseTrackerOptions o;
    o.retry_rot_scale = 0;
    auto tracker = MakeTracker(o);
    std::vector<double> res;
    std::vector<uint8_t> inl;
    const PoseEstimate first =
        tracker->Track(Pose(), ObservationsAt(once_turned, pts), frames_since_prev, &res, &inl, frames_since_prev, 8.0);
    EXPECT_TRUE(first.tracked) << first.lost_reason;
    return tracker->Track(first.cam_from_world, ObservationsAt(twice_turned, pts), frames_since_prev + 1, &res, &inl);
  };
  const PoseEstimate in_step = next_after(1);
  ASSERT_TRUE(in_step.tracked) << in_step.lost_reason;
  EXPECT_LT(AngularDistanceDeg(in_step.cam_from_world.q, twice_turned.q), 0.6);
  // Sampled too narrowly, the first try stops short of the turn: lost, or (as measured) a pose 2.3 degrees off that
  // 137 of the 150 exact features fit within the 3 px threshold, the silent error the per-frame rate prevents.
  const PoseEstimate late = next_after(8);
  EXPECT_TRUE(!late.tracked || AngularDistanceDeg(late.cam_from_world.q, twice_turned.q) > 1.0);
}

// The second try searches 64x the rotation volume with the same hypotheses; what it finds is kept only when its
// inliers fit about as tightly as the tracker's recent frames (PoseTrackerOptions::retry_max_residual_ratio).
// Here the right pose, 8 degrees of roll away, with features 1 px noisy per axis (inlier median ~1.18 px): after
// frames of 0.1 px noise (typical 0.12 px, floored at 0.3 px: limit 0.9 px) it is refused, after frames as noisy
// as it (typical ~1.18 px: limit 1.5 px, half the threshold) it is kept. Over noise seeds 1-8 the turn's median
// measured 1.06-1.29 px: margins of 1.16x or more both ways.
TEST(PoseTracker, TheWiderTrysPoseIsKeptOnlyWhenItFitsAsTightlyAsTheRecentFrames) {
  const auto pts = Cloud();
  auto noisy = [&](const Pose& pose, double sigma_px, uint64_t stream) {
    return NoisyObservationsAt(pose, pts, sigma_px, 11, stream);
  };
  const Pose turned(QuaternionFromRotationVector(Eigen::Vector3d(0, 0, DegToRad(8.0))), Eigen::Vector3d(0.01, 0, 0));
  auto run = [&](double recent_sigma_px, PoseTrackerOptions o) {
    auto tracker = MakeTracker(o);
    std::vector<double> res;
    std::vector<uint8_t> inl;
    for (uint64_t k = 1; k <= 10; ++k) {
      const PoseEstimate e = tracker->Track(Pose(), noisy(Pose(), recent_sigma_px, k), k, &res, &inl);
      EXPECT_TRUE(e.tracked && !e.widened) << e.lost_reason;
    }
    return tracker->Track(Pose(), noisy(turned, 1.0, 99), 11, &res, &inl);
  };
  const PoseEstimate after_tight = run(0.1, {});
  EXPECT_FALSE(after_tight.tracked);
  EXPECT_FALSE(after_tight.widened);
  EXPECT_NE(after_tight.lost_reason.find("wider rotation spread found"), std::string::npos) << after_tight.lost_reason;
  EXPECT_NE(after_tight.lost_reason.find("refused"), std::string::npos) << after_tight.lost_reason;
  // The same frame after frames as noisy as it: kept, and it is the turn.
  const PoseEstimate after_noisy = run(1.0, {});
  ASSERT_TRUE(after_noisy.tracked) << after_noisy.lost_reason;
  EXPECT_TRUE(after_noisy.widened);
  EXPECT_GT(after_noisy.median_inlier_residual_px, 0.9);
  EXPECT_LT(after_noisy.median_inlier_residual_px, 1.5);
  EXPECT_LT(AngularDistanceDeg(after_noisy.cam_from_world.q, turned.q), 1.0);
  // Without the check the tight run keeps it too.
  PoseTrackerOptions unchecked;
  unchecked.retry_max_residual_ratio = 0;
  const PoseEstimate kept = run(0.1, unchecked);
  ASSERT_TRUE(kept.tracked) << kept.lost_reason;
  EXPECT_TRUE(kept.widened);
  EXPECT_NEAR(kept.median_inlier_residual_px, after_noisy.median_inlier_residual_px, 0.3);
  PoseTrackerOptions bad;
  bad.retry_max_residual_fraction = 0;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

// After frames the tracker did not pose (skipped or lost) the first try is checked as the second is: a frame a
// little moved with 1 px noisy features (inlier median ~1.2 px) after frames of 0.1 px noise is refused when frames
// 11-19 were skipped, and tracked when it comes next (a first try in sequence is not checked: the fast scenario's
// right ones reach 5.7x their recent frames' residual). The frame's median measured 1.05-1.31 px over noise seeds
// 1-6 against the limit of 0.9 px.
TEST(PoseTracker, AFirstTryAfterSkippedFramesIsCheckedLikeASecondTry) {
  const auto pts = Cloud();
  auto noisy = [&](const Pose& pose, double sigma_px, uint64_t stream) {
    return NoisyObservationsAt(pose, pts, sigma_px, 12, stream);
  };
  const Pose moved(QuaternionFromRotationVector(Eigen::Vector3d(0, DegToRad(0.3), 0)), Eigen::Vector3d(0.01, 0, 0));
  auto run = [&](uint64_t index) {
    auto tracker = MakeTracker();
    std::vector<double> res;
    std::vector<uint8_t> inl;
    for (uint64_t k = 1; k <= 10; ++k) EXPECT_TRUE(tracker->Track(Pose(), noisy(Pose(), 0.1, k), k, &res, &inl).tracked);
    return tracker->Track(Pose(), noisy(moved, 1.0, 99), index, &res, &inl);
  };
  const PoseEstimate next = run(11);
  ASSERT_TRUE(next.tracked) << next.lost_reason;
  EXPECT_FALSE(next.widened);
  EXPECT_GT(next.median_inlier_residual_px, 0.9);  // the limit after 0.1 px frames: 3 x 0.3 px
  const PoseEstimate after_gap = run(20);
  EXPECT_FALSE(after_gap.tracked);
  EXPECT_NE(after_gap.lost_reason.find("after 9 frames without a pose"), std::string::npos) << after_gap.lost_reason;
}

TEST(PoseSmoother, FollowsALinearTrendExactlyAndSmoothsNoise) {
  PoseSmoother s({0.5, 0.0});
  Pose out;
  for (int i = 0; i < 60; ++i) {
    const Pose world_from_cam(QuaternionFromRotationVector(Eigen::Vector3d(0, 0.01 * i, 0)), Eigen::Vector3d(0.02 * i, 0, 0));
    out = s.Update(world_from_cam.Inverse()).Inverse();
    if (i == 59) {
      // DESP is unbiased for a linear trend: after ~50 frames at alpha 0.5 the start-up transient is ~1e-14.
      EXPECT_NEAR(out.t.x(), 0.02 * i, 1e-9);
      EXPECT_NEAR(AngularDistanceDeg(out.q, world_from_cam.q), 0.0, 1e-6);
    }
  }
  PoseSmoother noisy({0.3, 0.0});
  CounterRng rng(2, 0);
  double in2 = 0, out2 = 0;
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d p(0.01 * rng.Normal(), 0, 0);
    const Pose o = noisy.Update(Pose(Eigen::Quaterniond::Identity(), p).Inverse()).Inverse();
    if (i > 50) in2 += p.x() * p.x(), out2 += o.t.x() * o.t.x();
  }
  // Variance gain of DESP at alpha 0.3 is about 0.4; assert a clear reduction.
  EXPECT_LT(out2, 0.7 * in2);
  EXPECT_THROW(PoseSmoother({0.0, 0.0}), std::invalid_argument);
}

// The paper's precision test (§8.1, Fig. 4) on a shorter sequence: known map, sigma = 1 px, 10 % outliers.
struct Errors {
  double trans, rot;
  int lost;
};
Errors TrackPaperScenario(double noise, double outliers, int rounds) {
  sim::PaperScenarioOptions so;
  so.frames = 120;
  so.noise_px = noise;
  so.outlier_fraction = outliers;
  const apps::KnownMapInput input = apps::KnownMapInputFromSequence(sim::MakePaperScenario(so));
  KnownMapOptions o;
  o.tracker.hypotheses = 1 << 17;
  o.tracker.rounds = rounds;
  const auto results = apps::RunKnownMap(input, o, compute::MakeCpuPoseKernel());
  int lost = 0;
  for (const auto& r : results) lost += !r.estimate.tracked;
  eval::EvalOptions eo;
  eo.alignment = eval::Alignment::kNone;
  const auto err = eval::EvaluateTrajectory(input.groundtruth, apps::ResultsToTrajectory(results, false), eo);
  return {err.ate_m.mean, err.rot_deg.mean, lost};
}

TEST(KnownMapTracking, PaperPrecisionOnNoisyAndCleanScenario) {
  for (int rounds : {1, 3}) {
    const Errors noisy = TrackPaperScenario(1.0, 0.1, rounds);
    const Errors clean = TrackPaperScenario(0.0, 0.0, rounds);
    // The paper's Fig. 4 bounds: mean translation error <= 2 cm and mean rotation error <= 1 degree.
    EXPECT_EQ(noisy.lost, 0);
    EXPECT_LE(noisy.trans, 0.02) << "rounds " << rounds;
    EXPECT_LE(noisy.rot, 1.0) << "rounds " << rounds;
    EXPECT_LT(clean.trans, noisy.trans) << "rounds " << rounds;
    EXPECT_LT(clean.rot, noisy.rot) << "rounds " << rounds;
  }
}

}  // namespace
}  // namespace mcslam::slam
