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
  // Turned, the grid's corners reach sqrt(2) times as far.
  turned_radius_px_ = static_cast<int>(std::ceil(std::sqrt(2.0) * 2.5 * 1.5 * size_px)) + 1 + 7;
}

cv::Rect SiftDescriber::Patch(const cv::Point2f& uv, const cv::Size& image, bool turned) const {
  const int x = static_cast<int>(std::floor(uv.x)), y = static_cast<int>(std::floor(uv.y));
  const int r = turned ? turned_radius_px_ : radius_px_;
  return cv::Rect(x - r, y - r, 2 * r + 2, 2 * r + 2) & cv::Rect(0, 0, image.width, image.height);
}

void SiftDescriber::DescribeTurned(const cv::Mat& gray, std::span<const cv::Point2f> points,
                                   std::span<const float> angles_deg, std::vector<Descriptor>* out,
                                   std::vector<char>* ok) const {
  const size_t n = points.size();
  out->assign(n * angles_deg.size(), Descriptor{});
  ok->assign(n * angles_deg.size(), 0);
  cv::Rect box;
  std::vector<size_t> inside;
  for (size_t i = 0; i < n; ++i) {
    const cv::Rect patch = Patch(points[i], gray.size(), true);
    if (patch.empty()) continue;
    box = inside.empty() ? patch : (box | patch);
    inside.push_back(i);
  }
  if (inside.empty() || angles_deg.empty()) return;
  std::vector<cv::KeyPoint> kp;
  kp.reserve(inside.size() * angles_deg.size());
  for (const float angle : angles_deg)
    for (size_t i : inside)
      kp.emplace_back(points[i].x - static_cast<float>(box.x), points[i].y - static_cast<float>(box.y), size_px_,
                      angle, 0.0f, 0 /* octave 0, layer 0 */);
  cv::Mat desc;
  try {
    sift_->compute(gray(box), kp, desc);
  } catch (const cv::Exception&) {
    return;  // none described: the caller matches nothing
  }
  if (desc.rows != static_cast<int>(kp.size()) || desc.cols != kDescriptorLength || desc.type() != CV_32F) return;
  for (size_t a = 0; a < angles_deg.size(); ++a)
    for (size_t k = 0; k < inside.size(); ++k) {
      const int row = static_cast<int>(a * inside.size() + k);
      const size_t slot = a * n + inside[k];
      std::copy(desc.ptr<float>(row), desc.ptr<float>(row) + kDescriptorLength, (*out)[slot].begin());
      (*ok)[slot] = 1;
    }
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
