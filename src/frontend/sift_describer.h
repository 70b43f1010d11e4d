#pragma once
// Upright SIFT descriptors (OpenCV's) at given points (and turned ones, for a camera turned about its axis).
// OpenCV builds a Gaussian octave over whatever image it is given, at about 40 ns a pixel whatever the number of
// points, so each point is described from a small patch around it (everything its descriptor reads, so the values
// are those of a whole-image computation), and points whose patches overlap enough are described together from the
// box that holds their patches, once.
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#include <span>
#include <vector>

#include "frontend/frontend.h"

namespace mcslam::frontend {

class SiftDescriber {
 public:
  explicit SiftDescriber(double size_px);

  // One point's descriptor; false when SIFT gives none (it should not happen for a point inside the image).
  bool Describe(const cv::Mat& gray, const cv::Point2f& uv, Descriptor* out) const;

  // Every point's descriptor, the same values as Describe point by point: ok[i] says whether out[i] holds one.
  // Points are grouped by tiles of the image; a tile's points go in one call on the box around their patches
  // when that box is smaller than their patches together, else one call each. A call that throws is repeated
  // point by point, so that only a point that cannot be described goes without.
  void DescribeAll(const cv::Mat& gray, std::span<const cv::Point2f> points, std::vector<Descriptor>* out,
                   std::vector<char>* ok) const;

  // Every point's descriptor with its grid turned by each of `angles_deg` (OpenCV's keypoint angle): how the point
  // looks to a camera turned about its axis by that much since another view described it upright. One OpenCV call
  // over the box around every point's turned patch (one Gaussian octave for all of them): out and ok hold
  // angles_deg.size() x points.size() entries, angle by angle. All not ok when that call fails.
  void DescribeTurned(const cv::Mat& gray, std::span<const cv::Point2f> points, std::span<const float> angles_deg,
                      std::vector<Descriptor>* out, std::vector<char>* ok) const;

  // The patch one point needs (clipped to the image; empty when the point is too far outside it); a turned grid
  // reaches up to sqrt(2) times further.
  cv::Rect Patch(const cv::Point2f& uv, const cv::Size& image, bool turned = false) const;

 private:
  // One OpenCV call: points (indices into `points`) described from image(roi); false if it gave a wrong count.
  bool DescribeIn(const cv::Mat& gray, const cv::Rect& roi, std::span<const cv::Point2f> points,
                  std::span<const size_t> which, std::vector<Descriptor>* out, std::vector<char>* ok) const;

  float size_px_;
  int radius_px_ = 0, turned_radius_px_ = 0;
  cv::Ptr<cv::SIFT> sift_;
};

}  // namespace mcslam::frontend
