#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "test_util.h"
#include "geometry/essential.h"
#include "geometry/triangulation.h"
#include "sim/paper_scenario.h"

namespace mcslam::geometry {
namespace {

using mcslam::testing::LookAt;


Eigen::Vector2d ProjectNorm(const Pose& cam_from_world, const Eigen::Vector3d& point_in_world) {
  const Eigen::Vector3d p = cam_from_world * point_in_world;
  return p.head<2>() / p.z();
}

// Points of the paper scene seen in all the given frames, with their exact normalised observations.
struct MultiView {
  std::vector<Pose> cam_from_world;
  std::vector<Eigen::Vector3d> points_in_world;
  std::vector<std::vector<Eigen::Vector2d>> uv_norm;  // [point][view]
};

MultiView PaperMultiView(uint64_t seed, const std::vector<int>& frames) {
  sim::PaperScenarioOptions opt;
  opt.frames = frames.back() + 1;
  opt.seed = seed;
  const sim::SyntheticSequence seq = sim::MakePaperScenario(opt);
  MultiView mv;
  std::map<int64_t, int> count;
  for (const int f : frames) {
    mv.cam_from_world.push_back(seq.cam_from_world[f]);
    for (const auto& o : seq.frames[f].observations) ++count[o.feature_id];
  }
  for (const auto& [id, c] : count) {
    if (c != static_cast<int>(frames.size())) continue;
    mv.points_in_world.push_back(seq.points_in_world[id]);
    std::vector<Eigen::Vector2d> obs;
    for (const Pose& pose : mv.cam_from_world) obs.push_back(ProjectNorm(pose, seq.points_in_world[id]));
    mv.uv_norm.push_back(obs);
  }
  return mv;
}

void ExpectExact(const MultiView& mv, size_t min_points) {
  ASSERT_GE(mv.points_in_world.size(), min_points);
  TriangulationOptions options;
  for (size_t i = 0; i < mv.points_in_world.size(); ++i) {
    const Triangulation t = TriangulateDlt(mv.cam_from_world, mv.uv_norm[i], options);
    ASSERT_TRUE(t.ok) << "point " << i << ": " << t.failure;
    EXPECT_EQ(t.status, TriangulationStatus::kOk);
    EXPECT_TRUE(t.failure.empty());
    // Exact observations: the DLT's null vector is exact up to rounding (~1e-15 relative); 1e-9 relative to
    // the point's distance from the first camera (~3 m) leaves room for the conditioning of the 2n x 4 system.
    const double range = (mv.points_in_world[i] - mv.cam_from_world[0].OriginOfTargetInSource()).norm();
    EXPECT_LT((t.point_in_world - mv.points_in_world[i]).norm(), 1e-9 * range) << "point " << i;
    EXPECT_LT(t.max_reprojection_px, 1e-6);  // exact data: rounding only (px)
    EXPECT_GT(t.min_depth, 1.0);             // the scene is ~3 m away
  }
}

TEST(TriangulateDlt, ExactOnExactDataTwoViews) { ExpectExact(PaperMultiView(1, {0, 15}), 50); }

TEST(TriangulateDlt, ExactOnExactDataFiveViews) { ExpectExact(PaperMultiView(2, {0, 5, 10, 15, 20}), 50); }

TEST(TriangulateDlt, ParallaxIsTheLargestRayAngle) {
  // Cameras at x = 0, 0.1 and 0.4 m looking at a point 3 m ahead: the largest angle is between the outer two.
  const Eigen::Vector3d point(0.2, 3.0, 0.0);
  std::vector<Pose> poses;
  std::vector<Eigen::Vector2d> obs;
  for (const double x : {0.0, 0.1, 0.4}) {
    poses.push_back(LookAt(Eigen::Vector3d(x, 0, 0), point));
    obs.push_back(ProjectNorm(poses.back(), point));
  }
  const Triangulation t = TriangulateDlt(poses, obs, TriangulationOptions{});
  ASSERT_TRUE(t.ok) << t.failure;
  const double expected = RadToDeg(std::atan2(0.2, 3.0) * 2);  // symmetric about the point: 2 atan(0.2 / 3)
  EXPECT_NEAR(t.parallax_deg, expected, 1e-9);  // closed form vs atan2 of the same geometry: rounding only
  EXPECT_NEAR(ParallaxDeg(poses, point), expected, 1e-9);
}

TEST(TriangulateDlt, RejectsAPointBehindACamera) {
  const Eigen::Vector3d point(0.0, 3.0, 0.2);
  const Pose front = LookAt(Eigen::Vector3d(0, 0, 0), point);
  // The second camera is beyond the point, looking away from it: the point is behind it. Its "observation"
  // is the (valid) central projection through the camera centre, so the rays still meet at the point.
  const Pose away = LookAt(Eigen::Vector3d(0.5, 5.0, 0.0), Eigen::Vector3d(1.0, 8.0, 0.0));
  const std::vector<Pose> poses = {front, away};
  const std::vector<Eigen::Vector2d> obs = {ProjectNorm(front, point), ProjectNorm(away, point)};
  const Triangulation t = TriangulateDlt(poses, obs, TriangulationOptions{});
  EXPECT_FALSE(t.ok);
  EXPECT_EQ(t.status, TriangulationStatus::kBehindCamera) << t.failure;
  EXPECT_NE(t.failure.find("behind camera 1"), std::string::npos) << t.failure;
  EXPECT_LT((t.point_in_world - point).norm(), 1e-9);  // the point itself is still found (exact data)
  EXPECT_LT(t.min_depth, 0);
}

TEST(TriangulateDlt, RejectsTooSmallParallax) {
  const Eigen::Vector3d point(0.1, 3.0, -0.1);
  // 2 cm baseline at 3 m: parallax 0.38 deg < 1 deg.
  const std::vector<Pose> poses = {LookAt(Eigen::Vector3d(0, 0, 0), point), LookAt(Eigen::Vector3d(0.02, 0, 0), point)};
  const std::vector<Eigen::Vector2d> obs = {ProjectNorm(poses[0], point), ProjectNorm(poses[1], point)};
  const Triangulation t = TriangulateDlt(poses, obs, TriangulationOptions{});
  EXPECT_FALSE(t.ok);
  EXPECT_EQ(t.status, TriangulationStatus::kSmallParallax) << t.failure;
  EXPECT_NEAR(t.parallax_deg, 0.38, 0.01);  // 0.02 / 3.0 rad = 0.382 deg (the point is not exactly centred)
  TriangulationOptions lenient;
  lenient.min_parallax_deg = 0.1;
  EXPECT_TRUE(TriangulateDlt(poses, obs, lenient).ok);
}

TEST(TriangulateDlt, RejectsALargeReprojectionError) {
  const Eigen::Vector3d point(0.1, 3.0, 0.1);
  const std::vector<Pose> poses = {LookAt(Eigen::Vector3d(0, 0, 0), point), LookAt(Eigen::Vector3d(0.3, 0, 0), point)};
  std::vector<Eigen::Vector2d> obs = {ProjectNorm(poses[0], point), ProjectNorm(poses[1], point)};
  // Move the second observation by 20 px across its epipolar line, so that the two rays no longer meet
  // (along the line they would still meet, only at another depth).
  const Pose cam2_from_cam1 = poses[1] * poses[0].Inverse();
  const Eigen::Vector3d line = EssentialFromPose(cam2_from_cam1) * obs[0].homogeneous();
  obs[1] += (20.0 / 500.0) * line.head<2>().normalized();
  const Triangulation t = TriangulateDlt(poses, obs, TriangulationOptions{});
  EXPECT_FALSE(t.ok);
  EXPECT_EQ(t.status, TriangulationStatus::kLargeReprojection) << t.failure;
  // The DLT shares the 20 px gap between the two views: each error is about 10 px, certainly above 3.
  EXPECT_GT(t.max_reprojection_px, 5.0);
  EXPECT_LT(t.max_reprojection_px, 20.0);
  TriangulationOptions lenient;
  lenient.max_reprojection_px = 25.0;
  EXPECT_TRUE(TriangulateDlt(poses, obs, lenient).ok);
}

TEST(TriangulateDlt, ParallelRaysAreAtInfinity) {
  const std::vector<Pose> poses = {Pose::Identity(), Pose(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-0.2, 0, 0))};
  const std::vector<Eigen::Vector2d> obs = {Eigen::Vector2d(0.1, 0.05), Eigen::Vector2d(0.1, 0.05)};
  const Triangulation t = TriangulateDlt(poses, obs, TriangulationOptions{});
  EXPECT_FALSE(t.ok);
  EXPECT_EQ(t.status, TriangulationStatus::kAtInfinity) << t.failure;
}

TEST(TriangulateDlt, BadInputFailsWithoutCrashing) {
  const std::vector<Pose> two = {Pose::Identity(), Pose(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-0.2, 0, 0))};
  const std::vector<Eigen::Vector2d> obs2 = {Eigen::Vector2d(0.1, 0.05), Eigen::Vector2d(0.05, 0.05)};
  const TriangulationOptions options;
  EXPECT_EQ(TriangulateDlt(std::vector<Pose>{two[0]}, std::vector<Eigen::Vector2d>{obs2[0]}, options).status,
            TriangulationStatus::kBadInput);
  EXPECT_EQ(TriangulateDlt(two, std::vector<Eigen::Vector2d>{obs2[0]}, options).status, TriangulationStatus::kBadInput);
  std::vector<Eigen::Vector2d> nan_obs = obs2;
  nan_obs[1].y() = std::nan("");
  const Triangulation t = TriangulateDlt(two, nan_obs, options);
  EXPECT_EQ(t.status, TriangulationStatus::kBadInput);
  EXPECT_NE(t.failure.find("observation 1"), std::string::npos) << t.failure;
  // The same camera centre twice: every ray passes through it and the DLT returns the centre (depth 0).
  const std::vector<Pose> same = {Pose::Identity(), Pose(QuaternionFromRotationVector(Eigen::Vector3d(0, 0.1, 0)),
                                                         Eigen::Vector3d::Zero())};
  const Triangulation r = TriangulateDlt(same, obs2, options);
  EXPECT_FALSE(r.ok);
  EXPECT_TRUE(r.status == TriangulationStatus::kBehindCamera || r.status == TriangulationStatus::kAtInfinity)
      << r.failure;
}

