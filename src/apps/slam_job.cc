#include "apps/slam_job.h"

#include <cmath>
#include <fstream>
#include <map>
#include <stdexcept>

#include <fmt/format.h>

namespace mcslam::apps {

SlamRunResult RunSlam(const SequenceInput& input, const slam::SystemOptions& options,
                      std::unique_ptr<compute::PoseKernel> pose_kernel,
                      std::unique_ptr<compute::PointKernel> point_kernel, bool gt_scale,
                      const std::function<void(const slam::FrameReport&)>& on_frame,
                      const std::function<bool()>& stop) {
  slam::System system(input.camera, options, std::move(pose_kernel), std::move(point_kernel));
  if (gt_scale) {
    if (input.groundtruth.empty()) throw std::invalid_argument("--gt-scale needs a ground truth (groundtruth.txt)");
    system.SetBaselineOracle(BaselineOracle(input.groundtruth));
  }
  SlamRunResult res;
  ReportLog log;
  const RunClock clock;
  auto put = [&](const std::vector<slam::FrameReport>& reports) {
    for (const slam::FrameReport& r : reports) {
      log.Put(r);
      if (on_frame) on_frame(r);
    }
  };
  for (const FrameObservations& f : input.frames) {
    if (stop && stop()) break;
    put(system.Process(f));
  }
  put(system.Finish());  // the last keyframe's revised report (local_ba_async); a restart's outcome
  res.reports = std::move(log.reports);
  res.times = clock.Elapsed();
  res.initialised = system.made_a_map();
  res.self_calibration = system.self_calibration();
  res.self_calibration_camera = system.camera();
  for (const slam::MapPoint& p : system.result_map().points()) {
    if (p.state == slam::PointState::kRemoved) continue;
    res.map.points.push_back(p.position_in_world);
    res.map.ids.push_back(p.id);
  }
  return res;
}

std::optional<slam::FrameStatus> ReportLog::Put(const slam::FrameReport& r) {
  const auto [it, added] = index_of_frame.try_emplace(r.index, reports.size());
  if (added) {
    reports.push_back(r);
    return std::nullopt;
  }
  slam::FrameReport& old = reports[it->second];
  const slam::FrameStatus replaced = old.status;
  if (r.placed_after_loss) {  // posed late: what the frame cost when it came stands
    slam::FrameReport placed = r;
    placed.scored = old.scored;
    placed.map_points = old.map_points;
    placed.track_ms = old.track_ms, placed.map_ms = old.map_ms, placed.adjust_ms = old.adjust_ms;
    placed.init_ms = old.init_ms, placed.adjust_points_ms = old.adjust_points_ms;
    placed.local_ba_ms = old.local_ba_ms, placed.local_ba_wait_ms = old.local_ba_wait_ms;
    old = placed;
    return replaced;
  }
  if (r.pose_update && old.has_pose) {  // a corrected pose: the rest of the frame's report stands
    old.cam_from_world = r.cam_from_world;
    old.joined |= r.joined;
    old.reproj_mean_px = r.reproj_mean_px;
    old.reproj_median_px = r.reproj_median_px;
    return replaced;
  }
  old = r;
  return replaced;
}

std::function<std::optional<double>(double, double)> BaselineOracle(const io::Trajectory& gt) {
  return [&gt](double a, double b) -> std::optional<double> {
    // 20 ms: the association tolerance of the evaluation.
    const int i = io::NearestStampIndex(gt, a, 0.02), j = io::NearestStampIndex(gt, b, 0.02);
    if (i < 0 || j < 0) return std::nullopt;
    return (gt.world_from_cam[i].t - gt.world_from_cam[j].t).norm();
  };
}

io::Trajectory ReportsToTrajectory(const std::vector<slam::FrameReport>& reports, bool smoothed) {
  io::Trajectory t;
  for (const slam::FrameReport& r : reports) {
    if (!r.has_pose) continue;
    t.stamps_s.push_back(r.stamp_s);
    t.world_from_cam.push_back((smoothed ? r.smoothed_cam_from_world : r.cam_from_world).Inverse());
  }
  return t;
}

void WriteReportJson(const std::string& path, const nlohmann::json& report) {
  std::ofstream f(path);
  if (!f) throw std::runtime_error(fmt::format("cannot write '{}'", path));
  f << report.dump(2) << "\n";
  if (!f) throw std::runtime_error(fmt::format("error while writing '{}'", path));
}


}  // namespace mcslam::apps
