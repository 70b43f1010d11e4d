#pragma once
// The per-frame rows of a run and how they are written: frames.csv, and the helpers of report.json.
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "apps/options.h"
#include "eval/trajectory_eval.h"
#include "frontend/frontend.h"
#include "slam/system.h"

namespace mcslam::apps {

// ---- per-frame bookkeeping -------------------------------------------------------------------------------

struct FrameRow {
  int64_t index = 0;
  double stamp_s = 0;
  std::string name;
  bool skipped = false;
  std::string error;  // why skipped
  frontend::FrameStats fe;
  int features = 0, lost_tracks = 0;
  // Relocalisation in this frame: tried (after a lost or skipped frame), matches to map points, PnP inliers
  // (0: no pose found).
  bool reloc_tried = false;
  int reloc_matches = 0, reloc_inliers = 0;
  bool reloc_turned = false;  // ... from descriptors turned about the camera's axis (VisualSlamOptions::relocalise_turned)
  double reloc_ms = 0;
  int merged_tracks = 0;  // new tracks that went on as the map point of a place seen again (VisualSlamStep)
  double decode_ms = 0, frame_ms = 0;
  double backend_ms = 0;     // System::Process, wall time
  bool before_init = false;  // the back end had no map when this frame came: its time is initialisation's
};

struct Stage {
  std::vector<double> ms;
  void Add(double v) {
    if (v > 0 && std::isfinite(v)) ms.push_back(v);
  }
};

// {"count", "median_ms", "mean_ms", "p90_ms", "p99_ms", "max_ms"} of a stage (only the count, and null median
// and mean, when it never ran).
nlohmann::json StageJson(const Stage& s);
// report.json's "self_calibration": what the System measured of the lens' k1 and whether it took it (null when
// it never tried: no settled map, or off).
nlohmann::json SelfCalibrationJson(const slam::SelfCalibration& c);
// The table `run --timings` prints: per stage the frames it ran on, its median, 90th and 99th percentile and
// largest time; then the throughput (frames over the wall time), the latency of a frame (frame_total: read,
// front end, relocalisation and back end, one after the other) and the front end's median over the pose
// step's ("track"). Stages named as in report.json's stages_ms.
std::string StageTable(const std::vector<std::pair<std::string, Stage>>& stages, int64_t frames, double wall_s);
// report.json's per-frame counts, the same in every mode: frames tracked, lost, before the map, keyframes, and of
// the tracked those posed by a turn about the last centre (rotation_only), in a provisional map (provisional), and
// in one that never joined the map (guessed_scale: FrameReport::guessed_scale).
// waiting_for_init: the frames before the first map (or after a restart) by what held each back
// (slam::InitWait, named by slam::InitWaitName; kNone not counted).
struct ReportCounts {
  int64_t tracked = 0, lost = 0, not_initialised = 0, keyframes = 0, rotation_only = 0, provisional = 0,
          guessed_scale = 0;
  std::array<int64_t, slam::kInitWaitReasons> waiting_for_init{};
};
ReportCounts CountReports(const std::vector<slam::FrameReport>& reports);
// The exit of a run that never made its first map (kExitNotInitialised), its message saying what held the waiting
// frames back (slam::WhyNotInitialised): "the sequence never moved enough to initialise" where too little motion
// did, "too few features to track" where the scene's texture did.
[[nodiscard]] ExitError NotInitialisedError(const slam::InitOptions& init, const std::vector<slam::FrameReport>& reports,
                                            int64_t frames, const std::string& out_dir);
// Writes them into report.json's object `j` under those names.
void PutCounts(const ReportCounts& counts, nlohmann::json* j);
// {"count", "rmse", "mean", "median", "max"}, null where not finite.
nlohmann::json StatsJson(const eval::ErrorStats& s);
// frames.csv, one schema for every run: per frame the back end's report and its error against the ground truth
// when known, then the front end's counts and times, then the note.
// A run on images: one line per frame of `rows` (skipped frames included), its report found by index.
void WriteFramesCsv(const std::string& path, const std::vector<slam::FrameReport>& reports,
                    const std::map<int64_t, size_t>& report_of_index,
                    const std::map<int64_t, const eval::FrameError*>& error_of_index, const std::vector<FrameRow>& rows);
// A run without a front end (observations, --known-map): one line per report, the front end's cells empty;
// `errors` are those of the trajectory made of the posed reports in order.
void WriteFramesCsv(const std::string& path, const std::vector<slam::FrameReport>& reports,
                    const std::optional<eval::TrajectoryErrors>& errors);

}  // namespace mcslam::apps
