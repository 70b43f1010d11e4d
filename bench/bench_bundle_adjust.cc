// Google Benchmark case for the local bundle adjustment (System's MappingOptions::local_ba_keyframes), the largest
// part of a frame on the real sequences (docs/timing.md, docs/gpu.md): a problem of the size 7-Scenes gives it
// (28 keyframes of which the newest 8 are adjusted, ~300 points each seen by most of them, ~6,600 observations),
// 1 px noise and 5 % wrong matches, Cauchy loss, dense Schur, at most 10 iterations, as the System calls it.
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include <Eigen/Geometry>

#include "core/pose.h"
#include "core/random.h"
#include "geometry/bundle_adjust.h"

namespace {

using namespace mcslam;

struct LocalWindow {
  std::vector<Pose> cams;
  std::vector<Eigen::Vector3d> points;
  std::vector<geometry::BundleObservation> obs;
  std::vector<bool> fixed;
  geometry::BundleAdjustOptions options;
};

// Keyframes 2 cm apart on a gentle arc, looking at points 1.5-4 m ahead; the adjusted poses and the points start
// off the truth (as the next keyframe finds them: 5 mm, 0.2 degrees, 1 % of the depth).
LocalWindow MakeWindow(int keyframes, int adjusted, int points, uint64_t seed) {
  CounterRng rng(seed, 7);
  LocalWindow w;
  const double f = 525.0;
  std::vector<Pose> truth;
  for (int k = 0; k < keyframes; ++k) {
    const double a = 0.004 * k;
    const Eigen::Quaterniond q(Eigen::AngleAxisd(a, Eigen::Vector3d::UnitY()));
    const Eigen::Vector3d centre(0.02 * k, 0.002 * std::sin(0.3 * k), 0.0);
    truth.emplace_back(q.conjugate(), -(q.conjugate() * centre));
  }
  std::vector<Eigen::Vector3d> true_points;
  for (int i = 0; i < points; ++i)
    true_points.emplace_back(rng.Uniform(-1.2, 1.8), rng.Uniform(-0.9, 0.9), rng.Uniform(1.5, 4.0));
  for (int k = 0; k < keyframes; ++k) {
    Pose c = truth[k];
    if (k >= keyframes - adjusted) {
      c.t += Eigen::Vector3d(rng.Normal(), rng.Normal(), rng.Normal()) * 0.005;
      c.q = c.q * Eigen::Quaterniond(Eigen::AngleAxisd(0.0035 * rng.Normal(), Eigen::Vector3d::UnitX()));
    }
    w.cams.push_back(c);
    w.fixed.push_back(k < keyframes - adjusted);
  }
  for (int i = 0; i < points; ++i) {
    w.points.push_back(true_points[i] * (1.0 + 0.01 * rng.Normal()));
    // Seen by the keyframes of one stretch of the window (tracks begin and end), ~80 % of them.
    const int first = static_cast<int>(rng.Below(static_cast<uint32_t>(keyframes / 5 + 1)));
    for (int k = first; k < keyframes; ++k) {
      const Eigen::Vector3d p = truth[k] * true_points[i];
      Eigen::Vector2d uv = p.head<2>() / p.z() + Eigen::Vector2d(rng.Normal(), rng.Normal()) / f;
      if (rng.Uniform() < 0.05) uv += Eigen::Vector2d(rng.Uniform(-20, 20), rng.Uniform(-20, 20)) / f;
      w.obs.push_back({k, i, uv});
    }
  }
  w.options.focal_px = f;
  w.options.cauchy = true;
  w.options.huber_px = 2.385;
  w.options.max_iterations = 10;
  w.options.linear_solver = geometry::BundleAdjustOptions::LinearSolver::kDenseSchur;
  return w;
}

// Times BundleAdjust on a fresh copy of the window's cameras and points each iteration (the copy not timed).
void TimeAdjustment(benchmark::State& state, const LocalWindow& w) {
  int iterations = 0;
  double final_rms_px = 0;
  for (auto _ : state) {
    state.PauseTiming();
    std::vector<Pose> cams = w.cams;
    std::vector<Eigen::Vector3d> points = w.points;
    state.ResumeTiming();
    const geometry::BundleAdjustSummary s = geometry::BundleAdjust(cams, points, w.obs, w.fixed, w.options);
    iterations = s.iterations;
    final_rms_px = s.final_rms_px;
    benchmark::DoNotOptimize(cams.data());
  }
  state.counters["observations"] = static_cast<double>(w.obs.size());
  state.counters["lm_iterations"] = iterations;
  state.counters["final_rms_px"] = final_rms_px;
}

void BM_LocalBundleAdjust(benchmark::State& state) {
  const LocalWindow w = MakeWindow(28, 8, static_cast<int>(state.range(0)), 1);
  TimeAdjustment(state, w);
}
BENCHMARK(BM_LocalBundleAdjust)->Arg(150)->Arg(300)->Arg(600)->UseRealTime()->Unit(benchmark::kMillisecond);

// The settling of the first map (Settler::Settle): every posed frame since the reference (up to 120), all free but
// the first, and the points they share, Cauchy loss, at most 50 iterations; 7-Scenes' last settling step refines
// 114 frames and 315 points. The three linear solvers on the same problem: solver 0 sparse Schur, 1 dense Schur,
// 2 iterative Schur (as Settle runs it); final_rms_px says they reach the same fit.
void BM_SettleBundleAdjust(benchmark::State& state) {
  const int frames = static_cast<int>(state.range(0));
  LocalWindow w = MakeWindow(frames, frames - 1, 300, 2);
  w.options.max_iterations = 50;
  w.options.linear_solver = static_cast<geometry::BundleAdjustOptions::LinearSolver>(state.range(1));
  TimeAdjustment(state, w);
}
BENCHMARK(BM_SettleBundleAdjust)
    ->ArgsProduct({{40, 112}, {0, 1, 2}})
    ->ArgNames({"frames", "solver"})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
