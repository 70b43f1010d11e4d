#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <stdexcept>
#include <vector>

#include "compute/kernel_tolerance.h"
#include "compute/pose_fixture.h"
#include "compute/pose_kernel.h"

namespace mcslam::compute {
namespace {

// The scalar path of the shared header, in double for the sum: the reference the SIMD kernel must match.
std::vector<double> ReferenceScores(const PoseFixture& fx, const NormalTable& table, int count) {
  std::vector<double> scores(count);
  for (int i = 0; i < count; ++i) {
    float q[4], t[3];
    PerturbPose(fx.sampling, table.column(0)[i], table.column(1)[i], table.column(2)[i], table.column(3)[i],
                table.column(4)[i], table.column(5)[i], table.column(6)[i], q, t);
    const ScaledPose p = MakeScaledPose(q, t, fx.params.fx, fx.params.fy);
    double s = 0;
    for (size_t j = 0; j < fx.x.size(); ++j)
      s += ReprojectionDistance(p, fx.x[j], fx.y[j], fx.z[j], fx.u[j], fx.v[j], fx.params);
    scores[i] = s;
  }
  return scores;
}

TEST(NormalTable, FirstRowZeroMomentsAndSeed) {
  const NormalTable a(20000, 5), b(20000, 5), c(20000, 6);
  for (int k = 0; k < 7; ++k) EXPECT_EQ(a.column(k)[0], 0.0f);
  double s = 0, s2 = 0;
  int differ = 0;
  for (int i = 1; i < a.count(); ++i) {
    const double v = a.column(3)[i];
    s += v, s2 += v * v;
    ASSERT_EQ(v, b.column(3)[i]);
    differ += v != c.column(3)[i];
  }
  const double n = a.count() - 1, mean = s / n, var = s2 / n - mean * mean;
  // n = 2e4: standard error of the mean 0.007, of the variance 0.01; 5 sigma.
  EXPECT_NEAR(mean, 0.0, 0.035);
  EXPECT_NEAR(var, 1.0, 0.05);
  EXPECT_GT(differ, n * 0.99);
  NormalTable d(1000, 5);
  d.Fill(5, 0, 1);  // another epoch: other numbers
  EXPECT_NE(d.column(0)[1], a.column(0)[1]);
}

TEST(PoseKernelCpu, MatchesScalarReferenceAndPicksItsBest) {
  for (int points : {1, 17, 200}) {
    PoseFixture fx(points);
    fx.params.max_distance_px = 25.0f;  // exercise the cap too
    const int count = 5000;             // not a multiple of the SIMD width or the chunk
    const NormalTable table(count, 11);
    std::vector<float> scores(count);
    const BestHypothesis best = MakeCpuPoseKernel()->Score(fx.sampling, fx.View(), fx.params, table, count, scores.data());
    const std::vector<double> ref = ReferenceScores(fx, table, count);
    int ref_best = 0;
    for (int i = 0; i < count; ++i) {
      // Each SIMD distance uses the hardware rsqrt estimate (|rel err| < 2^-14 = 6.1e-5 with AVX-512,
      // 3.7e-4 with AVX2 only); plus float summation: 1e-4 relative (5e-4 without AVX-512).
      ASSERT_NEAR(scores[i], ref[i], kKernelRel * ref[i] + 1e-4) << "hypothesis " << i << " points " << points;
      if (ref[i] < ref[ref_best]) ref_best = i;
    }
    EXPECT_EQ(best.score, scores[best.index]);
    EXPECT_NEAR(ref[best.index], ref[ref_best], 2 * kKernelRel * ref[ref_best] + 1e-4);
  }
}

TEST(PoseKernelCpu, CentreWinsOnExactFeaturesAndResultIsThreadIndependent) {
  const PoseFixture fx(150);  // features are the exact projections at the identity (the centre)
  const NormalTable table(1 << 14, 2);
  const BestHypothesis one = MakeCpuPoseKernel(1)->Score(fx.sampling, fx.View(), fx.params, table, table.count());
  const BestHypothesis two = MakeCpuPoseKernel(2)->Score(fx.sampling, fx.View(), fx.params, table, table.count());
  EXPECT_EQ(one.index, 0);
  EXPECT_LT(one.score, 1e-2f);  // 150 float round-offs of ~1e-5 px
  EXPECT_EQ(one.index, two.index);
  EXPECT_EQ(one.score, two.score);
  EXPECT_NEAR(one.q[0], 1.0f, 1e-6f);
}

TEST(PoseKernelCpu, FindsAShiftedPose) {
  // Features seen from a camera moved 2 cm along x: the best hypothesis must move the same way.
  PoseFixture fx(200);
  for (size_t j = 0; j < fx.x.size(); ++j) fx.u[j] = 500.0f * (fx.x[j] + 0.02f) / fx.z[j];
  const NormalTable table(1 << 16, 4);
  const BestHypothesis best = MakeCpuPoseKernel()->Score(fx.sampling, fx.View(), fx.params, table, table.count());
  // Sampling resolution with 2^16 hypotheses in 6-D at sigma 1 cm / 1 deg is a few mm.
  EXPECT_NEAR(best.t[0], 0.02f, 0.006f);
  EXPECT_GT(best.index, 0);
}

// The branch and bound of a search that wants only the best (no all_scores): the same winner, the same score to
// the bit and the same quaternion as the search that scores every hypothesis in full, on tracking-shaped frames
// (noise, outliers, the winner a sampled hypothesis) of 17-300 points, counts that are not multiples of the SIMD
// width or the chunk, one and two threads; and on a table of identical hypotheses (zero spread: every score equal),
// where the tie stays at the lowest index, 0 (no block can pass a bound it equals).
TEST(PoseKernelCpu, StoppingHopelessHypothesesEarlyKeepsTheWinner) {
  for (int points : {17, 120, 300}) {
    for (uint64_t seed : {17, 18, 19}) {
      PoseFixture fx(points, seed);
      fx.MoveCamera(0.01f, 0.5f, 1.0f, 0.1f, seed);
      for (int count : {5000, 1 << 16}) {
        const NormalTable table(count, seed + 100);
        for (int threads : {1, 2}) {
          auto kernel = MakeCpuPoseKernel(threads);
          std::vector<float> all(count);
          const BestHypothesis full = kernel->Score(fx.sampling, fx.View(), fx.params, table, count, all.data());
          const BestHypothesis bound = kernel->Score(fx.sampling, fx.View(), fx.params, table, count);
          EXPECT_EQ(bound.index, full.index) << points << " points, seed " << seed << ", " << count << ", " << threads;
          EXPECT_EQ(bound.score, full.score) << points << " points, seed " << seed;
          for (int k = 0; k < 4; ++k) EXPECT_EQ(bound.q[k], full.q[k]);
          EXPECT_GT(full.index, 0);  // a sampled hypothesis, not the centre: the search had something to find
        }
      }
    }
  }
  PoseFixture fx(60);
  fx.MoveCamera();
  for (float& s : fx.sampling.sigma_q) s = 0.0f;
  for (float& s : fx.sampling.sigma_t) s = 0.0f;
  const NormalTable table(3000, 5);
  const BestHypothesis tie = MakeCpuPoseKernel()->Score(fx.sampling, fx.View(), fx.params, table, table.count());
  EXPECT_EQ(tie.index, 0);
}

TEST(PoseKernelCpu, PointsBehindTheCameraCostTheCap) {
  PoseFixture fx(3);
  for (float& z : fx.z) z = -3.0f;
  fx.params.max_distance_px = 7.0f;
  const NormalTable table(64, 1);
  std::vector<float> scores(64);
  MakeCpuPoseKernel()->Score(fx.sampling, fx.View(), fx.params, table, 64, scores.data());
  for (float s : scores) EXPECT_FLOAT_EQ(s, 21.0f);
}

// Records every call and forwards it to the CPU kernel.
class RecordingPoseKernel final : public PoseKernel {
 public:
  struct Call {
    PoseSampling s;
    int count;
    BestHypothesis best;
  };
  BackendKind kind() const override { return BackendKind::kCpu; }
  BestHypothesis Score(const PoseSampling& s, const PoseScoringPoints& p, const PoseScoringParams& k,
                       const NormalTable& n, int count, float* all) override {
    const BestHypothesis b = cpu_->Score(s, p, k, n, count, all);
    calls.push_back({s, count, b});
    return b;
  }
  std::vector<Call> calls;

