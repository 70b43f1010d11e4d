#include "frontend/image_noise.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <functional>
#include <vector>

#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

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
  // Away from the border, where the filters see the replicated edge. The response computed in bands of rows,
  // each a view into the noise image (its filters read the real rows beyond the band, as over the whole image: the
  // values are the same to the bit), on both cores: small buffers that stay in cache instead of 16 MB of fresh
  // ones (the whole image at once: 78 ms on the development machine, most of it page faults).
  const int margin = block_size + 2;
  const int interior = kSide - 2 * margin;
  // The value exceeded by `fraction` of the n responses is the one of rank k (0-based, ascending): the
  // (n - k)-th largest, found among each band's n - k largest.
  const size_t n = static_cast<size_t>(interior) * static_cast<size_t>(interior);
  const double q = std::clamp(1.0 - fraction, 0.0, 1.0);
  const size_t k = std::min(n - 1, static_cast<size_t>(q * static_cast<double>(n)));
  const size_t keep = n - k;
  constexpr int kBandRows = 64;
  const int bands = (interior + kBandRows - 1) / kBandRows;
  std::vector<std::vector<float>> band_values(static_cast<size_t>(bands));
  tbb::parallel_for(0, bands, [&](int band) {
    const int y0 = margin + band * kBandRows, y1 = std::min(y0 + kBandRows, kSide - margin);
    const int top = std::max(0, y0 - margin), bottom = std::min(kSide, y1 + margin);
    cv::Mat response;
    cv::cornerMinEigenVal(gray.rowRange(top, bottom), response, block_size, 3);
    std::vector<float>& v = band_values[static_cast<size_t>(band)];
    v.reserve(static_cast<size_t>((y1 - y0) * interior));
    for (int y = y0; y < y1; ++y) {
      const float* r = response.ptr<float>(y - top);
      v.insert(v.end(), r + margin, r + kSide - margin);
    }
    if (v.size() > keep) {
      std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(keep), v.end(), std::greater<float>());
      v.resize(keep);
    }
  });
  std::vector<float> largest;
  for (const std::vector<float>& v : band_values) largest.insert(largest.end(), v.begin(), v.end());
  std::nth_element(largest.begin(), largest.begin() + static_cast<std::ptrdiff_t>(keep - 1), largest.end(),
                   std::greater<float>());
  return static_cast<double>(largest[keep - 1]) / (kSigma * kSigma);
}

void CornerResponse(const cv::Mat& gray, int block_size, cv::Mat* response) {
  if (static_cast<int64_t>(gray.total()) < kBandedResponsePixels) {
    cv::cornerMinEigenVal(gray, *response, block_size, 3);
    return;
  }
  response->create(gray.size(), CV_32F);
  const int rows = gray.rows, margin = block_size + 2;
  const int bands = (rows + kResponseBandRows - 1) / kResponseBandRows;
  tbb::parallel_for(0, bands, [&](int band) {
    const int y0 = band * kResponseBandRows, y1 = std::min(rows, y0 + kResponseBandRows);
    const int top = std::max(0, y0 - margin), bottom = std::min(rows, y1 + margin);
    cv::Mat part;
    cv::cornerMinEigenVal(gray.rowRange(top, bottom), part, block_size, 3);
    part.rowRange(y0 - top, y1 - top).copyTo(response->rowRange(y0, y1));
  });
}

}  // namespace mcslam::frontend
