#include "apps/image_job.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <map>
#include <optional>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <spdlog/spdlog.h>

#include "apps/image_outputs.h"
#include "apps/run_report.h"
#include "apps/image_run.h"
#include "apps/options.h"
#include "apps/options_json.h"
#include "apps/slam_job.h"
#include "apps/viewer.h"
#include "core/median.h"
#include "eval/trajectory_eval.h"
#include "io/camera_io.h"
#include "io/datasets.h"
#include "io/ply.h"
#include "io/trajectory_io.h"
#include "pipeline/visual_slam.h"

namespace mcslam::apps {

namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }


bool AllDigits(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

}  // namespace

// ---- options ---------------------------------------------------------------------------------------------

void ImageJobOptions::Check() const {
  try {
    io::ParseDatasetKind(dataset);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("--dataset: {}", e.what()));
  }
  if (format != "tum" && format != "kitti")
    throw std::invalid_argument(fmt::format("--format must be tum or kitti, got '{}'", format));
  if (start < 0) throw std::invalid_argument(fmt::format("--start must be >= 0, got {}", start));
  if (end >= 0 && end < start)
    throw std::invalid_argument(fmt::format("--end {} is before --start {}", end, start));
  if (end < -1) throw std::invalid_argument(fmt::format("--end must be >= 0 (or -1: to the end), got {}", end));
  if (!(fps >= 0) || !std::isfinite(fps)) throw std::invalid_argument(fmt::format("--fps must be >= 0, got {}", fps));
  if (!overlay_path.empty() && Lower(fs::path(overlay_path).extension().string()) != ".mp4")
    throw std::invalid_argument(fmt::format("--overlay {}: the overlay is an .mp4 file (mp4v)", overlay_path));
  if (!(max_megapixels == 0 || (max_megapixels >= 0.01 && std::isfinite(max_megapixels))))
    throw std::invalid_argument(
        fmt::format("--max-megapixels must be 0 (frames as they come) or >= 0.01, got {}", max_megapixels));
  if (!plot_path.empty() && !cv::haveImageWriter(plot_path))
    throw std::invalid_argument(fmt::format("--plot {}: not an image file name OpenCV can write (use .png)", plot_path));
  if (!load_map_path.empty() && !relocalise)
    throw std::invalid_argument("--load-map: a run in a loaded map starts by relocalising in it; leave out --no-relocalise");
  if (!load_map_path.empty() && gt_scale)
    throw std::invalid_argument("--gt-scale: has no effect with --load-map (the map sets the scale); leave it out");
  try {
    frontend.Check();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("front end: {}", e.what()));
  }
}

