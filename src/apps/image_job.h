#pragma once
// The SLAM job on pixels: frames from an image folder, a video, a webcam or a dataset (io/datasets.h) go
// through the front end (detection, tracking, SIFT description on a TBB task that overlaps the back end,
// remapping of lost map points) into the System, and out come the files users keep:
//   trajectory.txt (TUM, world_from_cam), trajectory_smoothed.txt (DESP), [trajectory_kitti.txt + times],
//   map.ply, frames.csv (back end and front end per frame), report.json (counts, per-stage times, fps,
//   ATE/RPE when the ground truth is known), [an AR overlay video], [a top view plot against the ground truth].
#include <cstdint>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "frontend/frontend.h"
#include "slam/system.h"

namespace mcslam::apps {

struct ImageJobOptions {
  std::string dataset = "auto";  // io::ParseDatasetKind: auto | images | folder | video | webcam | kitti | ...
  std::string camera_path;       // replaces the dataset's camera (YAML, or a "fx fy cx cy [k1 k2 p1 p2 [k3]]" line)
  std::string gt_path;           // ground truth replacing the dataset's (TUM, KITTI or EuRoC; detected)
  std::string format = "tum";    // tum: trajectory.txt only; kitti: also trajectory_kitti.txt + trajectory_times.txt
  std::string overlay_path;      // AR overlay video (.mp4, mp4v); empty: none
  std::string plot_path;         // top view of the trajectory against the ground truth (.png); empty: none
  int64_t start = 0;             // first frame (index in the source) to process
  int64_t end = -1;              // last frame (inclusive); -1: to the end of the source
  double fps = 0.0;              // stamps of sources without their own (index / fps); 0: the source's
  bool gt_scale = false;         // the first baseline takes its length from the ground truth (--gt-scale)
  // After a lost frame, each frame's features are matched by their SIFT descriptors to the map points whose
  // tracks ended, and a pose that enough of them agree with (RANSAC PnP) restarts the tracking there.
  bool relocalise = true;
  // The back end's defaults are tuned on the paper's synthetic sequence (320x240, f = 500 px, 1 px noise).
  // For image input the job replaces a few of them (see ImageInputDefaults) unless the user set them.
  bool image_defaults = true;
  frontend::FrontendOptions frontend;
  // Throws std::invalid_argument naming the flag.
  void Check() const;
};

// --dataset, --camera, --gt, --format, --overlay, --plot, --start, --end, --fps, --max-features.
void AddImageJobFlags(CLI::App* cmd, ImageJobOptions* options);

// True when `input` is to be run by the image job: a --dataset other than auto was given, or the input is
// not a folder of observations (no observations.txt in it).
bool IsImageInput(const std::string& input, const ImageJobOptions& options);

// The System's options for real frames seen by `camera`, for every field whose flag is not in `given_flags`
// ("--init-displacement-px", ...):
//   --init-displacement-px  20 px * f / 500 px: it stands for an angle (2.3 degrees), so it scales with f;
//   --init-parallax-deg     3 degrees: the back end asks 5 for its synthetic 1 px noise; tracked features are
//                           quieter, and a forward-moving car (KITTI) loses its shared features before 5;
//   --sigma-rot-deg         0.5 degrees per frame: the spread of the rotation samples; real sequences at 10-30 Hz
//                           turn less than 1 degree a frame, and a tighter spread leaves more hypotheses near
//                           the answer (KITTI 06: ATE 5-29 cm over seeds at 1 degree, 5-8 cm at 0.5).
// Residual thresholds stay in pixels: the tracking noise is in pixels whatever the resolution.
slam::SystemOptions ImageInputDefaults(slam::SystemOptions options, const PinholeCamera& camera,
                                       const std::set<std::string>& given_flags);

struct ImageJobSummary {
  int64_t frames = 0;  // processed (skipped ones not counted)
  int64_t skipped = 0, tracked = 0, lost = 0, not_initialised = 0, keyframes = 0, map_points = 0;
  bool initialised = false;
  bool interrupted = false;
  double fps = 0;
  std::optional<double> ate_rmse_m;
};

// Runs the job and writes every output into `out_dir` (created). Throws std::runtime_error /
// std::invalid_argument with a message naming the file, flag or value for bad input (before any frame is
// processed where it can be known before), and after writing the outputs when the sequence never
// initialised or the user interrupted it.
// `given_flags`: the flags the user set (long names with "--"), which keep their values (ImageInputDefaults).
ImageJobSummary RunImageJob(const std::string& input, const std::string& out_dir, const slam::SystemOptions& system,
                            const std::string& backend, const ImageJobOptions& options,
                            const std::set<std::string>& given_flags);

}  // namespace mcslam::apps
