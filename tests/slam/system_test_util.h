// Helpers of the System's tests: the paper scenario's observations and a System run on them.
#pragma once

#include <cstdint>

#include "apps/slam_job.h"
#include "sim/paper_scenario.h"
#include "slam/system.h"

namespace mcslam::slam::test {

inline apps::SequenceInput Scenario(int frames, double noise, double outliers, uint64_t seed = 1) {
  sim::PaperScenarioOptions so;
  so.frames = frames;
  so.noise_px = noise;
  so.outlier_fraction = outliers;
  so.seed = seed;
  return apps::KnownMapInputFromSequence(sim::MakePaperScenario(so));
}

// 2^16 hypotheses a frame instead of 2^18: the tests' runs at a quarter of the pose step's cost.
inline SystemOptions FastOptions() {
  SystemOptions o;
  o.tracker.hypotheses = 1 << 16;
  return o;
}

inline apps::SlamRunResult RunSystem(const apps::SequenceInput& in, const SystemOptions& options, bool gt_scale) {
  return apps::RunSlam(in, options, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel(), gt_scale);
}
inline apps::SlamRunResult RunSystem(const apps::SequenceInput& in, bool gt_scale = true) {
  return RunSystem(in, FastOptions(), gt_scale);
}

}  // namespace mcslam::slam::test