 private:
  std::unique_ptr<PoseKernel> cpu_ = MakeCpuPoseKernel();
};

TEST(ScoreInRounds, SplitsTheHypothesesShrinksTheSpreadAndRecentresOnTheBest) {
  PoseFixture fx(200);
  for (size_t j = 0; j < fx.x.size(); ++j) fx.u[j] = 500.0f * (fx.x[j] + 0.02f) / fx.z[j];  // 2 cm along x
  const NormalTable table(10000, 4);
  const double sq[4] = {0.0087, 0.0087, 0.0087, 0.0087}, st[3] = {0.01, 0.01, 0.01};
  RecordingPoseKernel k;
  const BestHypothesis best = ScoreInRounds(k, fx.sampling, sq, st, fx.View(), fx.params, table, 10000, 3, 0.35);
  ASSERT_EQ(k.calls.size(), 3u);
  EXPECT_EQ(k.calls[0].count, 3333);
  EXPECT_EQ(k.calls[1].count, 3333);
  EXPECT_EQ(k.calls[2].count, 3334);  // the last round takes the rest
  for (int r = 0; r < 3; ++r) {
    const double f = std::pow(0.35, r);
    for (int c = 0; c < 4; ++c) EXPECT_EQ(k.calls[r].s.sigma_q[c], static_cast<float>(sq[c] * f)) << r;
    for (int c = 0; c < 3; ++c) EXPECT_EQ(k.calls[r].s.sigma_t[c], static_cast<float>(st[c] * f)) << r;
    if (r == 0) continue;
    // Centred on the best of the round before, which is scored again (row 0): never worse.
    for (int c = 0; c < 4; ++c) EXPECT_EQ(k.calls[r].s.q[c], k.calls[r - 1].best.q[c]) << r;
    for (int c = 0; c < 3; ++c) EXPECT_EQ(k.calls[r].s.t[c], k.calls[r - 1].best.t[c]) << r;
    EXPECT_LE(k.calls[r].best.score, k.calls[r - 1].best.score) << r;
  }
  EXPECT_EQ(best.score, k.calls[2].best.score);
  EXPECT_EQ(best.index, k.calls[2].best.index);
  // The first round started from the centre given.
  for (int c = 0; c < 3; ++c) EXPECT_EQ(k.calls[0].s.t[c], fx.sampling.t[c]);
  // One round is one call of every hypothesis: the kernel's own answer.
  RecordingPoseKernel one;
  const BestHypothesis b1 = ScoreInRounds(one, fx.sampling, sq, st, fx.View(), fx.params, table, 10000, 1, 0.35);
  ASSERT_EQ(one.calls.size(), 1u);
  EXPECT_EQ(one.calls[0].count, 10000);
  const BestHypothesis direct = MakeCpuPoseKernel()->Score(one.calls[0].s, fx.View(), fx.params, table, 10000);
  EXPECT_EQ(b1.index, direct.index);
  EXPECT_EQ(b1.score, direct.score);
  // More rounds than hypotheses: refused, naming both.
  RecordingPoseKernel none;
  EXPECT_THROW(ScoreInRounds(none, fx.sampling, sq, st, fx.View(), fx.params, table, 2, 3, 0.35), std::invalid_argument);
  EXPECT_TRUE(none.calls.empty());
}

}  // namespace
}  // namespace mcslam::compute
