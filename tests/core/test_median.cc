// Medians and quantiles (core/median.h): values of the set, at the ranks their comments give.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

#include "core/median.h"

namespace mcslam {
namespace {

TEST(Median, QuantileIsTheElementOfRankFloorQN) {
  std::vector<double> v;
  for (int i = 1; i <= 100; ++i) v.push_back(i);
  std::shuffle(v.begin(), v.end(), std::mt19937(7));
  EXPECT_EQ(Quantile(v, 0.0), 1.0);
  EXPECT_EQ(Quantile(v, 0.5), 51.0);  // rank 50 of 0..99
  EXPECT_EQ(Quantile(v, 0.5), UpperMedian(v));
  EXPECT_EQ(Quantile(v, 0.9), 91.0);
  EXPECT_EQ(Quantile(v, 0.99), 100.0);
  EXPECT_EQ(Quantile(v, 1.0), 100.0);  // clamped to the last
  EXPECT_EQ(Quantile({}, 0.9), 0.0);
  EXPECT_EQ(Quantile({3.5}, 0.99), 3.5);
  EXPECT_EQ(Median({1, 2, 3, 10}), 2.5);
  EXPECT_EQ(UpperMedian({1, 2, 3, 10}), 3.0);
}

}  // namespace
}  // namespace mcslam
