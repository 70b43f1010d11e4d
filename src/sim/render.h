#pragma once
// Images of a synthetic scene (issue #5, generalised for the scenario zoo of issue #16): the scene's textured
// quads (sim/scene.h) ray-cast for each frame's exact pose, so that the whole pipeline, front end included,
// has an end-to-end test with exact ground truth. The paper's scene is the box with a texture on each face,
// standing on a textured floor.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "sim/paper_scenario.h"
#include "sim/scene.h"

namespace mcslam::sim {

struct RenderOptions {
  int supersample = 2;          // rays per pixel along each axis (anti-aliasing)
  // Rays a pixel on an outline (its samples met more than one surface, or a neighbour's met another) is shaded
  // again from, spread over the pixel on a Fibonacci lattice (every ray on a row and a column of its own): the
  // coverage of a sensor's pixel, in steps of 1 / edge_samples. 0: the supersample grid only.
  int edge_samples = 55;
  double image_noise = 1.0;     // Gaussian noise added to the 8-bit image, grey levels (sensor-like), >= 0
  uint64_t seed = 1;            // textures and noise
  // A camera's own photometry, for the front end's tests against it (docs/robustness_photometric.md):
  // - its exposure steps every exposure_period frames through the cycle 1, exposure_step, 1 / exposure_step (an
  //   auto exposure that jumps; the light is scaled before the noise and the 8-bit clip, so a brighter frame
  //   saturates); 1: fixed;
  // - frames blur_every * k + 3 and + 4 (two of every blur_every from the fourth) are blurred by a Gaussian of
  //   blur_sigma_px (a shake, a refocus); 0: sharp.
  double exposure_step = 1.0;
  int exposure_period = 40;
  double blur_sigma_px = 0.0;
  int blur_every = 10;
  // The exposure frame `index` is rendered with, and whether it is blurred.
  double Exposure(uint64_t index) const;
  bool Blurred(uint64_t index) const;
  void Check() const;           // throws std::invalid_argument naming the bad field
};

// A scene's textures, made once from the seed (one per quad, its style and size), and its ray-caster.
class SceneRenderer {
 public:
  // The paper's scene, PaperScene().
  explicit SceneRenderer(const RenderOptions& options);
  SceneRenderer(Scene scene, const RenderOptions& options);
  // 8-bit grey image of the scene seen by `camera` from cam_from_world; frame_index seeds the noise. Rows
  // are shaded in parallel; the noise is drawn in raster order afterwards, so the image does not depend on
  // the number of threads.
  cv::Mat Render(const PinholeCamera& camera, const Pose& cam_from_world, uint64_t frame_index) const;
  struct Hit {
    Eigen::Vector3d point;  // world frame
    int surface = 0;        // the quad's index in the scene (paper: 0-5 the box faces -x, +x, -y, +y, -z, +z;
                            // 6 the floor)
    double u = 0, v = 0;    // texture coordinates in [0, 1]
  };
  // The scene point seen at pixel uv_px (the pixel grid of Render: centres at integers), or nullopt where the
  // ray meets only the background: the exact truth for a feature found in a rendered image.
  std::optional<Hit> SurfacePoint(const PinholeCamera& camera, const Pose& cam_from_world,
                                  const Eigen::Vector2d& uv_px) const;
  const Scene& scene() const { return scene_; }

 private:
  // The grey level (0-1) of a hit under the fixed light. Never inlined: fused into the pixel's sum (an FMA)
  // it rounds differently, and the paper's images must stay bit for bit what they were.
  [[gnu::noinline]] float Shade(const QuadHit& hit) const;

  RenderOptions options_;
  Scene scene_;
  QuadIntersector intersector_;
  std::vector<cv::Mat> textures_;  // CV_32F in [0, 1], one per quad
};

// Writes DIR/images/000000.png ... one per frame of `sequence`, ray-cast from sequence.scene (the layout
// `mcslam run` reads as a synthetic dataset, paired with DIR/groundtruth.txt by index). Frames are rendered
// in parallel. Throws naming a file it cannot write.
void RenderSequence(const SyntheticSequence& sequence, const std::string& dir, const RenderOptions& options);

}  // namespace mcslam::sim
