#pragma once
// Medians and quantiles of small sets of numbers (residuals, timings, depths). Each returns 0 for an empty set.
#include <algorithm>
#include <vector>

namespace mcslam {

// The element of rank n/2 (the upper of the two middle ones when n is even): always a value of the set. The
// in-place form reorders *v and allocates nothing (for per-frame paths that reuse a buffer).
inline double UpperMedianInPlace(std::vector<double>* v) {
  if (v->empty()) return 0.0;
  const size_t mid = v->size() / 2;
  std::nth_element(v->begin(), v->begin() + static_cast<std::ptrdiff_t>(mid), v->end());
  return (*v)[mid];
}
inline double UpperMedian(std::vector<double> v) { return UpperMedianInPlace(&v); }

// The median proper: the mean of the two middle values when n is even.
inline double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  if (v.size() % 2 == 1) return v[mid];
  return 0.5 * (v[mid] + *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid)));
}

// The element of rank floor(q * n) of the sorted set (q in [0, 1], clamped to the last): a value of the set, the
// upper median at q = 0.5.
inline double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(std::max(0.0, q) * static_cast<double>(v.size())));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

}  // namespace mcslam
