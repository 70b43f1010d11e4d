#include "frontend/patch_align.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace mcslam::frontend {

float PatchSharpness(const float* v, int side) {
  double sum = 0, sum2 = 0, grad = 0;
  const int n = side * side;
  for (int k = 0; k < n; ++k) sum += v[k], sum2 += static_cast<double>(v[k]) * v[k];
  for (int y = 1; y + 1 < side; ++y)
    for (int x = 1; x + 1 < side; ++x) {
      const double gx = 0.5 * (v[y * side + x + 1] - v[y * side + x - 1]);
      const double gy = 0.5 * (v[(y + 1) * side + x] - v[(y - 1) * side + x]);
      grad += gx * gx + gy * gy;
    }
  const double variance = sum2 / n - (sum / n) * (sum / n);
  const int interior = (side - 2) * (side - 2);
  return variance > 1e-9 && interior > 0 ? static_cast<float>(grad / interior / variance) : 0.0f;
}

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
  sharpness_ = PatchSharpness(values.data(), side);
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
  hessian_inv_ = lu.inverse();
  for (size_t j = 0; j < 6; ++j) {
    descent_[j].resize(static_cast<size_t>(n));
    double dot = 0;
    for (size_t k = 0; k < static_cast<size_t>(n); ++k) {
      descent_[j][k] = descent[k][j];
      dot += static_cast<double>(descent[k][j]) * values_[k];
    }
    descent_dot_values_[j] = dot;
  }
}

namespace {

// Bilinear samples of `image` (8-bit or float pixels, `stride` pixels a row) at x0 + k dx, y0 + k dy for
// k < n, written to `out`; returns their sum. The caller has checked that the row's ends are inside the image;
// clamping keeps rounding from reaching past the last pixel.
template <typename Pixel>
float SampleRow(const Pixel* image, size_t stride, int cols, int rows, float x0, float y0, float dx, float dy, int n,
                float* out) {
  float row = 0;
#pragma omp simd reduction(+ : row)
  for (int k = 0; k < n; ++k) {
    const float x = x0 + static_cast<float>(k) * dx, y = y0 + static_cast<float>(k) * dy;
    const int xi = std::min(static_cast<int>(x), cols - 2), yi = std::min(static_cast<int>(y), rows - 2);
    const float fx = x - static_cast<float>(xi), fy = y - static_cast<float>(yi);
    const size_t at = static_cast<size_t>(yi) * stride + static_cast<size_t>(xi);
    const float p00 = static_cast<float>(image[at]), p01 = static_cast<float>(image[at + 1]);
    const float p10 = static_cast<float>(image[at + stride]), p11 = static_cast<float>(image[at + stride + 1]);
    const float top = p00 + fx * (p01 - p00), bottom = p10 + fx * (p11 - p10);
    out[k] = top + fy * (bottom - top);
    row += out[k];
  }
  return row;
}

}  // namespace

AffinePatch::Result AffinePatch::Align(const cv::Mat& gray, const cv::Point2f& centre_in, const cv::Matx22f& linear_in,
                                       int max_iterations, float epsilon_px) const {
  CV_Assert(gray.type() == CV_8UC1 || gray.type() == CV_32FC1);
  const bool float_image = gray.type() == CV_32FC1;
  Result r;
  if (empty()) return r;
  const int n = side_ * side_;
  const float w1 = static_cast<float>(gray.cols - 1), h1 = static_cast<float>(gray.rows - 1);
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
    // Bilinear samples, row by row (a row's positions step by the warp's first column); each row's loop runs
    // as vector lanes (gathers where the CPU has them). Summed per row in float and across rows in double.
    const auto sample = [&](const auto* image, size_t stride) {
      double total = 0;
      for (int py = 0; py < side_; ++py) {
        const float dy = static_cast<float>(py) - half_;
        const float xr = L(0, 1) * dy - L(0, 0) * half_ + c.x, yr = L(1, 1) * dy - L(1, 0) * half_ + c.y;
        total += SampleRow(image, stride, gray.cols, gray.rows, xr, yr, L(0, 0), L(1, 0), side_,
                           sampled.data() + py * side_);
      }
      return total;
    };
    const double sum = float_image
                           ? sample(reinterpret_cast<const float*>(gray.data), gray.step[0] / sizeof(float))
                           : sample(gray.data, gray.step[0]);
    // Gain and bias: the sampled patch, zero-mean, scaled to the template's norm. One pass gives its norm, its
    // correlation with the template and its products with the steepest-descent images; the error's products
    // follow, as sum_k s_jk (d_k scale - t_k) = scale sum_k s_jk d_k - sum_k s_jk t_k.
    const float mean = static_cast<float>(sum / n);
    const float* v = sampled.data();
    const float* t = values_.data();
    const float *s0 = descent_[0].data(), *s1 = descent_[1].data(), *s2 = descent_[2].data(),
                *s3 = descent_[3].data(), *s4 = descent_[4].data(), *s5 = descent_[5].data();
    float nn = 0, dt = 0, b0 = 0, b1 = 0, b2 = 0, b3 = 0, b4 = 0, b5 = 0;
#pragma omp simd reduction(+ : nn, dt, b0, b1, b2, b3, b4, b5)
    for (int k = 0; k < n; ++k) {
      const float d = v[k] - mean;
      nn += d * d;
      dt += d * t[k];
      b0 += s0[k] * d, b1 += s1[k] * d, b2 += s2[k] * d, b3 += s3[k] * d, b4 += s4[k] * d, b5 += s5[k] * d;
    }
    const double norm = std::sqrt(static_cast<double>(nn));
    r.inside = true;
    r.centre = c;
    r.linear = L;
    r.iterations = it;
    r.correlation = norm > 1e-9 ? static_cast<float>(dt / (norm * norm_)) : 0.0f;
    r.variance = nn / static_cast<float>(n);
    if (it == max_iterations || norm <= 1e-9) break;
    const double scale = norm_ / norm;
    const std::array<float, 6> bd = {b0, b1, b2, b3, b4, b5};
    Eigen::Matrix<double, 6, 1> b;
    for (int j = 0; j < 6; ++j) b[j] = scale * bd[static_cast<size_t>(j)] - descent_dot_values_[static_cast<size_t>(j)];
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
  // The samples of the last pass are those at r's warp.
  if (r.inside) r.sharpness = PatchSharpness(sampled.data(), side_);
  return r;
}

}  // namespace mcslam::frontend
