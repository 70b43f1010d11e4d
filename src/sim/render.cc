#include "sim/render.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <numeric>
#include <optional>
#include <stdexcept>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "core/random.h"

namespace mcslam::sim {

void RenderOptions::Check() const {
  if (supersample < 1 || supersample > 8)
    throw std::invalid_argument(fmt::format("render: supersample must be in [1, 8], got {}", supersample));
  if (!(image_noise >= 0)) throw std::invalid_argument(fmt::format("render: image_noise must be >= 0, got {}", image_noise));
  if (!(exposure_step > 0) || !std::isfinite(exposure_step))
    throw std::invalid_argument(fmt::format("render: exposure_step must be positive, got {}", exposure_step));
  if (exposure_period < 1)
    throw std::invalid_argument(fmt::format("render: exposure_period must be >= 1, got {}", exposure_period));
  if (!(blur_sigma_px >= 0) || !std::isfinite(blur_sigma_px))
    throw std::invalid_argument(fmt::format("render: blur_sigma_px must be >= 0, got {}", blur_sigma_px));
  if (edge_samples != 0 && edge_samples < 2)
    throw std::invalid_argument(fmt::format("render: edge_samples must be 0 or >= 2, got {}", edge_samples));
  if (blur_every < 5) throw std::invalid_argument(fmt::format("render: blur_every must be >= 5, got {}", blur_every));
}

double RenderOptions::Exposure(uint64_t index) const {
  switch ((index / static_cast<uint64_t>(exposure_period)) % 3) {
    case 1: return exposure_step;
    case 2: return 1.0 / exposure_step;
    default: return 1.0;
  }
}

bool RenderOptions::Blurred(uint64_t index) const {
  const uint64_t k = index % static_cast<uint64_t>(blur_every);
  return blur_sigma_px > 0 && (k == 3 || k == 4);
}

namespace {

// Shapes per 512 x 512 texels (the paper's texture density); larger textures get proportionally more.
constexpr double kShapesPer512Squared = 140;

int ShapeCount(const cv::Mat& t, double per_512_squared) {
  return std::max(1, static_cast<int>(std::lround(per_512_squared * t.cols * t.rows / (512.0 * 512.0))));
}

cv::Point RandomTexel(CounterRng& rng, const cv::Mat& t) {
  // y drawn before x: the order in which GCC evaluated the paper texture's cv::Point(Below(), Below())
  // arguments, which its images (and the demo's figures) depend on.
  const int y = static_cast<int>(rng.Below(static_cast<uint32_t>(t.rows)));
  const int x = static_cast<int>(rng.Below(static_cast<uint32_t>(t.cols)));
  return {x, y};
}

// Filled discs and bars at random texels: radius r_min + [0, r_range) texels, grey in [v_lo, v_hi), a bar's
// height r * [aspect_lo, aspect_hi). The draws per shape (centre, radius, grey, kind, aspect) are in the order
// of the paper's texture, whose images must not change.
struct DiscsAndBars {
  int r_min;
  uint32_t r_range;
  double v_lo, v_hi;
  double aspect_lo, aspect_hi;
};

void Draw(CounterRng& rng, int count, const DiscsAndBars& s, cv::Mat& t) {
  for (int i = 0; i < count; ++i) {
    const cv::Point c = RandomTexel(rng, t);
    const int r = s.r_min + static_cast<int>(rng.Below(s.r_range));
    const double v = rng.Uniform(s.v_lo, s.v_hi);
    if (rng.Below(2) == 0)
      cv::circle(t, c, r, cv::Scalar(v), cv::FILLED, cv::LINE_AA);
    else
      cv::rectangle(t, c, c + cv::Point(r, static_cast<int>(r * rng.Uniform(s.aspect_lo, s.aspect_hi))), cv::Scalar(v),
                    cv::FILLED, cv::LINE_AA);
  }
}

// High-contrast random blobs and bars: many corners at several scales, like a printed poster.
void DrawBlobs(CounterRng& rng, cv::Mat& t) { Draw(rng, ShapeCount(t, kShapesPer512Squared), {6, 40, 0.0, 1.0, 0.3, 1.5}, t); }

// Facades: rectangles of varied size and aspect (windows, signs, bricks) on a wall of random grey, some discs.
void DrawFacade(CounterRng& rng, cv::Mat& t) {
  t.setTo(cv::Scalar(rng.Uniform(0.3, 0.7)));
  const int n = ShapeCount(t, kShapesPer512Squared);
  for (int i = 0; i < n; ++i) {
    const cv::Point c = RandomTexel(rng, t);
    const int w = 5 + static_cast<int>(rng.Below(45));
    const double v = rng.Uniform(0.0, 1.0);
    if (rng.Below(4) == 0)
      cv::circle(t, c, w / 2 + 3, cv::Scalar(v), cv::FILLED, cv::LINE_AA);
    else
      cv::rectangle(t, c, c + cv::Point(w, static_cast<int>(w * rng.Uniform(0.3, 2.0))), cv::Scalar(v), cv::FILLED,
                    cv::LINE_AA);
  }
}

// Asphalt or pavement: many small speckles of moderate contrast, and a few bright elongated marks.
void DrawGround(CounterRng& rng, cv::Mat& t) {
  Draw(rng, ShapeCount(t, 4 * kShapesPer512Squared), {2, 12, 0.2, 0.8, 0.5, 2.0}, t);
  const int marks = ShapeCount(t, kShapesPer512Squared / 10);
  for (int i = 0; i < marks; ++i) {
    const cv::Point c = RandomTexel(rng, t);
    const int len = 20 + static_cast<int>(rng.Below(40));
    cv::rectangle(t, c, c + cv::Point(len / 6, len), cv::Scalar(0.9), cv::FILLED, cv::LINE_AA);
  }
}

// Low texture: a smooth, low-contrast shading (a few wide soft discs, heavily blurred: no corner there) and a
// handful of distinct dark or bright blobs, the only places a corner detector responds to.
void DrawSmooth(CounterRng& rng, cv::Mat& t) {
  const int side = std::min(t.cols, t.rows);
  for (int i = 0; i < 6; ++i) {
    const cv::Point c = RandomTexel(rng, t);
    // Grey drawn before radius: the order in which GCC evaluated these two as cv::circle's arguments.
    const double grey = rng.Uniform(0.42, 0.58);
    const int radius = side / 6 + static_cast<int>(rng.Below(static_cast<uint32_t>(side / 4 + 1)));
    cv::circle(t, c, radius, cv::Scalar(grey), cv::FILLED, cv::LINE_AA);
  }
  cv::GaussianBlur(t, t, cv::Size(0, 0), std::max(2.0, side / 12.0));
  const int blobs = 1 + static_cast<int>(rng.Below(3));
  for (int i = 0; i < blobs; ++i) {
    const cv::Point c = RandomTexel(rng, t);
    const int r = side / 40 + 4 + static_cast<int>(rng.Below(static_cast<uint32_t>(side / 30 + 1)));
    cv::circle(t, c, r, cv::Scalar(rng.Below(2) == 0 ? 0.1 : 0.9), cv::FILLED, cv::LINE_AA);
  }
}

cv::Mat MakeTexture(const Quad& quad, uint64_t seed, uint32_t stream) {
  CounterRng rng(seed, stream);
  cv::Mat t(quad.texture_rows, quad.texture_cols, CV_32F, cv::Scalar(0.5));
  switch (quad.style) {
    case TextureStyle::kBlobs: DrawBlobs(rng, t); break;
    case TextureStyle::kFacade: DrawFacade(rng, t); break;
    case TextureStyle::kGround: DrawGround(rng, t); break;
    case TextureStyle::kSmooth: DrawSmooth(rng, t); break;
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

// The pixel rectangle (inclusive) a quad can cover in the image: its corners in the camera frame, clipped to
// the part in front of the camera (a wall beside a car reaches behind it), projected; widened by two pixels
// for the sub-pixel samples and rounding. Empty (x0 > x1) when the quad is wholly behind the camera.
struct PixelRect {
  int x0 = 1, x1 = 0, y0 = 1, y1 = 0;
};

PixelRect ScreenBounds(const PinholeCamera& camera, const Pose& cam_from_world, const Quad& q) {
  constexpr double kNearM = 1e-6;
  const Eigen::Vector3d corners[4] = {cam_from_world * q.At(0, 0), cam_from_world * q.At(1, 0),
                                      cam_from_world * q.At(1, 1), cam_from_world * q.At(0, 1)};
  double u_min = std::numeric_limits<double>::infinity(), u_max = -u_min, v_min = u_min, v_max = -u_min;
  bool any = false;
  const auto add = [&](const Eigen::Vector3d& p) {
    const double u = camera.fx * p.x() / p.z() + camera.cx, v = camera.fy * p.y() / p.z() + camera.cy;
    u_min = std::min(u_min, u), u_max = std::max(u_max, u);
    v_min = std::min(v_min, v), v_max = std::max(v_max, v);
    any = true;
  };
  // Sutherland-Hodgman against the plane z = kNearM: each vertex in front, and each crossing of an edge.
  for (int i = 0; i < 4; ++i) {
    const Eigen::Vector3d& a = corners[i];
    const Eigen::Vector3d& b = corners[(i + 1) % 4];
    if (a.z() >= kNearM) add(a);
    if ((a.z() >= kNearM) != (b.z() >= kNearM)) add(a + (kNearM - a.z()) / (b.z() - a.z()) * (b - a));
  }
  PixelRect r;
  if (!any) return r;
  if (camera.HasDistortion()) return PixelRect{0, camera.width - 1, 0, camera.height - 1};  // bounds are pinhole
  const auto clamp_to = [](double x, int hi) { return static_cast<int>(std::clamp(x, -1.0, static_cast<double>(hi))); };
  r.x0 = clamp_to(std::floor(u_min) - 2, camera.width);
  r.x1 = clamp_to(std::ceil(u_max) + 2, camera.width);
  r.y0 = clamp_to(std::floor(v_min) - 2, camera.height);
  r.y1 = clamp_to(std::ceil(v_max) + 2, camera.height);
  return r;
}

}  // namespace

SceneRenderer::SceneRenderer(const RenderOptions& options) : SceneRenderer(PaperScene(), options) {}

SceneRenderer::SceneRenderer(Scene scene, const RenderOptions& options)
    : options_(options), scene_(std::move(scene)), intersector_(scene_) {
  options_.Check();
  textures_.resize(scene_.quads.size());
  // Streams 100, 101, ...: the paper's seven textures keep the streams they always had.
  tbb::parallel_for(size_t{0}, scene_.quads.size(), [&](size_t i) {
    textures_[i] = MakeTexture(scene_.quads[i], options_.seed, static_cast<uint32_t>(100 + i));
  });
}

std::optional<SceneRenderer::Hit> SceneRenderer::SurfacePoint(const PinholeCamera& camera, const Pose& cam_from_world,
                                                               const Eigen::Vector2d& uv_px) const {
  const Pose world_from_cam = cam_from_world.Inverse();
  const Eigen::Vector3d o = world_from_cam.t, d = (world_from_cam.R() * camera.Unproject(uv_px)).normalized();
  const std::optional<QuadHit> hit = intersector_.Nearest(o, d, 0.0, std::numeric_limits<double>::infinity());
  if (!hit) return std::nullopt;
  return Hit{o + hit->t * d, hit->quad, hit->a, hit->b};
}

float SceneRenderer::Shade(const QuadHit& hit) const {
  if (hit.quad < 0) return scene_.background;
  const auto q = static_cast<size_t>(hit.quad);
  return scene_.quads[q].brightness * (0.15f + 0.85f * Bilinear(textures_[q], hit.a, hit.b));
}

cv::Mat SceneRenderer::Render(const PinholeCamera& camera, const Pose& cam_from_world, uint64_t frame_index) const {
  const Pose world_from_cam = cam_from_world.Inverse();
  const Eigen::Matrix3d R = world_from_cam.R();
  const Eigen::Vector3d o = world_from_cam.t;
  const int n = options_.supersample;

  // Culling: a quad is tried only for the pixels of its screen rectangle, and only when its front faces the
  // camera; a street of a hundred quads then costs a few tests a ray, like the paper's box.
  std::vector<PixelRect> rects(scene_.quads.size());
  std::vector<std::vector<int>> quads_of_row(static_cast<size_t>(camera.height));
  for (size_t q = 0; q < scene_.quads.size(); ++q) {
    const Quad& quad = scene_.quads[q];
    if (quad.normal_in_world.dot(o - quad.corner_in_world) <= 0) continue;
    rects[q] = ScreenBounds(camera, cam_from_world, quad);
    for (int y = std::max(rects[q].y0, 0); y <= std::min(rects[q].y1, camera.height - 1); ++y)
      quads_of_row[static_cast<size_t>(y)].push_back(static_cast<int>(q));
  }

  // The surface a ray through px meets first (quad -1: the background).
  const auto cast = [&](const Eigen::Vector2d& px, int x, int y) {
    const Eigen::Vector3d d = (R * camera.Unproject(px)).normalized();
    QuadHit best, hit;
    best.t = std::numeric_limits<double>::infinity();
    for (const int q : quads_of_row[static_cast<size_t>(y)]) {
      const PixelRect& r = rects[static_cast<size_t>(q)];
      if (x < r.x0 || x > r.x1) continue;
      if (intersector_.Hits(q, o, d, 0.0, best.t, &hit)) best = hit;
    }
    return best;
  };
  cv::Mat shade(camera.height, camera.width, CV_32F);
  // Per pixel the surface all its samples met, or kMixed where they met more than one (an outline).
  constexpr int kMixed = -2;
  cv::Mat surface(camera.height, camera.width, CV_32S);
  tbb::parallel_for(0, camera.height, [&](int y) {
    auto* row = shade.ptr<float>(y);
    auto* met = surface.ptr<int>(y);
    for (int x = 0; x < camera.width; ++x) {
      float acc = 0;
      int first = kMixed - 1;
      for (int sy = 0; sy < n; ++sy)
        for (int sx = 0; sx < n; ++sx) {
          // Sub-pixel sample positions; pixel centres at integer coordinates.
          const QuadHit best = cast(Eigen::Vector2d(x - 0.5 + (sx + 0.5) / n, y - 0.5 + (sy + 0.5) / n), x, y);
          acc += Shade(best);
          first = (first == kMixed - 1 || first == best.quad) ? best.quad : kMixed;
        }
      row[x] = acc;
      met[x] = first;
    }
  });
  // Outline pixels shaded again from edge_samples rays spread over the whole pixel: a sensor integrates the
  // light over its pixel's area, and n x n rays on a grid leave an outline at a shallow angle a staircase of
  // n sample rows, whose steps are corners that slide along the outline as the view changes (the sparse
  // scenario, seed 4: most of the corners on the box's top edge, tracks 1-7 px from any scene point). A
  // pixel is an outline's when its samples met different surfaces, or a 4-neighbour's met another surface.
  if (options_.edge_samples > 0) {
    const int m = options_.edge_samples;
    // A rank-1 lattice of m points with the generator nearest m over the golden ratio that is prime to m (the
    // Fibonacci lattice when m is a Fibonacci number): every sample on a row and a column of its own, so an
    // outline's coverage changes in steps of 1 / m whatever its angle.
    int g = static_cast<int>(std::lround(m / 1.6180339887498949));
    while (std::gcd(g, m) != 1) ++g;
    tbb::parallel_for(0, camera.height, [&](int y) {
      auto* row = shade.ptr<float>(y);
      const auto* met = surface.ptr<int>(y);
      for (int x = 0; x < camera.width; ++x) {
        const int s = met[x];
        bool outline = s == kMixed;
        if (!outline && x > 0) outline = met[x - 1] != s;
        if (!outline && x + 1 < camera.width) outline = met[x + 1] != s;
        if (!outline && y > 0) outline = surface.ptr<int>(y - 1)[x] != s;
        if (!outline && y + 1 < camera.height) outline = surface.ptr<int>(y + 1)[x] != s;
        if (!outline) continue;
        double acc = 0;
        for (int i = 0; i < m; ++i) {
          const double fx = (i + 0.5) / m, fy = (static_cast<double>((static_cast<int64_t>(i) * g) % m) + 0.5) / m;
          acc += Shade(cast(Eigen::Vector2d(x - 0.5 + fx, y - 0.5 + fy), x, y));
        }
        row[x] = static_cast<float>(acc / m * n * n);
      }
    });
  }

  if (options_.Blurred(frame_index)) cv::GaussianBlur(shade, shade, cv::Size(), options_.blur_sigma_px);
  const double exposure = options_.Exposure(frame_index);
  if (exposure != 1.0) shade *= exposure;
  cv::Mat img(camera.height, camera.width, CV_8U);
  CounterRng noise(options_.seed ^ 0x5eedULL, static_cast<uint32_t>(200 + frame_index));
  for (int y = 0; y < camera.height; ++y) {
    const auto* in = shade.ptr<float>(y);
    auto* out = img.ptr<uint8_t>(y);
    for (int x = 0; x < camera.width; ++x) {
      const double v = 255.0 * in[x] / (n * n) + options_.image_noise * noise.Normal();
      out[x] = static_cast<uint8_t>(std::clamp(std::lround(v), 0L, 255L));
    }
  }
  return img;
}

void RenderSequence(const SyntheticSequence& seq, const std::string& dir, const RenderOptions& options) {
  const SceneRenderer renderer(seq.scene, options);
  const std::filesystem::path images = std::filesystem::path(dir) / "images";
  std::filesystem::create_directories(images);
  tbb::parallel_for(size_t{0}, seq.cam_from_world.size(), [&](size_t i) {
    const std::string path = (images / fmt::format("{:06d}.png", i)).string();
    if (!cv::imwrite(path, renderer.Render(seq.camera, seq.cam_from_world[i], i)))
      throw std::runtime_error(fmt::format("cannot write '{}'", path));
  });
}

}  // namespace mcslam::sim
