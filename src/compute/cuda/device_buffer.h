#pragma once
// Owning handles of the CUDA backend: device buffers, pinned host buffers and a stream. Buffers only
// grow (by at least 1.5x), so once a kernel has seen its largest problem no call allocates again. nvcc only.
#include <cuda_runtime.h>

#include <algorithm>
#include <cstddef>

#include "compute/cuda/cuda_check.h"

namespace mcslam::compute::cuda {

// Growth policy shared by both buffer kinds: the new capacity for a request of n elements.
inline size_t GrownCapacity(size_t capacity, size_t n) { return std::max(n, capacity + capacity / 2); }

// Where a buffer lives: device memory, or page-locked host memory (the source and target of asynchronous
// copies). The check sits here so that an error names the real call.
struct DeviceMemory {
  static void Allocate(void** p, size_t bytes) { MCSLAM_CUDA_CHECK(cudaMalloc(p, bytes)); }
  static void Free(void* p) noexcept { cudaFree(p); }  // a destructor path: nothing useful to do with an error
};
struct PinnedMemory {
  static void Allocate(void** p, size_t bytes) { MCSLAM_CUDA_CHECK(cudaMallocHost(p, bytes)); }
  static void Free(void* p) noexcept { cudaFreeHost(p); }
};

template <typename T, typename Memory>
class Buffer {
 public:
  Buffer() = default;
  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;
  ~Buffer() { Release(); }

  // At least n elements (contents are not kept when it grows). n == 0 returns the current pointer,
  // which may be null.
  T* Reserve(size_t n) {
    if (n > capacity_) {
      const size_t c = GrownCapacity(capacity_, n);
      Release();
      Memory::Allocate(reinterpret_cast<void**>(&ptr_), c * sizeof(T));
      capacity_ = c;
      ++allocations_;
    }
    return ptr_;
  }
  T* get() const { return ptr_; }
  size_t capacity() const { return capacity_; }
  long allocations() const { return allocations_; }
  void Release() noexcept {
    if (ptr_ != nullptr) Memory::Free(ptr_);
    ptr_ = nullptr;
    capacity_ = 0;
  }

 private:
  T* ptr_ = nullptr;
  size_t capacity_ = 0;
  long allocations_ = 0;
};

template <typename T>
using DeviceBuffer = Buffer<T, DeviceMemory>;
template <typename T>
using PinnedBuffer = Buffer<T, PinnedMemory>;

// A stream and the host's wait on it. The wait sleeps on a blocking-sync event instead of
// cudaStreamSynchronize, which by default (cudaDeviceScheduleAuto, with fewer active contexts than cores)
// spins a core at 100 % for as long as the kernel runs: the host CPU would not be free while the GPU works
// (the paper's claim, measured by the run reports' cpu_s), and every frame would burn a core on waiting.
// Sleeping costs a wake-up when the device signals (microseconds to tens of microseconds, depending on the
// driver and the OS), once per call.
class Stream {
 public:
  Stream() {
    MCSLAM_CUDA_CHECK(cudaStreamCreateWithFlags(&stream_, cudaStreamNonBlocking));
    try {
      MCSLAM_CUDA_CHECK(cudaEventCreateWithFlags(&done_, cudaEventBlockingSync | cudaEventDisableTiming));
    } catch (...) {
      cudaStreamDestroy(stream_);
      throw;
    }
  }
  Stream(const Stream&) = delete;
  Stream& operator=(const Stream&) = delete;
  ~Stream() {
    if (done_ != nullptr) cudaEventDestroy(done_);
    if (stream_ != nullptr) cudaStreamDestroy(stream_);
  }
  cudaStream_t get() const { return stream_; }
  // Returns when everything enqueued on the stream so far has finished; throws on a CUDA error (a fault
  // inside a kernel surfaces here).
  void Synchronize() const {
    MCSLAM_CUDA_CHECK(cudaEventRecord(done_, stream_));
    MCSLAM_CUDA_CHECK(cudaEventSynchronize(done_));
  }

 private:
  cudaStream_t stream_ = nullptr;
  cudaEvent_t done_ = nullptr;
};

// Makes `device` current for a scope and restores the caller's device after it: a kernel may be called
// from any host thread, whatever device that thread last used.
class ScopedDevice {
 public:
  explicit ScopedDevice(int device) : device_(device) {
    MCSLAM_CUDA_CHECK(cudaGetDevice(&previous_));
    if (previous_ != device_) MCSLAM_CUDA_CHECK(cudaSetDevice(device_));
  }
  ScopedDevice(const ScopedDevice&) = delete;
  ScopedDevice& operator=(const ScopedDevice&) = delete;
  ~ScopedDevice() {
    if (previous_ != device_) cudaSetDevice(previous_);
  }

 private:
  int device_;
  int previous_ = 0;
};

}  // namespace mcslam::compute::cuda
