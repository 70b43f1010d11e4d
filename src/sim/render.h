#pragma once
// Images of the synthetic scene (issue #5): the paper's box with a texture on each face, standing on a
// textured floor, ray-cast for each frame's exact pose, so that the whole pipeline, front end included,
// has an end-to-end test with exact ground truth.
#include <cstdint>
#include <optional>
#include <string>

#include <opencv2/core.hpp>

#include "sim/paper_scenario.h"

namespace mcslam::sim {

struct RenderOptions {
  int supersample = 2;          // rays per pixel along each axis (anti-aliasing)
  double image_noise = 1.0;     // Gaussian noise added to the 8-bit image, grey levels (sensor-like), >= 0
  double floor_half_size_m = 4.0;  // the floor is a square of this half size under the box
  uint64_t seed = 1;            // textures and noise
  void Check() const;           // throws std::invalid_argument naming the bad field
};

// The scene's textures, made once from the seed (6 box faces and the floor).
class SceneRenderer {
 public:
  explicit SceneRenderer(const RenderOptions& options);
  // 8-bit grey image of the scene seen by `camera` from cam_from_world; frame_index seeds the noise.
  cv::Mat Render(const PinholeCamera& camera, const Pose& cam_from_world, uint64_t frame_index) const;
  struct Hit {
    Eigen::Vector3d point;  // world frame
    int surface = 0;        // 0-5 the box faces -x, +x, -y, +y, -z, +z; 6 the floor
    double u = 0, v = 0;    // texture coordinates in [0, 1]
  };
  // The scene point seen at pixel uv_px (the pixel grid of Render: centres at integers), or nullopt where the
  // ray meets only the background: the exact truth for a feature found in a rendered image.
  std::optional<Hit> SurfacePoint(const PinholeCamera& camera, const Pose& cam_from_world,
                                  const Eigen::Vector2d& uv_px) const;

 private:
  std::optional<Hit> Trace(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir) const;
  float Shade(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir) const;
  RenderOptions options_;
  cv::Mat textures_[7];  // CV_32F in [0, 1]: faces -x, +x, -y, +y, -z, +z, then the floor
};

// Writes DIR/images/000000.png ... one per frame of `sequence` (the layout `mcslam run` reads as a
// synthetic dataset, paired with DIR/groundtruth.txt by index). Throws naming a file it cannot write.
void RenderSequence(const SyntheticSequence& sequence, const std::string& dir, const RenderOptions& options);

}  // namespace mcslam::sim
