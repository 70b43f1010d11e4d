#include "frontend/patch_align.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace mcslam::frontend {

AffinePatch::AffinePatch(const cv::Mat& gray, const cv::Point2f& centre, int side) {
  CV_Assert(gray.type() == CV_8UC1 && side >= 3 && side % 2 == 1);
  const float h = static_cast<float>(side - 1) / 2.0f;
  // The patch with a one-pixel rim for central differences; all of it must be real pixels.
  if (!(centre.x - h - 1 >= 0 && centre.y - h - 1 >= 0 && centre.x + h + 1 <= static_cast<float>(gray.cols - 1) &&
        centre.y + h + 1 <= static_cast<float>(gray.rows - 1)))
    return;
  cv::Mat rim;
  cv::getRectSubPix(gray, cv::Size(side + 2, side + 2), centre, rim, CV_32F);
  const int n = side * side;
  std::vector<float> values(static_cast<size_t>(n));
  std::vector<std::array<float, 6>> descent(static_cast<size_t>(n));
  double sum = 0;
  for (int y = 0; y < side; ++y)
    for (int x = 0; x < side; ++x) {
      const float v = rim.at<float>(y + 1, x + 1);
      values[static_cast<size_t>(y * side + x)] = v;
      sum += v;
    }
  const float mean = static_cast<float>(sum / n);
  double norm2 = 0, sxx = 0, sxy = 0, syy = 0;
  for (int y = 0; y < side; ++y)
    for (int x = 0; x < side; ++x) {
      float& v = values[static_cast<size_t>(y * side + x)];
      v -= mean;
      norm2 += static_cast<double>(v) * v;
      const float gx = 0.5f * (rim.at<float>(y + 1, x + 2) - rim.at<float>(y + 1, x));
      const float gy = 0.5f * (rim.at<float>(y + 2, x + 1) - rim.at<float>(y, x + 1));
      sxx += static_cast<double>(gx) * gx, sxy += static_cast<double>(gx) * gy, syy += static_cast<double>(gy) * gy;
      const float dx = static_cast<float>(x) - h, dy = static_cast<float>(y) - h;
      // d(image position)/d(p) at p = 0 for p = (a11, a12, a21, a22, tx, ty), times the gradient.
      descent[static_cast<size_t>(y * side + x)] = {gx * dx, gx * dy, gy * dx, gy * dy, gx, gy};
    }
  // The error is taken after removing the sampled patch's mean and scaling it to the template's norm, which
  // takes from any change its part along the constant and along the template itself: the steepest-descent
  // images lose those parts too, or the Gauss-Newton step comes out short and the iteration crawls.
  for (int j = 0; j < 6; ++j) {
    double s_mean = 0, s_dot = 0;
    for (int k = 0; k < n; ++k) {
      s_mean += descent[static_cast<size_t>(k)][static_cast<size_t>(j)];
      s_dot += static_cast<double>(descent[static_cast<size_t>(k)][static_cast<size_t>(j)]) * values[static_cast<size_t>(k)];
    }
    s_mean /= n;
    const double along = norm2 > 0 ? s_dot / norm2 : 0.0;
    for (int k = 0; k < n; ++k)
      descent[static_cast<size_t>(k)][static_cast<size_t>(j)] -=
          static_cast<float>(s_mean + along * values[static_cast<size_t>(k)]);
  }
  Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
  for (int k = 0; k < n; ++k) {
    Eigen::Map<const Eigen::Matrix<float, 6, 1>> sd(descent[static_cast<size_t>(k)].data());
    H += (sd * sd.transpose()).cast<double>();
  }
  if (!(norm2 > 1e-6)) return;  // a flat patch: nothing to align
  Eigen::FullPivLU<Eigen::Matrix<double, 6, 6>> lu(H);
  if (!lu.isInvertible()) return;
  // Eigenvalues of [[sxx, sxy], [sxy, syy]].
  const double half_trace = 0.5 * (sxx + syy), root = std::sqrt(0.25 * (sxx - syy) * (sxx - syy) + sxy * sxy);
  const double l_max = half_trace + root, l_min = std::max(0.0, half_trace - root);
  texture_ratio_ = l_max > 0 ? static_cast<float>(l_min / l_max) : 0.0f;
  side_ = side;
  half_ = h;
  values_ = std::move(values);
  norm_ = static_cast<float>(std::sqrt(norm2));
  descent_ = std::move(descent);
  hessian_inv_ = lu.inverse();
}

