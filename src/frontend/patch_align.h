#pragma once
// Affine alignment of a small patch with an image, by inverse-compositional Gauss-Newton (Baker and Matthews)
// on intensities normalised for gain and bias in every iteration: the feature monitoring of Shi and Tomasi,
// done per track and per frame, so it must be cheap. The template side (its gradients, steepest-descent
// images and Hessian) is computed once when the patch is taken; an iteration then samples the image at the
// patch's pixels and solves a 6x6 system. Same criterion as OpenCV's ECC (zero-mean normalised
// correlation, affine), at a fraction of its cost per call (no per-call allocation, blur or image gradients).
#include <array>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace mcslam::frontend {

// Mean squared central-difference gradient over the interior of a side x side patch (row-major), divided by
// the patch's intensity variance: invariant to gain and bias, lowered by blur. 0 for a flat patch.
float PatchSharpness(const float* values, int side);

class AffinePatch {
 public:
  AffinePatch() = default;
  // The side x side patch of 8-bit `gray` centred at `centre` (sub-pixel). empty() when the patch (and the
  // pixel around it that its gradients need) does not fit in the image, or has no texture at all.
  AffinePatch(const cv::Mat& gray, const cv::Point2f& centre, int side);
  bool empty() const { return side_ == 0; }
  // Smallest over largest eigenvalue of the patch's structure tensor (its summed outer products of
  // gradients): near 0 for a patch that only holds an edge, whose alignment can slide along it; 0 when empty.
  float texture_ratio() const { return texture_ratio_; }
  int side() const { return side_; }
  // How sharp the patch is, whatever its gain and bias: the mean squared intensity gradient over the intensity
  // variance (PatchSharpness). Blur lowers it; a brighter or darker view of the same patch does not.
  float sharpness() const { return sharpness_; }
  float variance() const { return side_ > 0 ? norm_ * norm_ / static_cast<float>(side_ * side_) : 0.0f; }

  struct Result {
    bool inside = false;      // false: the patch does not fit in the image at the start; nothing else is set
    bool left_image = false;  // an update carried it out of the image (a diverging alignment); the other
                              // fields hold the last iterate inside
    float correlation = 0;    // zero-mean normalised correlation at the final warp, in [-1, 1]
    cv::Point2f centre;       // where the patch's centre lands in the image
    cv::Matx22f linear;       // image offset = linear * patch offset (from the patch's centre)
    int iterations = 0;
    float sharpness = 0;      // the sampled patch's sharpness() at the final warp
    float variance = 0;       // the sampled patch's intensity variance at the final warp
  };
  // Aligns with `gray` starting from (centre, linear); stops when an update moves the patch's corners by less
  // than `epsilon_px`, or after `max_iterations`. `gray` is 8-bit or float (CV_32FC1): the same pixel values give
  // the same result up to float rounding, and float pixels are sampled faster (by vector gathers).
  Result Align(const cv::Mat& gray, const cv::Point2f& centre, const cv::Matx22f& linear, int max_iterations = 30,
               float epsilon_px = 0.01f) const;

 private:
  int side_ = 0;
  float half_ = 0;                              // (side - 1) / 2: patch offsets run from -half to half
  std::vector<float> values_;                   // template intensities minus their mean
  float norm_ = 0;                              // their L2 norm
  float texture_ratio_ = 0;
  float sharpness_ = 0;
  // Steepest-descent images, one array of side * side per warp parameter (contiguous: an iteration's sums
  // over the pixels run as vector loops), and their dot products with the template (~0: they are made
  // orthogonal to it; kept so that an iteration's step is the same sum as with the template subtracted).
  std::array<std::vector<float>, 6> descent_;
  std::array<double, 6> descent_dot_values_{};
  Eigen::Matrix<double, 6, 6> hessian_inv_;
};

}  // namespace mcslam::frontend
