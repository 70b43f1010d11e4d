#include <gtest/gtest.h>

#include <cmath>

#include "core/camera.h"

namespace mcslam {
namespace {

PinholeCamera DistortedCamera() {
  // Typical webcam-like lens (magnitudes as in TUM fr1 / OpenCV calibrations).
  return PinholeCamera(517.3, 516.5, 318.6, 255.3, 640, 480, Distortion{0.2624, -0.9531, -0.0054, 0.0026, 1.1633});
}

// A fisheye: TUM-VI's 512x512 camera (the equidistant / Kannala-Brandt model), its image circle ~97 degrees off the
// axis, its corners ~108.
PinholeCamera FisheyeCamera() {
  return PinholeCamera(190.97, 190.97, 254.93, 256.89, 512, 512, Distortion::Equidistant(0.0034, 0.0007, -0.002, 0.0002));
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
  for (const PinholeCamera& cam : {PinholeCamera(500, 500, 160, 120, 320, 240), DistortedCamera(), FisheyeCamera()}) {
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
  for (const PinholeCamera& cam : {DistortedCamera(), FisheyeCamera()})
    for (const Eigen::Vector2d& n : {Eigen::Vector2d(0.31, -0.22), Eigen::Vector2d(1.4, 0.9), Eigen::Vector2d(1e-5, 0)}) {
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
      EXPECT_LT((J - Jn).norm(), 1e-6) << cam.ToString() << " at " << n.transpose();
    }
}

// The equidistant model puts a ray theta off the axis at f * theta_d(theta) from the principal point: 45 degrees
// (n = (1, 0)) with every coefficient 0 lands f * pi / 4 to the right, where a pinhole puts it f * 1.
TEST(Camera, EquidistantLensPutsARayAtItsAngle) {
  PinholeCamera cam(200, 200, 250, 250, 500, 500);
  cam.dist.model = LensModel::kEquidistant;
  EXPECT_TRUE(cam.HasDistortion());
  Eigen::Vector2d uv;
  ASSERT_TRUE(cam.Project(Eigen::Vector3d(1, 0, 1), &uv));
  EXPECT_NEAR(uv.x(), 250 + 200 * M_PI / 4, 1e-9);
  EXPECT_NEAR(uv.y(), 250, 1e-12);
  cam.dist.k1 = 0.1;  // theta_d = theta (1 + 0.1 theta^2)
  ASSERT_TRUE(cam.Project(Eigen::Vector3d(0, 1, 1), &uv));
  EXPECT_NEAR(uv.y(), 250 + 200 * (M_PI / 4) * (1 + 0.1 * M_PI * M_PI / 16), 1e-9);
  // p1, p2 belong to the other model.
  cam.dist.p1 = 0.01;
  EXPECT_THROW(cam.Check(), std::invalid_argument);
}

TEST(Camera, DistortionRoundTripOverTheImage) {
  for (const PinholeCamera& cam : {DistortedCamera(), FisheyeCamera()}) {
  double worst = 0;
  int tried = 0;
  for (int v = 0; v < cam.height; v += 20) {
    for (int u = 0; u < cam.width; u += 20) {
      const Eigen::Vector2d px(u, v);
      // The fisheye sees 195 degrees: its pixels more than 80 degrees off the axis have no ray [x, y, 1] worth
      // the name (UndistortPixel refuses them, kMaxPinholeRayAngleDeg).
      if (cam.dist.IsFisheye() && cam.PixelToNormalized(px).norm() > 80.0 * M_PI / 180.0) continue;
      ++tried;
      const Eigen::Vector3d ray = cam.Unproject(px);
      Eigen::Vector2d back;
      ASSERT_TRUE(cam.Project(ray, &back));
      worst = std::max(worst, (back - px).norm());
    }
  }
  // Gauss-Newton (Newton on theta for the fisheye) converges quadratically; 1e-9 px is far below any use (features
  // are ~0.1 px).
  EXPECT_LT(worst, 1e-9) << cam.ToString();
  EXPECT_GT(tried, 300);
  }
}

// The back end works with pinhole pixels: UndistortPixel gives NaN for a fisheye's pixel whose ray is more than
// kMaxPinholeRayAngleDeg off the axis, and the pinhole pixel of the ray otherwise; a radial-tangential camera's
// pixels all have one.
TEST(Camera, AFisheyesRaysFarOffTheAxisHaveNoPinholePixel) {
  const PinholeCamera fisheye = FisheyeCamera();
  int beyond = 0, within = 0;
  for (int i = 0; i < fisheye.width * fisheye.height; i += 7) {  // the corners are ~108 degrees off the axis
    const Eigen::Vector2d px(i % fisheye.width, i / fisheye.width);
    const Eigen::Vector2d n = fisheye.Undistort(fisheye.PixelToNormalized(px));
    const double angle_deg = std::atan(n.norm()) * 180.0 / M_PI;
    const Eigen::Vector2d pinhole = fisheye.UndistortPixel(px);
    if (std::abs(angle_deg - PinholeCamera::kMaxPinholeRayAngleDeg) < 1e-6) continue;  // the cut itself
    if (angle_deg > PinholeCamera::kMaxPinholeRayAngleDeg) {
      EXPECT_FALSE(pinhole.allFinite()) << px.transpose() << " at " << angle_deg << " deg";
      ++beyond;
    } else {
      ASSERT_TRUE(pinhole.allFinite()) << px.transpose() << " at " << angle_deg << " deg";
      // The same ray: the pinhole pixel's normalised coordinates are the ray's (rounding only).
      EXPECT_LT((fisheye.PixelToNormalized(pinhole) - n).norm(), 1e-9 * (1.0 + n.norm()));
      ++within;
    }
  }
  EXPECT_GT(beyond, 1000);  // TUM-VI's image reaches past the cut towards its corners
  EXPECT_GT(within, 10000);
  const PinholeCamera radtan = DistortedCamera();
  for (int u = 0; u < radtan.width; u += 4)
    for (int v = 0; v < radtan.height; v += 4) EXPECT_TRUE(radtan.UndistortPixel({u, v}).allFinite()) << u << "," << v;
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
