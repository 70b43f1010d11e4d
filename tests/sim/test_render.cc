#include <algorithm>
#include <cmath>
#include <cstdio>

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

// An outline at a shallow angle, rendered without noise: in every column the pixels' coverage by the surface
// below it sums to where the outline crosses that column, as a sensor's pixels integrate the light. A 2 x 2 grid
// of rays alone gets that wrong by up to a quarter of a pixel, in steps (a staircase whose steps are corners that
// slide along the outline as the view changes); the outline's pixels shaded again from
// RenderOptions::edge_samples rays get it to within the lattice's 1/55 px plus the 8-bit rounding (measured:
// 0.022 px at most over the 200 columns; 0.24 px on the grid alone). Bound 0.04 px: a sixth of the grid's
// error, 1.8 times the error measured (the geometry is exact and noise-free: no seed, and a vector width changes
// only the last bits of a ray).
TEST(Render, AnOutlineCoversItsPixelsAsASensorIntegratesThem) {
  // The plane z = 2 m facing the camera at the origin; the quad's top edge rises 1 in 40 across the image.
  constexpr double kZ = 2.0, kSlope = 0.025, kF = 500;
  const PinholeCamera camera(kF, kF, 159.5, 119.5, 320, 240);
  const double y0 = (100.0 - 119.5) * kZ / kF;  // the edge's y at x = 0: image row 100 at the centre column
  Scene scene;
  scene.quads.push_back(MakeQuad(Eigen::Vector3d(-1.0, y0 - kSlope, kZ), Eigen::Vector3d(2.0, 2.0 * kSlope, 0),
                                 Eigen::Vector3d(-2.0 * kSlope, 2.0, 0), -Eigen::Vector3d::UnitZ(),
                                 TextureStyle::kSmooth, 64));
  // The background black in one image and white in another: a pixel's coverage by the quad is then what the two
  // share, whatever the quad's texture there (I = c S + (1 - c) B, so 1 - c = (I_white - I_black) / 255).
  const auto worst_error_px = [&](int edge_samples) {
    RenderOptions ro;
    ro.image_noise = 0.0;
    ro.edge_samples = edge_samples;
    Scene black = scene, white = scene;
    black.background = 0.0f;
    white.background = 1.0f;
    const cv::Mat on_black = SceneRenderer(black, ro).Render(camera, Pose(), 0);
    const cv::Mat on_white = SceneRenderer(white, ro).Render(camera, Pose(), 0);
    double worst = 0;
    for (int u = 60; u < 260; ++u) {
      const double x = (u - camera.cx) * kZ / kF;
      const double v_true = kF * (y0 + kSlope * x) / kZ + camera.cy;
      const int r0 = static_cast<int>(std::lround(v_true)) - 3, r1 = r0 + 6;
      double uncovered = 0;  // rows r0..r1 span [r0 - 0.5, r1 + 0.5); the quad covers them below the edge
      for (int r = r0; r <= r1; ++r)
        uncovered += (on_white.at<uint8_t>(r, u) - on_black.at<uint8_t>(r, u)) / 255.0;
      worst = std::max(worst, std::abs((r0 - 0.5 + uncovered) - v_true));
    }
    return worst;
  };
  const double lattice = worst_error_px(RenderOptions().edge_samples), grid = worst_error_px(0);
  std::printf("[ outline ] worst edge position error: %.4f px with the outline's rays, %.4f px with the grid alone\n",
              lattice, grid);
  EXPECT_LT(lattice, 0.04);
  EXPECT_GT(grid, 0.15);  // the staircase the outline's rays are there to remove (measured: 0.24 px)
}

}  // namespace
}  // namespace mcslam::sim
