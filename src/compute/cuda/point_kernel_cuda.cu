// CUDA backend of the point kernel (paper §6.3, Algorithm 2): one block per point, its threads over the
// samples; sample i made by the same PerturbPointT as the CPU backend from row i of the normal table and
// scored by the same ReprojectionDistanceT summed over the point's observations (Eq. 10); the point's best sample by a
// block reduction (ties to the lowest index). Only one (score, index) per point comes back; the host makes
// the winning position from its row, as the CPU backend does.
//
// Memory: the normal table on the device, uploaded when it changes (device_normal_table.h). A call's problem
// (centres, spreads, keyframe poses, observations) is staged whole into one pinned buffer and sent in one
// asynchronous copy (point_staging.h). All threads of a block read the same observation at the same time, so
// the poses and features are read straight from global memory (a broadcast, L1-cached). Keeping the keyframes
// on the device across calls was tried and measured on an H100: it halved the bytes sent (30 KB instead of
// 55 KB a keyframe's adjustment) but made a call 14-23 % slower (host bookkeeping of ~18 us against 1-2 us of
// transfer saved), so each problem is sent whole (docs/gpu.md).
#include <cub/block/block_reduce.cuh>
#include <cuda_runtime.h>

#include <algorithm>
#include <limits>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>

#include "compute/cuda/candidate.h"
#include "compute/cuda/cuda_check.h"
#include "compute/cuda/cuda_kernels.h"
#include "compute/cuda/device_buffer.h"
#include "compute/cuda/device_normal_table.h"
#include "compute/cuda/point_staging.h"
#include "compute/point_kernel.h"
#include "compute/pose_math.h"

namespace mcslam::compute {

namespace cuda {
namespace {

constexpr int kPointBlock = 256;  // threads per point; the default 4096 samples are 16 per thread

// Block p scores samples 0 .. samples-1 of point p; thread t takes samples t, t + kPointBlock, ... in
// increasing order. centres: 6 columns of num_points floats (cx, cy, cz, sx, sy, sz); observation o is
// (obs_u, obs_v)[o] seen by keyframe poses[obs_pose[o]], obs_begin rebased to 0 (point_staging.h).
__global__ void __launch_bounds__(kPointBlock)
    ScorePointsKernel(const ScaledPose* __restrict__ poses, const int* __restrict__ obs_pose,
                      const float* __restrict__ obs_u, const float* __restrict__ obs_v,
                      const float* __restrict__ centres, int num_points, const int* __restrict__ obs_begin,
                      const PoseScoringParams k, const float* __restrict__ normals, size_t normal_stride, int samples,
                      Candidate* __restrict__ best_out) {
  using BlockReduce = cub::BlockReduce<Candidate, kPointBlock>;
  __shared__ typename BlockReduce::TempStorage reduce_storage;

  const size_t p = blockIdx.x;
  const size_t n = static_cast<size_t>(num_points);
  const float c[3] = {centres[p], centres[n + p], centres[2 * n + p]};
  const float sigma[3] = {centres[3 * n + p], centres[4 * n + p], centres[5 * n + p]};
  const int o0 = obs_begin[p], o1 = obs_begin[p + 1];
  const float cap = k.max_distance_px;

  Candidate best = NoCandidate();
  for (int i = static_cast<int>(threadIdx.x); i < samples; i += kPointBlock) {
    float z[3];
    PerturbPointT<float>(c, sigma, __ldg(normals + i), __ldg(normals + normal_stride + i),
                         __ldg(normals + 2 * normal_stride + i), z);
    // Observations in order o0 .. o1-1 as on the CPU (same float sum).
    float acc = 0.0f;
    for (int o = o0; o < o1; ++o)
      acc += ReprojectionDistanceT<ScalarMath, float, float, float>(poses[obs_pose[o]], z[0], z[1], z[2], obs_u[o],
                                                                    obs_v[o], k, cap);
    best = BestOf(best, Scored(acc, i));  // an infinite or NaN score is no candidate (candidate.h)
  }
  best = BlockReduce(reduce_storage).Reduce(best, BestOfOp{});
  if (threadIdx.x == 0) best_out[p] = best;
}

struct PointResources {
  Stream stream;
  DeviceNormalTable table;
  PinnedBuffer<unsigned char> host_problem;  // staged as point_staging.h plans it
  DeviceBuffer<unsigned char> problem;
  DeviceBuffer<Candidate> best;  // one per point
  PinnedBuffer<Candidate> host_best;
  long calls = 0;
  long bytes_uploaded = 0;  // staged problems sent (the normal table not counted)
};

class CudaPointKernel final : public PointKernel {
 public:
  explicit CudaPointKernel(int device) : device_(device) {
    const int n = CudaDeviceCount();
    if (device < 0 || device >= n)
      throw std::runtime_error("CUDA point kernel: no CUDA device " + std::to_string(device) + " (" +
                               (n == 0 ? CudaDeviceDescription() : std::to_string(n) + " device(s) present") + ")");
    ScopedDevice scoped(device_);
    res_ = std::make_unique<PointResources>();
  }
  ~CudaPointKernel() override {
    int previous = -1;
    const bool known = cudaGetDevice(&previous) == cudaSuccess;
    if (!known || previous != device_) cudaSetDevice(device_);
    res_.reset();
    if (known && previous != device_) cudaSetDevice(previous);
  }
  CudaPointKernel(const CudaPointKernel&) = delete;
  CudaPointKernel& operator=(const CudaPointKernel&) = delete;

