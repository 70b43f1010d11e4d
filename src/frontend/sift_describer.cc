#include "frontend/sift_describer.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <utility>

namespace mcslam::frontend {

namespace {
// Tile side for grouping: a group's box is at most (kTilePx + 2 radius)^2 px; with the default 6 px
// descriptor size (64 px patches) that is 9 patches' worth: a tile's points go together once they are 9,
// or fewer that lie close (measured on 7-Scenes: 64 and 128 px alike, 32 px slower).
constexpr int kTilePx = 128;
}  // namespace

SiftDescriber::SiftDescriber(double size_px) : size_px_(static_cast<float>(size_px)), sift_(cv::SIFT::create()) {
  // OpenCV's SIFT reads, for an upright keypoint, pixels less than (4 + 1) / 2 cells of 3 * size / 2 px
  // from it, from its first Gaussian level, whose blur (sigma ~1.5) reaches 6 px further.
  radius_px_ = static_cast<int>(std::ceil(2.5 * 1.5 * size_px)) + 1 + 7;
}

cv::Rect SiftDescriber::Patch(const cv::Point2f& uv, const cv::Size& image) const {
  const int x = static_cast<int>(std::floor(uv.x)), y = static_cast<int>(std::floor(uv.y));
  return cv::Rect(x - radius_px_, y - radius_px_, 2 * radius_px_ + 2, 2 * radius_px_ + 2) &
         cv::Rect(0, 0, image.width, image.height);
}

bool SiftDescriber::DescribeIn(const cv::Mat& gray, const cv::Rect& roi, std::span<const cv::Point2f> points,
                               std::span<const size_t> which, std::vector<Descriptor>* out,
                               std::vector<char>* ok) const {
  std::vector<cv::KeyPoint> kp;
  kp.reserve(which.size());
  for (size_t i : which)
    kp.emplace_back(points[i].x - static_cast<float>(roi.x), points[i].y - static_cast<float>(roi.y), size_px_,
                    0.0f /* upright */, 0.0f, 0 /* octave 0, layer 0 */);
  cv::Mat desc;
  sift_->compute(gray(roi), kp, desc);
  if (desc.rows != static_cast<int>(which.size()) || desc.cols != kDescriptorLength || desc.type() != CV_32F)
    return false;
  for (size_t r = 0; r < which.size(); ++r) {
    std::copy(desc.ptr<float>(static_cast<int>(r)), desc.ptr<float>(static_cast<int>(r)) + kDescriptorLength,
              (*out)[which[r]].begin());
    (*ok)[which[r]] = 1;
  }
  return true;
}

bool SiftDescriber::Describe(const cv::Mat& gray, const cv::Point2f& uv, Descriptor* out) const {
  const cv::Rect roi = Patch(uv, gray.size());
  if (roi.empty()) return false;
  std::vector<Descriptor> d(1);
  std::vector<char> ok(1, 0);
  const size_t which = 0;
  if (!DescribeIn(gray, roi, std::span<const cv::Point2f>(&uv, 1), std::span<const size_t>(&which, 1), &d, &ok))
    return false;
  *out = d[0];
  return true;
}

void SiftDescriber::DescribeAll(const cv::Mat& gray, std::span<const cv::Point2f> points,
                                std::vector<Descriptor>* out, std::vector<char>* ok) const {
  out->assign(points.size(), Descriptor{});
  ok->assign(points.size(), 0);
  // Each point's patch, and the points by tile (row-major, so the calls come in a fixed order).
  std::vector<cv::Rect> patch(points.size());
  std::map<std::pair<int, int>, std::vector<size_t>> tiles;
  for (size_t i = 0; i < points.size(); ++i) {
    patch[i] = Patch(points[i], gray.size());
    if (patch[i].empty()) continue;
    const int tx = static_cast<int>(std::floor(points[i].x)) / kTilePx;
    const int ty = static_cast<int>(std::floor(points[i].y)) / kTilePx;
    tiles[{ty, tx}].push_back(i);
  }
  const auto one_by_one = [&](std::span<const size_t> which) {
    for (size_t i : which) {
      try {
        DescribeIn(gray, patch[i], points, std::span<const size_t>(&i, 1), out, ok);
      } catch (const cv::Exception&) {
        // No descriptor for this point.
      }
    }
  };
  for (const auto& [tile, which] : tiles) {
    cv::Rect box = patch[which[0]];
    double separate = 0;
    for (size_t i : which) box |= patch[i], separate += patch[i].area();
    if (which.size() == 1 || box.area() >= separate) {
      one_by_one(which);
      continue;
    }
    bool done = false;
    try {
      done = DescribeIn(gray, box, points, which, out, ok);
    } catch (const cv::Exception&) {
    }
    if (!done) one_by_one(which);
  }
}

}  // namespace mcslam::frontend
