// mcslam bench: throughput of the Monte Carlo kernels (pose, points), and the accuracy of the pose estimator against the
// number of hypotheses on the paper's noisy scenario.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include "apps/commands.h"
#include "core/median.h"
#include "apps/known_map_job.h"
#include "apps/options.h"
#include "compute/cuda/cuda_kernels.h"
#include "compute/pose_fixture.h"
#include "slam/system.h"
#include "eval/trajectory_eval.h"

namespace mcslam::apps {

namespace {

// --backend cpu,cuda,auto (several: side by side on the same problem) or --compare (cpu,cuda).
struct BenchBackends {
  std::vector<std::string> backends{"cpu"};
  bool compare = false;
  std::vector<std::string> Names() const { return compare ? std::vector<std::string>{"cpu", "cuda"} : backends; }
};

void AddBenchBackendFlags(CLI::App* cmd, BenchBackends* b) {
  CLI::Option* backend =
      cmd->add_option("--backend", b->backends,
                      "Compute backend: cpu, cuda or auto (cuda when a GPU is present); several, comma-separated "
                      "(cpu,cuda), run side by side on the same problem and are compared")
          ->delimiter(',')
          ->check(CLI::IsMember({"cpu", "cuda", "auto"}))
          ->capture_default_str();
  cmd->add_flag("--compare", b->compare, "CPU and CUDA side by side (the same as --backend cpu,cuda)")->excludes(backend);
}

void AddWarmFlag(CLI::App* cmd, double* warm_s) {
  cmd->add_option("--warm-s", *warm_s,
                  "Seconds of untimed calls before the timed ones (at least one call): an idle GPU or CPU needs a "
                  "moment of load to reach its clocks")
      ->check(CLI::Range(0.0, 60.0))
      ->capture_default_str();
}

const char* BackendName(compute::BackendKind kind) { return kind == compute::BackendKind::kCuda ? "cuda" : "cpu"; }

// Every kernel first, so that a backend that cannot run is an error before anything is timed; then the
// device's name when one of them runs on it.
template <typename Kernel, typename Make>
std::vector<std::unique_ptr<Kernel>> MakeBenchKernels(const BenchBackends& b, Make make) {
  std::vector<std::unique_ptr<Kernel>> kernels;
  for (const std::string& name : b.Names()) kernels.push_back(make(name));
  for (const auto& k : kernels)
    if (k->kind() == compute::BackendKind::kCuda) {
      fmt::print("# cuda device 0: {}\n", compute::CudaDeviceDescription());
      break;
    }
  return kernels;
}

std::string Where(compute::BackendKind kind) {
  return kind == compute::BackendKind::kCuda ? std::string("device=0")
                                             : fmt::format("threads={}", compute::CpuThreadCount());
}

struct CallTimes {
  double median_ms = 0, min_ms = 0;
};

// Untimed calls first, for at least `warm_s` seconds (and at least one call: the first uploads the normal
// table to a device and grows its buffers; an idle GPU needs some time of load before it runs at its clocks,
// and a short benchmark would otherwise time the ramp), then `repeats` timed ones: wall time of the whole
// call, so on a device it includes staging and transfers. call(i) is given i = -1 in the warm-up and
// 0 .. repeats-1 when timed.
template <typename Call>
CallTimes TimeCalls(int repeats, double warm_s, Call&& call) {
  const auto warm_start = std::chrono::steady_clock::now();
  do call(-1);
  while (std::chrono::duration<double>(std::chrono::steady_clock::now() - warm_start).count() < warm_s);
  std::vector<double> ms;
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    call(r);
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  return {UpperMedian(ms), *std::min_element(ms.begin(), ms.end())};
}

double RelDiff(double a, double b) { return std::abs(a - b) / std::max(std::abs(b), 1e-30); }

struct PoseBenchArgs : BenchBackends {
  int hypotheses = 1 << 18;
  std::vector<int> points{200};
  int repeats = 15;
  double warm_s = 0.5;
  int rounds = 1;  // the paper's one-shot sampling; `mcslam run` uses PoseTrackerOptions::rounds
};

// Several backends run one after the other on the same problem and table; after the first, each is
// compared with the first (time, and the scores they give every hypothesis of the last call's first round),
// which makes a quick equivalence check on a GPU.
void BenchPose(const PoseBenchArgs& a) {
  if (a.rounds > a.hypotheses)
    throw std::invalid_argument(fmt::format("--rounds ({}) must not exceed --hypotheses ({})", a.rounds, a.hypotheses));
  const auto kernels = MakeBenchKernels<compute::PoseKernel>(a, MakePoseKernelFor);
  const compute::NormalTable table(a.hypotheses, 1);
  for (int np : a.points) {
    // A tracking frame's problem (the camera moved from the prior, noisy features, outliers): the winner is
    // a sampled hypothesis, as in a run. Two point sets in turn, as frames bring new features: a device
    // backend keeps the points of its last call and sends only new ones, so scoring one set again and again
    // would time no transfer at all. They differ in one feature by 1e-3 px; the timed calls are the same on
    // every backend, so the last (the one compared) scores the same set.
    compute::PoseFixture fx(np);
    fx.MoveCamera();
    compute::PoseFixture fx_next = fx;
    fx_next.u[0] += 1e-3f;
    const auto sampling = [](const compute::PoseFixture& f, double sq[4], double st[3]) {
      for (int k = 0; k < 4; ++k) sq[k] = f.sampling.sigma_q[k];
      for (int k = 0; k < 3; ++k) st[k] = f.sampling.sigma_t[k];
    };
    struct Run {
      CallTimes t;
      compute::BestHypothesis best;
      std::vector<float> scores;  // every hypothesis of the compared set's first round
    };
    std::vector<Run> runs;
    for (const auto& kernel : kernels) {
      Run run;
      const compute::PoseFixture* last = &fx;
      run.t = TimeCalls(a.repeats, a.warm_s, [&](int i) {
        last = i % 2 == 0 ? &fx_next : &fx;  // the warm-up (i = -1) and odd calls: fx
        double sq[4], st[3];
        sampling(*last, sq, st);
        run.best = compute::ScoreInRounds(*kernel, last->sampling, sq, st, last->View(), last->params, table,
                                          a.hypotheses, a.rounds, slam::PoseTrackerOptions{}.round_shrink);
        if (run.best.index < 0) throw std::runtime_error("bench: kernel returned no hypothesis");
      });
      fmt::print("bench pose backend={} {} hypotheses={} points={} rounds={} repeats={} frame_ms_median={:.3f} "
                 "frame_ms_min={:.3f} evals_per_s={:.4g}\n",
                 BackendName(kernel->kind()), Where(kernel->kind()), a.hypotheses, np, a.rounds, a.repeats, run.t.median_ms,
                 run.t.min_ms, double(a.hypotheses) * np / (run.t.median_ms * 1e-3));
      const int first_round = a.hypotheses / a.rounds;
      run.scores.resize(static_cast<size_t>(first_round));
      kernel->Score(last->sampling, last->View(), last->params, table, first_round, run.scores.data());
      runs.push_back(std::move(run));
    }
    for (size_t i = 1; i < runs.size(); ++i) {
      const Run &x = runs[0], &y = runs[i];
      // The largest difference of a hypothesis's score between the two, per point (px): float rounding in a
      // different order; and the gap between the two winners' scores, per point.
      double worst = 0;
      for (size_t h = 0; h < x.scores.size(); ++h)
        worst = std::max(worst, std::abs(double(y.scores[h]) - double(x.scores[h])) / std::max(np, 1));
      fmt::print("bench pose compare {}_vs_{} points={} speedup={:.2f} best_index={}/{} best_score={:.6g}/{:.6g} "
                 "winner_gap_px_per_point={:.2e} score_diff_px_per_point_max={:.2e}\n",
                 BackendName(kernels[i]->kind()), BackendName(kernels[0]->kind()), np, x.t.median_ms / y.t.median_ms,
                 y.best.index, x.best.index, y.best.score, x.best.score,
                 std::abs(double(y.best.score) - double(x.best.score)) / std::max(np, 1), worst);
    }
  }
}

// The point-adjustment kernel on the shape of one keyframe's adjustment: every point seen by
// every keyframe of the window, the System's samples per point and window size by default. --successive:
// the adjustments of successive keyframes instead, as a run makes them (compute::KeyframeWindowFixture): each
// call's window one keyframe on, the current keyframe's `points` points adjusted over the keyframes that see
// them (each keyframe sees a twentieth of its points fewer than the next).
struct PointBenchArgs : BenchBackends {
  std::vector<int> points{400};
  int samples = slam::MappingOptions{}.samples;
  int window = slam::MappingOptions{}.window;
  int repeats = 15;
  double warm_s = 0.5;
  bool successive = false;
};

// Bytes a CUDA kernel has sent so far (the normal table's excepted); -1 for another backend.
long BytesSent(const compute::PointKernel& kernel) {
#ifdef MCSLAM_WITH_CUDA
  if (kernel.kind() == compute::BackendKind::kCuda) return compute::cuda::StatsOf(kernel).bytes_uploaded;
#endif
  (void)kernel;
  return -1;
}

void BenchPoints(const PointBenchArgs& a) {
  const auto kernels = MakeBenchKernels<compute::PointKernel>(a, MakePointKernelFor);
  const compute::NormalTable table(a.samples, 1);
  for (int np : a.points) {
    // The problems of the calls in turn: one (the same every call), or one per call (the warm-up's first).
    std::vector<compute::KeyframeWindowFixture> successive;
    if (a.successive)
      for (int c = 0; c <= a.repeats; ++c)
        successive.emplace_back(c, a.window, np, std::max(1, np / 20));
    const compute::PointFixture fx(a.successive ? 0 : np, a.window, compute::PointFixture::Views::kAll);
    const int observations = a.successive ? successive.back().observations() : fx.observations();
    const double evals = double(a.samples) * observations;
    std::vector<std::pair<CallTimes, std::vector<compute::PointBest>>> runs;
    for (const auto& kernel : kernels) {
      std::vector<compute::PointBest> best(np);
      long bytes_timed = 0;  // bytes sent before the first timed call (after the warm-up)
      const CallTimes t = TimeCalls(a.repeats, a.warm_s, [&](int i) {
        if (i == 0) bytes_timed = BytesSent(*kernel);
        // The warm-up repeats the first problem; timed call i makes the adjustment of the keyframe after.
        const compute::PointAdjustProblem pr =
            a.successive ? successive[static_cast<size_t>(i + 1)].Problem() : fx.Problem();
        kernel->Score(pr, table, a.samples, best.data());
      });
      for (const compute::PointBest& b : best)
        if (b.index < 0) throw std::runtime_error("bench: kernel returned no sample for a point");
      const long bytes = BytesSent(*kernel);
      fmt::print("bench points backend={} {} points={} keyframes={} observations={} samples={} {}repeats={} "
                 "call_ms_median={:.3f} call_ms_min={:.3f} evals_per_s={:.4g}{}\n",
                 BackendName(kernel->kind()), Where(kernel->kind()), np, a.window, observations, a.samples,
                 a.successive ? "calls=successive " : "", a.repeats, t.median_ms, t.min_ms,
                 evals / (t.median_ms * 1e-3),
                 bytes < 0 ? std::string() : fmt::format(" bytes_sent_per_call={}", (bytes - bytes_timed) / a.repeats));
      runs.emplace_back(t, std::move(best));
    }
    for (size_t i = 1; i < runs.size(); ++i) {
      const auto &[tx, x] = runs[0];
      const auto &[ty, y] = runs[i];
      int same = 0;
      double worst = 0;
      for (int p = 0; p < np; ++p) {
        same += x[p].index == y[p].index;
        worst = std::max(worst, RelDiff(y[p].score, x[p].score));
      }
      fmt::print("bench points compare {}_vs_{} points={} speedup={:.2f} same_best={}/{} score_rel_diff_max={:.2e}\n",
                 BackendName(kernels[i]->kind()), BackendName(kernels[0]->kind()), np, tx.median_ms / ty.median_ms,
                 same, np, worst);
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
  CLI::App* bench = app.add_subcommand("bench", "Benchmarks: the Monte Carlo kernels, the pose estimator's accuracy, long runs (figures are medians)");
  bench->require_subcommand(1);

  auto pa = std::make_shared<PoseBenchArgs>();
  CLI::App* pose = bench->add_subcommand("pose", "Pose kernel: time per frame and hypothesis x point evaluations/s");
  pose->add_option("--hypotheses", pa->hypotheses, "Hypotheses per frame")->check(CLI::Range(1, 1 << 26))->capture_default_str();
  pose->add_option("--points", pa->points, "Map points scored (several values: one line each)")
      ->check(CLI::Range(1, 1 << 20))
      ->capture_default_str();
  pose->add_option("--repeats", pa->repeats, "Timed repetitions")->check(CLI::Range(1, 10000))->capture_default_str();
  AddWarmFlag(pose, &pa->warm_s);
  pose->add_option("--rounds", pa->rounds,
                   "Sampling rounds a frame, the hypotheses split among them as `mcslam run --rounds` does (1: the "
                   "paper's one-shot sampling; run's default is 3)")
      ->check(CLI::Range(1, 16))
      ->capture_default_str();
  AddBenchBackendFlags(pose, pa.get());
  pose->callback([pa] { BenchPose(*pa); });

  auto qa = std::make_shared<PointBenchArgs>();
  CLI::App* points = bench->add_subcommand(
      "points", "Point-adjustment kernel: time per call (one keyframe's adjustment) and sample x observation evaluations/s");
  points->add_option("--points", qa->points, "Points adjusted, each seen by every keyframe (several values: one line each)")
      ->check(CLI::Range(1, 1 << 20))
      ->capture_default_str();
  points->add_option("--samples", qa->samples, "Samples per point (the System's default)")
      ->check(CLI::Range(1, 1 << 22))
      ->capture_default_str();
  points->add_option("--window", qa->window, "Keyframes in the window (the System's default)")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  points->add_option("--repeats", qa->repeats, "Timed repetitions")->check(CLI::Range(1, 10000))->capture_default_str();
  AddWarmFlag(points, &qa->warm_s);
  points->add_flag("--successive", qa->successive,
                   "Time successive keyframes' adjustments, as a run makes them (the window one keyframe on each "
                   "call, each keyframe seeing a twentieth of the points fewer than the next), instead of one "
                   "adjustment repeated");
  AddBenchBackendFlags(points, qa.get());
  points->callback([qa] { BenchPoints(*qa); });

  auto sa = std::make_shared<SweepArgs>();
  sa->scenario.noise_px = 1.0;
  sa->scenario.outlier_fraction = 0.1;
  sa->scenario.frames = 150;
  CLI::App* sweep = bench->add_subcommand(
      "sweep", "Mean translation and rotation error of known-map tracking on the noisy paper scenario against 2^k hypotheses");
  sweep->add_option("--min-log2", sa->min_log2, "Smallest log2(hypotheses)")->check(CLI::Range(1, 24))->capture_default_str();
  sweep->add_option("--max-log2", sa->max_log2, "Largest log2(hypotheses)")->check(CLI::Range(1, 24))->capture_default_str();
  sweep->add_option("--frames", sa->scenario.frames, "Frames of the scenario")->check(Positive())->capture_default_str();
  sweep->add_option("--noise", sa->scenario.noise_px, "Pixel noise sigma")->check(NonNegative())->capture_default_str();
  sweep->add_option("--outliers", sa->scenario.outlier_fraction, "Outlier fraction")->check(Between(0.0, 1.0))->capture_default_str();
  sweep->add_option("--scenario-seed", sa->scenario.seed, "Seed of the scenario")->capture_default_str();
  sa->pose.Add(sweep);
  AddBackendFlag(sweep, &sa->backend);
  sweep->callback([sa] { BenchSweep(*sa); });

  RegisterBenchSoak(bench);
}

}  // namespace mcslam::apps
