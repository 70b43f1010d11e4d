// `mcslam eval GT EST`: compare an estimated trajectory with ground truth and print one summary line.
#include <cmath>
#include <cstdio>
#include <exception>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include <fmt/format.h>

#include "apps/commands.h"
#include "apps/options.h"
#include "eval/trajectory_eval.h"
#include "io/trajectory_io.h"

namespace mcslam::apps {
namespace {

struct EvalArgs {
  std::string gt_path, est_path;
  std::string align = "sim3";
  std::string csv_path;
  int delta = 1;
  double max_dt_s = eval::AssociationOptions{}.max_dt_s;
  std::string gt_format = "auto", est_format = "auto";
  std::string gt_times, est_times;
  int segments = 0;
};

void RunEval(const EvalArgs& a) {
  const io::Trajectory gt = io::ReadTrajectory(a.gt_path, io::ParseTrajectoryFormat(a.gt_format), a.gt_times);
  const io::Trajectory est = io::ReadTrajectory(a.est_path, io::ParseTrajectoryFormat(a.est_format), a.est_times);
  if (gt.has_stamps != est.has_stamps)
    std::fprintf(stderr, "mcslam eval: note: %s has no timestamps; poses are matched by index\n",
                 (gt.has_stamps ? a.est_path : a.gt_path).c_str());

  eval::EvalOptions options;
  options.alignment = eval::ParseAlignment(a.align);
  options.association.max_dt_s = a.max_dt_s;
  options.rpe_delta = a.delta;
  const eval::TrajectoryErrors errors = eval::EvaluateTrajectory(gt, est, options);
  // RPE compares poses delta apart: with fewer matched poses there is no pair, and its figures would be NaN.
  if (static_cast<size_t>(a.delta) >= errors.matched())
    throw std::invalid_argument(fmt::format("--delta {}: only {} poses matched, and the relative pose error needs "
                                            "pairs of poses that many apart (give --delta below {})",
                                            a.delta, errors.matched(), errors.matched()));

  if (errors.matched() < est.size())
    std::fprintf(stderr, "mcslam eval: note: %zu of %zu estimated poses have no ground truth and are not scored\n",
                 est.size() - errors.matched(), est.size());
  if (errors.alignment_result.rotation_ambiguous)
    std::fprintf(stderr, "%s",
                 fmt::format("mcslam eval: warning: the camera positions do not fix the alignment's rotation about the "
                             "path's main direction (position residual {:.3g} m against a lateral spread of {:.3g} m), "
                             "so rot_mean/median/max_deg measure the alignment more than the estimate; "
                             "rot_orient_*_deg do not depend on it (ATE is unaffected)\n",
                             errors.alignment_result.residual_rmse_m, errors.alignment_result.lateral_spread_m)
                     .c_str());
  // Checked before anything is printed: a bad --segments is an error, not half an answer.
  std::optional<eval::ScaleDrift> drift;
  if (a.segments > 0) drift = eval::EvaluateScaleDrift(errors, a.segments);
  if (!a.csv_path.empty()) eval::WriteFrameErrorsCsv(a.csv_path, errors);
  // stdout carries the summary line (then, with --segments, one line per segment), so scripts can parse it.
  std::fputs((eval::FormatSummary(errors) + "\n").c_str(), stdout);
  if (drift) {
    std::fputs(fmt::format("segments={} scale_max_over_min={:.6g}\n", drift->segments.size(), drift->max_over_min_scale)
                   .c_str(),
               stdout);
    for (size_t k = 0; k < drift->segments.size(); ++k) {
      const eval::SegmentErrors& g = drift->segments[k];
      // Keys of their own (not the summary's scale= and ate_rmse=), so that a key=value parser of the whole
      // output keeps the whole run's figures.
      std::fputs(fmt::format("segment={} poses={}-{} first_stamp={:.6f} last_stamp={:.6f} segment_scale={:.6g} "
                             "scale_vs_whole={:.6g} segment_ate_rmse={:.6g}\n",
                             k, g.first, g.first + g.count - 1, g.first_stamp_s, g.last_stamp_s, g.scale,
                             g.scale_vs_whole, g.ate_m.rmse)
                     .c_str(),
                 stdout);
    }
  }
  std::fflush(stdout);
}

}  // namespace

void RegisterEval(CLI::App& app) {
  auto args = std::make_shared<EvalArgs>();
  CLI::App* cmd = app.add_subcommand(
      "eval", "Compare an estimated trajectory with ground truth: align (Umeyama), then ATE, rotation error and RPE");
  cmd->add_option("GT", args->gt_path, "Ground-truth trajectory (TUM, KITTI or EuRoC CSV)")->required();
  cmd->add_option("EST", args->est_path, "Estimated trajectory (TUM, KITTI or EuRoC CSV)")->required();
  cmd->add_option("--align", args->align, "Alignment of the estimate onto the ground truth")
      ->check(CLI::IsMember({"sim3", "se3", "none"}, CLI::ignore_case))
      ->capture_default_str();
  cmd->add_option("--csv", args->csv_path, "Write per-frame errors to this CSV file");
  cmd->add_option("--delta", args->delta, fmt::format("RPE frame delta, in matched poses (default {})", args->delta))
      ->check(FiniteNumber(1, false, HUGE_VAL, ">= 1"));
  cmd->add_option("--max-dt", args->max_dt_s,
                  fmt::format("Largest stamp difference for a match, seconds (default {})", args->max_dt_s))
      ->check(NonNegative());
  const auto formats = CLI::IsMember({"auto", "tum", "kitti", "euroc"}, CLI::ignore_case);
  cmd->add_option("--gt-format", args->gt_format, "Ground-truth file format")->check(formats)->capture_default_str();
  cmd->add_option("--est-format", args->est_format, "Estimate file format")->check(formats)->capture_default_str();
  cmd->add_option("--gt-times", args->gt_times, "Times file (one stamp a line) for a KITTI ground truth");
  cmd->add_option("--est-times", args->est_times, "Times file (one stamp a line) for a KITTI estimate");
  cmd->add_option("--segments", args->segments,
                  "Also align this many consecutive runs of poses on their own (Sim(3)) and print their scale and "
                  "ATE: a monocular estimate's scale drift (0: off)")
      ->check(NonNegative());
  cmd->callback([args] { RunEval(*args); });
}

}  // namespace mcslam::apps
