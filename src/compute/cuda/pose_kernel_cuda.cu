// CUDA backend of the pose kernel (paper §7.1, Algorithm 1): one thread per hypothesis, each made by the
// same PerturbPoseT / MakeScaledPoseT as the CPU backend and scored by the same ReprojectionDistanceT;
// the best by a block reduction in the scoring kernel and a one-block second pass. Only the winner (and,
// when asked for, every score) comes back to the host.
//
// Memory: the normal table lives on the device, uploaded when the table changes (device_normal_table.h).
// The points and features (x, y, z, u, v) are staged in pinned memory and copied asynchronously on the
// kernel's stream into global memory, from which each block reads them through shared-memory tiles (every
// thread of a block reads the same point at the same time: a shared-memory broadcast). They stay there: a
// call with the very points of the call before (a frame's second and third sampling rounds) sends nothing but
// the sampling centre and spreads, which travel as kernel arguments (pose_staging.h). Constant memory, the
// textbook place for data every thread reads in step, was measured 4-11x slower on an H100 once a call has
// more than about 700 blocks (the warps of an SM drift apart and thrash the constant cache: 2^18 hypotheses x
// 2000 points 6.6 ms against 0.62 ms through shared tiles; docs/gpu.md), and was dropped.
#include <cub/block/block_reduce.cuh>
#include <cuda_runtime.h>

#include <algorithm>
#include <cstdint>
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
#include "compute/cuda/pose_staging.h"
#include "compute/pose_kernel.h"
#include "compute/pose_math.h"