AffinePatch::Result AffinePatch::Align(const cv::Mat& gray, const cv::Point2f& centre_in, const cv::Matx22f& linear_in,
                                       int max_iterations, float epsilon_px) const {
  CV_Assert(gray.type() == CV_8UC1);
  Result r;
  if (empty()) return r;
  const int n = side_ * side_;
  const float w1 = static_cast<float>(gray.cols - 1), h1 = static_cast<float>(gray.rows - 1);
  const size_t step = gray.step[0];
  const uint8_t* data = gray.data;
  thread_local std::vector<float> sampled;  // one buffer per thread: no allocation per call once grown
  sampled.resize(static_cast<size_t>(n));
  cv::Matx22f L = linear_in;
  cv::Point2f c = centre_in;
  for (int it = 0; it <= max_iterations; ++it) {
    // Sample the image under the warped patch (bilinear); the corners bound every sample.
    for (const float sx : {-half_, half_})
      for (const float sy : {-half_, half_}) {
        const float x = L(0, 0) * sx + L(0, 1) * sy + c.x, y = L(1, 0) * sx + L(1, 1) * sy + c.y;
        if (!(x >= 0 && y >= 0 && x < w1 && y < h1)) {
          r.left_image = it > 0;  // started inside, then an update carried the patch out: no alignment
          return r;
        }
      }
    double sum = 0;
    for (int py = 0; py < side_; ++py) {
      const float dy = static_cast<float>(py) - half_;
      for (int px = 0; px < side_; ++px) {
        const float dx = static_cast<float>(px) - half_;
        const float x = L(0, 0) * dx + L(0, 1) * dy + c.x, y = L(1, 0) * dx + L(1, 1) * dy + c.y;
        // Clamped: the corners bound every sample up to rounding, which must not reach past the last pixel.
        const int x0 = std::min(static_cast<int>(x), gray.cols - 2), y0 = std::min(static_cast<int>(y), gray.rows - 2);
        const float fx = x - static_cast<float>(x0), fy = y - static_cast<float>(y0);
        const uint8_t* p = data + static_cast<size_t>(y0) * step + x0;
        const float v = (1 - fy) * ((1 - fx) * p[0] + fx * p[1]) + fy * ((1 - fx) * p[step] + fx * p[step + 1]);
        sampled[static_cast<size_t>(py * side_ + px)] = v;
        sum += v;
      }
    }
    // Gain and bias: the sampled patch, zero-mean, scaled to the template's norm.
    const float mean = static_cast<float>(sum / n);
    double norm2 = 0, dot = 0;
    for (int k = 0; k < n; ++k) {
      const float v = sampled[static_cast<size_t>(k)] - mean;
      sampled[static_cast<size_t>(k)] = v;
      norm2 += static_cast<double>(v) * v;
      dot += static_cast<double>(v) * values_[static_cast<size_t>(k)];
    }
    const double norm = std::sqrt(norm2);
    r.inside = true;
    r.centre = c;
    r.linear = L;
    r.iterations = it;
    r.correlation = norm > 1e-9 ? static_cast<float>(dot / (norm * norm_)) : 0.0f;
    if (it == max_iterations || norm <= 1e-9) break;
    const float scale = static_cast<float>(norm_ / norm);
    Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
    for (int k = 0; k < n; ++k) {
      const float e = sampled[static_cast<size_t>(k)] * scale - values_[static_cast<size_t>(k)];
      const std::array<float, 6>& s = descent_[static_cast<size_t>(k)];
      for (int j = 0; j < 6; ++j) b[j] += static_cast<double>(s[static_cast<size_t>(j)]) * e;
    }
    const Eigen::Matrix<double, 6, 1> dp = hessian_inv_ * b;
    // Inverse composition: W <- W o W(dp)^-1, W(dp): offset -> (I + D) offset + d.
    const cv::Matx22f IplusD(static_cast<float>(1 + dp[0]), static_cast<float>(dp[1]), static_cast<float>(dp[2]),
                             static_cast<float>(1 + dp[3]));
    const float det = IplusD(0, 0) * IplusD(1, 1) - IplusD(0, 1) * IplusD(1, 0);
    if (!(std::abs(det) > 1e-3f)) break;
    const cv::Matx22f inv = cv::Matx22f(IplusD(1, 1), -IplusD(0, 1), -IplusD(1, 0), IplusD(0, 0)) * (1.0f / det);
    L = L * inv;
    const cv::Vec2f d(static_cast<float>(dp[4]), static_cast<float>(dp[5]));
    const cv::Vec2f shift = L * d;
    c -= cv::Point2f(shift[0], shift[1]);
    // How far the update moved the patch's farthest pixel (a corner): the stopping rule.
    const double moved = std::hypot(dp[4], dp[5]) + half_ * (std::abs(dp[0]) + std::abs(dp[1]) + std::abs(dp[2]) + std::abs(dp[3]));
    if (moved < epsilon_px) {
      // One more sampling pass gives the correlation at the final warp.
      max_iterations = it + 1;
    }
  }
  return r;
}

}  // namespace mcslam::frontend
