#pragma once
// A synthetic scoring problem for benchmarks and backend-equivalence tests: `count` points on a 1 m object
// about 3 m in front of an identity camera (the paper's set-up), features at their exact projections.
#include <cmath>
#include <vector>

#include "compute/pose_kernel.h"
#include "core/random.h"

namespace mcslam::compute {

struct PoseFixture {
  std::vector<float> x, y, z, u, v;
  PoseSampling sampling;
  PoseScoringParams params;

  explicit PoseFixture(int count, uint64_t seed = 3, float focal_px = 500.0f) {
    CounterRng rng(seed, 0);
    for (int i = 0; i < count; ++i) {
      const float X = static_cast<float>(rng.Uniform(-0.5, 0.5)), Y = static_cast<float>(rng.Uniform(-0.4, 0.4));
      const float Z = 3.0f + static_cast<float>(rng.Uniform(-0.3, 0.3));
      x.push_back(X), y.push_back(Y), z.push_back(Z);
      u.push_back(focal_px * X / Z), v.push_back(focal_px * Y / Z);
    }
    params.fx = params.fy = focal_px;
    for (float& s : sampling.sigma_q) s = 0.0087f;  // ~1 degree per axis
    for (float& s : sampling.sigma_t) s = 0.01f;    // 1 cm
  }
  PoseScoringPoints View() const {
    return {x.data(), y.data(), z.data(), u.data(), v.data(), static_cast<int>(x.size())};
  }
};

// Keyframes for point-kernel tests and benchmarks: five cameras 3 m from the origin, looking at it from a
// 7-degree arc (rotations of -0.06 .. 0.06 rad about y), with f = 500 px and a 50 px cap.
struct ArcCameras {
  std::vector<ScaledPose> poses;
  PoseScoringParams params;

  ArcCameras() {
    params.fx = params.fy = 500.0f;
    params.max_distance_px = 50.0f;
    for (int i = 0; i < 5; ++i) {
      const float a = 0.03f * (i - 2);
      const float q[4] = {std::cos(a / 2), 0.0f, std::sin(a / 2), 0.0f};
      const float t[3] = {0.0f, 0.0f, 3.0f};
      poses.push_back(MakeScaledPose(q, t, params.fx, params.fy));
    }
  }
};

}  // namespace mcslam::compute
