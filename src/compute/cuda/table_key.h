#pragma once
// When must the CUDA backend upload a NormalTable again? The device keeps one copy per kernel, keyed by
// the table's identity (object and data addresses, row count) and a fingerprint of its contents, so that
// the paper's fixed table is uploaded once and a table refilled in place (NormalTable::Fill, "fresh"
// random numbers every frame) is uploaded again. Plain C++17: the host tests check it without a GPU.
#include <cstdint>
#include <cstring>

#include "compute/pose_kernel.h"

namespace mcslam::compute::cuda {

struct NormalTableKey {
  const void* object = nullptr;
  const float* data = nullptr;
  int count = 0;
  uint64_t fingerprint = 0;
  bool operator==(const NormalTableKey& o) const {
    return object == o.object && data == o.data && count == o.count && fingerprint == o.fingerprint;
  }
  bool operator!=(const NormalTableKey& o) const { return !(*this == o); }
};

// Tables up to this many rows are hashed whole (7 x 8192 floats: about 20 microseconds) ...
constexpr int kFingerprintFullRows = 8192;
// ... larger ones at about this many evenly spaced rows per column, plus the last row (the paper's 2^18
// rows: about 10 microseconds). Fill rewrites every row but the first, so a refill is always seen; a table
// edited in a few places through column(k) between two calls may not be (edit it wholesale, or use a new
// table object).
constexpr int kFingerprintSampledRows = 1024;

// One step of a hash lane: (h ^ value) * odd constant is a bijection of h for a given value, so changing
// any one hashed value always changes the lane's final state.
inline uint64_t FingerprintStep(uint64_t h, float value) {
  uint32_t bits;
  std::memcpy(&bits, &value, sizeof bits);
  return (h ^ bits) * 0x9E3779B97F4A7C15ull;
}

// MurmurHash3's 64-bit finaliser (a bijection): every bit of a lane reaches every bit of the result.
inline uint64_t FingerprintFinish(uint64_t h) {
  h ^= h >> 33;
  h *= 0xFF51AFD7ED558CCDull;
  h ^= h >> 33;
  h *= 0xC4CEB9FE1A85EC53ull;
  return h ^ (h >> 33);
}

inline NormalTableKey MakeNormalTableKey(const NormalTable& table) {
  NormalTableKey key;
  key.object = &table;
  key.count = table.count();
  key.data = key.count > 0 ? table.column(0) : nullptr;
  // Four independent lanes (rows i, i + step, i + 2 step, i + 3 step), so that the multiplies overlap.
  uint64_t h[4] = {0xCBF29CE484222325ull ^ static_cast<uint32_t>(key.count), 0x84222325CBF29CE4ull,
                   0x2545F4914F6CDD1Dull, 0x9E3779B97F4A7C15ull};
  if (key.count > 0) {
    const int n = key.count;
    const int step = n <= kFingerprintFullRows ? 1 : n / kFingerprintSampledRows;
    for (int k = 0; k < 7; ++k) {
      const float* c = table.column(k);
      int i = 0;
      for (; i + 3 * step < n; i += 4 * step) {
        h[0] = FingerprintStep(h[0], c[i]);
        h[1] = FingerprintStep(h[1], c[i + step]);
        h[2] = FingerprintStep(h[2], c[i + 2 * step]);
        h[3] = FingerprintStep(h[3], c[i + 3 * step]);
      }
      for (; i < n; i += step) h[0] = FingerprintStep(h[0], c[i]);
      h[1] = FingerprintStep(h[1], c[n - 1]);
    }
  }
  key.fingerprint = FingerprintFinish(h[0]) ^ (FingerprintFinish(h[1]) * 3) ^ (FingerprintFinish(h[2]) * 5) ^
                    (FingerprintFinish(h[3]) * 7);
  return key;
}

}  // namespace mcslam::compute::cuda
