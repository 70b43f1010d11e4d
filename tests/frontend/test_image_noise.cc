// The image-noise measure and the Shi-Tomasi response of pure noise (frontend/image_noise.h).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "frontend/image_noise.h"

namespace mcslam::frontend {
namespace {

// A smooth scene (a ramp and a slow sinusoid: what the Laplacian-of-differences mask is blind to) with seeded
// Gaussian noise of `sigma` grey levels, rounded to 8 bits.
cv::Mat NoisyRamp(double sigma, uint64_t seed) {
  cv::Mat f(240, 320, CV_32F);
  for (int y = 0; y < f.rows; ++y)
    for (int x = 0; x < f.cols; ++x)
      f.at<float>(y, x) = static_cast<float>(60.0 + 0.3 * x + 0.2 * y + 20.0 * std::sin(x / 25.0));
  cv::Mat noise(f.size(), CV_32F);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, sigma);
  f += noise;
  cv::Mat g;
  f.convertTo(g, CV_8U);
  return g;
}

// Immerkaer's estimator on a smooth scene: the noise comes back within 0.3 grey levels plus 5 % (the median of
// integer responses moves in steps of 1 / (0.6745 * 6) = 0.25 grey levels; the 8-bit rounding adds 0.29 in
// quadrature, which matters only at sigma 1). Over 5 seeds.
TEST(ImageNoise, MeasuresTheAddedNoiseOnASmoothScene) {
  for (double sigma : {1.0, 3.0, 8.0})
    for (uint64_t seed = 1; seed <= 5; ++seed) {
      const double expected = std::sqrt(sigma * sigma + 1.0 / 12.0);
      EXPECT_NEAR(ImageNoiseSigma(NoisyRamp(sigma, seed)), expected, 0.3 + 0.05 * expected)
          << "sigma " << sigma << " seed " << seed;
    }
}

// Sharp edges are a small part of an image: the median ignores them, where a mean of the responses would not.
TEST(ImageNoise, EdgesDoNotCountAsNoise) {
  cv::Mat g(240, 320, CV_8U, cv::Scalar(40));
  for (int x = 0; x < 320; x += 40) cv::rectangle(g, cv::Rect(x, 0, 20, 240), cv::Scalar(200), cv::FILLED);
  EXPECT_EQ(ImageNoiseSigma(g), 0.0f);
  EXPECT_EQ(ImageNoiseSigma(cv::Mat(2, 2, CV_8U, cv::Scalar(1))), 0.0f);  // too small for the mask
}

// The response that noise of sigma 1 exceeds at a given fraction of the pixels scales with sigma^2: on a fresh
// noise image (another seed) of sigma 5, the pixels above 25 times the one-in-1000 response are about one in 1000.
// Bounds: a factor of 2 either way (neighbouring responses share their pixels, so the count varies more than a
// Poisson count of ~230 would).
TEST(ImageNoise, NoiseCornerResponseScalesWithTheVariance) {
  const double unit = NoiseCornerResponse(3, 1e-3);
  ASSERT_GT(unit, 0.0);
  cv::Mat f(512, 512, CV_32F);
  cv::RNG rng(99);
  rng.fill(f, cv::RNG::NORMAL, 128.0, 5.0);
  cv::Mat g, response;
  f.convertTo(g, CV_8U);
  cv::cornerMinEigenVal(g, response, 3, 3);
  const cv::Mat inner = response(cv::Rect(5, 5, 502, 502));
  const double above = cv::countNonZero(inner > unit * 25.0) / static_cast<double>(inner.total());
  EXPECT_GT(above, 0.5e-3);
  EXPECT_LT(above, 2e-3);
  // A rarer response is a larger one.
  EXPECT_GT(NoiseCornerResponse(3, 1e-5), 1.5 * unit);
}

// The response is computed in bands of rows on both cores and ranked among each band's largest: the same value, to
// the bit, as the whole noise image's response ranked at once (the measurement as first written), for several
// windows and fractions. Exact: the bands are views into one image, so their filters see the same pixels.
TEST(ImageNoise, NoiseCornerResponseIsTheWholeImagesQuantile) {
  cv::Mat noise(1024, 1024, CV_32F);
  cv::RNG rng(0x5eed);  // the measurement's own noise image
  rng.fill(noise, cv::RNG::NORMAL, 128.0, 8.0);
  cv::Mat gray;
  noise.convertTo(gray, CV_8U);
  for (int block : {3, 5, 7}) {
    cv::Mat response;
    cv::cornerMinEigenVal(gray, response, block, 3);
    const int margin = block + 2;
    std::vector<float> values;
    for (int y = margin; y < 1024 - margin; ++y)
      values.insert(values.end(), response.ptr<float>(y) + margin, response.ptr<float>(y) + 1024 - margin);
    for (double fraction : {0.0, 1e-5, 1e-3, 0.5, 1.0}) {
      const size_t k = std::min(values.size() - 1, static_cast<size_t>((1.0 - fraction) * static_cast<double>(values.size())));
      std::vector<float> sorted = values;
      std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(k), sorted.end());
      EXPECT_EQ(NoiseCornerResponse(block, fraction), static_cast<double>(sorted[k]) / 64.0)
          << "block " << block << " fraction " << fraction;
    }
  }
}

// The corner response: a small image as cv::cornerMinEigenVal gives it, to the bit; a large one done in bands the
// same up to the float rounding of the box sums that restart at each band (measured at most 4e-11 of the largest
// response at 1920x1440; bound 1e-9 of it, 25x that), and the same to the bit from run to run. A textured image with
// noise so that the response varies everywhere; block sizes 3 and 5 (the front end's default and a larger one).
TEST(CornerResponse, BandsGiveTheWholeImagesResponse) {
  for (const cv::Size size : {cv::Size(320, 240), cv::Size(1600, 1200)}) {
    cv::Mat g(size, CV_8U);
    cv::RNG rng(7);
    rng.fill(g, cv::RNG::UNIFORM, 0, 256);
    cv::GaussianBlur(g, g, cv::Size(0, 0), 2.0);
    for (const int block : {3, 5}) {
      cv::Mat whole, banded, again;
      cv::cornerMinEigenVal(g, whole, block, 3);
      CornerResponse(g, block, &banded);
      CornerResponse(g, block, &again);
      ASSERT_EQ(banded.size(), g.size());
      ASSERT_EQ(banded.type(), CV_32F);
      double largest = 0;
      cv::minMaxLoc(whole, nullptr, &largest);
      const double diff = cv::norm(whole, banded, cv::NORM_INF);
      if (static_cast<int64_t>(g.total()) < kBandedResponsePixels) {
        EXPECT_EQ(diff, 0.0) << size << " block " << block;
      } else {
        EXPECT_LE(diff, 1e-9 * largest) << size << " block " << block;
      }
      EXPECT_EQ(cv::norm(banded, again, cv::NORM_INF), 0.0) << size << " block " << block;
    }
  }
}

}  // namespace
}  // namespace mcslam::frontend
