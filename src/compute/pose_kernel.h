#pragma once
// The compute layer's pose interface (paper §5, §7.1): score every pose hypothesis against the map points
// that take part and return the best one. One implementation per backend.
#include <cstdint>
#include <memory>
#include <vector>

#include "compute/backend.h"
#include "compute/pose_math.h"

namespace mcslam::compute {

// The map points that take part in the score, structure of arrays. x, y, z: the point in the world;
// u, v: its tracked feature in this frame, undistorted pixels minus the principal point.
struct PoseScoringPoints {
  const float* x = nullptr;
  const float* y = nullptr;
  const float* z = nullptr;
  const float* u = nullptr;
  const float* v = nullptr;
  int count = 0;
};

// Standard-normal numbers, 7 per hypothesis (4 for omega, 3 for tau), as 7 columns of `count` floats.
// Row 0 is all zeros so that the sampling centre itself is always one of the hypotheses.
class NormalTable {
 public:
  NormalTable() = default;
  // The paper's table: made once from the seed (Philox, stream `stream`), reused every frame.
  NormalTable(int count, uint64_t seed, uint32_t stream = 0);
  // Refill every entry from (seed, stream, epoch): a fresh table per frame when epoch is the frame index.
  void Fill(uint64_t seed, uint32_t stream, uint64_t epoch);
  int count() const { return count_; }
  const float* column(int k) const { return data_.data() + static_cast<size_t>(k) * stride_; }
  float* column(int k) { return data_.data() + static_cast<size_t>(k) * stride_; }

 private:
  int count_ = 0;
  size_t stride_ = 0;  // padded to 16 floats
  std::vector<float> data_;
};

struct BestHypothesis {
  int index = -1;            // row of the normal table; -1 when nothing was scored
  float score = 0;           // summed capped distance, px
  float q[4] = {1, 0, 0, 0};  // the hypothesis, cam_from_world, (w, x, y, z)
  float t[3] = {0, 0, 0};
};

class PoseKernel {
 public:
  virtual ~PoseKernel() = default;
  virtual BackendKind kind() const = 0;
  // Scores hypotheses 0 .. count-1 (count <= normals.count()), hypothesis i made by PerturbPose from row i.
  // Returns the lowest score; ties go to the lowest index, so the result does not depend on threading. No
  // winner (index -1, score +infinity) when no score is finite (only possible with an infinite cap).
  // When all_scores is not null it receives every score (count floats).
  virtual BestHypothesis Score(const PoseSampling& sampling, const PoseScoringPoints& points,
                               const PoseScoringParams& params, const NormalTable& normals, int count,
                               float* all_scores = nullptr) = 0;
};

// A frame's pose search in rounds (PoseTrackerOptions::rounds): `hypotheses` in all, round r scoring
// hypotheses / rounds of them (the last round the rest) around the best so far, with the spreads sigma_q and
// sigma_t times shrink^r. Row 0 of the table is zero, so the centre is scored again in every round and a round
// never ends worse than the one before. rounds = 1 is the paper's one-shot sampling. Returns the last round's
// best (index -1 as soon as a round has no winner). The points are the same in every round: a device
// backend sends them once (compute/cuda/pose_staging.h).
BestHypothesis ScoreInRounds(PoseKernel& kernel, PoseSampling centre, const double sigma_q[4],
                             const double sigma_t[3], const PoseScoringPoints& points,
                             const PoseScoringParams& params, const NormalTable& normals, int hypotheses, int rounds,
                             double shrink);

// CPU backend: every core (oneTBB), hypotheses vectorised across SIMD lanes. threads <= 0: all cores.
std::unique_ptr<PoseKernel> MakeCpuPoseKernel(int threads = 0);

// CUDA backend (paper §7.1): one thread per hypothesis on CUDA device `device`. The table is kept on the
// device and uploaded again when it changes: a refill (Fill) or another table; a few entries edited in place
// may go unseen (compute/cuda/table_key.h). Score calls on one object are serialised. Defined only in
// builds with the CUDA backend (MCSLAM_WITH_CUDA); throws std::runtime_error when the device is not there,
// and from Score on any CUDA error (naming the call and cudaGetErrorString).
std::unique_ptr<PoseKernel> MakeCudaPoseKernel(int device = 0);

}  // namespace mcslam::compute
