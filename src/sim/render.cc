#include "sim/render.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <optional>
#include <stdexcept>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/random.h"

namespace mcslam::sim {

void RenderOptions::Check() const {
  if (supersample < 1 || supersample > 8)
    throw std::invalid_argument(fmt::format("render: supersample must be in [1, 8], got {}", supersample));
  if (!(image_noise >= 0)) throw std::invalid_argument(fmt::format("render: image_noise must be >= 0, got {}", image_noise));
  if (!(floor_half_size_m > 0))
    throw std::invalid_argument(fmt::format("render: floor_half_size_m must be > 0, got {}", floor_half_size_m));
}

namespace {

constexpr int kTextureSize = 512;

// High-contrast random blobs and bars: many corners at several scales, like a printed poster.
cv::Mat MakeTexture(uint64_t seed, uint32_t stream) {
  CounterRng rng(seed, stream);
  cv::Mat t(kTextureSize, kTextureSize, CV_32F, cv::Scalar(0.5));
  for (int i = 0; i < 140; ++i) {
    const cv::Point c(static_cast<int>(rng.Below(kTextureSize)), static_cast<int>(rng.Below(kTextureSize)));
    const int r = 6 + static_cast<int>(rng.Below(40));
    const double v = rng.Uniform(0.0, 1.0);
    if (rng.Below(2) == 0)
      cv::circle(t, c, r, cv::Scalar(v), cv::FILLED, cv::LINE_AA);
    else
      cv::rectangle(t, c, c + cv::Point(r, static_cast<int>(r * rng.Uniform(0.3, 1.5))), cv::Scalar(v), cv::FILLED,
                    cv::LINE_AA);
  }
  cv::GaussianBlur(t, t, cv::Size(0, 0), 1.2);
  return t;
}

float Bilinear(const cv::Mat& t, double u01, double v01) {
  const double x = std::clamp(u01, 0.0, 1.0) * (t.cols - 1), y = std::clamp(v01, 0.0, 1.0) * (t.rows - 1);
  const int x0 = std::min(static_cast<int>(x), t.cols - 2), y0 = std::min(static_cast<int>(y), t.rows - 2);
  const float fx = static_cast<float>(x - x0), fy = static_cast<float>(y - y0);
  const float* r0 = t.ptr<float>(y0);
  const float* r1 = t.ptr<float>(y0 + 1);
  return (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
}

}  // namespace

SceneRenderer::SceneRenderer(const RenderOptions& options) : options_(options) {
  options_.Check();
  for (int i = 0; i < 7; ++i) textures_[i] = MakeTexture(options_.seed, 100 + i);
}

std::optional<SceneRenderer::Hit> SceneRenderer::Trace(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const {
  // The box (centred at the origin, kPaperBoxSizeM), by the slab method.
  const Eigen::Vector3d h(kPaperBoxSizeM[0] / 2, kPaperBoxSizeM[1] / 2, kPaperBoxSizeM[2] / 2);
  double t_near = -std::numeric_limits<double>::infinity(), t_far = std::numeric_limits<double>::infinity();
  int axis = -1;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(d[k]) < 1e-12) {
      if (o[k] < -h[k] || o[k] > h[k]) t_near = std::numeric_limits<double>::infinity();
      continue;
    }
    double a = (-h[k] - o[k]) / d[k], b = (h[k] - o[k]) / d[k];
    if (a > b) std::swap(a, b);
    if (a > t_near) t_near = a, axis = k;
    t_far = std::min(t_far, b);
  }
  if (axis >= 0 && t_near <= t_far && t_near > 0) {
    const Eigen::Vector3d p = o + t_near * d;
    const int face = 2 * axis + (d[axis] < 0 ? 1 : 0);  // entering through +face when moving towards -axis
    const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
    return Hit{p, face, (p[a1] + h[a1]) / (2 * h[a1]), (p[a2] + h[a2]) / (2 * h[a2])};
  }
  // The floor under the box (z = -h.z), a square of floor_half_size_m.
  if (d.z() < -1e-9) {
    const double t = (-h.z() - o.z()) / d.z();
    const Eigen::Vector3d p = o + t * d;
    const double s = options_.floor_half_size_m;
    if (t > 0 && std::abs(p.x()) < s && std::abs(p.y()) < s) return Hit{p, 6, (p.x() + s) / (2 * s), (p.y() + s) / (2 * s)};
  }
  return std::nullopt;
}

float SceneRenderer::Shade(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const {
  // Fixed light: faces differ in brightness, so box edges are visible; the floor is darker.
  static const float kLight[7] = {0.75f, 0.9f, 0.8f, 0.95f, 0.6f, 1.0f, 0.7f};
  const std::optional<Hit> hit = Trace(o, d);
  if (!hit) return 0.35f;  // background
  return kLight[hit->surface] * (0.15f + 0.85f * Bilinear(textures_[hit->surface], hit->u, hit->v));
}

std::optional<SceneRenderer::Hit> SceneRenderer::SurfacePoint(const PinholeCamera& camera, const Pose& cam_from_world,
                                                               const Eigen::Vector2d& uv_px) const {
  const Pose world_from_cam = cam_from_world.Inverse();
  return Trace(world_from_cam.t, (world_from_cam.R() * camera.Unproject(uv_px)).normalized());
}

cv::Mat SceneRenderer::Render(const PinholeCamera& camera, const Pose& cam_from_world, uint64_t frame_index) const {
  const Pose world_from_cam = cam_from_world.Inverse();
  const Eigen::Matrix3d R = world_from_cam.R();
  const Eigen::Vector3d o = world_from_cam.t;
  const int n = options_.supersample;
  cv::Mat img(camera.height, camera.width, CV_8U);
  CounterRng noise(options_.seed ^ 0x5eedULL, static_cast<uint32_t>(200 + frame_index));
  for (int y = 0; y < camera.height; ++y) {
    auto* row = img.ptr<uint8_t>(y);
    for (int x = 0; x < camera.width; ++x) {
      float acc = 0;
      for (int sy = 0; sy < n; ++sy)
        for (int sx = 0; sx < n; ++sx) {
          // Sub-pixel sample positions; pixel centres at integer coordinates.
          const Eigen::Vector2d px(x - 0.5 + (sx + 0.5) / n, y - 0.5 + (sy + 0.5) / n);
          const Eigen::Vector3d ray = camera.Unproject(px);
          acc += Shade(o, (R * ray).normalized());
        }
      const double v = 255.0 * acc / (n * n) + options_.image_noise * noise.Normal();
      row[x] = static_cast<uint8_t>(std::clamp(std::lround(v), 0L, 255L));
    }
  }
  return img;
}

void RenderSequence(const SyntheticSequence& seq, const std::string& dir, const RenderOptions& options) {
  const SceneRenderer renderer(options);
  const std::filesystem::path images = std::filesystem::path(dir) / "images";
  std::filesystem::create_directories(images);
  for (size_t i = 0; i < seq.cam_from_world.size(); ++i) {
    const std::string path = (images / fmt::format("{:06d}.png", i)).string();
    if (!cv::imwrite(path, renderer.Render(seq.camera, seq.cam_from_world[i], i)))
      throw std::runtime_error(fmt::format("cannot write '{}'", path));
  }
}

}  // namespace mcslam::sim