  BackendKind kind() const override { return BackendKind::kCuda; }

  void Score(const PointAdjustProblem& pr, const NormalTable& normals, int samples, PointBest* best) override {
    samples = std::min(samples, normals.count());
    if (pr.num_points <= 0) return;
    if (samples <= 0) {  // as the CPU backend: nothing scored, positions untouched
      for (int p = 0; p < pr.num_points; ++p) {
        best[p].index = -1;
        best[p].score = std::numeric_limits<float>::infinity();
      }
      return;
    }
    const PointStagingLayout layout = PlanPointStaging(pr);  // throws std::invalid_argument

    const std::lock_guard<std::mutex> call_lock(call_mutex_);  // one call at a time per kernel object
    ScopedDevice scoped(device_);
    PointResources& r = *res_;
    const cudaStream_t stream = r.stream.get();
    const float* d_normals = r.table.Sync(normals, stream);

    const size_t np = static_cast<size_t>(pr.num_points);
    Candidate* d_best = r.best.Reserve(np);
    Candidate* h_best = r.host_best.Reserve(np);
    try {
      unsigned char* h_problem = r.host_problem.Reserve(layout.bytes);
      StagePointProblem(pr, layout, h_problem);
      unsigned char* d_problem = r.problem.Reserve(layout.bytes);
      MCSLAM_CUDA_CHECK(cudaMemcpyAsync(d_problem, h_problem, layout.bytes, cudaMemcpyHostToDevice, stream));
      ScorePointsKernel<<<static_cast<unsigned>(pr.num_points), kPointBlock, 0, stream>>>(
          reinterpret_cast<const ScaledPose*>(d_problem + layout.poses),
          reinterpret_cast<const int*>(d_problem + layout.obs_pose), reinterpret_cast<const float*>(d_problem + layout.obs_u),
          reinterpret_cast<const float*>(d_problem + layout.obs_v), reinterpret_cast<const float*>(d_problem + layout.centres),
          pr.num_points, reinterpret_cast<const int*>(d_problem + layout.obs_begin), pr.params, d_normals,
          r.table.stride(), samples, d_best);
      MCSLAM_CUDA_CHECK_LAUNCH("ScorePointsKernel");
      MCSLAM_CUDA_CHECK(cudaMemcpyAsync(h_best, d_best, sizeof(Candidate) * np, cudaMemcpyDeviceToHost, stream));
      r.stream.Synchronize();
      r.bytes_uploaded += static_cast<long>(layout.bytes);
    } catch (...) {
      cudaStreamSynchronize(stream);  // the pinned buffers are not reused while a copy may still read them
      throw;
    }
    ++r.calls;

    for (int p = 0; p < pr.num_points; ++p) {
      const Candidate c = h_best[p];
      if (IsNoCandidate(c)) {  // every sample's score infinite or NaN: no winner, position untouched (as the CPU)
        best[p].index = -1;
        best[p].score = std::numeric_limits<float>::infinity();
        continue;
      }
      if (c.index < 0 || c.index >= samples)
        throw std::runtime_error("CUDA point kernel: the reduction returned sample " + std::to_string(c.index) +
                                 " of " + std::to_string(samples) + " for point " + std::to_string(p));
      best[p].index = c.index;
      best[p].score = c.score;
      const float centre[3] = {pr.cx[p], pr.cy[p], pr.cz[p]};
      const float sigma[3] = {pr.sx[p], pr.sy[p], pr.sz[p]};
      PerturbPointT<float>(centre, sigma, normals.column(0)[c.index], normals.column(1)[c.index],
                           normals.column(2)[c.index], best[p].position);
    }
  }

  CudaKernelStats Stats() const {
    CudaKernelStats st;
    const PointResources& r = *res_;
    st.calls = r.calls;
    st.table_uploads = r.table.uploads();
    st.point_uploads = r.calls;  // one copy of the call's staged problem per call
    st.bytes_uploaded = r.bytes_uploaded;
    st.device_allocations = r.table.allocations() + r.problem.allocations() + r.best.allocations();
    st.pinned_allocations = r.host_problem.allocations() + r.host_best.allocations();
    return st;
  }

 private:
  int device_;
  std::mutex call_mutex_;  // the buffers and the stream serve one Score call at a time
  std::unique_ptr<PointResources> res_;
};

}  // namespace

CudaKernelStats StatsOf(const PointKernel& kernel) {
  const auto* k = dynamic_cast<const CudaPointKernel*>(&kernel);
  if (k == nullptr) throw std::invalid_argument("StatsOf: not a CUDA point kernel");
  return k->Stats();
}

}  // namespace cuda

std::unique_ptr<PointKernel> MakeCudaPointKernel(int device) {
  return std::make_unique<cuda::CudaPointKernel>(device);
}

}  // namespace mcslam::compute