void AddImageJobFlags(CLI::App* cmd, ImageJobOptions* o) {
  cmd->add_option("--dataset", o->dataset,
                  "Input kind: auto, folder (images), video, webcam, kitti, tum, euroc, 7scenes, synthetic (auto: from the "
                  "content; a folder with observations.txt is run as observations)")
      ->capture_default_str();
  cmd->add_option("--camera", o->camera_path,
                  "Camera replacing the dataset's: a YAML file (ORB-SLAM or mcslam style), a text file with the line "
                  "'fx fy cx cy [k1 k2 p1 p2 [k3]]', a KITTI calib.txt (its P0 line), or those numbers given inline "
                  "in quotes (image size from the frames)");
  cmd->add_option("--gt", o->gt_path, "Ground truth replacing the dataset's (TUM, KITTI or EuRoC file, world_from_cam)");
  cmd->add_option("--format", o->format, "Trajectory format: tum (trajectory.txt) or kitti (also trajectory_kitti.txt + times)")
      ->check(CLI::IsMember({"tum", "kitti"}))
      ->capture_default_str();
  cmd->add_option("--overlay", o->overlay_path, "AR overlay video (.mp4): tracked features and a cube in the map");
  cmd->add_option("--plot", o->plot_path, "Top view of the trajectory against the ground truth (.png)");
  cmd->add_option("--save-map", o->save_map_path,
                  "Write the map at the end of the run (points, descriptors, keyframes, camera: docs/map_format.md)");
  cmd->add_option("--load-map", o->load_map_path,
                  "Start in the map of an earlier run (--save-map): relocalise in it, then track and extend it in its "
                  "frame and scale");
  cmd->add_option("--save-tracks", o->save_tracks_dir,
                  "Write the front end's tracks into this folder as observations (observations.txt, camera.yaml): "
                  "`mcslam run FOLDER` runs the back end alone on them, scripts/track_quality.py measures them against "
                  "a ground truth");
  cmd->add_flag("--viewer", o->viewer,
                "Also write viewer.html: the map, the trajectory and the per-frame figures in a browser (three.js)");
  cmd->add_flag("--timings", o->timings,
                "After the summary line, print each stage's time a frame (median, 90th and 99th percentile, max), the "
                "throughput, the latency and the front end's median over the pose step's");
  cmd->add_option("--start", o->start, "First frame to process (index in the source)")->capture_default_str();
  cmd->add_option("--end", o->end, "Last frame to process, inclusive (-1: to the end)")->capture_default_str();
  cmd->add_option("--fps", o->fps, "Frame rate for the stamps of sources without their own (0: the source's)")
      ->capture_default_str();
  cmd->add_option("--max-features", o->frontend.max_features, "Front end: most tracks at once")->capture_default_str();
  cmd->add_option("--max-megapixels", o->max_megapixels,
                  "Frames of more pixels than this (millions) are worked on halved (again until they are not), the "
                  "camera with them: a 1920x1080 video at 960x540 (0: frames as they come)")
      ->capture_default_str();
  cmd->add_flag("--no-relocalise{false}", o->relocalise,
                "Once lost, only the last pose is searched around (default: the features are also matched to the map "
                "by their descriptors, and a pose from those restarts the tracking)");
  cmd->add_flag("--no-turned-relocalisation{false}", o->relocalise_turned,
                "Relocalise by upright descriptors only (default: when they place a lost frame nowhere, they are turned "
                "about the camera's axis in 30 degree steps, for a camera that turned about it since the map saw the "
                "place)");
  cmd->add_flag("--pipelined", o->pipelined,
                "Run each frame's front end on a thread of its own beside the back end of the frame before (the front "
                "end then looks for lost points where the frame before the last placed them; slower on two cores: "
                "docs/timing_pipelined.md)");
  cmd->add_flag("--describe-map-points-only", o->describe_map_points_only,
                "Front end: describe (SIFT) only the tracks that become map points, once they do, instead of every "
                "new track at its birth (faster; off by default: docs/tuning.md)");
  cmd->add_option("--descriptor-refresh-frames", o->frontend.descriptor_refresh_frames,
                  "Front end: a track is described again once its descriptor is this many frames old, so that a lost "
                  "map point is matched with how it looked when last seen (0: birth descriptors only)")
      ->check(NonNegative())
      ->capture_default_str();
  cmd->add_flag("--no-jolt-recovery{false}", o->frontend.jolt_recovery,
                "Front end: do not retry the tracks LK lost from where the image's measured global shift puts them");
  cmd->add_option("--anchor-every", o->frontend.anchor_every,
                  "Front end: frames between alignments of each track with the patch it was born with (0: off)")
      ->capture_default_str();
  cmd->add_option("--anchor-patch-px", o->frontend.anchor_patch_px, "Front end: side of the patch a track keeps from its birth")
      ->capture_default_str();
  cmd->add_option("--anchor-min-correlation", o->frontend.anchor_min_correlation,
                  "Front end: a track whose birth patch correlates less than this (normalised, affine) is a mismatch")
      ->capture_default_str();
  cmd->add_option_function<std::string>(
         "--anchor-mismatch",
         [o](const std::string& v) {
           using AM = frontend::FrontendOptions::AnchorMismatch;
           o->frontend.anchor_mismatch = v == "drop" ? AM::kDrop : v == "reanchor" ? AM::kReanchor : AM::kAuto;
         },
         "Front end: a track that no longer matches its birth patch is dropped (drop), or keeps going with a new "
         "patch (reanchor), or, per frame, the one or the other by how many tracks mismatch (auto) [default: auto]")
      ->check(CLI::IsMember({"auto", "drop", "reanchor"}));
}

bool IsImageInput(const std::string& input, const ImageJobOptions& options) {
  if (Lower(options.dataset) != "auto") return true;
  std::error_code ec;
  return !fs::is_regular_file(fs::path(input) / "observations.txt", ec);
}

// ---- the job ---------------------------------------------------------------------------------------------

