#pragma once
// Functions marked MCSLAM_HOST_DEVICE are compiled by both g++ (CPU backend) and nvcc (CUDA backend),
// so both backends run the very same per-element math.
#if defined(__CUDACC__)
#define MCSLAM_HOST_DEVICE __host__ __device__
#define MCSLAM_INLINE __forceinline__
#else
#define MCSLAM_HOST_DEVICE
#define MCSLAM_INLINE inline __attribute__((always_inline))
#endif
