// Google Benchmark cases for the pose kernel: hypotheses x points evaluations per second.
#include <benchmark/benchmark.h>


#include "compute/pose_fixture.h"
#include "compute/pose_kernel.h"

namespace {

using namespace mcslam;

void BM_PoseKernelCpu(benchmark::State& state) {
  const int hyps = static_cast<int>(state.range(0)), pts = static_cast<int>(state.range(1));
  // The problem `mcslam bench pose` times: points ~3 m in front of the camera, exact features.
  const compute::PoseFixture fx(pts);
  const compute::NormalTable table(hyps, 1);
  auto kernel = compute::MakeCpuPoseKernel();
  for (auto _ : state) benchmark::DoNotOptimize(kernel->Score(fx.sampling, fx.View(), fx.params, table, hyps));
  state.counters["evals_per_s"] =
      benchmark::Counter(static_cast<double>(hyps) * pts, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_PoseKernelCpu)->Args({1 << 18, 50})->Args({1 << 18, 200})->Args({1 << 18, 1000})->UseRealTime()
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
