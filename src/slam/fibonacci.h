#pragma once
// The keyframes a point is adjusted over (paper §6.3): the current one and those a Fibonacci number back,
// current − Fib(n) for n = 2, 3, ... (1, 2, 3, 5, 8, 13, 21, ...): many recent keyframes, a few old ones.
#include <vector>

namespace mcslam::slam {

// Indices into a list of `num_keyframes` keyframes (the last is the current one), newest first, at most
// `count` of them (>= 1), all >= 0.
inline std::vector<int> FibonacciWindow(int num_keyframes, int count) {
  std::vector<int> out;
  if (num_keyframes <= 0 || count <= 0) return out;
  const int current = num_keyframes - 1;
  out.push_back(current);
  long a = 1, b = 2;  // Fib(2), Fib(3)
  while (static_cast<int>(out.size()) < count && current - a >= 0) {
    out.push_back(static_cast<int>(current - a));
    const long next = a + b;
    a = b;
    b = next;
  }
  return out;
}

// How far back (in keyframes) a window of `count` reaches once there are enough keyframes: the last offset
// FibonacciWindow gives (0 for count <= 1).
inline long FibonacciReach(int count) {
  constexpr int kEnough = 1 << 30;  // more keyframes than any window of an int count reaches back
  const std::vector<int> window = FibonacciWindow(kEnough, count);
  return window.empty() ? 0 : kEnough - 1 - window.back();
}

}  // namespace mcslam::slam
