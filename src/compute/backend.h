#pragma once
// Which compute backends this build has and which devices are present.
#include <string>

namespace mcslam::compute {

enum class BackendKind { kCpu, kCuda };

// True when the library was built with the CUDA backend (nvcc was found at configure time).
bool CudaCompiled();
// Number of usable CUDA devices; 0 without a CUDA build, a driver, or a GPU. Never throws.
int CudaDeviceCount();
// One line describing the first CUDA device, or why there is none.
std::string CudaDeviceDescription();
// Number of worker threads the CPU backend uses (every core by default).
int CpuThreadCount();

}  // namespace mcslam::compute