cv::Mat Halved(const cv::Mat& image, int times) {
  cv::Mat out = image;
  for (int k = 0; k < times && out.cols >= 2 && out.rows >= 2; ++k) {
    const cv::Mat even = out(cv::Rect(0, 0, out.cols - out.cols % 2, out.rows - out.rows % 2));
    cv::Mat half;
    cv::resize(even, half, cv::Size(even.cols / 2, even.rows / 2), 0, 0, cv::INTER_AREA);
    out = half;
  }
  return out;
}

PinholeCamera HalvedCamera(const PinholeCamera& camera, double max_megapixels, int* halvings) {
  PinholeCamera c = camera;
  int n = 0;
  while (max_megapixels > 0 && static_cast<double>(c.width) * c.height > max_megapixels * 1e6 && c.width >= 2 &&
         c.height >= 2) {
    c.width -= c.width % 2;  // the odd last column or row left out: the principal point does not move
    c.height -= c.height % 2;
    c = c.Scaled(0.5);  // 2x2 averages: pixel centres where Scaled puts them
    ++n;
  }
  if (halvings) *halvings = n;
  return c;
}


// Everything that can be checked before any work.
void ImageRun::Open() {
  io::DatasetOptions dopt;
  dopt.kind = io::ParseDatasetKind(options.dataset);
  std::error_code ec;
  if (dopt.kind == io::DatasetKind::kAuto && AllDigits(input) && !fs::exists(input, ec))
    dopt.kind = io::DatasetKind::kWebcam;  // "mcslam run 0": the first webcam
  dopt.camera_path = options.camera_path;
  dopt.fps = options.fps;
  // --camera: a file, or the numbers inline ("fx fy cx cy ..."); io::OpenDataset tells which, or says neither.
  if (!options.camera_path.empty() && fs::is_directory(options.camera_path, ec))
    throw std::runtime_error(fmt::format("--camera {}: a folder, not a camera file", options.camera_path));
  if (!options.gt_path.empty() && !fs::exists(options.gt_path, ec))
    throw std::runtime_error(fmt::format("--gt {}: the file does not exist", options.gt_path));
  if (!options.gt_path.empty() && !fs::is_regular_file(options.gt_path, ec))
    throw std::runtime_error(fmt::format("--gt {}: is not a regular file (a folder, pipe or device)", options.gt_path));
  data = io::OpenDataset(input, dopt);
  for (const std::string& note : data.notes) spdlog::warn("{}", note);
  if (!data.camera)
    throw std::runtime_error(fmt::format(
        "{}: no camera: give one with --camera FILE (YAML, or a text line 'fx fy cx cy [k1 k2 p1 p2 [k3]]')",
        data.source->Description()));
  camera = *data.camera;
  camera.Check();
  input_camera = camera;
  camera = HalvedCamera(input_camera, options.max_megapixels, &halvings);
  if (halvings > 0)
    spdlog::info("frames of {}x{} worked on at {}x{} (halved {}: more than --max-megapixels {} million pixels; 0 keeps "
                 "them)",
                 input_camera.width, input_camera.height, camera.width, camera.height,
                 halvings == 1 ? std::string("once") : fmt::format("{} times", halvings), options.max_megapixels);
  if (!data.image_size)
    spdlog::warn("{}: the image size is not known before reading; frames of another size than the camera's {}x{} "
                 "will be skipped",
                 data.source->Description(), input_camera.width, input_camera.height);

  gt = data.ground_truth;
  gt_origin = gt ? fmt::format("{} ({})", data.path, io::ToString(data.kind)) : "";
  if (!options.gt_path.empty()) {
    gt = io::ReadTrajectory(options.gt_path);
    gt_origin = options.gt_path;
    if (gt->empty()) throw std::runtime_error(fmt::format("--gt {}: holds no pose", options.gt_path));
  }

  if (!options.load_map_path.empty()) {
    try {
      map_in = io::ReadMapFile(options.load_map_path);
    } catch (const std::runtime_error& e) {
      throw std::runtime_error(fmt::format("--load-map: {}", e.what()));
    }
  }

  count = data.source->FrameCount();
  // A video's frame count is the container's word and may be off; only lists of images are exact.
  const bool exact_count = count && data.kind != io::DatasetKind::kVideo && data.kind != io::DatasetKind::kWebcam;
  if (exact_count && options.start >= *count)
    throw std::invalid_argument(
        fmt::format("--start {} is out of range: {} has {} frames (0..{})", options.start, data.source->Description(),
                    *count, *count - 1));
  if (exact_count && options.end >= *count)
    throw std::invalid_argument(fmt::format("--end {} is out of range: {} has {} frames (0..{})", options.end,
                                            data.source->Description(), *count, *count - 1));
}

