#pragma once
// The reduction element of the CUDA backend: a score and the row it belongs to. Plain C++17 and
// MCSLAM_HOST_DEVICE, so the host tests check the order the device reductions use.
#include <climits>
#include <cmath>
#include <limits>

#include "core/host_device.h"

namespace mcslam::compute::cuda {

struct Candidate {
  float score;
  int index;
};

// The score as the order sees it: a NaN ranks as +infinity, so that the order stays total (a NaN never
// wins against a number; the CPU backend never picks one either).
MCSLAM_HOST_DEVICE MCSLAM_INLINE float RankedScore(float s) {
#if defined(__CUDA_ARCH__)
  return isnan(s) ? __int_as_float(0x7f800000) : s;
#else
  return std::isnan(s) ? std::numeric_limits<float>::infinity() : s;
#endif
}

// Strict total order on (ranked score, index): lower score first, ties to the lower index. As a min over
// a total order, BestOf is associative and commutative, so any reduction tree (any block size, any number
// of blocks, any thread order) returns the same element: the lowest score at the lowest index, which is
// what the CPU backend returns.
MCSLAM_HOST_DEVICE MCSLAM_INLINE bool Better(const Candidate& a, const Candidate& b) {
  const float sa = RankedScore(a.score), sb = RankedScore(b.score);
  return sa < sb || (sa == sb && a.index < b.index);
}

MCSLAM_HOST_DEVICE MCSLAM_INLINE Candidate BestOf(const Candidate& a, const Candidate& b) {
  return Better(b, a) ? b : a;
}

// The identity of BestOf: loses to every real candidate (indices are below INT_MAX).
MCSLAM_HOST_DEVICE MCSLAM_INLINE Candidate NoCandidate() {
#if defined(__CUDA_ARCH__)
  return Candidate{__int_as_float(0x7f800000), INT_MAX};
#else
  return Candidate{std::numeric_limits<float>::infinity(), INT_MAX};
#endif
}

// A scored row as the reductions take it: a score that is not below +infinity (infinite, or NaN) is no
// candidate at all. The CPU backend keeps a score only when it is below the best so far, starting from
// +infinity, so where every score is infinite or NaN it has no winner (index -1: "no finite hypothesis
// score", and the tracker calls the frame lost); the device must not make one up either.
MCSLAM_HOST_DEVICE MCSLAM_INLINE Candidate Scored(float score, int index) {
#if defined(__CUDA_ARCH__)
  return score < __int_as_float(0x7f800000) ? Candidate{score, index} : NoCandidate();
#else
  return score < std::numeric_limits<float>::infinity() ? Candidate{score, index} : NoCandidate();
#endif
}

// True for the result of a reduction that saw no candidate.
MCSLAM_HOST_DEVICE MCSLAM_INLINE bool IsNoCandidate(const Candidate& c) { return c.index == INT_MAX; }

struct BestOfOp {
  MCSLAM_HOST_DEVICE MCSLAM_INLINE Candidate operator()(const Candidate& a, const Candidate& b) const {
    return BestOf(a, b);
  }
};

}  // namespace mcslam::compute::cuda
