// Google Benchmark case for the bas-relief valley search of the initialisation (geometry::RelativePoseMinima, run by
// Initializer::ValleyNeighbours on every initialisation attempt that reaches a winning two-view solution): up to 53
// Levenberg-Marquardt refinements of the two views' Sampson cost, as the System calls it (at most 100 iterations
// each, radius = the views' median parallax). The scene: 50, 150 or 400 correspondences between two views of points
// 2-4 m ahead, a sideways baseline giving about 3.6 degrees of parallax (the held-out rotation seed 15's window:
// 3.7 degrees), 0.5 px noise, focal 500 px.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Geometry>

#include "core/pose.h"
#include "core/random.h"
#include "geometry/essential.h"
#include "geometry/triangulation.h"

namespace {

using namespace mcslam;

void BM_RelativePoseMinima(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const double f = 500.0;
  CounterRng rng(1, 3);
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.04, Eigen::Vector3d(0.2, 1.0, 0.1).normalized()));
  const Pose cam2_from_cam1(q, Eigen::Vector3d(-0.2, 0.02, 0.01));
  std::vector<Eigen::Vector2d> uv1, uv2;
  std::vector<double> parallax;
  const Pose views[2] = {Pose(), cam2_from_cam1};
  while (static_cast<int>(uv1.size()) < n) {
    const Eigen::Vector3d X(rng.Uniform(-1.2, 1.2), rng.Uniform(-0.9, 0.9), rng.Uniform(2.0, 4.0));
    const Eigen::Vector3d Y = cam2_from_cam1 * X;
    if (Y.z() <= 0) continue;
    uv1.push_back(X.head<2>() / X.z() + Eigen::Vector2d(rng.Normal(), rng.Normal()) * 0.5 / f);
    uv2.push_back(Y.head<2>() / Y.z() + Eigen::Vector2d(rng.Normal(), rng.Normal()) * 0.5 / f);
    parallax.push_back(geometry::ParallaxDeg(views, X));
  }
  std::nth_element(parallax.begin(), parallax.begin() + n / 2, parallax.end());
  const double radius_deg = parallax[n / 2];
  geometry::RefineOptions options;
  options.scale = f;
  options.max_iterations = 100;
  const Pose start(cam2_from_cam1.q, cam2_from_cam1.t.normalized());
  size_t minima = 0;
  for (auto _ : state) {
    const std::vector<geometry::RelativePoseMinimum> m =
        geometry::RelativePoseMinima(start, uv1, uv2, {}, radius_deg, options);
    minima = m.size();
    benchmark::DoNotOptimize(m.data());
  }
  state.counters["radius_deg"] = radius_deg;
  state.counters["minima"] = static_cast<double>(minima);
}
BENCHMARK(BM_RelativePoseMinima)->Arg(50)->Arg(150)->Arg(400)->UseRealTime()->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
