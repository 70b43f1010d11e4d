#pragma once
// The full SLAM job on a folder of observations: the System of the slam layer over every frame, and the
// outputs users keep (trajectories, map, per-frame CSV with errors when the ground truth is known).
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "apps/known_map_job.h"
#include "apps/run_timing.h"
#include "eval/trajectory_eval.h"
#include "io/ply.h"
#include "slam/system.h"

namespace mcslam::apps {

// The final report of every frame, in frame order: a later report of the same frame (the initialisation
// resolving frames first reported as waiting) replaces the earlier one.
struct ReportLog {
  std::vector<slam::FrameReport> reports;
  std::map<int64_t, size_t> index_of_frame;  // frame index -> position in reports
  // Adds r, or replaces the report of its frame; returns the replaced report's status when it replaced one.
  std::optional<slam::FrameStatus> Put(const slam::FrameReport& r);
};

struct SlamRunResult {
  std::vector<slam::FrameReport> reports;  // one per frame, in order (the final report of each)
  bool initialised = false;
  slam::SelfCalibration self_calibration;  // what the System measured of the lens' k1
  PinholeCamera self_calibration_camera;   // the camera the map was made with
  io::PointCloud map;                       // active and lost points, with ids
  RunTimes times;                           // wall and process CPU time of the frames' processing
};

// Runs the System over every frame. gt_scale: the first baseline takes its length from the ground truth.
// Stops early, keeping what it has, when `stop` returns true.
SlamRunResult RunSlam(const SequenceInput& input, const slam::SystemOptions& options,
                      std::unique_ptr<compute::PoseKernel> pose_kernel,
                      std::unique_ptr<compute::PointKernel> point_kernel, bool gt_scale,
                      const std::function<void(const slam::FrameReport&)>& on_frame = {},
                      const std::function<bool()>& stop = {});

// For --gt-scale: the distance between the ground-truth camera centres at two stamps (nearest pose within
// 20 ms of each, as the evaluation associates), or nothing when either stamp has no pose. The trajectory must outlive the function.
std::function<std::optional<double>(double, double)> BaselineOracle(const io::Trajectory& groundtruth);

io::Trajectory ReportsToTrajectory(const std::vector<slam::FrameReport>& reports, bool smoothed);

// Writes a run report (report.json) to `path`; throws naming the file when it cannot.
void WriteReportJson(const std::string& path, const nlohmann::json& report);

}  // namespace mcslam::apps
