#include <thread>

#include <oneapi/tbb/info.h>

#include "compute/backend.h"

namespace mcslam::compute {

#ifndef MCSLAM_WITH_CUDA
bool CudaCompiled() { return false; }
int CudaDeviceCount() { return 0; }
std::string CudaDeviceDescription() { return "no CUDA backend in this build (nvcc was not found at configure time)"; }
#else
bool CudaCompiled() { return true; }
#endif

int CpuThreadCount() { return tbb::info::default_concurrency(); }

}  // namespace mcslam::compute
