// Google Benchmark case for the front end's per-frame noise measure (frontend/image_noise.h, run on every frame
// since the detection's threshold follows it): Immerkaer's mask over every other row and the median of its
// absolute responses, taken from their histogram. The baseline, measured in the same run, is the same responses
// collected as doubles and their median taken with std::nth_element (how it was first written). Frames: 320x240
// (the paper's), 640x480 (7-Scenes), 1241x376 (KITTI), a seeded noisy texture. Counter `sigma`: both agree.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "frontend/image_noise.h"

namespace {

cv::Mat Frame(int w, int h) {
  cv::Mat f(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      f.at<float>(y, x) = static_cast<float>(128.0 + 60.0 * std::sin(x / 7.0) * std::cos(y / 11.0));
  cv::Mat noise(f.size(), CV_32F);
  cv::RNG rng(3);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, 2.0);
  f += noise;
  cv::Mat g;
  f.convertTo(g, CV_8U);
  return g;
}

float NthElementSigma(const cv::Mat& gray) {
  std::vector<double> response;
  response.reserve(static_cast<size_t>((gray.rows / 2) * gray.cols));
  for (int y = 1; y + 1 < gray.rows; y += 2) {
    const uint8_t *a = gray.ptr<uint8_t>(y - 1), *b = gray.ptr<uint8_t>(y), *c = gray.ptr<uint8_t>(y + 1);
    for (int x = 1; x + 1 < gray.cols; ++x)
      response.push_back(std::abs(static_cast<double>(a[x - 1] - 2 * a[x] + a[x + 1] - 2 * b[x - 1] + 4 * b[x] -
                                                     2 * b[x + 1] + c[x - 1] - 2 * c[x] + c[x + 1])));
  }
  const size_t mid = response.size() / 2;
  std::nth_element(response.begin(), response.begin() + static_cast<std::ptrdiff_t>(mid), response.end());
  return static_cast<float>(response[mid]) / (0.6745f * 6.0f);
}

// Args: width, height, 0 = histogram (the front end's), 1 = nth_element (baseline).
void BM_ImageNoise(benchmark::State& state) {
  const cv::Mat gray = Frame(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  const bool baseline = state.range(2) == 1;
  float sigma = 0;
  for (auto _ : state) {
    sigma = baseline ? NthElementSigma(gray) : mcslam::frontend::ImageNoiseSigma(gray);
    benchmark::DoNotOptimize(sigma);
  }
  state.counters["sigma"] = sigma;
  state.SetLabel(baseline ? "nth_element" : "histogram");
}
BENCHMARK(BM_ImageNoise)
    ->Args({320, 240, 0})->Args({320, 240, 1})
    ->Args({640, 480, 0})->Args({640, 480, 1})
    ->Args({1241, 376, 0})->Args({1241, 376, 1})
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