void ImageRun::Setup(const slam::SystemOptions& system_in) {
  std::error_code ec;
  sys_opts = system_in;
  sys_opts.Check();
  auto pose_kernel = MakePoseKernelFor(backend);
  auto point_kernel = MakePointKernelFor(backend);

  fs::create_directories(out_dir, ec);
  if (!fs::is_directory(out_dir, ec)) throw std::runtime_error(fmt::format("--out {}: cannot create the folder", out_dir));
  out = fs::path(out_dir);
  // The overlay and the plot may go elsewhere: their folders are made now, so that the end of a long run
  // cannot fail for want of one.
  for (const std::string& path : {options.overlay_path, options.plot_path})
    if (const fs::path parent = fs::path(path).parent_path(); !path.empty() && !parent.empty())
      fs::create_directories(parent, ec);

  double video_fps = 30.0;
  if (options.fps > 0) {
    video_fps = options.fps;
  } else if (data.kind == io::DatasetKind::kKitti) {
    video_fps = 10.0;
  } else if (auto* vs = dynamic_cast<io::VideoSource*>(data.source.get()); vs && vs->fps() > 0) {
    video_fps = vs->fps();
  }
  if (!options.overlay_path.empty()) overlay = std::make_unique<Overlay>(options.overlay_path, camera, video_fps);
  if (!options.save_tracks_dir.empty()) {
    const fs::path dir(options.save_tracks_dir);
    fs::create_directories(dir, ec);
    if (!fs::is_directory(dir, ec))
      throw std::runtime_error(fmt::format("--save-tracks {}: cannot create the folder", options.save_tracks_dir));
    io::WriteCameraYaml((dir / "camera.yaml").string(), camera, video_fps);
    tracks_out = std::make_unique<io::ObservationWriter>((dir / "observations.txt").string());
  }

  pipeline::VisualSlamOptions vs_opts;
  vs_opts.frontend = options.frontend;
  vs_opts.frontend.describe_async = true;  // SIFT of the new tracks runs while the back end estimates the pose
  vs_opts.system = sys_opts;
  vs_opts.relocalise = options.relocalise;
  vs_opts.relocalise_turned = options.relocalise_turned;
  vs_opts.pipelined = options.pipelined;
  vs_opts.describe_map_points_only = options.describe_map_points_only;
  fe_opts = vs_opts.frontend;
  vslam = std::make_unique<pipeline::VisualSlam>(camera, vs_opts, std::move(pose_kernel), std::move(point_kernel));
  if (options.gt_scale) {
    if (!gt) throw std::invalid_argument("--gt-scale needs a ground truth: the dataset has none and no --gt was given");
    vslam->system().SetBaselineOracle(BaselineOracle(*gt));
  }

  if (map_in) {
    try {
      vslam->LoadMap(*map_in);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(fmt::format("--load-map {}: {}", options.load_map_path, e.what()));
    }
    spdlog::info("starting in the map {}: {} points, {} keyframes", options.load_map_path, map_in->points.size(),
                 map_in->keyframes.size());
    map_in.reset();  // the System holds it now
  }
  if (const fs::path parent = fs::path(options.save_map_path).parent_path();
      !options.save_map_path.empty() && !parent.empty())
    fs::create_directories(parent, ec);

  last = options.end >= 0 ? options.end : (count ? *count - 1 : -1);
  spdlog::info("{}: {} camera {} ({}); frames {}..{}; {} hypotheses/frame, {} samples/point, backend {}; "
               "initialisation after a median feature motion of {:.2f} deg and a median parallax of {:.1f} deg; rotation "
               "samples {:.2f} deg; new points from {:.1f} deg of parallax",
               data.source->Description(), io::ToString(data.kind), camera.ToString(), data.camera_origin,
               options.start, last >= 0 ? fmt::format("{}", last) : std::string("end"), sys_opts.tracker.hypotheses,
               sys_opts.mapping.samples, backend, sys_opts.init.min_median_motion_deg,
               sys_opts.init.min_median_parallax_deg, sys_opts.tracker.sigma_rot_deg, sys_opts.mapping.min_parallax_deg);
  if (gt) spdlog::info("ground truth: {} poses from {}", gt->size(), gt_origin);
}

