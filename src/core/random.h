#pragma once
// Counter-based random numbers (Philox4x32-10, Salmon et al., SC'11): the value at (seed, stream, counter)
// is a pure function, so any thread on any backend can draw its own numbers with no shared state, and the
// same seed gives the same numbers on the CPU and on the GPU.
#include <cmath>
#include <cstdint>

#include "core/host_device.h"

namespace mcslam {

struct Philox4x32 {
  uint32_t v[4];
};

MCSLAM_HOST_DEVICE MCSLAM_INLINE Philox4x32 Philox4x32_10(uint32_t c0, uint32_t c1, uint32_t c2, uint32_t c3,
                                                          uint32_t k0, uint32_t k1) {
  constexpr uint32_t kM0 = 0xD2511F53u, kM1 = 0xCD9E8D57u;
  constexpr uint32_t kW0 = 0x9E3779B9u, kW1 = 0xBB67AE85u;
#if defined(__CUDACC__)
#pragma unroll
#endif
  for (int round = 0; round < 10; ++round) {
    const uint64_t p0 = static_cast<uint64_t>(kM0) * c0;
    const uint64_t p1 = static_cast<uint64_t>(kM1) * c2;
    const uint32_t hi0 = static_cast<uint32_t>(p0 >> 32), lo0 = static_cast<uint32_t>(p0);
    const uint32_t hi1 = static_cast<uint32_t>(p1 >> 32), lo1 = static_cast<uint32_t>(p1);
    const uint32_t n0 = hi1 ^ c1 ^ k0, n2 = hi0 ^ c3 ^ k1;
    c0 = n0;
    c1 = lo1;
    c2 = n2;
    c3 = lo0;
    k0 += kW0;
    k1 += kW1;
  }
  return Philox4x32{{c0, c1, c2, c3}};
}

// Uniform in (0, 1], never 0 so that log() is safe.
MCSLAM_HOST_DEVICE MCSLAM_INLINE double UniformOpen01(uint32_t bits) { return (bits + 1.0) * (1.0 / 4294967296.0); }

// Two standard-normal numbers from two uniform words (Box-Muller).
MCSLAM_HOST_DEVICE MCSLAM_INLINE void BoxMuller(uint32_t a, uint32_t b, double* n0, double* n1) {
  const double r = sqrt(-2.0 * log(UniformOpen01(a)));
  const double phi = 6.283185307179586476925 * UniformOpen01(b);
  *n0 = r * cos(phi);
  *n1 = r * sin(phi);
}

// Random numbers addressed by (seed, stream, index): stream separates independent uses of one seed
// (noise, outliers, hypotheses ...), index counts within a stream. Each Philox call yields 4 words.
MCSLAM_HOST_DEVICE MCSLAM_INLINE Philox4x32 PhiloxAt(uint64_t seed, uint32_t stream, uint64_t block) {
  return Philox4x32_10(static_cast<uint32_t>(block), static_cast<uint32_t>(block >> 32), stream, 0x6d63736cu,
                       static_cast<uint32_t>(seed), static_cast<uint32_t>(seed >> 32));
}

// Sequential host-side generator over one (seed, stream): reproducible, and equal to what a device thread
// reading the same blocks would get.
class CounterRng {
 public:
  CounterRng(uint64_t seed, uint32_t stream) : seed_(seed), stream_(stream) {}

  uint32_t NextU32() {
    if (used_ == 4) {
      buf_ = PhiloxAt(seed_, stream_, block_++);
      used_ = 0;
    }
    return buf_.v[used_++];
  }
  // Uniform in [0, 1).
  double Uniform() { return NextU32() * (1.0 / 4294967296.0); }
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  double Normal() {
    if (have_spare_) {
      have_spare_ = false;
      return spare_;
    }
    double n0, n1;
    const uint32_t a = NextU32(), b = NextU32();
    BoxMuller(a, b, &n0, &n1);
    spare_ = n1;
    have_spare_ = true;
    return n0;
  }
  // Integer in [0, n).
  uint32_t Below(uint32_t n) { return static_cast<uint32_t>((static_cast<uint64_t>(NextU32()) * n) >> 32); }

 private:
  uint64_t seed_;
  uint32_t stream_;
  uint64_t block_ = 0;
  Philox4x32 buf_{};
  int used_ = 4;
  bool have_spare_ = false;
  double spare_ = 0.0;
};

}  // namespace mcslam
