#pragma once
// The Monte Carlo point adjustment (paper §6.3, Algorithm 2): on a keyframe, each map point it sees whose residual
// over the Fibonacci-spaced keyframe window is above the candidate threshold gets a spread from the linearised
// projection (Eq. 8 and Eq. 9), samples drawn in it are scored over the window by the point kernel (Eq. 7 and
// Eq. 10), and the best replaces the point when it fits better; a point no sample saves leaves the map.
#include <memory>

#include "compute/point_kernel.h"
#include "slam/frame_report.h"

namespace mcslam::slam {

struct SlamState;

class PointAdjuster {
 public:
  // The kernel's normal samples drawn once, from the System's seed.
  PointAdjuster(SlamState& s, std::unique_ptr<compute::PointKernel> kernel);
  void AdjustPoints(int slot, FrameReport* r);
  // For a restart: the kernel goes to the System that replaces this one.
  std::unique_ptr<compute::PointKernel> ReleaseKernel() { return std::move(kernel_); }

 private:
  SlamState& s_;
  std::unique_ptr<compute::PointKernel> kernel_;
  compute::NormalTable normals_;
};

}  // namespace mcslam::slam