void ImageRun::RunFrames() {
  InstallInterruptHandler();
  bool was_lost = false;  // for the log: the last frame was lost
  Progress progress(last >= 0 ? std::optional<int64_t>(last) : std::nullopt);
  const RunClock clock;  // wall and process CPU time of the frames' processing
  const auto t_start = Clock::now();
  auto elapsed_s = [&] { return std::chrono::duration<double>(Clock::now() - t_start).count(); };

  auto put_reports = [&](const std::vector<slam::FrameReport>& step_reports) {
    for (const slam::FrameReport& r : step_reports) {
      if (const std::optional<slam::FrameStatus> replaced = log.Put(r)) {
        tracked -= *replaced == slam::FrameStatus::kTracked;
        lost -= *replaced == slam::FrameStatus::kLost;
      }
      tracked += r.status == slam::FrameStatus::kTracked;
      lost += r.status == slam::FrameStatus::kLost;
      if (r.init_rejected) init_rejections.push_back({{"frame", r.index}, {"why", r.note}});
      if (r.self_calibration) progress.Clear(), spdlog::info("frame {}: {}", r.index, r.note);
      if (r.depth_reversed) {
        progress.Clear(), spdlog::warn("frame {}: {}", r.index, r.note);
        depth_reversals.push_back({{"frame", r.index}, {"why", r.note}});
      }
      if (r.map_restarted) {
        progress.Clear(), spdlog::warn("frame {}: {}", r.index, r.note);
        map_restarts.push_back({{"frame", r.index}, {"why", r.note}});
      }
      if (r.initialisation && !r.note.empty()) init_of_map.try_emplace(map_restarts.size(), r.index, r.note);
      if (r.initialisation && !r.note.empty() && !init_frame) {
        init_frame = r.index;
        init_note = r.note;
        progress.Clear();
        spdlog::info("frame {}: {}", r.index, r.note);
      }
    }
  };
  // The frames pushed whose steps have not come back: their rows, start times and images (for the overlay).
  struct Pending {
    FrameRow row;
    Clock::time_point t_frame;
    cv::Mat image;
  };
  std::deque<Pending> pending;
  auto finish = [&](const pipeline::VisualSlamStep& step) {
    Pending p = std::move(pending.front());
    pending.pop_front();
    FrameRow& row = p.row;
    const frontend::FrameResult& fr = step.frontend;
    if (tracks_out) {
      io::ObservationFrame of{fr.index, fr.stamp_s, {}};
      of.observations.reserve(fr.features.size());
      for (const frontend::TrackedFeature& f : fr.features) of.observations.push_back({f.feature_id, f.uv_px.x(), f.uv_px.y()});
      tracks_out->Append(of);
    }
    row.fe = fr.stats;
    row.features = static_cast<int>(fr.features.size());
    row.lost_tracks = static_cast<int>(fr.lost.size());
    row.before_init = step.before_init;
    row.reloc_tried = step.reloc_tried;
    row.reloc_matches = step.reloc_matches;
    row.reloc_inliers = step.reloc_inliers;
    row.reloc_turned = step.reloc_turned;
    row.reloc_ms = step.reloc_ms;
    row.merged_tracks = step.merged_tracks;
    row.backend_ms = step.backend_ms;
    if (step.reloc_inliers > 0) {
      progress.Clear();
      spdlog::info("frame {}: relocalised from {} of {} features matched to the map{}{}", row.index, row.reloc_inliers,
                   row.reloc_matches, step.reloc_near_provisional ? " (near the provisional map's orientation)" : "",
                   step.reloc_turned ? fmt::format(" (their descriptors turned by {:.0f} deg about the camera's axis)",
                                                   step.reloc_turn_deg)
                                     : std::string());
    }
    ++frames_processed;
    const slam::FrameReport* current = nullptr;
    put_reports(step.reports);
    if (auto it = report_of_index.find(row.index); it != report_of_index.end()) current = &reports[it->second];
    if (current) {
      const bool is_lost = current->status == slam::FrameStatus::kLost;
      if (is_lost && !was_lost) progress.Clear(), spdlog::warn("frame {} lost: {}", current->index, current->note);
      if (!is_lost && was_lost && current->status == slam::FrameStatus::kTracked)
        progress.Clear(), spdlog::info("frame {}: tracking resumed", current->index);
      was_lost = is_lost;
    }
    if (overlay) {
      if (init_frame) {
        std::vector<Eigen::Vector3d> pts;
        for (const slam::MapPoint& pt : vslam->system().map().points())
          if (pt.state != slam::PointState::kRemoved) pts.push_back(pt.position_in_world);
        overlay->Anchor(pts);
      }
      overlay->SetCamera(vslam->system().camera());
      overlay->Write(p.image, fr, vslam->system().map(), current);
    }
    row.frame_ms = MsSince(p.t_frame);  // the frame's latency: from the reader's hand-over to its step
    const int64_t index = row.index;
    rows.push_back(std::move(row));
    progress.Update(frames_processed, index, tracked, lost, vslam->system().map().points().size(),
                    frames_processed / std::max(elapsed_s(), 1e-9));
  };
  // The frame in flight, before a frame's row that must come after it or the end.
  auto finish_in_flight = [&] {
    if (std::optional<pipeline::VisualSlamStep> step = vslam->Flush()) finish(*step);
  };
  try {
    io::Frame frame;
    // The next frame is read and decoded while this one is worked on; decode_ms is the reading's own time.
    io::PrefetchingSource reader(data.source.get());
    while (!Interrupted()) {
      const auto t_frame = Clock::now();
      double decode_ms = 0;
      if (!reader.Next(&frame, &decode_ms)) {
        source_ended = true;
        break;
      }
      frames_decoded = frame.index + 1;
      if (frame.index < options.start) continue;
      if (options.end >= 0 && frame.index > options.end) break;
      ++frames_read;
      FrameRow row;
      row.index = frame.index;
      row.stamp_s = frame.stamp_s;
      row.name = frame.name;
      row.decode_ms = decode_ms;
      if (frame.ok() && (frame.image.cols != input_camera.width || frame.image.rows != input_camera.height))
        frame.error = fmt::format("the image is {}x{} but the camera is {}x{}", frame.image.cols, frame.image.rows,
                                  input_camera.width, input_camera.height),
        frame.image.release();
      if (frame.ok()) frame.image = Halved(frame.image, halvings);
      if (!frame.ok()) {
        finish_in_flight();
        progress.Clear();
        spdlog::warn("frame {} ({}) skipped: {}", frame.index, frame.name, frame.error);
        row.skipped = true;
        vslam->SkipFrame();
        row.error = frame.error;
        row.frame_ms = MsSince(t_frame);
        rows.push_back(std::move(row));
        continue;
      }

      std::optional<pipeline::VisualSlamStep> step;
      try {
        // Pipelined (VisualSlamOptions::pipelined): the step of the frame before comes back.
        step = vslam->Push(frame.image, frame.index, frame.stamp_s);
      } catch (const pipeline::UnusableFrame& e) {  // a pixel type the front end does not take: this frame only
        finish_in_flight();
        progress.Clear();
        spdlog::warn("frame {} ({}) skipped: {}", frame.index, frame.name, e.what());
        row.skipped = true;
        row.error = e.what();
        row.frame_ms = MsSince(t_frame);
        rows.push_back(std::move(row));
        continue;
      }
      // The frame's own image for the overlay: pipelined, its step comes after the next one was decoded, maybe into
      // the same buffer.
      pending.push_back({std::move(row), t_frame,
                         overlay && vslam->options().pipelined ? frame.image.clone() : frame.image});
      if (step) finish(*step);
    }
  } catch (const std::exception& e) {
    failure = e.what();  // outputs first, then the error
  }
  try {
    finish_in_flight();  // the frame whose back end had not run when the loop stopped
    put_reports(vslam->Finish());  // the last keyframe's report, revised by its local bundle adjustment
  } catch (const std::exception& e) {
    if (failure.empty()) failure = e.what();
  }
  times = clock.Elapsed();
  // The initialisation of the map whose frames the run kept (a restart may have replaced the first one): the
  // first map whose initialisation's frame still has its pose.
  if (!map_restarts.empty()) {
    init_frame.reset();
    for (const auto& [map, init] : init_of_map)
      if (auto it = report_of_index.find(init.first); it != report_of_index.end() && reports[it->second].has_pose) {
        init_frame = init.first;
        init_note = init.second;
        break;
      }
  }
  const double wall_s = times.wall_s;
  progress.Update(frames_processed, rows.empty() ? 0 : rows.back().index, tracked, lost, vslam->system().map().points().size(),
                  frames_processed / std::max(wall_s, 1e-9), true);
  progress.Clear();
  interrupted = Interrupted();
  if (interrupted) spdlog::warn("interrupted: writing the {} frames done so far", rows.size());
  CheckEnd();
}

