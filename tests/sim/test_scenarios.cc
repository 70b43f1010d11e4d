// The scenario zoo (sim/scenarios.h): determinism, exact ground truth (observations are the projections of
// unoccluded points, and what the renderer sees at their pixels), and the property that makes each scenario
// what it is.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Eigenvalues>
#include <opencv2/imgproc.hpp>

#include "core/median.h"
#include "sim/render.h"
#include "sim/scenarios.h"

namespace mcslam::sim {
namespace {

SyntheticSequence Make(const std::string& name, uint64_t seed = 1) {
  ScenarioOptions o;
  o.name = name;
  o.seed = seed;
  return MakeScenario(o);
}

Eigen::Vector3d Center(const Pose& cam_from_world) { return cam_from_world.OriginOfTargetInSource(); }

// Median over consecutive frame pairs of the image displacement of the points seen in both.
double MedianDisplacementPx(const SyntheticSequence& seq) {
  std::vector<double> d;
  for (size_t i = 1; i < seq.frames.size(); ++i) {
    std::map<int64_t, Eigen::Vector2d> previous;
    for (const SyntheticObservation& o : seq.frames[i - 1].observations) previous[o.feature_id] = o.uv_true_px;
    for (const SyntheticObservation& o : seq.frames[i].observations) {
      const auto it = previous.find(o.feature_id);
      if (it != previous.end()) d.push_back((o.uv_true_px - it->second).norm());
    }
  }
  return Median(d);
}

class EveryScenario : public ::testing::TestWithParam<std::string> {};

TEST_P(EveryScenario, SameSeedSameSequenceOtherSeedAnother) {
  const SyntheticSequence a = Make(GetParam(), 3), b = Make(GetParam(), 3), c = Make(GetParam(), 4);
  ASSERT_EQ(a.frames.size(), b.frames.size());
  ASSERT_EQ(a.points_in_world, b.points_in_world);
  for (size_t i = 0; i < a.frames.size(); ++i) {
    EXPECT_EQ(a.cam_from_world[i].q.coeffs(), b.cam_from_world[i].q.coeffs());
    EXPECT_EQ(a.cam_from_world[i].t, b.cam_from_world[i].t);
    ASSERT_EQ(a.frames[i].observations.size(), b.frames[i].observations.size());
    for (size_t k = 0; k < a.frames[i].observations.size(); ++k)
      EXPECT_EQ(a.frames[i].observations[k].uv_px, b.frames[i].observations[k].uv_px);
  }
  // Another seed: other points (and another path or layout).
  EXPECT_NE(a.points_in_world, c.points_in_world);
}

TEST_P(EveryScenario, ObservationsAreExactProjectionsOfUnoccludedPoints) {
  const SyntheticSequence seq = Make(GetParam());
  const ScenarioInfo info = DescribeScenario(GetParam());
  ASSERT_EQ(static_cast<int>(seq.frames.size()), info.frames);
  ASSERT_EQ(static_cast<int>(seq.points_in_world.size()), info.num_points);
  const QuadIntersector scene(seq.scene);
  for (size_t i = 0; i < seq.frames.size(); i += 7) {
    const Pose& pose = seq.cam_from_world[i];
    const Eigen::Vector3d c = Center(pose);
    for (const SyntheticObservation& o : seq.frames[i].observations) {
      const Eigen::Vector3d& p = seq.points_in_world[static_cast<size_t>(o.feature_id)];
      Eigen::Vector2d uv;
      ASSERT_TRUE(seq.camera.ProjectWorld(pose, p, &uv));
      EXPECT_EQ(o.uv_px, o.uv_true_px);  // noise 0
      EXPECT_LT((uv - o.uv_px).norm(), 1e-9);
      EXPECT_TRUE(seq.camera.InImage(o.uv_px));
      // The first surface on the ray from the camera centre is the point's own: it is not hidden.
      const auto hit = scene.Nearest(c, p - c, 0.0, 2.0);
      ASSERT_TRUE(hit.has_value());
      EXPECT_NEAR(hit->t, 1.0, 1e-9) << GetParam() << " frame " << i << " point " << o.feature_id;
    }
  }
}

TEST_P(EveryScenario, EveryFrameSeesEnoughPointsAndRendersTexture) {
  const SyntheticSequence seq = Make(GetParam());
  const bool sparse = GetParam() == "sparse";
  for (const SyntheticFrame& f : seq.frames) {
    if (sparse)
      EXPECT_LT(f.observations.size(), 40u);
    else
      EXPECT_GE(f.observations.size(), 70u) << GetParam();
  }
  // A rendered frame: Shi-Tomasi as the front end runs it finds plenty of corners (sparse: few), and the
  // renderer sees each observed point at its pixel.
  RenderOptions ro;
  ro.seed = 1;
  const SceneRenderer renderer(seq.scene, ro);
  const size_t k = seq.frames.size() / 2;
  const cv::Mat img = renderer.Render(seq.camera, seq.cam_from_world[k], k);
  ASSERT_EQ(img.cols, seq.camera.width);
  ASSERT_EQ(img.rows, seq.camera.height);
  cv::Mat mask = cv::Mat::zeros(img.size(), CV_8U);
  mask(cv::Rect(12, 12, img.cols - 24, img.rows - 24)).setTo(255);
  std::vector<cv::Point2f> corners;
  cv::goodFeaturesToTrack(img, corners, 2000, 0.01, 10, mask, 3);
  if (sparse)
    EXPECT_LT(corners.size(), 40u);
  else
    EXPECT_GE(corners.size(), 100u) << GetParam();
  for (const SyntheticObservation& o : seq.frames[k].observations) {
    const auto hit = renderer.SurfacePoint(seq.camera, seq.cam_from_world[k], o.uv_true_px);
    ASSERT_TRUE(hit.has_value());
    EXPECT_LT((hit->point - seq.points_in_world[static_cast<size_t>(o.feature_id)]).norm(), 1e-6);
  }
}

INSTANTIATE_TEST_SUITE_P(Zoo, EveryScenario, ::testing::ValuesIn(ScenarioNames()),
                         [](const auto& param_info) {
                           std::string name = param_info.param;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

TEST(Scenarios, PaperIsMakePaperScenario) {
  const SyntheticSequence a = MakeScenario({.frames = 30, .noise_px = 1, .outlier_fraction = 0.1});
  const SyntheticSequence b = MakePaperScenario({.frames = 30, .noise_px = 1, .outlier_fraction = 0.1});
  ASSERT_EQ(a.frames.size(), b.frames.size());
  for (size_t i = 0; i < a.frames.size(); ++i) {
    EXPECT_EQ(a.cam_from_world[i].t, b.cam_from_world[i].t);
    ASSERT_EQ(a.frames[i].observations.size(), b.frames[i].observations.size());
    for (size_t k = 0; k < a.frames[i].observations.size(); ++k)
      EXPECT_EQ(a.frames[i].observations[k].uv_px, b.frames[i].observations[k].uv_px);
  }
}

TEST(Scenarios, ForwardDrivesAMetreAFrameAndTurnsNinetyDegrees) {
  const SyntheticSequence seq = Make("forward");
  EXPECT_EQ(seq.fps, 10.0);
  EXPECT_EQ(seq.camera.width, 620);
  std::vector<double> step;
  for (size_t i = 1; i < seq.frames.size(); ++i)
    step.push_back((Center(seq.cam_from_world[i]) - Center(seq.cam_from_world[i - 1])).norm());
  EXPECT_NEAR(Median(step), 1.0, 0.1);
  for (const Pose& p : seq.cam_from_world) EXPECT_NEAR(Center(p).z(), 1.6, 0.05);
  // Heading: the camera's z axis, projected on the ground.
  const auto heading = [](const Pose& cam_from_world) {
    const Eigen::Vector3d z = cam_from_world.Inverse().R().col(2);
    return std::atan2(z.y(), z.x());
  };
  const double turn_deg = RadToDeg(heading(seq.cam_from_world.back()) - heading(seq.cam_from_world.front()));
  EXPECT_GE(turn_deg, 80.0);
  EXPECT_LE(turn_deg, 100.0);
}

TEST(Scenarios, RotationHasPureRotationSegmentsAndARotatingStart) {
  const SyntheticSequence seq = Make("rotation");
  int in_segments = 0;
  for (size_t i = 1; i < seq.frames.size(); ++i) {
    const double t0 = seq.stamps_s[i - 1], t1 = seq.stamps_s[i];
    for (const auto& [s, e] : kRotationPureSegmentsS) {
      if (t0 < s || t1 > e) continue;
      ++in_segments;
      EXPECT_LT((Center(seq.cam_from_world[i]) - Center(seq.cam_from_world[i - 1])).norm(), 1e-3) << "frame " << i;
    }
  }
  EXPECT_GE(in_segments, 40);  // 0.8 s and 1 s at 30 Hz
  // The segments turn the camera by tens of degrees.
  const auto frame_at = [&](double t) { return static_cast<size_t>(std::lround(t * seq.fps)); };
  for (const auto& [s, e] : kRotationPureSegmentsS)
    EXPECT_GT(AngularDistanceDeg(seq.cam_from_world[frame_at(s)].q, seq.cam_from_world[frame_at(e)].q), 30.0);
  // The opening: mostly rotation (more than 15 deg) for little translation (under 2 cm).
  const size_t opening_end = frame_at(kRotationOpeningS);
  EXPECT_GT(AngularDistanceDeg(seq.cam_from_world[0].q, seq.cam_from_world[opening_end].q), 15.0);
  EXPECT_LT((Center(seq.cam_from_world[0]) - Center(seq.cam_from_world[opening_end])).norm(), 0.02);
}

TEST(Scenarios, StillStartIsStillThenMoves) {
  const SyntheticSequence seq = Make("still-start");
  const size_t still_frames = static_cast<size_t>(kStillStartS * seq.fps);
  for (size_t i = 1; i <= still_frames; ++i) {
    EXPECT_EQ(seq.cam_from_world[i].t, seq.cam_from_world[0].t) << i;
    EXPECT_EQ(seq.cam_from_world[i].q.coeffs(), seq.cam_from_world[0].q.coeffs()) << i;
  }
  // A second later it moves like the paper's camera (centimetres a frame).
  const size_t k = still_frames + static_cast<size_t>(seq.fps);
  EXPECT_GT((Center(seq.cam_from_world[k + 1]) - Center(seq.cam_from_world[k])).norm(), 0.005);
}

TEST(Scenarios, StopAndGoStandsExactlyStillTwiceAndMovesBetween) {
  const SyntheticSequence seq = Make("stop-and-go");
  const auto frame_at = [&](double t) { return static_cast<size_t>(std::ceil(t * seq.fps - 1e-9)); };
  size_t still_pairs = 0;
  for (const double start : kStopAndGoStopsS) {
    const size_t first = frame_at(start + kStopRampS), last = frame_at(start + kStopRampS + kStopS) - 1;
    ASSERT_LT(last, seq.cam_from_world.size());
    for (size_t i = first + 1; i <= last; ++i, ++still_pairs) {
      EXPECT_EQ(seq.cam_from_world[i].t, seq.cam_from_world[first].t) << i;
      EXPECT_EQ(seq.cam_from_world[i].q.coeffs(), seq.cam_from_world[first].q.coeffs()) << i;
    }
    // Before the stop and a second after it, it moves like the paper's camera (centimetres a frame).
    for (const size_t k : {frame_at(start) - 2, frame_at(start + 2 * kStopRampS + kStopS + 1.0)})
      EXPECT_GT((Center(seq.cam_from_world[k + 1]) - Center(seq.cam_from_world[k])).norm(), 0.005) << k;
  }
  // Two stops of 1.5 s at 30 frames a second: 44 frames the same as the one before them, at least.
  EXPECT_GE(still_pairs, 2 * static_cast<size_t>(kStopS * seq.fps) - 2);
}

TEST(Scenarios, PlanarPointsAreOnOnePlane) {
  const SyntheticSequence seq = Make("planar");
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : seq.points_in_world) mean += p;
  mean /= static_cast<double>(seq.points_in_world.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& p : seq.points_in_world) scatter += (p - mean) * (p - mean).transpose();
  const Eigen::Vector3d normal = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(scatter).eigenvectors().col(0);
  double worst = 0;
  for (const Eigen::Vector3d& p : seq.points_in_world) worst = std::max(worst, std::abs(normal.dot(p - mean)));
  EXPECT_LT(worst, 1e-3);
  // The camera moves towards and away from the plane: distances vary by more than half a metre.
  double near = 1e9, far = 0;
  for (const Pose& pose : seq.cam_from_world) {
    const double d = std::abs(normal.dot(Center(pose) - mean));
    near = std::min(near, d), far = std::max(far, d);
  }
  EXPECT_GT(far - near, 0.5);
}

TEST(Scenarios, FastMovesTheImageMuchFasterThanPaper) {
  const double paper = MedianDisplacementPx(Make("paper")), fast = MedianDisplacementPx(Make("fast"));
  EXPECT_GT(fast, 8.0 * paper);
  EXPECT_GE(fast, 20.0);
  EXPECT_LE(fast, 40.0);
}

TEST(Scenarios, OptionsAreCheckedNamingTheField) {
  ScenarioOptions o;
  o.name = "cube";
  EXPECT_THROW(o.Check(), std::invalid_argument);
  o.name = "forward";
  EXPECT_EQ(o.MaxFrames(), 161);  // 160 m at 1 m a frame, both ends
  o.frames = 162;
  try {
    o.Check();
    ADD_FAILURE() << "162 frames of forward accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("frames"), std::string::npos) << e.what();
  }
  o.speed = 0.5;  // half as fast: twice the frames fit
  EXPECT_NO_THROW(o.Check());
}

// A lens (radial-tangential, as a camera file declares it): the observations are the points' projections through
// it, the renderer sees each observed point at its (bent) pixel, and the camera the sequence carries declares it.
TEST(Scenarios, ALensBendsTheObservationsAndTheImagesAlike) {
  ScenarioOptions o;
  o.name = "forward";  // 81 degrees across: the lens moves its corners by tens of pixels
  o.frames = 4;
  o.lens = Distortion{-0.28, 0.07, 0.0002, 0.00002, 0.0};  // a EuRoC-like lens
  const SyntheticSequence seq = MakeScenario(o);
  EXPECT_EQ(seq.camera.dist.k1, -0.28);
  EXPECT_EQ(seq.camera.dist.p2, 0.00002);
  PinholeCamera pinhole = seq.camera;
  pinhole.dist = Distortion{};
  double most_bent = 0;
  RenderOptions ro;
  const SceneRenderer renderer(seq.scene, ro);
  for (size_t i = 0; i < seq.frames.size(); ++i) {
    ASSERT_GE(seq.frames[i].observations.size(), 70u);
    for (const SyntheticObservation& obs : seq.frames[i].observations) {
      const Eigen::Vector3d& p = seq.points_in_world[static_cast<size_t>(obs.feature_id)];
      Eigen::Vector2d uv, uv_pinhole;
      ASSERT_TRUE(seq.camera.ProjectWorld(seq.cam_from_world[i], p, &uv));
      ASSERT_TRUE(pinhole.ProjectWorld(seq.cam_from_world[i], p, &uv_pinhole));
      EXPECT_LT((uv - obs.uv_px).norm(), 1e-9);
      most_bent = std::max(most_bent, (uv - uv_pinhole).norm());
      const auto hit = renderer.SurfacePoint(seq.camera, seq.cam_from_world[i], obs.uv_true_px);
      ASSERT_TRUE(hit.has_value());
      EXPECT_LT((hit->point - p).norm(), 1e-6);
    }
  }
  // Barrel distortion pulls the edges in: at 0.9 normalised units (the corners) by about 15 % of the radius.
  EXPECT_GT(most_bent, 20.0);
}

// Another resolution, the same field of view: the camera's size and focal length scaled together, and every
// observation where the unscaled one is, in the scaled pixel grid (centres: u' + 0.5 = s (u + 0.5)).
TEST(Scenarios, AnImageScaleSeesTheSameSceneAtAnotherResolution) {
  for (const std::string name : {"paper", "rotation"}) {
    ScenarioOptions o;
    o.name = name;
    o.frames = 5;
    const SyntheticSequence base = MakeScenario(o);
    o.image_scale = 2.0;
    const SyntheticSequence big = MakeScenario(o);
    EXPECT_EQ(big.camera.width, 2 * base.camera.width);
    EXPECT_EQ(big.camera.height, 2 * base.camera.height);
    EXPECT_EQ(big.camera.fx, 2 * base.camera.fx);
    ASSERT_EQ(big.frames.size(), base.frames.size());
    for (size_t i = 0; i < big.frames.size(); ++i) {
      std::map<int64_t, Eigen::Vector2d> at;
      for (const SyntheticObservation& b : base.frames[i].observations) at[b.feature_id] = b.uv_px;
      // At the image's edge a point can be just in one grid and just out of the other.
      EXPECT_NEAR(static_cast<double>(big.frames[i].observations.size()),
                  static_cast<double>(base.frames[i].observations.size()), 3.0);
      for (const SyntheticObservation& b : big.frames[i].observations) {
        if (const auto it = at.find(b.feature_id); it != at.end()) {
          EXPECT_LT((b.uv_px - (2.0 * (it->second + Eigen::Vector2d(0.5, 0.5)) - Eigen::Vector2d(0.5, 0.5))).norm(), 1e-9);
        }
      }
    }
  }
  ScenarioOptions bad;
  bad.image_scale = 0;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
  bad.image_scale = std::nan("");
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

// A wider field of view, the same image: the focal length that gives it, every point the narrow camera sees seen
// by the wide one nearer the principal point (by the ratio of the focal lengths), and in a room (rotation's points
// are all around) more points in view (the paper's box already fills the narrow view).
TEST(Scenarios, AWiderFieldOfViewSeesMoreOfTheSceneInTheSameImage) {
  for (const std::string name : {"paper", "rotation", "forward"}) {
    ScenarioOptions o;
    o.name = name;
    o.frames = 5;
    const SyntheticSequence base = MakeScenario(o);
    o.hfov_deg = name == "forward" ? 100 : 70;  // the forward camera sees 81.6 degrees of its own
    const SyntheticSequence wide = MakeScenario(o);
    EXPECT_EQ(wide.camera.width, base.camera.width);
    EXPECT_NEAR(2 * std::atan(0.5 * wide.camera.width / wide.camera.fx) * 180 / M_PI, o.hfov_deg, 1e-9);
    ASSERT_LT(wide.camera.fx, base.camera.fx) << name;
    EXPECT_EQ(wide.camera.fx, wide.camera.fy);
    const double ratio = wide.camera.fx / base.camera.fx;
    size_t seen_base = 0, seen_wide = 0;
    for (size_t i = 0; i < wide.frames.size(); ++i) {
      std::map<int64_t, Eigen::Vector2d> at;
      for (const SyntheticObservation& w : wide.frames[i].observations) at[w.feature_id] = w.uv_px;
      for (const SyntheticObservation& b : base.frames[i].observations) {
        const auto it = at.find(b.feature_id);
        ASSERT_NE(it, at.end()) << name << " frame " << i << ": point " << b.feature_id << " left the wider view";
        const Eigen::Vector2d c(base.camera.cx, base.camera.cy);
        EXPECT_LT((it->second - (c + ratio * (b.uv_px - c))).norm(), 1e-9);
      }
      seen_base += base.frames[i].observations.size();
      seen_wide += wide.frames[i].observations.size();
    }
    EXPECT_GE(seen_wide, seen_base) << name;
    if (name == "rotation") {
      EXPECT_GT(seen_wide, seen_base + seen_base / 4);
    }
  }
  ScenarioOptions bad;
  for (double hfov : {-1.0, 4.0, 151.0, std::nan("")}) {
    bad.hfov_deg = hfov;
    EXPECT_THROW(bad.Check(), std::invalid_argument) << hfov;
  }
}

TEST(Scenarios, ALensThatTurnsBackIsRefusedAndAPointBentBackIntoTheImageIsNotSeen) {
  ScenarioOptions o;
  o.name = "forward";
  o.lens.k1 = -0.5;  // r (1 - 0.5 r^2) turns at r = 0.82, before the forward camera's corners (0.9)
  try {
    o.Check();
    ADD_FAILURE() << "a lens that turns back inside the image was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("k1 -0.5"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("one to one"), std::string::npos) << e.what();
  }
  o.lens.k2 = 0.2;  // the quartic term straightens it: one to one out to the corners
  EXPECT_NO_THROW(o.Check());
  o.lens = Distortion{std::nan(""), 0, 0, 0, 0};
  EXPECT_THROW(o.Check(), std::invalid_argument);

  // k1 = -0.28 alone turns at r = 1.09 (r_d = 0.73): a point 2 units off the axis lands at r_d = -0.24, inside
  // the paper camera's image, but its pixel's ray is another one.
  PinholeCamera cam = PaperCamera();
  cam.dist.k1 = -0.28;
  const Eigen::Vector3d far_off(2.0, 0.0, 1.0), near_axis(0.1, 0.05, 1.0);
  Eigen::Vector2d uv;
  ASSERT_TRUE(cam.Project(far_off, &uv));
  EXPECT_TRUE(cam.InImage(uv));
  EXPECT_FALSE(RayLandsOnItsPixel(cam, far_off, uv));
  ASSERT_TRUE(cam.Project(near_axis, &uv));
  EXPECT_TRUE(RayLandsOnItsPixel(cam, near_axis, uv));
  cam.dist = Distortion{};
  EXPECT_TRUE(RayLandsOnItsPixel(cam, far_off, {0, 0}));  // no lens: nothing to check
}

}  // namespace
}  // namespace mcslam::sim