// Cheirality of a two-view triangulation: at the true relative pose every point of the paper scene is in front of
// both cameras (exact data) and comes back where it is; with the translation's sign flipped none is (each ray pair
// then meets behind a camera); a parallel pair (at infinity) and a point behind the cameras are left out, and the
// indices keep the order they were given in.
TEST(TriangulateInFrontOfBoth, CheiralityDecidesTheTranslationsSign) {
  const MultiView mv = PaperMultiView(1, {0, 15});
  ASSERT_GE(mv.points_in_world.size(), 50u);
  const Pose cam2_from_cam1 = mv.cam_from_world[1] * mv.cam_from_world[0].Inverse();
  std::vector<Eigen::Vector2d> uv1, uv2;
  for (const auto& obs : mv.uv_norm) uv1.push_back(obs[0]), uv2.push_back(obs[1]);
  const InFrontOfBoth all = TriangulateInFrontOfBoth(cam2_from_cam1, uv1, uv2);
  ASSERT_EQ(all.indices.size(), uv1.size());
  for (size_t k = 0; k < all.indices.size(); ++k) {
    EXPECT_EQ(all.indices[k], static_cast<int>(k));
    const Eigen::Vector3d truth = mv.cam_from_world[0] * mv.points_in_world[k];
    EXPECT_LT((all.points_in_cam1[k] - truth).norm(), 1e-9 * truth.norm());  // exact data: rounding only
  }
  const Pose flipped(cam2_from_cam1.q, -cam2_from_cam1.t);
  EXPECT_TRUE(TriangulateInFrontOfBoth(flipped, uv1, uv2).indices.empty());
  // A subset, out of order; one correspondence made parallel (at infinity) and one pointing behind the cameras.
  uv2[3] = (cam2_from_cam1.q * uv1[3].homogeneous()).hnormalized();  // the same direction in both: infinitely far
  const Eigen::Vector3d behind = -(mv.cam_from_world[0] * mv.points_in_world[5]);  // projects to uv1[5] too
  uv2[5] = (cam2_from_cam1 * behind).hnormalized();
  const std::vector<int> subset = {7, 3, 5, 2};
  const InFrontOfBoth some = TriangulateInFrontOfBoth(cam2_from_cam1, uv1, uv2, subset);
  EXPECT_EQ(some.indices, (std::vector<int>{7, 2}));
}

TEST(TriangulationOptions, CheckNamesTheBadField) {
  auto message = [](TriangulationOptions o) {
    try {
      o.Check();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(message(TriangulationOptions{}), "");
  TriangulationOptions o;
  o.focal_px = 0;
  EXPECT_NE(message(o).find("focal_px"), std::string::npos);
  o = {};
  o.max_reprojection_px = std::nan("");
  EXPECT_NE(message(o).find("max_reprojection_px"), std::string::npos);
  o = {};
  o.min_parallax_deg = -1;
  EXPECT_NE(message(o).find("min_parallax_deg"), std::string::npos);
  o = {};
  o.min_depth = -1;
  EXPECT_NE(message(o).find("min_depth"), std::string::npos);
}

}  // namespace
}  // namespace mcslam::geometry
