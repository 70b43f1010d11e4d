// mcslam bench: throughput of the Monte Carlo kernels, and the accuracy of the pose estimator against the
// number of hypotheses on the paper's noisy scenario.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "apps/commands.h"
#include "core/median.h"
#include "apps/known_map_job.h"
#include "apps/options.h"
#include "compute/pose_fixture.h"
#include "eval/trajectory_eval.h"

namespace mcslam::apps {

namespace {


struct PoseBenchArgs {
  int hypotheses = 1 << 18;
  std::vector<int> points{200};
  int repeats = 15;
  std::vector<std::string> backends{"cpu"};
  bool compare = false;  // --compare: the same as --backend cpu,cuda
};

const char* BackendName(compute::BackendKind kind) { return kind == compute::BackendKind::kCuda ? "cuda" : "cpu"; }

struct PoseBenchRun {
  std::string backend;
  double median_ms = 0, min_ms = 0;
  compute::BestHypothesis best;
};

// Several backends run one after the other on the same problem and table; after the first, each is
// compared with the first (time and chosen hypothesis), which makes a quick equivalence check on a GPU.
void BenchPose(const PoseBenchArgs& a) {
  const std::vector<std::string> names = a.compare ? std::vector<std::string>{"cpu", "cuda"} : a.backends;
  // Every kernel first: a backend that cannot run is an error before anything is timed.
  std::vector<std::unique_ptr<compute::PoseKernel>> kernels;
  for (const std::string& name : names) kernels.push_back(MakePoseKernelFor(name));
  for (const auto& k : kernels)
    if (k->kind() == compute::BackendKind::kCuda) {
      fmt::print("# cuda device 0: {}\n", compute::CudaDeviceDescription());
      break;
    }
  const compute::NormalTable table(a.hypotheses, 1);
  for (int np : a.points) {
    const compute::PoseFixture fx(np);
    std::vector<PoseBenchRun> runs;
    for (const auto& kernel : kernels) {
      kernel->Score(fx.sampling, fx.View(), fx.params, table, a.hypotheses);  // warm-up (and table upload)
      PoseBenchRun run;
      run.backend = BackendName(kernel->kind());
      std::vector<double> ms;
      for (int r = 0; r < a.repeats; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        run.best = kernel->Score(fx.sampling, fx.View(), fx.params, table, a.hypotheses);
        ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
        if (run.best.index < 0) throw std::runtime_error("bench: kernel returned no hypothesis");
      }
      run.median_ms = UpperMedian(ms);
      run.min_ms = *std::min_element(ms.begin(), ms.end());
      const std::string where = kernel->kind() == compute::BackendKind::kCuda
                                    ? std::string("device=0")
                                    : fmt::format("threads={}", compute::CpuThreadCount());
      fmt::print("bench pose backend={} {} hypotheses={} points={} repeats={} frame_ms_median={:.3f} "
                 "frame_ms_min={:.3f} evals_per_s={:.4g}\n",
                 run.backend, where, a.hypotheses, np, a.repeats, run.median_ms, run.min_ms,
                 double(a.hypotheses) * np / (run.median_ms * 1e-3));
      runs.push_back(run);
    }
    for (size_t i = 1; i < runs.size(); ++i) {
      const PoseBenchRun &x = runs[0], &y = runs[i];
      const double rel = std::abs(double(y.best.score) - x.best.score) / std::max(std::abs(double(x.best.score)), 1e-30);
      fmt::print("bench pose compare {}_vs_{} points={} speedup={:.2f} best_index={}/{} best_score={:.6g}/{:.6g} "
                 "score_rel_diff={:.2e}\n",
                 y.backend, x.backend, np, x.median_ms / y.median_ms, y.best.index, x.best.index, y.best.score,
                 x.best.score, rel);
    }
  }
}

struct SweepArgs {
  int min_log2 = 10, max_log2 = 20;
  sim::PaperScenarioOptions scenario;
  PoseFlags pose;
  std::string backend = "cpu";
};

void BenchSweep(SweepArgs a) {
  if (a.min_log2 > a.max_log2) throw std::invalid_argument("--min-log2 must not exceed --max-log2");
  a.scenario.Check();
  const KnownMapInput input = KnownMapInputFromSequence(sim::MakePaperScenario(a.scenario));
  fmt::print("# noisy paper scenario: {} frames, noise {} px, outliers {}, seed {}, random={}, rounds={}\n",
             a.scenario.frames, a.scenario.noise_px, a.scenario.outlier_fraction, a.scenario.seed, a.pose.random,
             a.pose.tracker.rounds);
  fmt::print("{:>10} {:>8} {:>14} {:>14} {:>12} {:>8}\n", "hypotheses", "log2", "trans_mean_m", "rot_mean_deg",
             "frame_ms", "lost");
  for (int l = a.min_log2; l <= a.max_log2; ++l) {
    PoseFlags flags = a.pose;
    flags.tracker.hypotheses = 1 << l;
    slam::KnownMapOptions options;
    options.tracker = flags.Resolve();
    const auto results = RunKnownMap(input, options, MakePoseKernelFor(a.backend));
    std::vector<double> ms;
    int lost = 0;
    for (const auto& r : results)
      if (!r.given) ms.push_back(r.time_ms), lost += !r.estimate.tracked;
    eval::EvalOptions eo;
    eo.alignment = eval::Alignment::kNone;
    const auto err = eval::EvaluateTrajectory(input.groundtruth, ResultsToTrajectory(results, false), eo);
    fmt::print("{:>10} {:>8} {:>14.6f} {:>14.5f} {:>12.3f} {:>8}\n", 1 << l, l, err.ate_m.mean, err.rot_deg.mean,
               UpperMedian(ms), lost);
  }
}

}  // namespace

void RegisterBench(CLI::App& app) {
  CLI::App* bench = app.add_subcommand("bench", "Benchmarks of the Monte Carlo kernels (figures are medians)");
  bench->require_subcommand(1);

  auto pa = std::make_shared<PoseBenchArgs>();
  CLI::App* pose = bench->add_subcommand("pose", "Pose kernel: time per frame and hypothesis x point evaluations/s");
  pose->add_option("--hypotheses", pa->hypotheses, "Hypotheses per frame")->check(CLI::Range(1, 1 << 26))->capture_default_str();
  pose->add_option("--points", pa->points, "Map points scored (several values: one line each)")
      ->check(CLI::Range(1, 1 << 20))
      ->capture_default_str();
  pose->add_option("--repeats", pa->repeats, "Timed repetitions")->check(CLI::Range(1, 10000))->capture_default_str();
  CLI::Option* backend =
      pose->add_option("--backend", pa->backends,
                       "Compute backend: cpu, cuda or auto (cuda when a GPU is present); several, comma-separated "
                       "(cpu,cuda), run side by side on the same problem and are compared")
          ->delimiter(',')
          ->check(CLI::IsMember({"cpu", "cuda", "auto"}))
          ->capture_default_str();
  pose->add_flag("--compare", pa->compare, "CPU and CUDA side by side (the same as --backend cpu,cuda)")
      ->excludes(backend);
  pose->callback([pa] { BenchPose(*pa); });

  auto sa = std::make_shared<SweepArgs>();
  sa->scenario.noise_px = 1.0;
  sa->scenario.outlier_fraction = 0.1;
  sa->scenario.frames = 150;
  CLI::App* sweep = bench->add_subcommand(
      "sweep", "Mean translation and rotation error of known-map tracking on the noisy paper scenario against 2^k hypotheses");
  sweep->add_option("--min-log2", sa->min_log2, "Smallest log2(hypotheses)")->check(CLI::Range(1, 24))->capture_default_str();
  sweep->add_option("--max-log2", sa->max_log2, "Largest log2(hypotheses)")->check(CLI::Range(1, 24))->capture_default_str();
  sweep->add_option("--frames", sa->scenario.frames, "Frames of the scenario")->check(CLI::PositiveNumber)->capture_default_str();
  sweep->add_option("--noise", sa->scenario.noise_px, "Pixel noise sigma")->check(CLI::NonNegativeNumber)->capture_default_str();
  sweep->add_option("--outliers", sa->scenario.outlier_fraction, "Outlier fraction")->check(CLI::Range(0.0, 1.0))->capture_default_str();
  sweep->add_option("--scenario-seed", sa->scenario.seed, "Seed of the scenario")->capture_default_str();
  sa->pose.Add(sweep);
  AddBackendFlag(sweep, &sa->backend);
  sweep->callback([sa] { BenchSweep(*sa); });
}

}  // namespace mcslam::apps
