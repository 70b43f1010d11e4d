#pragma once
// Introspection of the CUDA kernels (MakeCudaPoseKernel, MakeCudaPointKernel) for tests and benchmarks:
// how often each uploaded its normal table and its points and allocated memory. Plain C++: includable without nvcc; the
// functions exist only in builds with the CUDA backend (MCSLAM_WITH_CUDA).
#include "compute/point_kernel.h"
#include "compute/pose_kernel.h"

namespace mcslam::compute::cuda {

struct CudaKernelStats {
  long calls = 0;               // Score calls that reached the device
  long table_uploads = 0;       // NormalTable copies to the device
  long point_uploads = 0;       // copies of the scoring points (pose kernel) or of the problem (point kernel)
  long bytes_uploaded = 0;      // bytes of those copies (the normal table's not counted)
  long device_allocations = 0;  // cudaMalloc calls so far (the buffers only grow)
  long pinned_allocations = 0;  // cudaMallocHost calls so far
};

// Throws std::invalid_argument when the kernel is not a CUDA kernel.
CudaKernelStats StatsOf(const PoseKernel& kernel);
CudaKernelStats StatsOf(const PointKernel& kernel);

}  // namespace mcslam::compute::cuda
