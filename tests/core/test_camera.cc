#include <gtest/gtest.h>

#include "core/camera.h"

namespace mcslam {
namespace {

PinholeCamera DistortedCamera() {
  // Typical webcam-like lens (magnitudes as in TUM fr1 / OpenCV calibrations).
  return PinholeCamera(517.3, 516.5, 318.6, 255.3, 640, 480, Distortion{0.2624, -0.9531, -0.0054, 0.0026, 1.1633});
}

// Central differences with step h have truncation error O(h^2 * f''') ~ 1e-8 relative for these
// smooth maps at h = 1e-6 and rounding error ~1e-16/1e-6 = 1e-10: a relative tolerance of 1e-6 is ample.
template <typename F>
Eigen::Matrix<double, 2, 3> NumericJacobian(F f, const Eigen::Vector3d& x) {
  Eigen::Matrix<double, 2, 3> J;
  for (int i = 0; i < 3; ++i) {
    const double h = 1e-6 * std::max(1.0, std::abs(x[i]));
    Eigen::Vector3d a = x, b = x;
    a[i] += h;
    b[i] -= h;
    J.col(i) = (f(a) - f(b)) / (2 * h);
  }
  return J;
}

TEST(Camera, ProjectJacobianMatchesFiniteDifferences) {
  for (const PinholeCamera& cam : {PinholeCamera(500, 500, 160, 120, 320, 240), DistortedCamera()}) {
    for (const Eigen::Vector3d& p : {Eigen::Vector3d(0.1, -0.2, 2.0), Eigen::Vector3d(-0.5, 0.3, 1.2),
                                     Eigen::Vector3d(0.0, 0.0, 3.0)}) {
      Eigen::Vector2d uv;
      Eigen::Matrix<double, 2, 3> J;
      ASSERT_TRUE(cam.Project(p, &uv, &J));
      auto f = [&](const Eigen::Vector3d& x) {
        Eigen::Vector2d out;
        cam.Project(x, &out);
        return out;
      };
      const Eigen::Matrix<double, 2, 3> Jn = NumericJacobian(f, p);
      EXPECT_LT((J - Jn).norm(), 1e-6 * Jn.norm()) << "J=\n" << J << "\nJn=\n" << Jn;
    }
  }
}

TEST(Camera, WorldAndTranslationJacobiansMatchFiniteDifferences) {
  const PinholeCamera cam = DistortedCamera();
  const Pose cam_from_world(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized())),
                            Eigen::Vector3d(0.1, -0.2, 2.5));
  const Eigen::Vector3d point_in_world(0.2, 0.1, 0.3);
  Eigen::Vector2d uv;
  Eigen::Matrix<double, 2, 3> Jw, Jt;
  ASSERT_TRUE(cam.ProjectWorld(cam_from_world, point_in_world, &uv, &Jw, &Jt));
  auto f_world = [&](const Eigen::Vector3d& x) {
    Eigen::Vector2d out;
    cam.ProjectWorld(cam_from_world, x, &out);
    return out;
  };
  auto f_trans = [&](const Eigen::Vector3d& t) {
    Pose p = cam_from_world;
    p.t = t;
    Eigen::Vector2d out;
    cam.ProjectWorld(p, point_in_world, &out);
    return out;
  };
  const auto Jwn = NumericJacobian(f_world, point_in_world);
  const auto Jtn = NumericJacobian(f_trans, cam_from_world.t);
  EXPECT_LT((Jw - Jwn).norm(), 1e-6 * Jwn.norm());
  EXPECT_LT((Jt - Jtn).norm(), 1e-6 * Jtn.norm());
}

TEST(Camera, DistortionJacobianMatchesFiniteDifferences) {
  const PinholeCamera cam = DistortedCamera();
  const Eigen::Vector2d n(0.31, -0.22);
  Eigen::Matrix2d J;
  cam.Distort(n, &J);
  const double h = 1e-7;
  Eigen::Matrix2d Jn;
  for (int i = 0; i < 2; ++i) {
    Eigen::Vector2d a = n, b = n;
    a[i] += h;
    b[i] -= h;
    Jn.col(i) = (cam.Distort(a) - cam.Distort(b)) / (2 * h);
  }
  EXPECT_LT((J - Jn).norm(), 1e-6);
}

TEST(Camera, DistortionRoundTripOverTheImage) {
  const PinholeCamera cam = DistortedCamera();
  double worst = 0;
  for (int v = 0; v < cam.height; v += 20) {
    for (int u = 0; u < cam.width; u += 20) {
      const Eigen::Vector2d px(u, v);
      const Eigen::Vector3d ray = cam.Unproject(px);
      Eigen::Vector2d back;
      ASSERT_TRUE(cam.Project(ray, &back));
      worst = std::max(worst, (back - px).norm());
    }
  }
  // Gauss-Newton converges quadratically; 1e-9 px is far below any use (features are ~0.1 px).
  EXPECT_LT(worst, 1e-9);
}

TEST(Camera, PixelNormalizedRoundTripAndBehindCamera) {
  const PinholeCamera cam(500, 480, 160, 120, 320, 240);
  const Eigen::Vector2d px(12.5, 200.25);
  EXPECT_LT((cam.NormalizedToPixel(cam.PixelToNormalized(px)) - px).norm(), 1e-12);
  Eigen::Vector2d uv(-1, -1);
  EXPECT_FALSE(cam.Project(Eigen::Vector3d(0, 0, -1), &uv));
  EXPECT_EQ(uv, Eigen::Vector2d(-1, -1));
  EXPECT_TRUE(cam.InImage({0, 0}));
  EXPECT_FALSE(cam.InImage({319.5, 10}));
}

TEST(Camera, CheckRejectsBadValues) {
  EXPECT_THROW(PinholeCamera(0, 500, 160, 120, 320, 240).Check(), std::invalid_argument);
  EXPECT_THROW(PinholeCamera(500, 500, 160, 120, 0, 240).Check(), std::invalid_argument);
  EXPECT_THROW(PinholeCamera(500, std::nan(""), 160, 120, 320, 240).Check(), std::invalid_argument);
  EXPECT_NO_THROW(DistortedCamera().Check());
}

}  // namespace
}  // namespace mcslam