namespace mcslam::compute {

namespace cuda {
namespace {

constexpr int kPoseBlock = 256;    // hypotheses per block
constexpr int kReduceBlock = 256;  // threads of the second pass
constexpr int kTilePoints = 256;   // points per shared-memory tile
static_assert(kTilePoints % kPoseBlock == 0 || kPoseBlock % kTilePoints == 0);

// Scores hypotheses [blockIdx.x * kPoseBlock, +kPoseBlock) of `count`; writes each score to scores[h]
// when scores is not null, and the block's best to block_best[blockIdx.x]. Threads past `count` score row
// 0 (valid memory) and take part in the tiles and the reduction, but their result is NoCandidate, as is a
// score that is infinite or NaN (candidate.h: Scored).
__global__ void __launch_bounds__(kPoseBlock)
    ScorePosesKernel(const PoseSampling s, const PoseScoringParams k, const float* __restrict__ normals,
                     size_t normal_stride, const float* __restrict__ points, int num_points, int count,
                     float* __restrict__ scores, Candidate* __restrict__ block_best) {
  using BlockReduce = cub::BlockReduce<Candidate, kPoseBlock>;
  __shared__ typename BlockReduce::TempStorage reduce_storage;

  const int h = blockIdx.x * kPoseBlock + static_cast<int>(threadIdx.x);
  const bool active = h < count;
  const size_t row = active ? static_cast<size_t>(h) : 0;
  float q[4], t[3];
  PerturbPoseT<ScalarMath, float>(s, __ldg(normals + row), __ldg(normals + normal_stride + row),
                                  __ldg(normals + 2 * normal_stride + row), __ldg(normals + 3 * normal_stride + row),
                                  __ldg(normals + 4 * normal_stride + row), __ldg(normals + 5 * normal_stride + row),
                                  __ldg(normals + 6 * normal_stride + row), q, t);
  const ScaledPose p = MakeScaledPoseT<float>(q, t, k.fx, k.fy);
  const float cap = k.max_distance_px;

  // The residual loop of Algorithm 1 (the score, Eq. 6), points in order 0 .. num_points-1 as on the CPU (same float sum).
  float acc = 0.0f;
  __shared__ float tile[5][kTilePoints];
  const size_t n_all = static_cast<size_t>(num_points);
  for (int j0 = 0; j0 < num_points; j0 += kTilePoints) {
    const int n = min(kTilePoints, num_points - j0);
    __syncthreads();  // every thread is done with the previous tile
    for (int i = static_cast<int>(threadIdx.x); i < n; i += kPoseBlock) {
      const size_t j = static_cast<size_t>(j0 + i);
      tile[0][i] = __ldg(points + j);
      tile[1][i] = __ldg(points + n_all + j);
      tile[2][i] = __ldg(points + 2 * n_all + j);
      tile[3][i] = __ldg(points + 3 * n_all + j);
      tile[4][i] = __ldg(points + 4 * n_all + j);
    }
    __syncthreads();  // the tile is complete
    for (int j = 0; j < n; ++j)
      acc += ReprojectionDistanceT<ScalarMath, float, float, float>(p, tile[0][j], tile[1][j], tile[2][j], tile[3][j],
                                                                    tile[4][j], k, cap);
  }

  if (active && scores != nullptr) scores[h] = acc;
  const Candidate mine = active ? Scored(acc, h) : NoCandidate();
  const Candidate best = BlockReduce(reduce_storage).Reduce(mine, BestOfOp{});
  if (threadIdx.x == 0) block_best[blockIdx.x] = best;
}

// Second pass: the best of n block results (one block; ties to the lowest index, see candidate.h).
__global__ void __launch_bounds__(kReduceBlock)
    ReduceCandidatesKernel(const Candidate* __restrict__ in, int n, Candidate* __restrict__ out) {
  using BlockReduce = cub::BlockReduce<Candidate, kReduceBlock>;
  __shared__ typename BlockReduce::TempStorage reduce_storage;
  Candidate best = NoCandidate();
  for (int i = static_cast<int>(threadIdx.x); i < n; i += kReduceBlock) best = BestOf(best, in[i]);
  best = BlockReduce(reduce_storage).Reduce(best, BestOfOp{});
  if (threadIdx.x == 0) *out = best;
}

// Everything that lives on (or is pinned for) the device; destroyed with the kernel's device current.

struct PoseResources {
  Stream stream;
  DeviceNormalTable table;
  PinnedBuffer<float> host_points;     // 5 columns of staged points (pose_staging.h)
  int staged_count = -1;               // points in host_points; -1: none staged
  bool on_device = false;              // the staged points are in `points` too (only after a call that completed)
  long point_uploads = 0;
  long bytes_uploaded = 0;
  DeviceBuffer<float> points;          // the same, on the device
  DeviceBuffer<Candidate> block_best;  // one per block of the scoring kernel
  DeviceBuffer<Candidate> best;        // the winner
  DeviceBuffer<float> scores;          // every score, only when the caller asks for them
  PinnedBuffer<Candidate> host_best;
  long calls = 0;
};

class CudaPoseKernel final : public PoseKernel {
 public:
  explicit CudaPoseKernel(int device) : device_(device) {
    const int n = CudaDeviceCount();
    if (device < 0 || device >= n)
      throw std::runtime_error("CUDA pose kernel: no CUDA device " + std::to_string(device) + " (" +
                               (n == 0 ? CudaDeviceDescription() : std::to_string(n) + " device(s) present") + ")");
    ScopedDevice scoped(device_);
    res_ = std::make_unique<PoseResources>();
    // The per-call buffers that do not depend on the problem size, allocated now rather than on frame 1.
    res_->best.Reserve(1);
    res_->host_best.Reserve(1);
  }
  ~CudaPoseKernel() override {
    int previous = -1;
    const bool known = cudaGetDevice(&previous) == cudaSuccess;
    if (!known || previous != device_) cudaSetDevice(device_);
    res_.reset();
    if (known && previous != device_) cudaSetDevice(previous);
  }
  CudaPoseKernel(const CudaPoseKernel&) = delete;
  CudaPoseKernel& operator=(const CudaPoseKernel&) = delete;

  BackendKind kind() const override { return BackendKind::kCuda; }

