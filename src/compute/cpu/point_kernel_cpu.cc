// CPU backend of the point kernel (Algorithm 2; a sample scored by Eq. 10, its reprojection distances summed over
// the keyframes): points spread over the cores (oneTBB), the samples of one point vectorised across SIMD lanes,
// each observation's keyframe pose and feature broadcast.
#include <algorithm>
#include <limits>

#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_arena.h>

#include "compute/cpu/simd.h"
#include "compute/point_kernel.h"

namespace mcslam::compute {

namespace {

using cpu::kLanes;
using cpu::LoadVec;
using cpu::SimdMath;
using cpu::VecF;

void ScorePoint(const PointAdjustProblem& pr, const NormalTable& normals, int samples, int p, PointBest* best) {
  const float c[3] = {pr.cx[p], pr.cy[p], pr.cz[p]};
  const float s[3] = {pr.sx[p], pr.sy[p], pr.sz[p]};
  const int o0 = pr.obs_begin[p], o1 = pr.obs_begin[p + 1];
  VecF cap;
  for (int l = 0; l < kLanes; ++l) cap[l] = pr.params.max_distance_px;
  float best_score = std::numeric_limits<float>::infinity();
  int best_index = -1;
  for (int b = 0; b < samples; b += kLanes) {
    VecF z[3];
    PerturbPointT<VecF>(c, s, LoadVec(normals.column(0) + b), LoadVec(normals.column(1) + b),
                        LoadVec(normals.column(2) + b), z);
    VecF acc = {};  // zero (not cap * 0, which is NaN for an infinite cap)
    for (int o = o0; o < o1; ++o)
      acc += ReprojectionDistanceT<SimdMath, VecF, float, VecF>(pr.poses[pr.obs_pose[o]], z[0], z[1], z[2], pr.obs_u[o],
                                                                pr.obs_v[o], pr.params, cap);
    const int valid = std::min(kLanes, samples - b);
    for (int l = 0; l < valid; ++l)
      if (acc[l] < best_score) best_score = acc[l], best_index = b + l;
  }
  best->index = best_index;
  best->score = best_score;
  if (best_index >= 0) {
    float n[3] = {normals.column(0)[best_index], normals.column(1)[best_index], normals.column(2)[best_index]};
    PerturbPointT<float>(c, s, n[0], n[1], n[2], best->position);
  }
}

class CpuPointKernel final : public PointKernel {
 public:
  explicit CpuPointKernel(int threads) : arena_(threads > 0 ? threads : tbb::task_arena::automatic) {}
  BackendKind kind() const override { return BackendKind::kCpu; }
  void Score(const PointAdjustProblem& pr, const NormalTable& normals, int samples, PointBest* best) override {
    samples = std::min(samples, normals.count());
    arena_.execute([&] {
      tbb::parallel_for(tbb::blocked_range<int>(0, pr.num_points, 1), [&](const tbb::blocked_range<int>& r) {
        for (int p = r.begin(); p < r.end(); ++p) ScorePoint(pr, normals, samples, p, best + p);
      });
    });
  }

 private:
  tbb::task_arena arena_;
};

}  // namespace

std::unique_ptr<PointKernel> MakeCpuPointKernel(int threads) { return std::make_unique<CpuPointKernel>(threads); }

}  // namespace mcslam::compute
