#pragma once
// Every CUDA runtime call of the backend goes through MCSLAM_CUDA_CHECK: a failure becomes a
// std::runtime_error naming the call, where it was made and cudaGetErrorString. nvcc only.
#include <cuda_runtime.h>

#include <stdexcept>
#include <string>

namespace mcslam::compute::cuda {

[[noreturn]] inline void ThrowCudaError(cudaError_t err, const char* call, const char* file, int line) {
  cudaGetLastError();  // clear a non-sticky error so that it is not reported again by the next check
  std::string where(file);
  const size_t slash = where.find_last_of('/');
  if (slash != std::string::npos) where = where.substr(slash + 1);
  throw std::runtime_error(std::string("CUDA error: ") + call + " failed (" + where + ":" + std::to_string(line) +
                           "): " + cudaGetErrorName(err) + ": " + cudaGetErrorString(err));
}

}  // namespace mcslam::compute::cuda

#define MCSLAM_CUDA_CHECK(call)                                                           \
  do {                                                                                    \
    const cudaError_t mcslam_cuda_err_ = (call);                                          \
    if (mcslam_cuda_err_ != cudaSuccess)                                                  \
      ::mcslam::compute::cuda::ThrowCudaError(mcslam_cuda_err_, #call, __FILE__, __LINE__); \
  } while (0)

// After a <<<...>>> launch: a bad configuration (or an earlier asynchronous fault) is reported here;
// faults inside the kernel surface at the stream synchronisation, which is checked too.
#define MCSLAM_CUDA_CHECK_LAUNCH(name) \
  ::mcslam::compute::cuda::CheckLaunch(name, __FILE__, __LINE__)

namespace mcslam::compute::cuda {
inline void CheckLaunch(const char* name, const char* file, int line) {
  const cudaError_t err = cudaGetLastError();
  if (err != cudaSuccess) ThrowCudaError(err, (std::string("launch of ") + name).c_str(), file, line);
}
}  // namespace mcslam::compute::cuda
