#pragma once
// Host side of the CUDA pose kernel's points: how a PoseScoringPoints is staged (5 columns x, y, z, u, v of
// `count` floats each, one pinned buffer, one copy) and whether the points of a call are the ones staged by
// the call before. The pose step scores the same points in several rounds a frame (PoseTrackerOptions::
// rounds: 3 by default), so only a frame's first round has to send them; a later round finds them on the
// device. The comparison is exact (every byte of every column), never a hash: a point set that differs
// in one bit is sent. Plain C++17: the host tests check it without a GPU.
#include <cstddef>
#include <cstring>

#include "compute/pose_kernel.h"

namespace mcslam::compute::cuda {

inline size_t StagedPosePointFloats(int count) { return 5 * static_cast<size_t>(count > 0 ? count : 0); }

// Writes the points as 5 columns into dst (StagedPosePointFloats(pts.count) floats).
inline void StagePosePoints(const PoseScoringPoints& pts, float* dst) {
  if (pts.count <= 0) return;
  const size_t n = static_cast<size_t>(pts.count);
  const float* columns[5] = {pts.x, pts.y, pts.z, pts.u, pts.v};
  for (size_t c = 0; c < 5; ++c) std::memcpy(dst + c * n, columns[c], sizeof(float) * n);
}

// True when `staged` (staged_count points, as StagePosePoints writes them) holds exactly these points.
inline bool SameAsStaged(const PoseScoringPoints& pts, const float* staged, int staged_count) {
  if (pts.count != staged_count) return false;
  if (pts.count <= 0) return true;
  if (staged == nullptr) return false;
  const size_t n = static_cast<size_t>(pts.count);
  const float* columns[5] = {pts.x, pts.y, pts.z, pts.u, pts.v};
  for (size_t c = 0; c < 5; ++c)
    if (std::memcmp(staged + c * n, columns[c], sizeof(float) * n) != 0) return false;
  return true;
}

}  // namespace mcslam::compute::cuda