void ImageRun::CheckEnd() {
  // A video that ends well before the frame count its header promises was cut off or is damaged: the run is
  // what it is, but it says so (log and report.json's notes) instead of passing for the whole video. Container
  // counts are estimates for some codecs: a few frames short (2 %, at least 2) is not reported.
  notes = data.notes;
  if (source_ended && data.kind == io::DatasetKind::kVideo && count &&
      static_cast<double>(frames_decoded) < 0.98 * static_cast<double>(*count) - 2.0) {
    notes.push_back(fmt::format("{}: the video ended after {} of the {} frames its header promises (cut off or "
                                "damaged?); the run covers only those",
                                input, frames_decoded, *count));
    spdlog::warn("{}", notes.back());
  }
  if (frames_read == 0 && failure.empty() && !interrupted)
    failure = options.start > 0 ? fmt::format("--start {}: {} ended before that frame (no frame to process)",
                                              options.start, data.source->Description())
                                : fmt::format("{}: no frame to process", data.source->Description());
}

// Whatever happened before, what was computed is written.
void ImageRun::WriteOutputs() {
  WriteTrajectoryMapAndFrames();
  WriteMap();
  if (vslam->system().self_calibration().accepted) {  // the camera the map was made with, for the next run
    try {
      io::WriteCameraYaml((out / "camera_selfcalibrated.yaml").string(), vslam->system().camera());
    } catch (const std::exception& e) {
      if (failure.empty()) failure = e.what();
    }
  }
  if (options.viewer) {  // before the report, so that the report carries its failure
    ViewerOptions vo;
    vo.ground_truth = gt;
    vo.title = input;
    if (map_saved) vo.map_file = options.save_map_path;
    try {
      WriteViewer(out_dir, (out / "viewer.html").string(), vo);
    } catch (const std::exception& e) {
      if (failure.empty()) failure = fmt::format("--viewer: {}", e.what());
    }
  }
  WriteReport();
  WritePlot();
  if (overlay) overlay.reset();  // closes the file
  if (tracks_out) {
    try {
      tracks_out->Close();
      // The ground truth beside them, so that the folder runs and evaluates as it is. Without stamps (a KITTI
      // poses file), pose i is frame i: each processed frame's pose takes the frame's stamp.
      if (gt) {
        io::Trajectory g;
        if (gt->has_stamps) {
          g = *gt;
        } else {
          for (const FrameRow& row : rows)
            if (!row.skipped && row.index >= 0 && static_cast<size_t>(row.index) < gt->size())
              g.stamps_s.push_back(row.stamp_s), g.world_from_cam.push_back(gt->world_from_cam[row.index]);
        }
        io::WriteTum((fs::path(options.save_tracks_dir) / "groundtruth.txt").string(), g);
      }
    } catch (const std::exception& e) {
      if (failure.empty()) failure = fmt::format("--save-tracks: {}", e.what());
    }
    tracks_out.reset();
  }
}

