// SiftDescriber: points described together (one OpenCV call on the box around several patches) get the very
// descriptors they get one by one, wherever they lie: clustered as a remapping window's candidates are, spread
// over the image, at the borders, and outside it.
#include <gtest/gtest.h>

#include <cstring>
#include <opencv2/core.hpp>
#include <vector>

#include "frontend/sift_describer.h"
#include "synthetic_images.h"

namespace mcslam::frontend {
namespace {

void ExpectSameAsOneByOne(const SiftDescriber& d, const cv::Mat& gray, const std::vector<cv::Point2f>& pts,
                          const char* what) {
  std::vector<Descriptor> all;
  std::vector<char> ok;
  d.DescribeAll(gray, pts, &all, &ok);
  ASSERT_EQ(all.size(), pts.size());
  ASSERT_EQ(ok.size(), pts.size());
  for (size_t i = 0; i < pts.size(); ++i) {
    Descriptor one{};
    const bool one_ok = d.Describe(gray, pts[i], &one);
    ASSERT_EQ(static_cast<bool>(ok[i]), one_ok) << what << ", point " << i << " at " << pts[i];
    // Bit for bit: the same pixels reach each descriptor either way.
    if (one_ok) {
      EXPECT_EQ(std::memcmp(all[i].data(), one.data(), sizeof(Descriptor)), 0) << what << ", point " << i;
    }
  }
}

TEST(SiftDescriber, DescribingTogetherGivesTheDescriptorsOfOneByOne) {
  const cv::Mat gray = [] {
    cv::Mat f;
    testing::MovingTexture(cv::Size(640, 480), 5).Frame(0, 0).convertTo(f, CV_8U);
    return f;
  }();
  const SiftDescriber d(6.0);
  cv::RNG rng(3);
  // Clustered: 40 windows of 30 x 30 px with 5 points each (what remapping describes).
  std::vector<cv::Point2f> clustered;
  for (int w = 0; w < 40; ++w) {
    const float cx = rng.uniform(20.f, 620.f), cy = rng.uniform(20.f, 460.f);
    for (int k = 0; k < 5; ++k) {
      // y drawn before x, here and below: the order in which GCC evaluated emplace_back(x + uniform(),
      // y + uniform()) (argument order is unspecified in C++; clang goes left to right).
      const float y = cy + rng.uniform(-15.f, 15.f), x = cx + rng.uniform(-15.f, 15.f);
      clustered.emplace_back(x, y);
    }
  }
  ExpectSameAsOneByOne(d, gray, clustered, "clustered");
  // Spread: 300 points anywhere, most in tiles of their own or a few.
  std::vector<cv::Point2f> spread;
  for (int k = 0; k < 300; ++k) {
    const float y = rng.uniform(0.f, 479.f), x = rng.uniform(0.f, 639.f);
    spread.emplace_back(x, y);
  }
  ExpectSameAsOneByOne(d, gray, spread, "spread");
  // At the borders and corners (patches cut by the image) with an inner neighbour in the same tile, and
  // points outside the image (no descriptor, or one from what of the patch is inside: as one by one).
  const std::vector<cv::Point2f> edges{{0, 0},      {3, 5},       {20, 20},  {639, 479}, {630, 470}, {0, 240},
                                       {5, 250},    {320, 0},     {330, 4},  {-100, -100}, {700, 240}, {-20, 10},
                                       {645, 470}};
  ExpectSameAsOneByOne(d, gray, edges, "edges");
  ExpectSameAsOneByOne(d, gray, {}, "none");
}

}  // namespace
}  // namespace mcslam::frontend
