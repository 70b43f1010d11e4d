// mcslam run: the SLAM job. For now pose tracking against a known map (--known-map), the paper's
// precision test; the full back end (initialisation, mapping) comes with the back-end issue.
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <string>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "apps/commands.h"
#include "apps/known_map_job.h"
#include "apps/options.h"
#include "eval/trajectory_eval.h"

namespace mcslam::apps {

namespace {

struct RunArgs {
  std::string input, out, backend = "cpu";
  bool known_map = false;
  PoseFlags pose;
  double smooth_alpha = 0.5;
};

double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

void Run(const RunArgs& a) {
  if (!a.known_map)
    throw std::invalid_argument("mcslam run: only --known-map tracking exists in this version (the full back end, "
                                "with initialisation and mapping, is not built yet)");
  slam::KnownMapOptions options;
  options.tracker = a.pose.Resolve();
  options.smoother.alpha = a.smooth_alpha;
  options.smoother.Check();
  auto kernel = MakePoseKernelFor(a.backend);

  const KnownMapInput input = LoadKnownMapInput(a.input);
  std::filesystem::create_directories(a.out);
  spdlog::info("known-map tracking: {} frames, {} map points, {} hypotheses/frame, backend {}", input.frames.size(),
               input.map.size(), options.tracker.hypotheses, a.backend);

  InstallInterruptHandler();
  const auto t_start = std::chrono::steady_clock::now();
  size_t done = 0;
  const auto results = RunKnownMap(
      input, options, std::move(kernel),
      [&](const slam::FrameResult& r) {
        if (++done % 50 == 0) spdlog::info("frame {}/{}", done, input.frames.size());
        if (!r.estimate.tracked) spdlog::warn("frame {} lost: {}", r.index, r.estimate.lost_reason);
      },
      [] { return Interrupted(); });
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  if (Interrupted()) spdlog::warn("interrupted: writing the {} frames done so far", results.size());

  const io::Trajectory traj = ResultsToTrajectory(results, false);
  io::WriteTum((std::filesystem::path(a.out) / "trajectory.txt").string(), traj);
  io::WriteTum((std::filesystem::path(a.out) / "trajectory_smoothed.txt").string(), ResultsToTrajectory(results, true));
  WriteFramesCsv((std::filesystem::path(a.out) / "frames.csv").string(), results);

  int tracked = 0, lost = 0, keyframes = 0;
  std::vector<double> ms;
  for (const auto& r : results) {
    if (r.given) continue;
    tracked += r.estimate.tracked;
    lost += !r.estimate.tracked;
    keyframes += r.estimate.keyframe;
    ms.push_back(r.time_ms);
  }
  std::string line = fmt::format("frames={} tracked={} lost={} keyframes={} pose_ms_median={:.3f} fps={:.1f}",
                                 results.size(), tracked + 1, lost, keyframes, Median(ms), results.size() / wall_s);
  if (!input.groundtruth.empty() && traj.size() >= 3) {
    // The map is the ground truth's, so the estimate is in its frame already: no alignment.
    eval::EvalOptions eo;
    eo.alignment = eval::Alignment::kNone;
    const auto err = eval::EvaluateTrajectory(input.groundtruth, traj, eo);
    line += fmt::format(" trans_mean_m={:.6g} rot_mean_deg={:.6g} ate_rmse={:.6g}", err.ate_m.mean, err.rot_deg.mean,
                        err.ate_m.rmse);
  }
  fmt::print("{}\n", line);
  if (Interrupted()) throw std::runtime_error("interrupted by the user (outputs written)");
}

}  // namespace

void RegisterRun(CLI::App& app) {
  auto args = std::make_shared<RunArgs>();
  CLI::App* cmd = app.add_subcommand("run", "Track a sequence: writes trajectory.txt, trajectory_smoothed.txt, frames.csv");
  cmd->add_option("input", args->input, "Input folder (as written by `mcslam synth`)")->required();
  cmd->add_option("--out", args->out, "Output folder")->required();
  cmd->add_flag("--known-map", args->known_map, "Track against the folder's ground-truth map (map_gt.ply)");
  cmd->add_option("--smooth-alpha", args->smooth_alpha, "DESP smoothing weight of the new pose, (0, 1]")
      ->check(CLI::Range(1e-6, 1.0))
      ->capture_default_str();
  args->pose.Add(cmd);
  AddBackendFlag(cmd, &args->backend);
  cmd->callback([args] { Run(*args); });
}

}  // namespace mcslam::apps
