// The frames' working size (ImageJobOptions::max_megapixels): a frame halved and the camera halved with it.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "apps/image_job.h"
#include "core/camera.h"

namespace mcslam::apps {
namespace {

TEST(HalvedCamera, HalvesWhileOfMorePixelsThanTheLimit) {
  int n = -1;
  const PinholeCamera hd(1400.0, 1400.0, 959.5, 539.5, 1920, 1080);
  PinholeCamera c = HalvedCamera(hd, 1.5, &n);
  EXPECT_EQ(n, 1);
  EXPECT_EQ(c.width, 960);
  EXPECT_EQ(c.height, 540);
  EXPECT_DOUBLE_EQ(c.fx, 700.0);
  EXPECT_DOUBLE_EQ(c.cx, 479.5);  // the image's centre stays its centre
  c = HalvedCamera(hd.Scaled(2.0), 1.5, &n);  // 3840x2160
  EXPECT_EQ(n, 2);
  EXPECT_EQ(c.width, 960);
  const PinholeCamera hd720(900.0, 900.0, 639.5, 479.5, 1280, 960);
  c = HalvedCamera(hd720, 1.5, &n);  // 1.23 Mpx: as it is
  EXPECT_EQ(n, 0);
  EXPECT_EQ(c.width, 1280);
  EXPECT_DOUBLE_EQ(c.fx, 900.0);
  c = HalvedCamera(hd, 0.0, &n);  // 0: never
  EXPECT_EQ(n, 0);
  EXPECT_EQ(c.width, 1920);
  // Odd sizes: the last column and row are left out, the principal point where the 2x2 averages put it.
  const PinholeCamera odd(718.0, 718.0, 607.2, 185.2, 1241, 377);
  c = HalvedCamera(odd, 0.4, &n);  // 0.468 Mpx
  EXPECT_EQ(n, 1);
  EXPECT_EQ(c.width, 620);
  EXPECT_EQ(c.height, 188);
  EXPECT_DOUBLE_EQ(c.cx, 0.5 * (607.2 + 0.5) - 0.5);
  EXPECT_DOUBLE_EQ(c.cy, 0.5 * (185.2 + 0.5) - 0.5);
  // The distortion is in normalised coordinates: it stays.
  PinholeCamera bent = hd;
  bent.dist.k1 = -0.2;
  EXPECT_DOUBLE_EQ(HalvedCamera(bent, 1.5, &n).dist.k1, -0.2);
}

// Points seen by the camera as they come, each a Gaussian blob of intensity centred on its projection, in a frame of
// odd size; the frame halved twice: each blob's intensity centroid (which 2x2 averages keep) is where the halved
// camera projects the point. Float pixels, so that nothing is rounded: 1e-3 px, for the blobs' tails cut at the
// window's edge (their sigma 2.5 px, the window +-16 px).
TEST(Halved, AFrameAndItsCameraAgreeWherePointsProject) {
  const PinholeCamera camera(1100.0, 1090.0, 1001.3, 612.7, 2001, 1203);
  int n = 0;
  const PinholeCamera small = HalvedCamera(camera, 0.2, &n);  // 2.4 Mpx, then 0.6
  ASSERT_EQ(n, 2);
  const std::vector<Eigen::Vector3d> points = {
      {0.0, 0.0, 4.0}, {-1.2, 0.4, 3.0}, {0.9, -0.5, 2.5}, {1.5, 0.8, 5.0}, {-2.0, -1.0, 6.0}};
  cv::Mat frame(camera.height, camera.width, CV_32F, cv::Scalar(0));
  constexpr double kSigma = 2.5;
  constexpr int kReach = 16;
  for (const Eigen::Vector3d& p : points) {
    const Eigen::Vector2d uv(camera.fx * p.x() / p.z() + camera.cx, camera.fy * p.y() / p.z() + camera.cy);
    for (int y = static_cast<int>(uv.y()) - kReach; y <= static_cast<int>(uv.y()) + kReach; ++y)
      for (int x = static_cast<int>(uv.x()) - kReach; x <= static_cast<int>(uv.x()) + kReach; ++x) {
        const double d2 = (x - uv.x()) * (x - uv.x()) + (y - uv.y()) * (y - uv.y());
        frame.at<float>(y, x) += static_cast<float>(std::exp(-0.5 * d2 / (kSigma * kSigma)));
      }
  }
  const cv::Mat half = Halved(frame, n);
  ASSERT_EQ(half.cols, small.width);
  ASSERT_EQ(half.rows, small.height);
  for (const Eigen::Vector3d& p : points) {
    const Eigen::Vector2d uv(small.fx * p.x() / p.z() + small.cx, small.fy * p.y() / p.z() + small.cy);
    double sum = 0, sx = 0, sy = 0;
    for (int y = static_cast<int>(uv.y()) - kReach / 4; y <= static_cast<int>(uv.y()) + kReach / 4; ++y)
      for (int x = static_cast<int>(uv.x()) - kReach / 4; x <= static_cast<int>(uv.x()) + kReach / 4; ++x) {
        const double w = half.at<float>(y, x);
        sum += w, sx += w * x, sy += w * y;
      }
    ASSERT_GT(sum, 0.0);
    EXPECT_NEAR(sx / sum, uv.x(), 1e-3) << p.transpose();
    EXPECT_NEAR(sy / sum, uv.y(), 1e-3) << p.transpose();
  }
}

}  // namespace
}  // namespace mcslam::apps
