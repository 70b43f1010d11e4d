#include "frontend/image_noise.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace mcslam::frontend {

float ImageNoiseSigma(const cv::Mat& gray) {
  CV_Assert(gray.type() == CV_8UC1);
  if (gray.rows < 3 || gray.cols < 3) return 0.0f;
  // |mask response| <= 16 * 255.
  std::array<uint32_t, 16 * 255 + 1> histogram{};
  size_t n = 0;
  for (int y = 1; y + 1 < gray.rows; y += 2) {
    const uint8_t *a = gray.ptr<uint8_t>(y - 1), *b = gray.ptr<uint8_t>(y), *c = gray.ptr<uint8_t>(y + 1);
    for (int x = 1; x + 1 < gray.cols; ++x) {
      const int r = a[x - 1] - 2 * a[x] + a[x + 1] - 2 * b[x - 1] + 4 * b[x] - 2 * b[x + 1] + c[x - 1] - 2 * c[x] +
                    c[x + 1];
      ++histogram[static_cast<size_t>(std::abs(r))];
    }
    n += static_cast<size_t>(gray.cols - 2);
  }
  // The upper median: the value of rank n / 2 in sorted order.
  const size_t rank = n / 2;
  size_t below = 0;
  size_t median = 0;
  for (; median < histogram.size(); ++median) {
    below += histogram[median];
    if (below > rank) break;
  }
  return static_cast<float>(static_cast<double>(median)) / (0.6745f * 6.0f);
}

double NoiseCornerResponse(int block_size, double fraction) {
  constexpr int kSide = 1024;
  constexpr double kSigma = 8.0;  // large against the 8-bit rounding (its variance 1/12), far from 0 and 255
  cv::Mat noise(kSide, kSide, CV_32F);
  cv::RNG rng(0x5eed);
  rng.fill(noise, cv::RNG::NORMAL, 128.0, kSigma);
  cv::Mat gray;
  noise.convertTo(gray, CV_8U);
  cv::Mat response;
  cv::cornerMinEigenVal(gray, response, block_size, 3);
  // Away from the border, where the filters see the replicated edge.
  const int margin = block_size + 2;
  std::vector<float> values;
  values.reserve(static_cast<size_t>((kSide - 2 * margin) * (kSide - 2 * margin)));
  for (int y = margin; y < kSide - margin; ++y) {
    const float* r = response.ptr<float>(y);
    values.insert(values.end(), r + margin, r + kSide - margin);
  }
  const double q = std::clamp(1.0 - fraction, 0.0, 1.0);
  const size_t k = std::min(values.size() - 1, static_cast<size_t>(q * static_cast<double>(values.size())));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return static_cast<double>(values[k]) / (kSigma * kSigma);
}

}  // namespace mcslam::frontend
