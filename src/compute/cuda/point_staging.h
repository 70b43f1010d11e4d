#pragma once
// Host side of the CUDA point kernel: the checks that keep the device from reading out of bounds (every
// call), and the layout of the one buffer that carries a whole PointAdjustProblem to the device (one copy per
// call). Plain C++17: the host tests check it without a GPU.
#include <cstddef>
#include <cstring>
#include <stdexcept>
#include <string>

#include "compute/point_kernel.h"

namespace mcslam::compute::cuda {

// Byte offsets of each section in the staged buffer (each aligned to 256 bytes, as cudaMalloc's base is).
struct PointStagingLayout {
  int num_points = 0;
  int num_poses = 0;
  int num_obs = 0;        // obs_begin[num_points] - obs_begin[0]
  int first_obs = 0;      // obs_begin[0]: the staged observations start there, obs_begin is rebased to 0
  size_t poses = 0;       // num_poses ScaledPose
  size_t centres = 0;     // 6 columns of num_points floats: cx, cy, cz, sx, sy, sz
  size_t obs_begin = 0;   // num_points + 1 ints, rebased
  size_t obs_pose = 0;    // num_obs ints
  size_t obs_u = 0;       // num_obs floats
  size_t obs_v = 0;       // num_obs floats
  size_t bytes = 0;       // total
};

inline size_t AlignStaging(size_t x) { return (x + 255) & ~size_t{255}; }

[[noreturn]] inline void FailPointProblem(const std::string& what) {
  throw std::invalid_argument("CUDA point kernel: " + what);
}

// Checks the problem (throws std::invalid_argument saying what is wrong) and plans its staging.
inline PointStagingLayout PlanPointStaging(const PointAdjustProblem& pr) {
  PointStagingLayout l;
  if (pr.num_points < 0) FailPointProblem("num_points is negative (" + std::to_string(pr.num_points) + ")");
  if (pr.num_poses < 0) FailPointProblem("num_poses is negative (" + std::to_string(pr.num_poses) + ")");
  l.num_points = pr.num_points;
  l.num_poses = pr.num_poses;
  if (l.num_points == 0) return l;
  if (!pr.cx || !pr.cy || !pr.cz || !pr.sx || !pr.sy || !pr.sz || !pr.obs_begin)
    FailPointProblem("a point array (cx, cy, cz, sx, sy, sz or obs_begin) is null");
  l.first_obs = pr.obs_begin[0];
  if (l.first_obs < 0) FailPointProblem("obs_begin[0] is negative (" + std::to_string(l.first_obs) + ")");
  for (int p = 0; p < l.num_points; ++p)
    if (pr.obs_begin[p + 1] < pr.obs_begin[p])
      FailPointProblem("obs_begin decreases at point " + std::to_string(p) + " (" + std::to_string(pr.obs_begin[p]) + " then " +
           std::to_string(pr.obs_begin[p + 1]) + ")");
  l.num_obs = pr.obs_begin[l.num_points] - l.first_obs;
  if (l.num_obs > 0) {
    if (!pr.obs_pose || !pr.obs_u || !pr.obs_v) FailPointProblem("an observation array (obs_pose, obs_u or obs_v) is null");
    if (l.num_poses > 0 && !pr.poses) FailPointProblem("poses is null");
    for (int o = l.first_obs; o < l.first_obs + l.num_obs; ++o)
      if (pr.obs_pose[o] < 0 || pr.obs_pose[o] >= l.num_poses)
        FailPointProblem("observation " + std::to_string(o) + " refers to keyframe pose " + std::to_string(pr.obs_pose[o]) +
             " of " + std::to_string(l.num_poses));
  }
  size_t at = 0;
  l.poses = at;
  at = AlignStaging(at + sizeof(ScaledPose) * static_cast<size_t>(l.num_poses));
  l.centres = at;
  at = AlignStaging(at + sizeof(float) * 6 * static_cast<size_t>(l.num_points));
  l.obs_begin = at;
  at = AlignStaging(at + sizeof(int) * (static_cast<size_t>(l.num_points) + 1));
  l.obs_pose = at;
  at = AlignStaging(at + sizeof(int) * static_cast<size_t>(l.num_obs));
  l.obs_u = at;
  at = AlignStaging(at + sizeof(float) * static_cast<size_t>(l.num_obs));
  l.obs_v = at;
  at = AlignStaging(at + sizeof(float) * static_cast<size_t>(l.num_obs));
  l.bytes = at;
  return l;
}

// Writes the problem into dst (l.bytes bytes, laid out as planned).
// The centres and spreads as 6 columns of num_points floats at `centres`, and obs_begin rebased by first_obs at
// `obs_begin`.
inline void StagePointColumns(const PointAdjustProblem& pr, int first_obs, unsigned char* centres,
                              unsigned char* obs_begin) {
  const size_t np = static_cast<size_t>(pr.num_points);
  const float* columns[6] = {pr.cx, pr.cy, pr.cz, pr.sx, pr.sy, pr.sz};
  for (int c = 0; c < 6; ++c) std::memcpy(centres + sizeof(float) * np * c, columns[c], sizeof(float) * np);
  int* begin = reinterpret_cast<int*>(obs_begin);
  for (size_t p = 0; p <= np; ++p) begin[p] = pr.obs_begin[p] - first_obs;
}

inline void StagePointProblem(const PointAdjustProblem& pr, const PointStagingLayout& l, unsigned char* dst) {
  if (l.num_points == 0) return;
  const size_t no = static_cast<size_t>(l.num_obs);
  if (l.num_poses > 0 && pr.poses) std::memcpy(dst + l.poses, pr.poses, sizeof(ScaledPose) * l.num_poses);
  StagePointColumns(pr, l.first_obs, dst + l.centres, dst + l.obs_begin);
  if (no > 0) {
    std::memcpy(dst + l.obs_pose, pr.obs_pose + l.first_obs, sizeof(int) * no);
    std::memcpy(dst + l.obs_u, pr.obs_u + l.first_obs, sizeof(float) * no);
    std::memcpy(dst + l.obs_v, pr.obs_v + l.first_obs, sizeof(float) * no);
  }
}

}  // namespace mcslam::compute::cuda
