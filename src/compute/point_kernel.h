#pragma once
// The compute layer's point interface (paper §6.2-6.3, Algorithm 2): for every map point to adjust, score
// random samples around it by their summed reprojection distance over a set of keyframes and return the
// best sample of each point. One implementation per backend.
#include <memory>

#include "compute/backend.h"
#include "compute/pose_kernel.h"
#include "compute/pose_math.h"

namespace mcslam::compute {

// Structure of arrays. Point p has centre (cx, cy, cz)[p], spread (sx, sy, sz)[p] and its observations
// obs_begin[p] .. obs_begin[p + 1] - 1; observation o is seen by keyframe obs_pose[o] (index into poses) at
// (obs_u, obs_v)[o]: undistorted pixels minus the principal point.
struct PointAdjustProblem {
  const ScaledPose* poses = nullptr;  // keyframe poses, cam_from_world, pre-scaled (MakeScaledPose)
  int num_poses = 0;
  const float* cx = nullptr;
  const float* cy = nullptr;
  const float* cz = nullptr;
  const float* sx = nullptr;
  const float* sy = nullptr;
  const float* sz = nullptr;
  const int* obs_begin = nullptr;  // num_points + 1 entries
  int num_points = 0;
  const int* obs_pose = nullptr;
  const float* obs_u = nullptr;
  const float* obs_v = nullptr;
  PoseScoringParams params;  // fx, fy, cap per observation, min depth
};

struct PointBest {
  int index = -1;  // sample index (row of the normal table; row 0 = the centre itself)
  float score = 0;
  float position[3] = {0, 0, 0};
};

class PointKernel {
 public:
  virtual ~PointKernel() = default;
  virtual BackendKind kind() const = 0;
  // Scores samples 0 .. samples-1 of every point (sample i from columns 0-2 of row i of `normals`) and
  // writes the best of each point to best[p]. Ties go to the lowest index. A point none of whose samples has
  // a finite score (only possible with an infinite cap) gets index -1, score +infinity, position untouched.
  virtual void Score(const PointAdjustProblem& problem, const NormalTable& normals, int samples, PointBest* best) = 0;
};

std::unique_ptr<PointKernel> MakeCpuPointKernel(int threads = 0);

// CUDA backend: one block per point, its threads over the samples. Defined only in builds with the CUDA
// backend (MCSLAM_WITH_CUDA); throws as MakeCudaPoseKernel does, and std::invalid_argument from Score when
// the problem is inconsistent (an observation of a pose that is not there, obs_begin decreasing; with the
// keyframe fields: some of them missing, one keyframe id for two keyframes that observations refer to, an
// observation that is not the feature it names). With the keyframe fields, keyframes stay on the device across
// calls.
std::unique_ptr<PointKernel> MakeCudaPointKernel(int device = 0);

}  // namespace mcslam::compute
