#pragma once
// The relative tolerance of a CPU kernel's score against the scalar reference in double, and of the CPU's against
// the CUDA kernel's: each per-point distance of the CPU uses the hardware reciprocal square root estimate
// (|rel err| < 2^-14 = 6.1e-5 with AVX-512, 1.5 * 2^-12 = 3.7e-4 with AVX), every distance is positive, so a sum
// keeps that relative bound; float summation adds < 2e-5 relative for a few hundred points.

namespace mcslam::compute {

#if defined(__AVX512F__)
inline constexpr double kKernelRel = 1e-4;
#else
inline constexpr double kKernelRel = 5e-4;
#endif

}  // namespace mcslam::compute
