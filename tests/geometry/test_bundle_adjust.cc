#include <gtest/gtest.h>

#include "core/random.h"
#include "geometry/bundle_adjust.h"
#include "geometry/pnp.h"

namespace mcslam::geometry {
namespace {

// Eight cameras on a 40 cm arc looking at a 1 m cloud 3 m away, exact observations.
struct Scene {
  std::vector<Pose> cams;
  std::vector<Eigen::Vector3d> pts;
  std::vector<BundleObservation> obs;
  Scene() {
    CounterRng rng(1, 0);
    for (int i = 0; i < 150; ++i) pts.emplace_back(rng.Uniform(-0.5, 0.5), rng.Uniform(-0.4, 0.4), 3 + rng.Uniform(-0.3, 0.3));
    for (int c = 0; c < 8; ++c) {
      const Eigen::Vector3d centre(0.05 * c, 0.01 * c, 0.0);
      const Eigen::Quaterniond world_from_cam_q = QuaternionFromRotationVector(Eigen::Vector3d(0, -0.01 * c, 0));
      cams.push_back(Pose(world_from_cam_q, centre).Inverse());
    }
    for (int c = 0; c < 8; ++c)
      for (int i = 0; i < 150; ++i) {
        const Eigen::Vector3d p = cams[c] * pts[i];
        obs.push_back({c, i, p.head<2>() / p.z()});
      }
  }
};

// Up to 100 iterations, the first two cameras held: they fix the gauge, scale included.
BundleAdjustSummary AdjustWithTheFirstTwoFixed(std::vector<Pose>& cams, std::vector<Eigen::Vector3d>& pts,
                                               const std::vector<BundleObservation>& obs) {
  std::vector<bool> fixed(cams.size(), false);
  fixed[0] = fixed[1] = true;
  BundleAdjustOptions o;
  o.max_iterations = 100;
  return BundleAdjust(cams, pts, obs, fixed, o);
}

TEST(BundleAdjust, RecoversPerturbedPosesAndPoints) {
  const Scene truth;
  std::vector<Pose> cams = truth.cams;
  std::vector<Eigen::Vector3d> pts = truth.pts;
  CounterRng rng(2, 0);
  for (size_t c = 2; c < cams.size(); ++c)
    cams[c] = Pose(cams[c].q * QuaternionFromRotationVector(Eigen::Vector3d(0.005 * rng.Normal(), 0.005 * rng.Normal(), 0.005 * rng.Normal())),
                   cams[c].t + Eigen::Vector3d(0.01 * rng.Normal(), 0.01 * rng.Normal(), 0.01 * rng.Normal()));
  for (auto& p : pts) p += Eigen::Vector3d(0.02 * rng.Normal(), 0.02 * rng.Normal(), 0.02 * rng.Normal());
  const BundleAdjustSummary s = AdjustWithTheFirstTwoFixed(cams, pts, truth.obs);
  EXPECT_GT(s.initial_rms_px, 1.0);
  EXPECT_LT(s.final_rms_px, 1e-4);  // exact data: converges to zero residual (float-free double solve)
  for (size_t c = 0; c < cams.size(); ++c) {
    EXPECT_LT((cams[c].t - truth.cams[c].t).norm(), 1e-4) << c;
    EXPECT_LT(AngularDistanceDeg(cams[c].q, truth.cams[c].q), 1e-3) << c;
  }
}

// One point that starts behind a camera (a wrong match triangulated from little parallax can end there):
// its observation by that camera has no residual and is left out; without that, Ceres gave up the whole
// adjustment at its first evaluation ("Residual and Jacobian evaluation failed") and nothing moved.
TEST(BundleAdjust, APointBehindACameraDoesNotStopTheAdjustment) {
  const Scene truth;
  std::vector<Pose> cams = truth.cams;
  std::vector<Eigen::Vector3d> pts = truth.pts;
  CounterRng rng(4, 0);
  for (size_t c = 2; c < cams.size(); ++c)
    cams[c] = Pose(cams[c].q, cams[c].t + Eigen::Vector3d(0.01 * rng.Normal(), 0.01 * rng.Normal(), 0.01 * rng.Normal()));
  pts[7] = Eigen::Vector3d(0.1, 0.0, -1.0);  // behind every camera
  const BundleAdjustSummary s = AdjustWithTheFirstTwoFixed(cams, pts, truth.obs);
  EXPECT_EQ(s.left_out_behind, 8);  // point 7 in each of the 8 cameras
  EXPECT_TRUE(s.converged) << s.report;
  for (size_t c = 0; c < cams.size(); ++c) {
    EXPECT_LT((cams[c].t - truth.cams[c].t).norm(), 1e-4) << c;  // exact data: the other 149 points fix them
  }
}

TEST(Pnp, RecoversAPoseWithOutliers) {
  const Scene sc;
  std::vector<Eigen::Vector2d> uv;
  for (const auto& o : sc.obs)
    if (o.camera == 5) uv.push_back(o.uv_norm);
  CounterRng rng(3, 0);
  for (size_t i = 0; i < uv.size(); i += 5) uv[i] += Eigen::Vector2d(rng.Uniform(-0.1, 0.1), rng.Uniform(-0.1, 0.1));
  int inliers = 0;
  const auto pose = SolvePnp(sc.pts, uv, {}, &inliers);
  ASSERT_TRUE(pose.has_value());
  EXPECT_GE(inliers, 110);  // 120 exact of 150; a few of the 30 perturbed may still fall within 3 px
  EXPECT_LT((pose->t - sc.cams[5].t).norm(), 1e-6);
  EXPECT_LT(AngularDistanceDeg(pose->q, sc.cams[5].q), 1e-5);
}

}  // namespace
}  // namespace mcslam::geometry
