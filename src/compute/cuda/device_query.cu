#include <cuda_runtime.h>

#include <string>

#include "compute/backend.h"

namespace mcslam::compute {

int CudaDeviceCount() {
  int n = 0;
  if (cudaGetDeviceCount(&n) != cudaSuccess) {
    cudaGetLastError();  // clear the sticky "no driver / no device" error
    return 0;
  }
  return n;
}

std::string CudaDeviceDescription() {
  int n = 0;
  const cudaError_t err = cudaGetDeviceCount(&n);
  if (err != cudaSuccess) {
    cudaGetLastError();
    return std::string("no CUDA device: ") + cudaGetErrorString(err);
  }
  if (n == 0) return "no CUDA device present";
  cudaDeviceProp prop{};
  if (const cudaError_t perr = cudaGetDeviceProperties(&prop, 0); perr != cudaSuccess) {
    cudaGetLastError();
    return std::to_string(n) + " CUDA device(s), but device 0 cannot be queried: " + cudaGetErrorString(perr);
  }
  return std::string(prop.name) + " (sm_" + std::to_string(prop.major) + std::to_string(prop.minor) + ", " +
         std::to_string(prop.totalGlobalMem >> 20) + " MiB)";
}

}  // namespace mcslam::compute
