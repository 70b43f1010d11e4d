// The image's noise, and the Shi-Tomasi response that noise alone reaches.
#pragma once

#include <opencv2/core.hpp>

namespace mcslam::frontend {

// The sigma (grey levels) of the image's pixel noise, robustly: the median absolute response to the 3x3
// Laplacian-of-differences mask (its L2 norm 6) over every other row, as a Gaussian's MAD (Immerkaer's estimator,
// with the median for the mean so that edges do not count). The responses are integers, so the median comes from
// their histogram. gray: 8-bit, one channel; 0 for an image under 3x3.
float ImageNoiseSigma(const cv::Mat& gray);

// The min-eigenvalue response (cv::cornerMinEigenVal with `block_size` and a 3x3 Sobel, on 8-bit pixels) that an
// image of pure Gaussian noise of sigma 1 grey level exceeds at a `fraction` of its pixels. The response of noise
// scales with sigma^2. Measured once on a seeded 1024x1024 noise image (the same value on every machine up to
// OpenCV's float rounding).
double NoiseCornerResponse(int block_size, double fraction);

// The min-eigenvalue response of every pixel (cv::cornerMinEigenVal with `block_size` and a 3x3 Sobel) into
// `response` (CV_32F, the image's size). An image of kBandedResponsePixels or more is done in bands of
// kResponseBandRows rows on every core, each band a view into the image with `block_size` + 2 rows beyond it (the
// filters read the real rows there, as over the whole image): the same values up to the float rounding of OpenCV's
// running box sums, which restart at each band (measured at 1920x1440: at most 4e-11 of the frame's largest
// response), the bands fixed by the image's height, not by the number of cores. A smaller image is done at once, as
// before (the bands paid only for large frames: 22.7 -> 14.3 ms at 1920x1440 on 2 cores, 0.70 -> 0.58 ms at
// 320x240).
inline constexpr int kBandedResponsePixels = 1 << 20;
inline constexpr int kResponseBandRows = 128;
void CornerResponse(const cv::Mat& gray, int block_size, cv::Mat* response);

}  // namespace mcslam::frontend