  BestHypothesis Score(const PoseSampling& s, const PoseScoringPoints& pts, const PoseScoringParams& k,
                       const NormalTable& normals, int count, float* all_scores) override {
    BestHypothesis result;
    count = std::min(count, normals.count());
    if (count <= 0) return result;
    const int np = std::max(pts.count, 0);
    if (np > 0 && (!pts.x || !pts.y || !pts.z || !pts.u || !pts.v))
      throw std::invalid_argument("CUDA pose kernel: a point array (x, y, z, u or v) is null with count " +
                                  std::to_string(np));

    const std::lock_guard<std::mutex> call_lock(call_mutex_);  // one call at a time per kernel object
    ScopedDevice scoped(device_);
    PoseResources& r = *res_;
    const cudaStream_t stream = r.stream.get();
    const float* d_normals = r.table.Sync(normals, stream);

    // Stage the points as 5 columns (pinned, so the copy below is asynchronous), unless they are the ones
    // already staged.
    const bool same_points = r.staged_count >= 0 && SameAsStaged(pts, r.host_points.get(), r.staged_count);
    if (!same_points) {
      r.on_device = false;
      r.staged_count = -1;  // stays so if Reserve throws
      StagePosePoints(pts, r.host_points.Reserve(StagedPosePointFloats(np)));
      r.staged_count = np;
    }
    const float* staged = r.host_points.get();
    const size_t point_bytes = sizeof(float) * StagedPosePointFloats(np);

    const int blocks = (count + kPoseBlock - 1) / kPoseBlock;
    Candidate* d_block_best = r.block_best.Reserve(blocks);
    Candidate* d_best = r.best.Reserve(1);
    Candidate* h_best = r.host_best.Reserve(1);
    float* d_scores = all_scores != nullptr ? r.scores.Reserve(count) : nullptr;

    try {
      // The same count as the call that left them there: no reallocation, the points are still there.
      float* d_points = r.points.Reserve(std::max<size_t>(StagedPosePointFloats(np), 1));
      if (np > 0 && !(same_points && r.on_device)) {
        r.on_device = false;
        MCSLAM_CUDA_CHECK(cudaMemcpyAsync(d_points, staged, point_bytes, cudaMemcpyHostToDevice, stream));
        ++r.point_uploads;
        r.bytes_uploaded += static_cast<long>(point_bytes);
      }
      ScorePosesKernel<<<blocks, kPoseBlock, 0, stream>>>(s, k, d_normals, r.table.stride(), d_points, np, count,
                                                         d_scores, d_block_best);
      MCSLAM_CUDA_CHECK_LAUNCH("ScorePosesKernel");
      ReduceCandidatesKernel<<<1, kReduceBlock, 0, stream>>>(d_block_best, blocks, d_best);
      MCSLAM_CUDA_CHECK_LAUNCH("ReduceCandidatesKernel");
      MCSLAM_CUDA_CHECK(cudaMemcpyAsync(h_best, d_best, sizeof(Candidate), cudaMemcpyDeviceToHost, stream));
      if (all_scores != nullptr)
        MCSLAM_CUDA_CHECK(
            cudaMemcpyAsync(all_scores, d_scores, sizeof(float) * count, cudaMemcpyDeviceToHost, stream));
      r.stream.Synchronize();
      r.on_device = true;
    } catch (...) {
      // Whatever was enqueued finishes before the lock (and the staged points) can be reused; the next call
      // sends its points again.
      cudaStreamSynchronize(stream);
      r.on_device = false;
      throw;
    }
    ++r.calls;

    const Candidate best = *h_best;
    if (IsNoCandidate(best)) {  // every score infinite or NaN: no winner, as on the CPU
      result.score = std::numeric_limits<float>::infinity();
      return result;
    }
    if (best.index < 0 || best.index >= count)
      throw std::runtime_error("CUDA pose kernel: the reduction returned hypothesis " + std::to_string(best.index) +
                               " of " + std::to_string(count));
    result.index = best.index;
    result.score = best.score;
    // The winner's pose from its row on the host, by the same PerturbPose as the CPU backend.
    const int i = best.index;
    PerturbPose(s, normals.column(0)[i], normals.column(1)[i], normals.column(2)[i], normals.column(3)[i],
                normals.column(4)[i], normals.column(5)[i], normals.column(6)[i], result.q, result.t);
    return result;
  }

  CudaKernelStats Stats() const {
    CudaKernelStats st;
    const PoseResources& r = *res_;
    st.calls = r.calls;
    st.table_uploads = r.table.uploads();
    st.point_uploads = r.point_uploads;
    st.bytes_uploaded = r.bytes_uploaded;
    st.device_allocations = r.table.allocations() + r.points.allocations() + r.block_best.allocations() +
                            r.best.allocations() + r.scores.allocations();
    st.pinned_allocations = r.host_points.allocations() + r.host_best.allocations();
    return st;
  }

 private:
  int device_;
  std::mutex call_mutex_;  // the buffers and the stream serve one Score call at a time
  std::unique_ptr<PoseResources> res_;
};

}  // namespace

CudaKernelStats StatsOf(const PoseKernel& kernel) {
  const auto* k = dynamic_cast<const CudaPoseKernel*>(&kernel);
  if (k == nullptr) throw std::invalid_argument("StatsOf: not a CUDA pose kernel");
  return k->Stats();
}

}  // namespace cuda

std::unique_ptr<PoseKernel> MakeCudaPoseKernel(int device) { return std::make_unique<cuda::CudaPoseKernel>(device); }

}  // namespace mcslam::compute
