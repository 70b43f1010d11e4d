// Google Benchmark cases for the host side of the CUDA point kernel (plain C++, no GPU needed): what staging a
// keyframe's point adjustment costs the CPU, over successive keyframes' calls. The paper's claim is that the
// CPU stays free while the GPU works, so the host's share of a call matters.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <vector>

#include "compute/cuda/point_staging.h"
#include "compute/pose_fixture.h"

namespace {

using namespace mcslam;

// Successive keyframes' adjustments as `mcslam bench points --successive` makes them: the current keyframe's
// `points` points over a 12-keyframe window that moves one keyframe a call. 200 calls, cycled.
const std::vector<compute::KeyframeWindowFixture>& Calls(int points) {
  static std::vector<compute::KeyframeWindowFixture> calls;
  static int made_for = -1;
  if (made_for != points) {
    calls.clear();
    for (int c = 0; c < 200; ++c) calls.emplace_back(c, 12, points, std::max(1, points / 20));
    made_for = points;
  }
  return calls;
}

void BM_PointStagingWhole(benchmark::State& state) {
  const auto& calls = Calls(static_cast<int>(state.range(0)));
  std::vector<unsigned char> buf;
  size_t c = 0, bytes = 0;
  for (auto _ : state) {
    const compute::PointAdjustProblem pr = calls[c++ % calls.size()].Problem();
    const compute::cuda::PointStagingLayout l = compute::cuda::PlanPointStaging(pr);
    if (buf.size() < l.bytes) buf.resize(l.bytes);
    compute::cuda::StagePointProblem(pr, l, buf.data());
    benchmark::DoNotOptimize(buf.data());
    bytes += l.bytes;
  }
  state.counters["bytes_per_call"] = benchmark::Counter(static_cast<double>(bytes), benchmark::Counter::kAvgIterations);
}

BENCHMARK(BM_PointStagingWhole)->Arg(100)->Arg(400)->Arg(1000)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
