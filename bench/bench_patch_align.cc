// Google Benchmark case for the front end's birth-patch alignment (frontend/patch_align.h; the `anchor` stage of
// docs/timing.md, 9-11 ms a frame on KITTI 06 and 7-Scenes on 2 cores): every track's 21x21 birth patch aligned
// with the next frame from where Lucas-Kanade put it, at most FrontendOptions::anchor_max_iterations. The frame
// is a textured 640x480 image with 1-level noise; the next one sees it through a small affine warp (2 % scale,
// 2 degrees, 3 px) with another gain and bias, and each alignment starts 0.5 px off (LK's error).
// Counters: calls a second, mean iterations a call, and how far the aligned centres land from the truth.
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "core/random.h"
#include "frontend/frontend.h"
#include "frontend/patch_align.h"

namespace {

using mcslam::CounterRng;
using mcslam::frontend::AffinePatch;
const mcslam::frontend::FrontendOptions kOptions;

struct Scene {
  cv::Mat first, next;
  std::vector<cv::Point2f> at, truth;   // patch centres in the first frame, and where they are in the next
  cv::Matx22f linear;                   // the warp's linear part (patch offsets -> next-frame offsets)
};

// A texture of Gaussian blobs 3-9 px wide, evaluated exactly at each pixel of each frame, plus 8-bit noise.
Scene MakeScene() {
  CounterRng rng(11, 3);
  struct Blob { float x, y, s, a; };
  std::vector<Blob> blobs;
  for (int i = 0; i < 2500; ++i)
    blobs.push_back({static_cast<float>(rng.Uniform(-20, 660)), static_cast<float>(rng.Uniform(-20, 500)),
                     static_cast<float>(rng.Uniform(3, 9)), static_cast<float>(rng.Uniform(-70, 70))});
  const float angle = 2.0f * static_cast<float>(CV_PI) / 180.0f, scale = 1.02f;
  Scene s;
  s.linear = cv::Matx22f(scale * std::cos(angle), -scale * std::sin(angle), scale * std::sin(angle),
                         scale * std::cos(angle));
  const cv::Point2f centre(320, 240), shift(3.0f, -2.0f);
  const cv::Matx22f inv = s.linear.inv();
  auto render = [&](bool warped, float gain, float bias) {
    cv::Mat img(480, 640, CV_32F, cv::Scalar(128));
    for (const Blob& b : blobs) {
      const int r = static_cast<int>(std::ceil(3.5f * b.s * scale)) + 4;
      // The blob's centre in this frame, and its extent there.
      cv::Vec2f c(b.x, b.y);
      if (warped)
        c = s.linear * cv::Vec2f(b.x - centre.x, b.y - centre.y) + cv::Vec2f(centre.x + shift.x, centre.y + shift.y);
      for (int y = std::max(0, static_cast<int>(c[1]) - r); y < std::min(480, static_cast<int>(c[1]) + r); ++y)
        for (int x = std::max(0, static_cast<int>(c[0]) - r); x < std::min(640, static_cast<int>(c[0]) + r); ++x) {
          cv::Vec2f o(static_cast<float>(x) - c[0], static_cast<float>(y) - c[1]);
          if (warped) o = inv * o;
          img.at<float>(y, x) += b.a * std::exp(-(o[0] * o[0] + o[1] * o[1]) / (2 * b.s * b.s));
        }
    }
    cv::Mat noise(img.size(), CV_32F);
    for (int y = 0; y < noise.rows; ++y)
      for (int x = 0; x < noise.cols; ++x) noise.at<float>(y, x) = static_cast<float>(rng.Normal());
    cv::Mat out;
    cv::Mat(img * gain + bias + noise).convertTo(out, CV_8U);
    return out;
  };
  s.first = render(false, 1.0f, 0.0f);
  s.next = render(true, 1.1f, -6.0f);
  std::vector<cv::Point2f> corners;
  cv::goodFeaturesToTrack(s.first, corners, 300, 0.01, 10, cv::noArray(), 3);
  for (const cv::Point2f& p : corners) {
    const cv::Vec2f t = s.linear * cv::Vec2f(p.x - centre.x, p.y - centre.y);
    const cv::Point2f q(centre.x + shift.x + t[0], centre.y + shift.y + t[1]);
    if (q.x < 20 || q.y < 20 || q.x > 619 || q.y > 459 || p.x < 20 || p.y < 20 || p.x > 619 || p.y > 459) continue;
    s.at.push_back(p);
    s.truth.push_back(q);
  }
  return s;
}

// Args: the frame's pixels (0: 8-bit; 1: float, as the front end passes them, converted once outside the
// timing), and the stop in thousandths of a pixel (1: FrontendOptions::anchor_epsilon_px's default; 10: a
// looser stop, measured and not taken, see frontend.h).
void BM_AnchorAlign(benchmark::State& state) {
  static const Scene scene = MakeScene();
  static const cv::Mat next_float = [] {
    cv::Mat f;
    scene.next.convertTo(f, CV_32F);
    return f;
  }();
  const cv::Mat& next = state.range(0) ? next_float : scene.next;
  const float epsilon_px = static_cast<float>(state.range(1)) * 1e-3f;
  std::vector<AffinePatch> patches;
  for (const cv::Point2f& p : scene.at) patches.emplace_back(scene.first, p, kOptions.anchor_patch_px);
  long calls = 0, iterations = 0;
  double error = 0;
  for (auto _ : state) {
    for (size_t i = 0; i < patches.size(); ++i) {
      const float a = static_cast<float>(i) * 2.39996f;  // start 0.5 px off, in a direction that turns per patch
      const cv::Point2f start = scene.truth[i] + cv::Point2f(0.5f * std::cos(a), 0.5f * std::sin(a));
      const AffinePatch::Result r =
          patches[i].Align(next, start, cv::Matx22f::eye(), kOptions.anchor_max_iterations, epsilon_px);
      benchmark::DoNotOptimize(r);
      ++calls;
      iterations += r.iterations;
      error += cv::norm(r.centre - scene.truth[i]);
    }
  }
  state.counters["calls/s"] = benchmark::Counter(static_cast<double>(calls), benchmark::Counter::kIsRate);
  state.counters["iterations"] = static_cast<double>(iterations) / static_cast<double>(calls);
  state.counters["error_px"] = error / static_cast<double>(calls);
  state.counters["patches"] = static_cast<double>(patches.size());
}
BENCHMARK(BM_AnchorAlign)->Args({0, 1})->Args({1, 1})->Args({0, 10})->Args({1, 10})->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
