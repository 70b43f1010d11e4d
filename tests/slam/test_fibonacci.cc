#include <gtest/gtest.h>

#include "slam/fibonacci.h"

namespace mcslam::slam {
namespace {

TEST(FibonacciWindow, CurrentThenFibonacciStepsBack) {
  // 100 keyframes, current = 99: 99, 98, 97, 96, 94, 91, 86, 78, 65, 44, 10
  EXPECT_EQ(FibonacciWindow(100, 12), (std::vector<int>{99, 98, 97, 96, 94, 91, 86, 78, 65, 44, 10}));
  EXPECT_EQ(FibonacciWindow(100, 4), (std::vector<int>{99, 98, 97, 96}));
  EXPECT_EQ(FibonacciWindow(3, 12), (std::vector<int>{2, 1, 0}));
  EXPECT_EQ(FibonacciWindow(1, 12), (std::vector<int>{0}));
  EXPECT_TRUE(FibonacciWindow(0, 12).empty());
}

}  // namespace
}  // namespace mcslam::slam
