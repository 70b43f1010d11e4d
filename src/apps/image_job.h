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
  // ... and also by descriptors turned about the camera's axis when upright ones place nothing
  // (pipeline::VisualSlamOptions::relocalise_turned; --no-turned-relocalisation).
  bool relocalise_turned = true;
  // --pipelined: the front end of each frame runs beside the back end of the frame before
  // (pipeline::VisualSlamOptions::pipelined).
  bool pipelined = false;
  // --describe-map-points-only (pipeline::VisualSlamOptions::describe_map_points_only).
  bool describe_map_points_only = false;
  // Map files (io/map_file.h): the map written at the end of the run; a map of an earlier run to start in
  // (relocalised against it, then extended, in its frame and scale).
  std::string save_map_path, load_map_path;
  // A folder of observations (observations.txt, camera.yaml) holding the front end's tracks of every processed
  // frame: `mcslam run` on it runs the back end alone on the same tracks (no relocalisation: descriptors are not
  // kept), and scripts/track_quality.py measures them against a ground truth. Empty: none.
  std::string save_tracks_dir;
  // Frames of more pixels than this (millions) are worked on halved (2x2 averages; an odd last row or column left
  // out), again until they are not, and the camera with them: a 1920x1080 video is tracked at 960x540, 1280x960
  // and KITTI's 1241x376 as they come. The front end's work grows with the pixels and a frame's accuracy in angle
  // does not need them past ~1 Mpx: the paper scenario rendered at 1920x1440 ran 2.4x as fast halved, ATE 0.24 ->
  // 0.49 mm on a 2.1 m path (docs/usage.md). The outputs are the same files in the same world (the trajectory, the
  // map); pixel figures (residuals, the overlay, saved tracks and map files) are the worked frames'. 0: frames as
  // they come.
  double max_megapixels = 1.5;
  bool viewer = false;  // also write viewer.html (apps/viewer.h) into the output folder
  bool timings = false; // print the per-stage time table after the summary line (StageTable)
  frontend::FrontendOptions frontend;
  // Throws std::invalid_argument naming the flag.
  void Check() const;
};

// A frame halved `times` times (ImageJobOptions::max_megapixels): an odd last column or row left out, then each 2x2 block
// averaged (cv::INTER_AREA at exactly one half).
cv::Mat Halved(const cv::Mat& image, int times);
// The camera of such frames: halved while of more than `max_megapixels` million pixels (0: never); how many times
// in *halvings.
PinholeCamera HalvedCamera(const PinholeCamera& camera, double max_megapixels, int* halvings);

// --dataset, --camera, --gt, --format, --overlay, --plot, --start, --end, --fps, --max-features.
void AddImageJobFlags(CLI::App* cmd, ImageJobOptions* options);

// True when `input` is to be run by the image job: a --dataset other than auto was given, or the input is
// not a folder of observations (no observations.txt in it).
bool IsImageInput(const std::string& input, const ImageJobOptions& options);

struct ImageJobSummary {
  int64_t frames = 0;  // processed (skipped ones not counted)
  int64_t skipped = 0, tracked = 0, lost = 0, not_initialised = 0, keyframes = 0, map_points = 0;
  bool initialised = false;
  bool localised = false;  // some frame was posed (a run in a loaded map is initialised from the start)
  bool interrupted = false;
  double fps = 0;
  std::optional<double> ate_rmse_m;
};

// Runs the job and writes every output into `out_dir` (created). Throws std::runtime_error /
// std::invalid_argument with a message naming the file, flag or value for bad input (before any frame is
// processed where it can be known before), and after writing the outputs when the sequence never
// initialised or the user interrupted it.
// The System's options are the same for every input (one default configuration): what differs between inputs
// is measured by the system itself.
ImageJobSummary RunImageJob(const std::string& input, const std::string& out_dir, const slam::SystemOptions& system,
                            const std::string& backend, const ImageJobOptions& options);

}  // namespace mcslam::apps
