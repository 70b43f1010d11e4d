#pragma once
// Test images with known motion: a smooth random texture (blurred noise) seen through a window that
// moves by a known, possibly sub-pixel, offset. The shift is applied in the frequency domain, which is
// exact for this band-limited texture: OpenCV's cubic resampling (a = -0.75) would shift fine texture by up
// to ~0.04 px more or less than asked, as much as the accuracy the tests check.
#include <cmath>
#include <cstdint>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <utility>

namespace mcslam::testing {

class MovingTexture {
 public:
  // A texture `margin` px larger than the frames on every side; it wraps around (periodic), so shifts up
  // to the margin show texture that was never in the first frame.
  MovingTexture(cv::Size frame_size, uint64_t seed, int margin = 96, double blur_sigma_px = 2.0)
      : size_(frame_size), margin_(margin) {
    cv::RNG rng(seed);
    cv::Mat noise(frame_size.height + 2 * margin, frame_size.width + 2 * margin, CV_32F);
    rng.fill(noise, cv::RNG::UNIFORM, 0.0, 1.0);
    // Blurred in the frequency domain, so that the texture is periodic and smooth across its wrap.
    cv::Mat spectrum;
    cv::dft(noise, spectrum, cv::DFT_COMPLEX_OUTPUT);
    ApplyPerFrequency(spectrum, [&](double fx, double fy) {
      const double g = std::exp(-2.0 * CV_PI * CV_PI * blur_sigma_px * blur_sigma_px * (fx * fx + fy * fy));
      return std::pair{g, 0.0};
    });
    cv::Mat texture = RealPart(spectrum);
    cv::Scalar mean, stddev;
    cv::meanStdDev(texture, mean, stddev);
    // Mean 128, std 45: strong texture that rarely saturates 8 bits.
    texture = (texture - mean[0]) * (45.0 / stddev[0]) + 128.0;
    cv::dft(texture, spectrum_, cv::DFT_COMPLEX_OUTPUT);
  }

  // The frame whose content has moved by (dx, dy) px: frame(x, y) = texture at (x - dx, y - dy).
  cv::Mat Frame(double dx, double dy) const {
    cv::Mat shifted = spectrum_.clone();
    ApplyPerFrequency(shifted, [&](double fx, double fy) {
      const double phase = -2.0 * CV_PI * (fx * dx + fy * dy);
      return std::pair{std::cos(phase), std::sin(phase)};
    });
    const cv::Mat image = RealPart(shifted);
    cv::Mat out8;
    image(cv::Rect(margin_, margin_, size_.width, size_.height)).convertTo(out8, CV_8U);  // rounds, saturates
    return out8;
  }

 private:
  // Multiplies each frequency (fx, fy in cycles per pixel) of a complex spectrum by f(fx, fy) = (re, im).
  template <typename F>
  static void ApplyPerFrequency(cv::Mat& spectrum, F f) {
    const int rows = spectrum.rows, cols = spectrum.cols;
    for (int v = 0; v < rows; ++v) {
      const double fy = (v <= rows / 2 ? v : v - rows) / static_cast<double>(rows);
      auto* row = spectrum.ptr<cv::Vec2f>(v);
      for (int u = 0; u < cols; ++u) {
        const double fx = (u <= cols / 2 ? u : u - cols) / static_cast<double>(cols);
        const auto [c, s] = f(fx, fy);
        const double re = row[u][0], im = row[u][1];
        row[u] = cv::Vec2f(static_cast<float>(re * c - im * s), static_cast<float>(re * s + im * c));
      }
    }
  }
  static cv::Mat RealPart(const cv::Mat& spectrum) {
    cv::Mat complex_image;
    cv::dft(spectrum, complex_image, cv::DFT_INVERSE | cv::DFT_SCALE | cv::DFT_COMPLEX_OUTPUT);
    cv::Mat planes[2];
    cv::split(complex_image, planes);
    return planes[0];
  }

  cv::Size size_;
  int margin_;
  cv::Mat spectrum_;
};

}  // namespace mcslam::testing
