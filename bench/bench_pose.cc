// Google Benchmark cases for the pose kernel: hypotheses x points evaluations per second.
#include <benchmark/benchmark.h>

#include <vector>

#include "compute/pose_kernel.h"
#include "core/random.h"

namespace {

using namespace mcslam;

struct Scene {
  std::vector<float> x, y, z, u, v;
  compute::PoseScoringPoints View() const {
    return {x.data(), y.data(), z.data(), u.data(), v.data(), static_cast<int>(x.size())};
  }
};

// Points about 3 m in front of an identity camera (the paper's object distance), features at their
// exact projections (f = 500).
Scene MakeScene(int n) {
  CounterRng rng(3, 0);
  Scene s;
  for (int i = 0; i < n; ++i) {
    const float X = rng.Uniform(-0.5, 0.5), Y = rng.Uniform(-0.4, 0.4), Z = 3.0f + rng.Uniform(-0.3, 0.3);
    s.x.push_back(X);
    s.y.push_back(Y);
    s.z.push_back(Z);
    s.u.push_back(500.0f * X / Z);
    s.v.push_back(500.0f * Y / Z);
  }
  return s;
}

void BM_PoseKernelCpu(benchmark::State& state) {
  const int hyps = static_cast<int>(state.range(0)), pts = static_cast<int>(state.range(1));
  const Scene scene = MakeScene(pts);
  const compute::NormalTable table(hyps, 1);
  auto kernel = compute::MakeCpuPoseKernel();
  compute::PoseSampling s;
  for (int i = 0; i < 4; ++i) s.sigma_q[i] = 0.005f;
  for (int i = 0; i < 3; ++i) s.sigma_t[i] = 0.01f;
  compute::PoseScoringParams k;
  k.fx = k.fy = 500;
  for (auto _ : state) benchmark::DoNotOptimize(kernel->Score(s, scene.View(), k, table, hyps));
  state.counters["evals_per_s"] =
      benchmark::Counter(static_cast<double>(hyps) * pts, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_PoseKernelCpu)->Args({1 << 18, 50})->Args({1 << 18, 200})->Args({1 << 18, 1000})->UseRealTime()
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
