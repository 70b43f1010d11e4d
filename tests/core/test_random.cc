#include <gtest/gtest.h>

#include <cmath>

#include "core/random.h"

namespace mcslam {
namespace {

TEST(Random, SameSeedSameNumbersOtherSeedOther) {
  CounterRng a(42, 1), b(42, 1), c(43, 1), d(42, 2);
  int equal_c = 0, equal_d = 0;
  for (int i = 0; i < 1000; ++i) {
    const uint32_t x = a.NextU32();
    EXPECT_EQ(x, b.NextU32());
    equal_c += (x == c.NextU32());
    equal_d += (x == d.NextU32());
  }
  // Independent 32-bit words collide with probability 2^-32 each.
  EXPECT_LE(equal_c, 1);
  EXPECT_LE(equal_d, 1);
}

TEST(Random, PhiloxKnownAnswer) {
  // Known-answer vector of the Random123 distribution (kat_vectors: philox4x32 10 rounds, all-zero
  // counter and key): 6627e8d5 e169c58d bc57ac4c 9b00dbd8.
  const Philox4x32 r = Philox4x32_10(0, 0, 0, 0, 0, 0);
  EXPECT_EQ(r.v[0], 0x6627e8d5u);
  EXPECT_EQ(r.v[1], 0xe169c58du);
  EXPECT_EQ(r.v[2], 0xbc57ac4cu);
  EXPECT_EQ(r.v[3], 0x9b00dbd8u);
}

TEST(Random, NormalMomentsAndUniformRange) {
  CounterRng rng(1, 0);
  const int n = 200000;
  double s = 0, s2 = 0, s4 = 0;
  for (int i = 0; i < n; ++i) {
    const double x = rng.Normal();
    s += x;
    s2 += x * x;
    s4 += x * x * x * x;
  }
  const double mean = s / n, var = s2 / n - mean * mean, kurt = s4 / n;
  // Standard errors for n = 2e5: mean 0.0022, variance 0.0032, 4th moment ~0.022; allow ~5 sigma.
  EXPECT_NEAR(mean, 0.0, 0.012);
  EXPECT_NEAR(var, 1.0, 0.016);
  EXPECT_NEAR(kurt, 3.0, 0.11);
  for (int i = 0; i < 10000; ++i) {
    const double u = rng.Uniform();
    ASSERT_GE(u, 0.0);
    ASSERT_LT(u, 1.0);
    ASSERT_LT(rng.Below(7), 7u);
  }
}

}  // namespace
}  // namespace mcslam
