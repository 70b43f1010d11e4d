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

}  // namespace mcslam::frontend
