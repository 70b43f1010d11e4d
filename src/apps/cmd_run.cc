// mcslam run: the SLAM job on a folder of observations: the full back end (two-view initialisation,
// Monte Carlo tracking and mapping), or, with --known-map, pose tracking against the folder's ground-truth
// map (the paper's precision test). Any other input (image folder, video, webcam, dataset) goes through the
// front end first (apps/image_job.h).
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <optional>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "apps/commands.h"
#include "core/median.h"
#include "apps/image_job.h"
#include "apps/known_map_job.h"
#include "apps/options_json.h"
#include "apps/run_report.h"
#include "apps/options.h"
#include "apps/run_timing.h"
#include "apps/slam_job.h"
#include "io/camera_io.h"
#include "io/ply.h"
#include "eval/trajectory_eval.h"

namespace mcslam::apps {

namespace {

// `mcslam run`'s System options before its flags: the library's, with each keyframe's local bundle adjustment
// solved beside the next frame (MappingOptions::local_ba_async; the run flushes it after its last frame).
slam::SystemOptions RunSystemDefaults() {
  slam::SystemOptions options;
  options.mapping.local_ba_async = true;
  return options;
}

struct RunArgs {
  std::string input, out, backend = "cpu";
  bool known_map = false;
  bool gt_scale = false;
  std::string init_method = "8point";
  std::string pose_method = "mc", structure_method = "mc";
  PoseFlags pose;
  slam::SystemOptions system = RunSystemDefaults();
  double smooth_alpha = 0.5;
  ImageJobOptions image;
  std::string options_from;  // an earlier run's report.json
  // Flags that act only in some modes: those of the map building (no effect with --known-map) and those of the
  // front end and the pixel outputs (no effect on a folder of observations). Given where they do nothing, they
  // are an error naming them, not silently ignored.
  std::vector<const CLI::Option*> mapping_flags, image_flags;
  // And those of the known map only: where the run builds its map, the System sets them from the map it built.
  std::vector<const CLI::Option*> known_map_flags;
};

// The options added to cmd after its first `from` ones (CLI11 keeps them in the order they were added).
std::vector<const CLI::Option*> OptionsSince(const CLI::App* cmd, size_t from) {
  const std::vector<const CLI::Option*> all = cmd->get_options();
  return {all.begin() + static_cast<std::ptrdiff_t>(std::min(from, all.size())), all.end()};
}

// The first flag of `flags` given on the command line, refused: it does nothing in this mode.
void RefuseFlagsWithoutEffect(const std::vector<const CLI::Option*>& flags, const std::string& why) {
  for (const CLI::Option* f : flags)
    if (f->count() > 0)
      throw std::invalid_argument(fmt::format("{}: has no effect {}; leave it out", f->get_name(), why));
}


// The part of report.json that every run on a folder of observations shares.
// `tracker`: the pose tracker's options as the run used them (with --options-from, the report's, not the flags').
nlohmann::json RunReportHead(const RunArgs& a, const char* mode, const slam::PoseTrackerOptions& tracker) {
  nlohmann::json j;
  j["input"] = a.input;
  j["mode"] = mode;
  j["options"] = {{"backend", a.backend},
                  {"hypotheses", tracker.hypotheses},
                  {"rounds", tracker.rounds},
                  {"seed", tracker.seed},
                  {"random", tracker.random == slam::RandomMode::kTable ? "table" : "fresh"}};
  return j;
}

slam::SystemOptions ResolveSystemOptions(const RunArgs& a) {
  slam::SystemOptions options = a.system;
  options.tracker = a.pose.Resolve();
  options.smoother.alpha = a.smooth_alpha;
  options.seed = options.tracker.seed;
  options.init.method =
      a.init_method == "5point" ? geometry::EssentialMethod::kFivePointOpenCV : geometry::EssentialMethod::kEightPoint;
  options.pose_method = slam::ParsePoseMethod(a.pose_method);
  options.structure_method = slam::ParseStructureMethod(a.structure_method);
  options.Check();
  return options;
}

// --options-from: the report.json of an earlier run, checked to hold the options of this run's mode (a System's,
// or with --known-map the known-map tracker's).
nlohmann::json ReadOptionsReport(const std::string& path, bool known_map) {
  std::error_code ec;
  const std::filesystem::file_status st = std::filesystem::status(path, ec);
  if (ec || st.type() == std::filesystem::file_type::not_found)
    throw std::invalid_argument(fmt::format("--options-from {}: the file does not exist", path));
  if (st.type() != std::filesystem::file_type::regular)
    throw std::invalid_argument(fmt::format("--options-from {}: not a regular file", path));
  std::ifstream f(path);
  if (!f) throw std::invalid_argument(fmt::format("--options-from {}: cannot open it", path));
  nlohmann::json j = nlohmann::json::parse(f, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) throw std::invalid_argument(fmt::format("--options-from {}: not JSON", path));
  const char* key = known_map ? "known_map" : "system";
  if (!j.is_object() || !j.contains("options") || !j["options"].is_object() || !j["options"].contains(key) ||
      !j["options"][key].is_object())
    throw std::invalid_argument(fmt::format("--options-from {}: no options.{} in it (the report.json of a `mcslam run` "
                                            "{})",
                                            path, key, known_map ? "with --known-map" : "that built a map"));
  return j;
}

// Options from --options-from: the report's part (`from_report`) with every option where the flags (`given`)
// differ from their `defaults` on top, then `check`ed; a bad report or result names the file.
template <typename Options, typename CheckFn>
Options OverlayReport(const RunArgs& a, const nlohmann::json& from_report, const Options& defaults, const Options& given,
                      CheckFn check) {
  Options out = defaults;
  try {
    FromJson(OverlayChanges(from_report, ToJson(defaults), ToJson(given)), &out);
    check(out);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("--options-from {}: {}", a.options_from, e.what()));
  }
  return out;
}

// The run's System options: the flags', or with --options-from the earlier run's with the flags that change an
// option from its default on top.
slam::SystemOptions SystemOptionsFor(const RunArgs& a, const nlohmann::json* report) {
  const slam::SystemOptions given = ResolveSystemOptions(a);
  if (!report) return given;
  return OverlayReport(a, (*report)["options"]["system"], ResolveSystemOptions(RunArgs{}), given,
                       [](const slam::SystemOptions& o) { o.Check(); });
}

// The known-map tracker's options: the flags', or with --options-from the earlier known-map run's with the flags
// that change an option from its default on top.
slam::KnownMapOptions KnownMapOptionsFor(const RunArgs& a, const nlohmann::json* report) {
  auto resolve = [](const RunArgs& args) {
    slam::KnownMapOptions o;
    o.tracker = args.pose.Resolve();  // checked there
    o.smoother.alpha = args.smooth_alpha;
    o.smoother.Check();
    return o;
  };
  const slam::KnownMapOptions given = resolve(a);
  if (!report) return given;
  return OverlayReport(a, (*report)["options"]["known_map"], resolve(RunArgs{}), given,
                       [](const slam::KnownMapOptions& o) {
                         o.tracker.Check();
                         o.smoother.Check();
                       });
}

// The image job's options: the flags', or with --options-from the earlier run's front end and relocalisation with
// the flags that change them from their defaults on top.
ImageJobOptions ImageOptionsFor(const RunArgs& a, const nlohmann::json* report) {
  ImageJobOptions image = a.image;
  image.gt_scale = a.gt_scale;
  if (!report) return image;
  const ImageJobOptions defaults;
  if ((*report)["options"].contains("frontend"))
    image.frontend = OverlayReport(a, (*report)["options"]["frontend"], defaults.frontend, image.frontend,
                                   [](const frontend::FrontendOptions&) {});  // checked where the job starts
  const nlohmann::json reloc = report->value("relocalisation", nlohmann::json::object());
  if (image.relocalise == defaults.relocalise && reloc.is_object() && reloc.contains("enabled") &&
      reloc["enabled"].is_boolean())
    image.relocalise = reloc["enabled"].get<bool>();
  if (image.relocalise_turned == defaults.relocalise_turned && reloc.is_object() && reloc.contains("turned") &&
      reloc["turned"].is_boolean())
    image.relocalise_turned = reloc["turned"].get<bool>();
  // The report's image options, each where the command line left it at its default.
  const nlohmann::json im = (*report)["options"].value("image", nlohmann::json::object());
  const auto flag_from_report = [&im](const char* name, bool fallback, bool* value) {
    if (*value == fallback && im.is_object() && im.contains(name) && im[name].is_boolean())
      *value = im[name].get<bool>();
  };
  flag_from_report("pipelined", defaults.pipelined, &image.pipelined);
  flag_from_report("describe_map_points_only", defaults.describe_map_points_only, &image.describe_map_points_only);
  return image;
}

void RunFullSlam(const RunArgs& a, const slam::SystemOptions& options) {
  auto pose_kernel = MakePoseKernelFor(a.backend);
  auto point_kernel = MakePointKernelFor(a.backend);
  const SequenceInput input = LoadSequenceInput(a.input);
  std::filesystem::create_directories(a.out);
  const std::filesystem::path out(a.out);
  spdlog::info("SLAM: {} frames, {} hypotheses/frame, {} samples/point, backend {}", input.frames.size(),
               options.tracker.hypotheses, options.mapping.samples, a.backend);
  InstallInterruptHandler();
  bool announced = false;
  bool was_lost = false;
  int64_t progress_logged = -1;  // a frame's report may come twice (revised by its local bundle adjustment)
  const SlamRunResult res = RunSlam(
      input, options, std::move(pose_kernel), std::move(point_kernel), a.gt_scale,
      [&](const slam::FrameReport& r) {
        if (!r.initialisation && (r.index + 1) % 50 == 0 && r.index > progress_logged)
          spdlog::info("frame {}/{}", r.index + 1, input.frames.size()), progress_logged = r.index;
        if (r.initialisation && !r.note.empty() && !announced) spdlog::info("{}", r.note), announced = true;
        if (r.self_calibration) spdlog::info("frame {}: {}", r.index, r.note);
        if (r.depth_reversed) spdlog::warn("frame {}: {}", r.index, r.note);
        // Log the changes of state, not every lost frame.
        const bool lost = r.status == slam::FrameStatus::kLost;
        if (lost && !was_lost) spdlog::warn("frame {} lost: {}", r.index, r.note);
        if (!lost && was_lost && r.status == slam::FrameStatus::kTracked) spdlog::info("frame {}: tracking resumed", r.index);
        was_lost = lost;
      },
      [] { return Interrupted(); });
  if (Interrupted()) spdlog::warn("interrupted: writing the {} frames done so far", res.reports.size());

  // Outputs first: whatever happens next, what was computed is kept.
  const io::Trajectory traj = ReportsToTrajectory(res.reports, false);
  io::WriteTum((out / "trajectory.txt").string(), traj);
  io::WriteTum((out / "trajectory_smoothed.txt").string(), ReportsToTrajectory(res.reports, true));
  io::WritePly((out / "map.ply").string(), res.map);
  if (res.self_calibration.accepted)  // the camera the map was made with, for the next run
    io::WriteCameraYaml((out / "camera_selfcalibrated.yaml").string(), res.self_calibration_camera);
  std::optional<eval::TrajectoryErrors> err;
  if (!input.groundtruth.empty() && traj.size() >= 3) {
    try {
      err = eval::EvaluateTrajectory(input.groundtruth, traj, {});
    } catch (const std::exception& e) {  // no evaluation, but the outputs are still written
      spdlog::warn("no evaluation against the ground truth: {}", e.what());
    }
  }
  WriteFramesCsv((out / "frames.csv").string(), res.reports, err);

  const ReportCounts counts = CountReports(res.reports);
  std::vector<double> ms;
  for (const auto& r : res.reports) {
    if (r.status == slam::FrameStatus::kTracked && !r.initialisation) ms.push_back(r.track_ms + r.map_ms + r.adjust_ms);
  }
  const double fps = res.reports.size() / std::max(res.times.wall_s, 1e-9);
  std::string line = fmt::format("frames={} tracked={} lost={} not_initialised={} keyframes={} map_points={} "
                                 "frame_ms_median={:.3f} fps={:.1f}",
                                 res.reports.size(), counts.tracked, counts.lost, counts.not_initialised,
                                 counts.keyframes, res.map.points.size(),
                                 UpperMedian(ms), fps);
  nlohmann::json j = RunReportHead(a, "slam", options.tracker);
  j["options"]["samples_per_point"] = options.mapping.samples;
  j["options"]["system"] = ToJson(options);  // every option: what the run did, from its report alone
  j["frames"] = res.reports.size();
  PutCounts(counts, &j);
  j["map_points"] = res.map.points.size();
  j["initialised"] = res.initialised;
  j["initialisation"] = nullptr;
  j["initialisation_rejections"] = nlohmann::json::array();
  j["depth_reversals"] = nlohmann::json::array();
  j["map_restarts"] = nlohmann::json::array();
  for (const auto& r : res.reports) {
    if (r.map_restarted) j["map_restarts"].push_back({{"frame", r.index}, {"why", r.note}});
    if (r.init_rejected) j["initialisation_rejections"].push_back({{"frame", r.index}, {"why", r.note}});
    if (r.depth_reversed) j["depth_reversals"].push_back({{"frame", r.index}, {"why", r.note}});
    if (r.initialisation && !r.note.empty() && j["initialisation"].is_null())
      j["initialisation"] = {{"frame", r.index}, {"note", r.note}};
  }
  j["self_calibration"] = SelfCalibrationJson(res.self_calibration);
  j["interrupted"] = Interrupted();
  j["frame_ms_median"] = UpperMedian(ms);
  j["fps"] = fps;
  AddRunTimes(res.times, &j);
  j["ground_truth"] = nullptr;
  if (err) {
    line += fmt::format(" ate_rmse={:.6g} trans_mean_m={:.6g} rot_mean_deg={:.6g} rpe_rot_mean_deg={:.6g} scale={:.6g}",
                        err->ate_m.rmse, err->ate_m.mean, err->rot_deg.mean, err->rpe_rot_deg.mean,
                        err->alignment_result.gt_world_from_est_world.scale);
    j["ground_truth"] = {{"alignment", "sim3"},
                         {"scale", err->alignment_result.gt_world_from_est_world.scale},
                         {"ate_rmse_m", err->ate_m.rmse},
                         {"trans_mean_m", err->ate_m.mean},
                         {"rot_mean_deg", err->rot_deg.mean},
                         {"rot_median_deg", err->rot_deg.median},
                         {"rot_orient_mean_deg", err->rot_orient_deg.mean},
                         {"rotation_ambiguous", err->alignment_result.rotation_ambiguous},
                         {"path_length_m", err->gt_path_length_m},
                         {"mirrored", err->mirrored},
                         {"rpe_rot_mean_deg", err->rpe_rot_deg.mean}};
  }
  if (!res.reports.empty()) line += fmt::format(" final_reproj_mean_px={:.4f}", res.reports.back().reproj_mean_px);
  line += RunTimesFields(res.times);
  WriteReportJson((out / "report.json").string(), j);
  fmt::print("{}\n", line);
  if (Interrupted()) throw InterruptedError();
  if (!res.initialised)
    throw NotInitialisedError(options.init, res.reports, static_cast<int64_t>(res.reports.size()), a.out);
}

void Run(const RunArgs& a) {
  std::optional<nlohmann::json> report;
  if (!a.options_from.empty()) {
    report = ReadOptionsReport(a.options_from, a.known_map);
    spdlog::info("options from {} (flags given here on top)", a.options_from);
  }
  const nlohmann::json* rep = report ? &*report : nullptr;
  if (!a.known_map)
    RefuseFlagsWithoutEffect(a.known_map_flags,
                             "where the run builds its map (the pose step's translation floor is set from the map's "
                             "depth when it is made: SystemOptions::sigma_trans_floor_rel_depth); it acts with "
                             "--known-map only");
  if (!a.known_map && IsImageInput(a.input, a.image)) {
    RunImageJob(a.input, a.out, SystemOptionsFor(a, rep), a.backend, ImageOptionsFor(a, rep));
    return;
  }
  RefuseFlagsWithoutEffect(a.image_flags, fmt::format("on a folder of observations ({}/observations.txt: features "
                                                      "already tracked, its own camera and ground truth; to run on its "
                                                      "rendered images instead, add --dataset synthetic)",
                                                      a.input));
  if (!a.known_map) return RunFullSlam(a, SystemOptionsFor(a, rep));
  RefuseFlagsWithoutEffect(a.mapping_flags, "with --known-map (the map is given: nothing is initialised or mapped)");
  const slam::KnownMapOptions options = KnownMapOptionsFor(a, rep);
  auto kernel = MakePoseKernelFor(a.backend);

  const KnownMapInput input = LoadKnownMapInput(a.input);
  std::filesystem::create_directories(a.out);
  spdlog::info("known-map tracking: {} frames, {} map points, {} hypotheses/frame, backend {}", input.frames.size(),
               input.map.size(), options.tracker.hypotheses, a.backend);

  InstallInterruptHandler();
  const RunClock clock;
  size_t done = 0;
  const auto results = RunKnownMap(
      input, options, std::move(kernel),
      [&](const slam::FrameResult& r) {
        if (++done % 50 == 0) spdlog::info("frame {}/{}", done, input.frames.size());
        if (!r.estimate.tracked) spdlog::warn("frame {} lost: {}", r.index, r.estimate.lost_reason);
      },
      [] { return Interrupted(); });
  const RunTimes times = clock.Elapsed();
  if (Interrupted()) spdlog::warn("interrupted: writing the {} frames done so far", results.size());

  const io::Trajectory traj = ResultsToTrajectory(results, false);
  io::WriteTum((std::filesystem::path(a.out) / "trajectory.txt").string(), traj);
  io::WriteTum((std::filesystem::path(a.out) / "trajectory_smoothed.txt").string(), ResultsToTrajectory(results, true));
  // The map is the ground truth's, so the estimate is in its frame already: no alignment.
  std::optional<eval::TrajectoryErrors> err;
  if (!input.groundtruth.empty() && traj.size() >= 3) {
    eval::EvalOptions eo;
    eo.alignment = eval::Alignment::kNone;
    err = eval::EvaluateTrajectory(input.groundtruth, traj, eo);
  }
  std::vector<slam::FrameReport> reports;
  reports.reserve(results.size());
  for (const slam::FrameResult& r : results) reports.push_back(ToFrameReport(r));
  WriteFramesCsv((std::filesystem::path(a.out) / "frames.csv").string(), reports, err);

  int tracked = 0, lost = 0, keyframes = 0;
  std::vector<double> ms;
  for (const auto& r : results) {
    if (r.given) continue;
    tracked += r.estimate.tracked;
    lost += !r.estimate.tracked;
    keyframes += r.estimate.keyframe;
    ms.push_back(r.time_ms);
  }
  const double fps = results.size() / std::max(times.wall_s, 1e-9);
  std::string line = fmt::format("frames={} tracked={} lost={} keyframes={} pose_ms_median={:.3f} fps={:.1f}",
                                 results.size(), tracked + 1, lost, keyframes, UpperMedian(ms), fps);
  nlohmann::json j = RunReportHead(a, "known_map", options.tracker);
  j["options"]["known_map"] = ToJson(options);  // every option: what the run did, from its report alone
  j["frames"] = results.size();
  j["tracked"] = tracked + 1;  // the first frame's pose is given
  j["lost"] = lost;
  j["keyframes"] = keyframes;
  j["interrupted"] = Interrupted();
  j["pose_ms_median"] = UpperMedian(ms);
  j["fps"] = fps;
  AddRunTimes(times, &j);
  j["ground_truth"] = nullptr;
  if (err) {
    line += fmt::format(" trans_mean_m={:.6g} rot_mean_deg={:.6g} ate_rmse={:.6g}", err->ate_m.mean, err->rot_deg.mean,
                        err->ate_m.rmse);
    j["ground_truth"] = {{"alignment", "none"},
                         {"ate_rmse_m", err->ate_m.rmse},
                         {"trans_mean_m", err->ate_m.mean},
                         {"rot_mean_deg", err->rot_deg.mean}};
  }
  line += RunTimesFields(times);
  WriteReportJson((std::filesystem::path(a.out) / "report.json").string(), j);
  fmt::print("{}\n", line);
  if (Interrupted()) throw InterruptedError();
}

}  // namespace