// A map that cannot be written loses nothing else: the failure is the run's, reported after every output.
void ImageRun::WriteMap() {
  if (options.save_map_path.empty()) return;
  try {
    io::MapFile map = vslam->ExportMap();
    map.options = {{"backend", backend}, {"system", ToJson(sys_opts)}, {"frontend", ToJson(fe_opts)}};
    if (map.points.empty())
      spdlog::warn("--save-map {}: the map is empty (the run never initialised)", options.save_map_path);
    io::WriteMapFile(options.save_map_path, map);
    spdlog::info("map written to {}: {} points, {} keyframes", options.save_map_path, map.points.size(),
                 map.keyframes.size());
    map_saved = true;
  } catch (const std::exception& e) {
    if (failure.empty()) failure = fmt::format("--save-map: {}", e.what());
  }
}

void ImageRun::WriteTrajectoryMapAndFrames() {
  // The trajectory, with the frame index of each pose.
  io::Trajectory smooth;
  for (const slam::FrameReport& r : reports) {
    if (!r.has_pose) continue;
    traj.stamps_s.push_back(r.stamp_s), smooth.stamps_s.push_back(r.stamp_s);
    traj.world_from_cam.push_back(r.cam_from_world.Inverse());
    smooth.world_from_cam.push_back(r.smoothed_cam_from_world.Inverse());
    traj_frames.push_back(r.index);
  }
  io::WriteTum((out / "trajectory.txt").string(), traj);
  io::WriteTum((out / "trajectory_smoothed.txt").string(), smooth);
  if (options.format == "kitti")
    io::WriteKitti((out / "trajectory_kitti.txt").string(), traj, (out / "trajectory_kitti_times.txt").string());
  io::PointCloud cloud;
  for (const slam::MapPoint& p : vslam->system().result_map().points()) {
    if (p.state == slam::PointState::kRemoved) continue;
    cloud.points.push_back(p.position_in_world);
    cloud.ids.push_back(p.id);
  }
  io::WritePly((out / "map.ply").string(), cloud);
  sum.map_points = static_cast<int64_t>(cloud.points.size());

  if (gt && traj.size() >= 3) {
    // A ground truth without stamps (a KITTI poses file without times) pairs by frame index: pose i is frame
    // i of the source, so both sides carry the frame index as their stamp for the evaluation.
    io::Trajectory gt_eval = *gt, est_eval = traj;
    if (!gt->has_stamps) {
      for (size_t i = 0; i < gt_eval.size(); ++i) gt_eval.stamps_s[i] = static_cast<double>(i);
      for (size_t i = 0; i < est_eval.size(); ++i) est_eval.stamps_s[i] = static_cast<double>(traj_frames[i]);
      gt_eval.has_stamps = true;
    }
    try {
      errors = eval::EvaluateTrajectory(gt_eval, est_eval, {});
    } catch (const std::exception& e) {
      eval_failure = e.what();
      spdlog::warn("no evaluation against the ground truth: {}", eval_failure);
    }
  } else if (gt) {
    eval_failure = fmt::format("only {} posed frames (3 needed for a Sim(3) alignment)", traj.size());
  }
  std::map<int64_t, const eval::FrameError*> error_of_index;
  if (errors)
    for (const eval::FrameError& e : errors->frames) error_of_index[traj_frames[e.est_index]] = &e;
  WriteFramesCsv((out / "frames.csv").string(), reports, report_of_index, error_of_index, rows);
}


