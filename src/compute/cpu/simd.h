#pragma once
// SIMD vector type of the CPU backend (GCC vector extensions) and the Math policy with which the templates
// of pose_math.h are instantiated: one hypothesis (pose kernel) or one sample (point kernel) per lane.
// Include only from translation units compiled with the hot-loop flags (see CMakeLists.txt).
#include <cstring>

#include <immintrin.h>

#include "core/host_device.h"

namespace mcslam::compute::cpu {

#if defined(__AVX512F__)
constexpr int kLanes = 16;
typedef float VecF __attribute__((vector_size(64)));
inline VecF RsqrtApprox(VecF x) { return _mm512_rsqrt14_ps(x); }  // |rel err| < 2^-14
#elif defined(__AVX__)
constexpr int kLanes = 8;
typedef float VecF __attribute__((vector_size(32)));
inline VecF RsqrtApprox(VecF x) { return _mm256_rsqrt_ps(x); }  // |rel err| < 1.5 * 2^-12
#else
constexpr int kLanes = 4;
typedef float VecF __attribute__((vector_size(16)));
inline VecF RsqrtApprox(VecF x) { return _mm_rsqrt_ps(x); }
#endif

struct SimdMath {
  // The hardware estimate alone (relative error < 2^-14 with AVX-512, 1.5 * 2^-12 with AVX): a Newton step
  // would cost 4 of the loop's 20 multiply-class operations, the ones that bound its speed, and it changes
  // neither the chosen pose nor the tracking accuracy measurably (docs/pose_estimation.md).
  static MCSLAM_INLINE VecF Rsqrt(VecF x) { return RsqrtApprox(x); }
  // With one Newton step (~1e-7 relative): hypotheses are unit quaternions to float precision.
  static MCSLAM_INLINE VecF RsqrtAccurate(VecF x) {
    const VecF y = RsqrtApprox(x);
    return y * (1.5f - 0.5f * x * y * y);
  }
  static MCSLAM_INLINE VecF Min(VecF a, VecF b) { return a < b ? a : b; }
  static MCSLAM_INLINE VecF SelectGreater(VecF x, float than, VecF a, VecF b) { return x > than ? a : b; }
};

inline VecF LoadVec(const float* p) {
  VecF v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

}  // namespace mcslam::compute::cpu
