// mcslam bench soak: a long run (10,000 frames by default) of a synthetic scenario through the whole pipeline, to
// see that the time a frame takes and the memory the process holds stay bounded (issues #18 and #20). Frames are
// rendered one at a time as the run goes (so the images' memory does not grow with the run), or, with
// --observations, the scenario's exact feature observations go to the back end alone. Every window of frames
// prints its per-frame time (median, 95th percentile), the tracked frames, the map's size and the process's
// resident memory; the last line compares the last window with the first.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "apps/commands.h"
#include "apps/known_map_job.h"
#include "apps/options.h"
#include "core/median.h"
#include "eval/trajectory_eval.h"
#include "pipeline/visual_slam.h"
#include "sim/render.h"
#include "sim/scenarios.h"
#include "slam/system.h"

namespace mcslam::apps {

namespace {

struct SoakArgs {
  std::string scenario = "paper";
  int frames = 10000;
  int window = 1000;
  uint64_t seed = 1;
  bool observations = false;
  bool merge_revisited_points = slam::MappingOptions{}.merge_revisited_points;
  std::string backend = "cpu";
  std::string csv;
};

// A field of /proc/self/status ("VmRSS:", "VmHWM:", in kB) in MiB; nullopt where the kernel has no such file.
std::optional<double> ProcStatusMiB(const char* field) {
  const std::optional<uint64_t> kb = ReadNumberFile("/proc/self/status", field);
  if (!kb) return std::nullopt;
  return static_cast<double>(*kb) / 1024.0;
}

struct Window {
  int first = 0, last = 0;
  double median_ms = 0, p95_ms = 0;
  int tracked = 0, map_points = 0;
  double rss_mib = 0;
  // Medians of the parts of a frame (rendered images only; 0 otherwise): the front end, its remapping (frames
  // with requests), the back end; and the remap requests a frame.
  double frontend_ms = 0, remap_ms = 0, backend_ms = 0, remap_requests = 0;
};

void BenchSoak(const SoakArgs& a) {
  if (a.window > a.frames)
    throw std::invalid_argument(fmt::format("--window {} is longer than --frames {}", a.window, a.frames));
  sim::ScenarioOptions so;
  so.name = a.scenario;
  so.frames = a.frames;
  so.seed = a.seed;
  so.Check();
  const sim::SyntheticSequence seq = sim::MakeScenario(so);
  const std::vector<FrameObservations> obs = a.observations ? ToSlamFrames(sim::ToObservationFrames(seq))
                                                            : std::vector<FrameObservations>{};
  std::optional<sim::SceneRenderer> renderer;
  std::unique_ptr<pipeline::VisualSlam> vslam;
  std::unique_ptr<slam::System> system;
  slam::SystemOptions sys_opts;
  sys_opts.seed = a.seed;
  sys_opts.mapping.merge_revisited_points = a.merge_revisited_points;
  if (a.observations) {
    system = std::make_unique<slam::System>(seq.camera, sys_opts, MakePoseKernelFor(a.backend),
                                            MakePointKernelFor(a.backend));
  } else {
    sim::RenderOptions ro;
    ro.seed = a.seed;
    renderer.emplace(seq.scene, ro);
    pipeline::VisualSlamOptions vo;
    vo.system = sys_opts;
    vslam = std::make_unique<pipeline::VisualSlam>(seq.camera, vo, MakePoseKernelFor(a.backend),
                                                   MakePointKernelFor(a.backend));
  }
  fmt::print("# bench soak: scenario {} seed {}, {} frames, {}, backend {}, default options; per-frame time excludes "
             "{}\n",
             a.scenario, a.seed, a.frames, a.observations ? "observations to the back end" : "rendered images",
             a.backend, a.observations ? "nothing" : "rendering");
  fmt::print("{:>6} {:>6} {:>12} {:>10} {:>8} {:>11} {:>9} {:>12} {:>9} {:>11} {:>15}\n", "first", "last",
             "median_ms", "p95_ms", "tracked", "map_points", "rss_mib", "frontend_ms", "remap_ms", "backend_ms",
             "remap_requests");

  InstallInterruptHandler();
  std::map<int64_t, Pose> posed;  // index -> cam_from_world, the latest report's
  std::vector<Window> windows;
  std::vector<double> ms, fe_ms, remap_ms, be_ms, requests;
  Window w;
  double render_ms_sum = 0;
  int tracked_all = 0, done = 0;
  using Clock = std::chrono::steady_clock;
  for (int i = 0; i < a.frames && !Interrupted(); ++i) {
    std::vector<slam::FrameReport> reports;
    if (a.observations) {
      const auto t0 = Clock::now();
      reports = system->Process(obs[static_cast<size_t>(i)]);
      ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      w.map_points = system->map().CountInState(slam::PointState::kActive) +
                     system->map().CountInState(slam::PointState::kLost);
    } else {
      const auto r0 = Clock::now();
      const cv::Mat image = renderer->Render(seq.camera, seq.cam_from_world[static_cast<size_t>(i)],
                                             static_cast<uint64_t>(i));
      const auto t0 = Clock::now();
      render_ms_sum += std::chrono::duration<double, std::milli>(t0 - r0).count();
      pipeline::VisualSlamStep step = vslam->Process(image, i, seq.stamps_s[static_cast<size_t>(i)]);
      ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      fe_ms.push_back(step.frontend.stats.total_ms);
      if (step.frontend.stats.remap_requests > 0) remap_ms.push_back(step.frontend.stats.remap_ms);
      be_ms.push_back(step.backend_ms);
      requests.push_back(step.frontend.stats.remap_requests);
      reports = std::move(step.reports);
      w.map_points = vslam->system().map().CountInState(slam::PointState::kActive) +
                     vslam->system().map().CountInState(slam::PointState::kLost);
    }
    for (const slam::FrameReport& r : reports)
      if (r.has_pose) posed[r.index] = r.cam_from_world;
    for (const slam::FrameReport& r : reports)
      if (r.index == i && r.status == slam::FrameStatus::kTracked) ++w.tracked, ++tracked_all;
    ++done;
    if (static_cast<int>(ms.size()) == a.window || i + 1 == a.frames) {
      w.first = i + 1 - static_cast<int>(ms.size());
      w.last = i;
      w.median_ms = UpperMedian(ms);
      w.p95_ms = Quantile(ms, 0.95);
      w.rss_mib = ProcStatusMiB("VmRSS:").value_or(0);
      auto median = [](const std::vector<double>& v) { return v.empty() ? 0.0 : UpperMedian(v); };
      w.frontend_ms = median(fe_ms);
      w.remap_ms = median(remap_ms);
      w.backend_ms = median(be_ms);
      w.remap_requests = median(requests);
      fe_ms.clear(), remap_ms.clear(), be_ms.clear(), requests.clear();
      fmt::print("{:>6} {:>6} {:>12.3f} {:>10.3f} {:>8} {:>11} {:>9.1f} {:>12.3f} {:>9.3f} {:>11.3f} {:>15.0f}\n",
                 w.first, w.last, w.median_ms, w.p95_ms, w.tracked, w.map_points, w.rss_mib, w.frontend_ms,
                 w.remap_ms, w.backend_ms, w.remap_requests);
      std::fflush(stdout);
      windows.push_back(w);
      w = Window{};
      ms.clear();
    }
  }
  if (windows.empty()) throw InterruptedError();

  // The whole trajectory against the truth (Sim(3)): a long run that stays fast by drifting away is no success.
  io::Trajectory est;
  for (const auto& [index, cam_from_world] : posed) {
    est.stamps_s.push_back(seq.stamps_s[static_cast<size_t>(index)]);
    est.world_from_cam.push_back(cam_from_world.Inverse());
  }
  std::string accuracy = " ate_rmse_m=nan ate_over_path=nan";
  if (est.size() >= 3) {
    const io::Trajectory gt = sim::ToTrajectory(seq);
    const eval::TrajectoryErrors err = eval::EvaluateTrajectory(gt, est, {});
    accuracy = fmt::format(" ate_rmse_m={:.6g} ate_over_path={:.3g}", err.ate_m.rmse,
                           err.ate_m.rmse / std::max(err.gt_path_length_m, 1e-12));
  }
  const Window& first = windows.front();
  const Window& last = windows.back();
  fmt::print(
      "bench soak frames={} tracked={} first_median_ms={:.3f} last_median_ms={:.3f} last_over_first={:.3f} "
      "rss_first_mib={:.1f} rss_last_mib={:.1f} rss_peak_mib={:.1f} render_ms_mean={:.3f}{}\n",
      done, tracked_all, first.median_ms, last.median_ms, last.median_ms / std::max(first.median_ms, 1e-9),
      first.rss_mib, last.rss_mib, ProcStatusMiB("VmHWM:").value_or(0), done ? render_ms_sum / done : 0.0, accuracy);
  if (!a.csv.empty()) {
    std::ofstream f(a.csv);
    if (!f) throw std::runtime_error(fmt::format("cannot write '{}'", a.csv));
    f << "first,last,median_ms,p95_ms,tracked,map_points,rss_mib,frontend_ms,remap_ms,backend_ms,remap_requests\n";
    for (const Window& x : windows)
      f << fmt::format("{},{},{:.4f},{:.4f},{},{},{:.2f},{:.4f},{:.4f},{:.4f},{:.0f}\n", x.first, x.last, x.median_ms,
                       x.p95_ms, x.tracked, x.map_points, x.rss_mib, x.frontend_ms, x.remap_ms, x.backend_ms,
                       x.remap_requests);
    if (!f) throw std::runtime_error(fmt::format("error while writing '{}'", a.csv));
  }
  if (Interrupted()) throw InterruptedError();
}

}  // namespace

void RegisterBenchSoak(CLI::App* bench) {
  auto a = std::make_shared<SoakArgs>();
  CLI::App* soak = bench->add_subcommand(
      "soak", "A long synthetic run (front end and back end): per-frame time and resident memory, window by window");
  soak->add_option("--scenario", a->scenario, "Scenario (mcslam synth --scenario)")->capture_default_str();
  soak->add_option("--frames", a->frames, "Frames")->check(CLI::Range(2, 1000000))->capture_default_str();
  soak->add_option("--window", a->window, "Frames a line (its median and 95th percentile)")
      ->check(CLI::Range(1, 1000000))
      ->capture_default_str();
  soak->add_option("--seed", a->seed, "Seed of the scenario, its images and the run")->capture_default_str();
  soak->add_flag("--observations", a->observations,
                 "The scenario's feature observations to the back end alone, instead of rendered images through the "
                 "front end");
  soak->add_option("--csv", a->csv, "Also write the windows to this CSV file");
  soak->add_option("--merge-revisited-points", a->merge_revisited_points,
                   "A new track at a mapped place goes on as the map point there (run's option of the same name)")
      ->capture_default_str();
  AddBackendFlag(soak, &a->backend);
  soak->callback([a] { BenchSoak(*a); });
}

}  // namespace mcslam::apps
