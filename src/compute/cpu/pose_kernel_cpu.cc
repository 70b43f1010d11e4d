// CPU backend of the pose kernel: hypotheses vectorised across SIMD lanes (the inner loop over the points
// runs in lock-step, each point's data broadcast), chunks of hypotheses spread over every core (oneTBB).
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <limits>

#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/parallel_reduce.h>
#include <oneapi/tbb/task_arena.h>

#include "compute/cpu/simd.h"
#include "compute/pose_kernel.h"
#include "core/random.h"

namespace mcslam::compute {

NormalTable::NormalTable(int count, uint64_t seed, uint32_t stream) : count_(count) {
  stride_ = (static_cast<size_t>(count) + 15) & ~size_t{15};
  data_.assign(7 * stride_, 0.0f);
  Fill(seed, stream, 0);
}

void NormalTable::Fill(uint64_t seed, uint32_t stream, uint64_t epoch) {
  if (count_ <= 0) return;
  // Row i of epoch e comes from Philox blocks (e * count + i) * 2 and +1: 8 words -> 8 normals, 7 used.
  tbb::parallel_for(tbb::blocked_range<int>(1, std::max(count_, 1), 4096), [&](const tbb::blocked_range<int>& r) {
    for (int i = r.begin(); i < r.end(); ++i) {
      const uint64_t block = (epoch * static_cast<uint64_t>(count_) + i) * 2;
      const Philox4x32 a = PhiloxAt(seed, stream, block), b = PhiloxAt(seed, stream, block + 1);
      double n[8];
      BoxMuller(a.v[0], a.v[1], &n[0], &n[1]);
      BoxMuller(a.v[2], a.v[3], &n[2], &n[3]);
      BoxMuller(b.v[0], b.v[1], &n[4], &n[5]);
      BoxMuller(b.v[2], b.v[3], &n[6], &n[7]);
      for (int k = 0; k < 7; ++k) column(k)[i] = static_cast<float>(n[k]);
    }
  });
  for (int k = 0; k < 7; ++k) column(k)[0] = 0.0f;
}

namespace {

using cpu::kLanes;
using cpu::LoadVec;
using cpu::SimdMath;
using cpu::VecF;

constexpr int kChunk = 256;  // hypotheses per task; a multiple of kLanes
static_assert(kChunk % kLanes == 0);

// Branch and bound, for a caller that wants only the best hypothesis (PoseKernel::Score without all_scores): the
// distances are never negative, so a hypothesis' running sum never falls, and one whose sum has passed the score of
// a hypothesis already scored in full cannot be the lowest; a block of kLanes hypotheses stops once all of its sums
// have (checked every kPruneEvery points). The bound is the lowest full score any task has found so far, shared
// between the tasks; which blocks stop early then depends on the threads' timing, but only blocks that cannot hold
// the winner stop (strictly above the bound), so the winner, its score and the tie to the lowest index are those of
// the full search. A stopped block's scores are +infinity.
constexpr int kPruneEvery = 16;

// The bound is kept as the bits of a float: every running sum is a float >= 0 (or NaN), and for those the bits
// order as the values do, with NaN above +infinity; so neither -ffast-math's assumptions about NaN nor a NaN sum can
// lower the bound or stop a block.
uint32_t Bits(float x) {
  uint32_t b;
  std::memcpy(&b, &x, sizeof b);
  return b;
}

bool AllAbove(const VecF& acc, uint32_t bound) {
  for (int l = 0; l < kLanes; ++l)
    if (Bits(acc[l]) <= bound) return false;
  return true;
}

// bound = min(bound, the first `valid` lanes of acc).
void LowerBound(std::atomic<uint32_t>* bound, const VecF& acc, int valid) {
  uint32_t lowest = Bits(std::numeric_limits<float>::infinity());
  for (int l = 0; l < valid; ++l) lowest = std::min(lowest, Bits(acc[l]));
  uint32_t current = bound->load(std::memory_order_relaxed);
  while (lowest < current && !bound->compare_exchange_weak(current, lowest, std::memory_order_relaxed)) {
  }
}

// Algorithm 1 and its score, Eq. 6: each hypothesis' capped reprojection distances summed over the scoring
// points. Scores hypotheses [h0, h0 + n) into out[0 .. n); with a bound, a block that cannot win stops early
// (above). The table's columns are padded to 16 floats, so the last block may read past `count` into zeros; only n
// scores are written.
void ScoreChunk(const PoseSampling& s, const PoseScoringPoints& pts, const PoseScoringParams& k,
                const NormalTable& normals, int h0, int n, float* __restrict out, std::atomic<uint32_t>* bound) {
  const float* __restrict px = pts.x;
  const float* __restrict py = pts.y;
  const float* __restrict pz = pts.z;
  const float* __restrict pu = pts.u;
  const float* __restrict pv = pts.v;
  const int np = pts.count;
  VecF cap;
  for (int l = 0; l < kLanes; ++l) cap[l] = k.max_distance_px;
  for (int b = 0; b < n; b += kLanes) {
    const int h = h0 + b;
    VecF q[4], t[3];
    PerturbPoseT<SimdMath, VecF>(s, LoadVec(normals.column(0) + h), LoadVec(normals.column(1) + h),
                                 LoadVec(normals.column(2) + h), LoadVec(normals.column(3) + h),
                                 LoadVec(normals.column(4) + h), LoadVec(normals.column(5) + h),
                                 LoadVec(normals.column(6) + h), q, t);
    const ScaledPoseT<VecF> p = MakeScaledPoseT<VecF>(q, t, k.fx, k.fy);
    VecF acc = {};  // zero (not cap * 0, which is NaN for an infinite cap)
    bool pruned = false;
    for (int j0 = 0; j0 < np && !pruned; j0 += kPruneEvery) {
      const int j1 = std::min(np, j0 + kPruneEvery);
      for (int j = j0; j < j1; ++j)
        acc += ReprojectionDistanceT<SimdMath, VecF, VecF, float>(p, px[j], py[j], pz[j], pu[j], pv[j], k, cap);
      if (bound != nullptr && j1 < np) pruned = AllAbove(acc, bound->load(std::memory_order_relaxed));
    }
    const int valid = n - b < kLanes ? n - b : kLanes;
    if (pruned) {
      for (int l = 0; l < kLanes; ++l) acc[l] = std::numeric_limits<float>::infinity();
    } else if (bound != nullptr) {
      LowerBound(bound, acc, valid);
    }
    if (valid == kLanes) {
      std::memcpy(out + b, &acc, sizeof acc);
    } else {
      for (int l = 0; l < valid; ++l) out[b + l] = acc[l];
    }
  }
}

struct Best {
  float score = std::numeric_limits<float>::infinity();
  int index = -1;
  bool Beats(const Best& o) const { return score < o.score || (score == o.score && index < o.index && index >= 0); }
};

class CpuPoseKernel final : public PoseKernel {
 public:
  explicit CpuPoseKernel(int threads) : arena_(threads > 0 ? threads : tbb::task_arena::automatic) {}
  BackendKind kind() const override { return BackendKind::kCpu; }

