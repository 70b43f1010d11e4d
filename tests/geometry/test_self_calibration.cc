#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "core/random.h"
#include "geometry/self_calibration.h"

namespace mcslam::geometry {
namespace {

// A hand-held survey: 30 cameras on a 60 cm arc, each turned a little, looking at 300 points 2-4 m away that
// fill a 640x480 image at f = 525 px (7-Scenes' field of view, 63 degrees across). Observations through
// `truth` (its distortion included) with Gaussian noise of noise_px.
struct Survey {
  PinholeCamera truth;
  std::vector<Pose> cams;
  std::vector<Eigen::Vector3d> pts;
  std::vector<PixelObservation> obs;
  std::vector<bool> fixed;
  Survey(double k1, double noise_px, uint64_t seed) : truth(525, 525, 319.5, 239.5, 640, 480, Distortion{k1}) {
    CounterRng rng(seed, 0);
    for (int i = 0; i < 300; ++i) {
      const double z = rng.Uniform(2.0, 4.0), y = rng.Uniform(-0.45, 0.45) * z, x = rng.Uniform(-0.6, 0.6) * z;
      pts.emplace_back(x, y, z);
    }
    for (int c = 0; c < 30; ++c) {
      const double a = 0.02 * c;
      const Eigen::Vector3d centre(a, 0.1 * std::sin(3 * a), 0.05 * a);
      const Eigen::Quaterniond world_from_cam_q = QuaternionFromRotationVector(Eigen::Vector3d(0.1 * std::sin(5 * a), -0.6 * a, 0.05 * a));
      cams.push_back(Pose(world_from_cam_q, centre).Inverse());
    }
    for (int c = 0; c < 30; ++c)
      for (int i = 0; i < 300; ++i) {
        Eigen::Vector2d uv;
        if (!truth.Project(cams[c] * pts[i], &uv) || !truth.InImage(uv)) continue;
        const double dv = noise_px * rng.Normal(), du = noise_px * rng.Normal();
        obs.push_back({c, i, uv + Eigen::Vector2d(du, dv)});
      }
    fixed.assign(cams.size(), false);
    fixed[0] = fixed[1] = true;  // the gauge and the scale
  }
  PinholeCamera Given(double k1) const {
    PinholeCamera c = truth;
    c.dist.k1 = k1;
    return c;
  }
};

IntrinsicsOptions K1Only() {
  IntrinsicsOptions o;
  o.free_focal = false;
  return o;
}

// A lens with k1 = -0.05 given as distortion-free: the fit finds k1 to within its formal spread, and the change
// is far beyond it (measured -0.0508, sigma 0.0021, 24 sigma). Tolerance: 4 sigma or 0.002, whichever is larger.
TEST(SelfCalibration, FindsTheFirstRadialCoefficientOfAnUndeclaredLens) {
  const Survey s(-0.05, 0.5, 1);
  const IntrinsicsFit fit = RefineIntrinsics(s.Given(0.0), s.cams, s.pts, s.obs, s.fixed, K1Only());
  EXPECT_NEAR(fit.camera.dist.k1, -0.05, std::max(4 * fit.sigma_k1, 0.002));
  EXPECT_NEAR(fit.delta_k1, fit.camera.dist.k1, 1e-15);  // added to the given 0
  EXPECT_EQ(fit.focal_scale, 1.0);                       // held
  // A bundle adjustment with the wrong k1 bends the structure to absorb most of the distortion (rms 0.70 px
  // against 0.68 with k1 free, here): what is left is still 21 formal sigma (the System takes >= 10).
  EXPECT_GT(fit.chi2, 15.0 * 15.0);
  EXPECT_NEAR(fit.sigma_k1, std::abs(fit.delta_k1) / std::sqrt(fit.chi2), 1e-15);
  EXPECT_LT(fit.cost_free, fit.cost_fixed);
  EXPECT_LT(fit.rms_free_px, fit.rms_fixed_px);
  EXPECT_LT(fit.rms_free_px, 0.5 * std::sqrt(2.0) * 1.05);  // the noise, 0.5 px a coordinate, within 5 %
}

// The given camera right: over seeds 1-10 the change stays inside its spread. The likelihood ratio is chi-square
// with one degree of freedom under this white noise (measured sqrt 0.29-1.77 over these seeds); 16 (4 sigma)
// would be passed by chance once in 16,000 fits.
TEST(SelfCalibration, ACorrectCameraStaysWithinItsSpread) {
  for (uint64_t seed = 1; seed <= 10; ++seed) {
    const Survey s(0.02, 0.5, seed);
    const IntrinsicsFit fit = RefineIntrinsics(s.Given(0.02), s.cams, s.pts, s.obs, s.fixed, K1Only());
    EXPECT_LT(fit.chi2, 16.0) << "seed " << seed;
    EXPECT_NEAR(fit.camera.dist.k1, 0.02 + fit.delta_k1, 1e-15);  // the given k1 plus the change
  }
}

// With the focal length free as well, a 5 % wrong focal length and k1 are both found (the survey turns, which
// separates them; a settling window of real tracks does not, so the System keeps the focal length as given).
TEST(SelfCalibration, FindsTheFocalLengthToWhenFreed) {
  const Survey s(-0.05, 0.3, 2);
  PinholeCamera given = s.Given(0.0);
  given.fx *= 1.05, given.fy *= 1.05;
  IntrinsicsOptions o;
  o.max_iterations = 100;
  const IntrinsicsFit fit = RefineIntrinsics(given, s.cams, s.pts, s.obs, s.fixed, o);
  EXPECT_NEAR(fit.camera.fx, 525.0, 0.005 * 525.0);  // measured 1.4 px off (0.26 %): 0.5 % allowed
  EXPECT_NEAR(fit.camera.fy / fit.camera.fx, 1.0, 1e-12);  // one scale for both
  EXPECT_NEAR(fit.camera.dist.k1, -0.05, 0.003);
  EXPECT_GT(fit.chi2, 100.0);
  EXPECT_EQ(fit.sigma_k1, 0.0);  // not one number when two intrinsics moved
}

TEST(SelfCalibration, RefusesBadInputNamingIt) {
  const Survey s(0.0, 0.5, 3);
  IntrinsicsOptions o;
  o.loss_px = 0;
  EXPECT_THROW(
      try { RefineIntrinsics(s.truth, s.cams, s.pts, s.obs, s.fixed, o); } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("loss_px"), std::string::npos) << e.what();
        throw;
      },
      std::invalid_argument);
  std::vector<PixelObservation> bad = s.obs;
  bad.back().point = static_cast<int>(s.pts.size());
  EXPECT_THROW(RefineIntrinsics(s.truth, s.cams, s.pts, bad, s.fixed, K1Only()), std::invalid_argument);
  EXPECT_THROW(RefineIntrinsics(s.truth, s.cams, s.pts, s.obs, std::vector<bool>(3, true), K1Only()),
               std::invalid_argument);
  // Nothing to measure the camera by (no observation, or every point behind its camera): the camera as given.
  const PinholeCamera given = s.Given(0.01);
  for (const bool behind : {false, true}) {
    std::vector<Eigen::Vector3d> pts = s.pts;
    if (behind)
      for (Eigen::Vector3d& p : pts) p.z() = -p.z();
    const IntrinsicsFit fit =
        RefineIntrinsics(given, s.cams, pts, behind ? s.obs : std::vector<PixelObservation>{}, s.fixed, K1Only());
    EXPECT_EQ(fit.camera.dist.k1, 0.01);
    EXPECT_EQ(fit.chi2, 0.0);
    EXPECT_EQ(fit.observations, 0);
  }
}

}  // namespace
}  // namespace mcslam::geometry
