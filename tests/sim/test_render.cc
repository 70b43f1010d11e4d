#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include "sim/paper_scenario.h"
#include "sim/render.h"

namespace mcslam::sim {
namespace {

TEST(Render, BoxIsWhereItProjectsTexturedAndDeterministic) {
  PaperScenarioOptions so;
  so.frames = 1;
  const SyntheticSequence seq = MakePaperScenario(so);
  RenderOptions ro;
  ro.image_noise = 0.0;
  const SceneRenderer renderer(ro);
  const cv::Mat img = renderer.Render(seq.camera, seq.cam_from_world[0], 0);
  ASSERT_EQ(img.cols, 320);
  ASSERT_EQ(img.rows, 240);
  ASSERT_EQ(img.type(), CV_8U);
  // The box centre projects inside the image; around it the texture varies (a textured face, not the flat
  // background of 0.35 * 255 = 89).
  Eigen::Vector2d c;
  ASSERT_TRUE(seq.camera.ProjectWorld(seq.cam_from_world[0], Eigen::Vector3d::Zero(), &c));
  const cv::Rect patch(static_cast<int>(c.x()) - 20, static_cast<int>(c.y()) - 20, 40, 40);
  cv::Scalar mean, stddev;
  cv::meanStdDev(img(patch), mean, stddev);
  EXPECT_GT(stddev[0], 15.0);  // random blobs of grey levels 0..1 at 85 % contrast: tens of grey levels
  // Same options, same image; another seed, another texture.
  EXPECT_EQ(cv::norm(img, renderer.Render(seq.camera, seq.cam_from_world[0], 0), cv::NORM_INF), 0.0);
  RenderOptions other = ro;
  other.seed = 2;
  EXPECT_GT(cv::norm(img, SceneRenderer(other).Render(seq.camera, seq.cam_from_world[0], 0), cv::NORM_L1), 0.0);
  RenderOptions bad;
  bad.supersample = 0;
  EXPECT_THROW(bad.Check(), std::invalid_argument);
}

}  // namespace
}  // namespace mcslam::sim