  BestHypothesis Score(const PoseSampling& s, const PoseScoringPoints& pts, const PoseScoringParams& k,
                       const NormalTable& normals, int count, float* all_scores) override {
    BestHypothesis result;
    count = std::min(count, normals.count());
    if (count <= 0) return result;
    const int chunks = (count + kChunk - 1) / kChunk;
    std::atomic<uint32_t> bound(Bits(std::numeric_limits<float>::infinity()));
    std::atomic<uint32_t>* prune = all_scores ? nullptr : &bound;  // every score wanted: none stopped early
    const Best best = arena_.execute([&] {
      return tbb::parallel_reduce(
          tbb::blocked_range<int>(0, chunks, 4), Best{},
          [&](const tbb::blocked_range<int>& r, Best b) {
            alignas(64) float local[kChunk];
            for (int c = r.begin(); c < r.end(); ++c) {
              const int h0 = c * kChunk, n = std::min(kChunk, count - h0);
              float* out = all_scores ? all_scores + h0 : local;
              ScoreChunk(s, pts, k, normals, h0, n, out, prune);
              for (int i = 0; i < n; ++i) {
                const Best cand{out[i], h0 + i};
                if (cand.Beats(b)) b = cand;
              }
            }
            return b;
          },
          [](const Best& a, const Best& b) { return b.Beats(a) ? b : a; });
    });
    result.index = best.index;
    result.score = best.score;
    if (best.index < 0) return result;  // every score NaN or infinite: no winner, nothing to rebuild
    const int i = best.index;
    PerturbPose(s, normals.column(0)[i], normals.column(1)[i], normals.column(2)[i], normals.column(3)[i],
                normals.column(4)[i], normals.column(5)[i], normals.column(6)[i], result.q, result.t);
    return result;
  }

 private:
  tbb::task_arena arena_;
};

}  // namespace

std::unique_ptr<PoseKernel> MakeCpuPoseKernel(int threads) { return std::make_unique<CpuPoseKernel>(threads); }

}  // namespace mcslam::compute
