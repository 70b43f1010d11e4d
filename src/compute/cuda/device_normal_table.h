#pragma once
// The device copy of a NormalTable (7 columns, each padded to 32 floats so every column starts on a
// 128-byte line), uploaded only when the table differs from the one last seen (table_key.h). nvcc only.
#include <cuda_runtime.h>

#include <cstddef>

#include "compute/cuda/device_buffer.h"
#include "compute/cuda/table_key.h"
#include "compute/pose_kernel.h"

namespace mcslam::compute::cuda {

class DeviceNormalTable {
 public:
  // The device columns of `table` (column k at get() + k * stride()), with the copy enqueued on `stream`
  // when needed. Call only with table.count() > 0.
  const float* Sync(const NormalTable& table, cudaStream_t stream) {
    const NormalTableKey key = MakeNormalTableKey(table);
    if (valid_ && key == key_) return data_.get();
    valid_ = false;  // stays false if a copy below throws
    const size_t rows = static_cast<size_t>(table.count());
    stride_ = (rows + 31) & ~size_t{31};
    float* d = data_.Reserve(7 * stride_);
    // Pageable source: cudaMemcpyAsync returns once the data is staged, so the table may change afterwards.
    for (int k = 0; k < 7; ++k)
      MCSLAM_CUDA_CHECK(cudaMemcpyAsync(d + k * stride_, table.column(k), rows * sizeof(float), cudaMemcpyHostToDevice,
                                        stream));
    key_ = key;
    valid_ = true;
    ++uploads_;
    return d;
  }
  size_t stride() const { return stride_; }
  long uploads() const { return uploads_; }
  long allocations() const { return data_.allocations(); }

 private:
  DeviceBuffer<float> data_;
  size_t stride_ = 0;
  NormalTableKey key_;
  bool valid_ = false;
  long uploads_ = 0;
};

}  // namespace mcslam::compute::cuda