// The summary line, then the run's failure when it had one.
ImageJobSummary ImageRun::Finish() {

  std::string line = fmt::format(
      "frames={} tracked={} lost={} not_initialised={} skipped={} keyframes={} map_points={} fps={:.2f}", sum.frames,
      sum.tracked, sum.lost, sum.not_initialised, sum.skipped, sum.keyframes, sum.map_points, sum.fps);
  if (errors)
    line += fmt::format(" ate_rmse={:.6g} ate_mean={:.6g} rot_mean_deg={:.6g} rpe_trans_rmse={:.6g} scale={:.6g}",
                        errors->ate_m.rmse, errors->ate_m.mean, errors->rot_deg.mean, errors->rpe_trans_m.rmse,
                        errors->alignment_result.gt_world_from_est_world.scale);
  line += RunTimesFields(times);
  fmt::print("{}\n", line);
  if (options.timings) fmt::print("{}", StageTable(stages, frames_processed, times.wall_s));
  std::fflush(stdout);

  if (!failure.empty()) throw std::runtime_error(fmt::format("{} (outputs so far written to {})", failure, out_dir));
  if (interrupted) throw InterruptedError();
  if (sum.initialised && !sum.localised && !options.load_map_path.empty())
    throw ExitError(kExitNotInitialised,
                    fmt::format("no frame was relocalised in the map {} ({} frames; outputs written to {}): the run "
                                "never saw a place of the map as it looked when it was made",
                                options.load_map_path, frames_processed, out_dir));
  if (!sum.initialised) throw NotInitialisedError(sys_opts.init, reports, frames_processed, out_dir);
  return sum;
}

ImageJobSummary RunImageJob(const std::string& input, const std::string& out_dir, const slam::SystemOptions& system_in,
                            const std::string& backend, const ImageJobOptions& options) {
  options.Check();
  ImageRun run(input, out_dir, backend, options);
  run.Open();
  run.Setup(system_in);
  run.RunFrames();
  run.WriteOutputs();
  return run.Finish();
}

}  // namespace mcslam::apps