void RegisterRun(CLI::App& app) {
  auto args = std::make_shared<RunArgs>();
  CLI::App* cmd = app.add_subcommand(
      "run", "SLAM on a sequence: writes trajectory.txt, trajectory_smoothed.txt, map.ply, frames.csv");
  cmd->add_option("input", args->input,
                  "Input: a folder of observations (as written by `mcslam synth`), an image folder, a video file, a "
                  "webcam index (N or webcam:N) or a dataset folder (KITTI, TUM, EuRoC, 7-Scenes)")
      ->required();
  cmd->add_option("--out", args->out, "Output folder")->required();
  cmd->add_flag("--known-map", args->known_map, "Track against the folder's ground-truth map (map_gt.ply) instead of building one");
  const size_t mapping_from = cmd->get_options().size();
  cmd->add_flag("--gt-scale", args->gt_scale, "Take the first baseline's length from the ground truth (as the paper does)");
  cmd->add_option("--init-method", args->init_method, "Essential matrix: 8point (normalised 8-point + RANSAC + LM) or 5point (OpenCV)")
      ->check(CLI::IsMember({"8point", "5point"}))
      ->capture_default_str();
  cmd->add_option("--init-motion-deg", args->system.init.min_median_motion_deg,
                  "Median feature motion (angle between a feature's rays in two frames) that starts the "
                  "initialisation")
      ->check(Between(1e-6, 89.0))
      ->capture_default_str();
  cmd->add_option("--init-nonrot-px", args->system.init.min_nonrotational_motion_px,
                  "... or the median motion that no turn of the camera explains, in pixels, that starts it (a camera "
                  "circling what it looks at; 0: the median motion alone)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--pose", args->pose_method, "Pose step: mc (Monte Carlo, the paper) or pnp (RANSAC PnP + LM, baseline)")
      ->check(CLI::IsMember({"mc", "pnp"}))
      ->capture_default_str();
  cmd->add_option("--structure", args->structure_method,
                  "Structure step: mc (Monte Carlo point adjustment, the paper) or ba (local bundle adjustment, baseline)")
      ->check(CLI::IsMember({"mc", "ba"}))
      ->capture_default_str();
  cmd->add_option("--ba-iterations", args->system.ba_iterations, "Iteration cap of the local bundle adjustment")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  cmd->add_option("--init-parallax-deg", args->system.init.min_median_parallax_deg,
                  "Median parallax the initialisation needs (two views and the refined window)")
      ->check(NonNegative())
      ->capture_default_str();
  cmd->add_option("--settle-parallax-deg", args->system.init.settle_parallax_deg,
                  "After initialisation, the frames since the reference and the map are refined together (bundle "
                  "adjustment) each time their median parallax grows by half, until it reaches this (0: never)")
      ->check(Between(0.0, 89.0))
      ->capture_default_str();
  cmd->add_flag("--no-pose-before-reference{false}", args->system.init.pose_frames_before_reference,
                "Leave the frames before the initialisation's reference frame (when it moved on while waiting) "
                "without a pose instead of placing them against the first map");
  cmd->add_flag("--no-pose-lost-frames{false}", args->system.pose_lost_frames_when_found,
                "Leave the frames lost before a frame that is tracked again (relocalised, or found from the last pose) "
                "without a pose instead of placing them against the map through the tracks they share with it");
  cmd->add_flag("--no-self-calibration{false}", args->system.init.self_calibrate,
                "Keep the camera's distortion as given instead of refining its first radial coefficient from the "
                "settled first map when the map measures it clearly (docs/self_calibration.md)");
  cmd->add_option("--samples", args->system.mapping.samples, "Monte Carlo samples per adjusted point")
      ->check(CLI::Range(1, 1 << 22))
      ->capture_default_str();
  cmd->add_option("--window", args->system.mapping.window, "Keyframes in the Fibonacci window of the point adjustment")
      ->check(CLI::Range(2, 64))
      ->capture_default_str();
  cmd->add_option("--starving-inliers", args->system.mapping.starving_inliers,
                  "Keyframes with fewer pose inliers than this take new points from 2 degrees of parallax whatever "
                  "--min-parallax-deg says, and from tracks seen in 2 posed frames instead of 3, so that the map "
                  "does not run dry (0: off)")
      ->check(NonNegative())
      ->capture_default_str();
  cmd->add_flag("--no-provisional-map{false}", args->system.bridge,
                "After a turn that took the map out of view ends in a move, stay lost until the map is found again "
                "instead of tracking on a provisional map that joins it then (docs/rotation_only.md)");
  cmd->add_option("--history-frames", args->system.mapping.history_frames,
                  "Frames whose features the back end keeps (older ones keep only their pose; never less than the "
                  "window reaches back)")
      ->capture_default_str();
  cmd->add_option("--adjust-px", args->system.mapping.adjust_threshold_px,
                  "Residual (median over the window) above which a point that no sample fixes is an outlier")
      ->check(Positive())
      ->capture_default_str();
  cmd->add_option("--candidate-px", args->system.mapping.candidate_threshold_px,
                  "Residual above which a point is re-sampled (the paper: the same as --adjust-px)")
      ->check(NonNegative())
      ->capture_default_str();
  cmd->add_flag("!--no-adjust", args->system.mapping.adjust, "Skip the Monte Carlo point adjustment");
  cmd->add_option("--local-ba-keyframes", args->system.mapping.local_ba_keyframes,
                  "After each keyframe's point adjustment, refine the poses of this many newest keyframes together "
                  "with their points (bundle adjustment, the older window keyframes fixed; 0: off, the paper's "
                  "back end)")
      ->check(CLI::Range(0, 64))
      ->capture_default_str();
  cmd->add_option("--local-ba-min-step", args->system.mapping.local_ba_min_step_of_depth,
                  "The local bundle adjustment's keyframes at least this fraction of the scene's median depth apart "
                  "(0: the newest keyframes, consecutive)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  cmd->add_option("--local-ba-tolerance", args->system.mapping.local_ba_function_tolerance,
                  "The local bundle adjustment ends when an iteration lowers its cost by less than this fraction of it "
                  "(or after --ba-iterations)")
      ->check(CLI::Range(0.0, 0.999))
      ->capture_default_str();
  cmd->add_option("--local-ba-async", args->system.mapping.local_ba_async,
                  "Solve each keyframe's local bundle adjustment on its own thread while the next frame is read and "
                  "its features tracked; applied before that frame's pose step (false: in place, the next frame "
                  "waits; the same poses on a folder of observations)")
      ->capture_default_str();
  cmd->add_option("--merge-revisited-points", args->system.mapping.merge_revisited_points,
                  "A new track whose point is where a map point not seen in the frame projects, in every view it is "
                  "triangulated from, goes on as that point (false: it makes a new point; off by default until the "
                  "two runs it worsens are understood, docs/tuning.md; always on in a map loaded by --load-map)")
      ->capture_default_str();
  cmd->add_option("--min-parallax-deg", args->system.mapping.min_parallax_deg,
                  "Smallest parallax for a new point (largest angle between its viewing rays)")
      ->check(NonNegative())
      ->capture_default_str();
  cmd->add_option("--new-point-depth-noise", args->system.mapping.max_relative_depth_noise,
                  "New points also need the parallax at which the tracks' measured noise gives at most this "
                  "relative depth error (capped at --max-noise-parallax-deg)")
      ->check(Positive())
      ->capture_default_str();
  cmd->add_option("--max-noise-parallax-deg", args->system.mapping.max_noise_parallax_deg,
                  "Cap of the parallax the tracks' noise asks of new points (0: only --min-parallax-deg)")
      ->check(Between(0.0, 89.0))
      ->capture_default_str();
  args->mapping_flags = OptionsSince(cmd, mapping_from);
  cmd->add_option("--smooth-alpha", args->smooth_alpha, "DESP smoothing weight of the new pose, (0, 1]")
      ->check(Between(1e-6, 1.0))
      ->capture_default_str();
  args->pose.Add(cmd);
  args->known_map_flags = {cmd->get_option("--sigma-trans-floor")};
  AddBackendFlag(cmd, &args->backend);
  cmd->add_option("--options-from", args->options_from,
                  "Take every option from an earlier run's report.json (its System's and front end's, or with "
                  "--known-map its tracker's and smoother's); flags given here that change an option from its "
                  "default apply on top");
  const size_t image_from = cmd->get_options().size();
  AddImageJobFlags(cmd, &args->image);
  args->image_flags = OptionsSince(cmd, image_from);
  cmd->callback([args] { Run(*args); });
}

}  // namespace mcslam::apps
