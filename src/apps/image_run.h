#pragma once
// The state of one run of the image job (image_job.cc), phase by phase; run_report.cc writes its report from
// it. Internal to apps.
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "apps/image_job.h"
#include "apps/image_outputs.h"
#include "apps/run_report.h"
#include "apps/run_timing.h"
#include "apps/slam_job.h"
#include "eval/trajectory_eval.h"
#include "io/datasets.h"
#include "io/map_file.h"
#include "io/observations_io.h"
#include "io/trajectory_io.h"
#include "pipeline/visual_slam.h"

namespace mcslam::apps {

// One run, phase by phase; its members are what the phases hand on to each other.
struct ImageRun {
  ImageRun(std::string input_, std::string out_dir_, std::string backend_, ImageJobOptions options_)
      : input(std::move(input_)), out_dir(std::move(out_dir_)), backend(std::move(backend_)), options(std::move(options_)) {}
  // Given.
  std::string input, out_dir, backend;
  ImageJobOptions options;
  // Open: the input, its camera and ground truth; no frame is processed before every check has passed.
  io::Dataset data;
  PinholeCamera camera;        // the camera of the frames as worked on (halved: ImageJobOptions::max_megapixels)
  PinholeCamera input_camera;  // ... and as given, of the frames as they come
  int halvings = 0;            // how many times each frame is halved
  std::optional<io::Trajectory> gt;
  std::string gt_origin;
  std::optional<int64_t> count;  // frames, when the source knows
  std::optional<io::MapFile> map_in;  // --load-map, read before any frame
  bool map_saved = false;             // --save-map written
  // Setup.
  slam::SystemOptions sys_opts;
  frontend::FrontendOptions fe_opts;
  std::unique_ptr<pipeline::VisualSlam> vslam;
  std::unique_ptr<Overlay> overlay;
  std::unique_ptr<io::ObservationWriter> tracks_out;  // --save-tracks: the front end's tracks, frame by frame
  std::filesystem::path out;
  int64_t last = -1;  // the last frame to process, when known
  // RunFrames.
  std::vector<FrameRow> rows;
  ReportLog log;
  std::vector<slam::FrameReport>& reports = log.reports;
  const std::map<int64_t, size_t>& report_of_index = log.index_of_frame;
  std::optional<int64_t> init_frame;
  std::string init_note, failure;
  nlohmann::json init_rejections = nlohmann::json::array();  // initialisations found and refused, and why
  nlohmann::json depth_reversals = nlohmann::json::array();  // maps found mirrored in depth while settling, flipped
  nlohmann::json map_restarts = nlohmann::json::array();  // maps dropped after staying lost, and why
  std::map<size_t, std::pair<int64_t, std::string>> init_of_map;  // per map (restarts before it): its initialisation
  int tracked = 0, lost = 0;
  int64_t frames_processed = 0, frames_read = 0;
  int64_t frames_decoded = 0;  // frames the source gave, from its first (before --start included)
  bool source_ended = false;   // the source ran out (not --end, an interrupt or a failure)
  RunTimes times;
  bool interrupted = false;
  std::vector<std::string> notes;
  // WriteOutputs.
  io::Trajectory traj;
  std::vector<int64_t> traj_frames;  // the frame index of each pose of traj
  std::optional<eval::TrajectoryErrors> errors;
  std::string eval_failure;
  ImageJobSummary sum;
  std::vector<std::pair<std::string, Stage>> stages;  // per-stage times (report.json's stages_ms), in loop order

  void Open();
  void Setup(const slam::SystemOptions& system_in);
  void RunFrames();
  void WriteOutputs();
  ImageJobSummary Finish();

 private:
  void CheckEnd();
  void WriteTrajectoryMapAndFrames();
  void WriteReport();
  void WritePlot();
  void WriteMap();
};

}  // namespace mcslam::apps
