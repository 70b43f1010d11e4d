#include "apps/known_map_job.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include <fmt/format.h>

#include "io/camera_io.h"
#include "io/observations_io.h"
#include "io/ply.h"

namespace mcslam::apps {

namespace fs = std::filesystem;

std::vector<FrameObservations> ToSlamFrames(const std::vector<io::ObservationFrame>& frames) {
  std::vector<FrameObservations> out;
  out.reserve(frames.size());
  for (const io::ObservationFrame& f : frames) {
    FrameObservations s;
    s.index = f.index;
    s.stamp_s = f.stamp_s;
    s.features.reserve(f.observations.size());
    for (const io::Observation& o : f.observations) s.features.push_back({o.feature_id, {o.u_px, o.v_px}});
    out.push_back(std::move(s));
  }
  return out;
}

SequenceInput LoadSequenceInput(const std::string& dir) {
  if (!fs::is_directory(dir)) throw std::runtime_error(fmt::format("input folder '{}' does not exist", dir));
  auto need = [&](const char* name) {
    const fs::path p = fs::path(dir) / name;
    if (!fs::exists(p)) throw std::runtime_error(fmt::format("'{}' is missing", p.string()));
    return p.string();
  };
  SequenceInput in;
  in.camera = io::ReadCameraYaml(need("camera.yaml"));
  in.frames = ToSlamFrames(io::ReadObservations(need("observations.txt")));
  const fs::path gt = fs::path(dir) / "groundtruth.txt";
  if (fs::exists(gt)) in.groundtruth = io::ReadTum(gt.string());
  if (in.frames.empty()) throw std::runtime_error(fmt::format("'{}/observations.txt' holds no frame", dir));
  return in;
}

KnownMapInput LoadKnownMapInput(const std::string& dir) {
  KnownMapInput in;
  static_cast<SequenceInput&>(in) = LoadSequenceInput(dir);
  const fs::path ply = fs::path(dir) / "map_gt.ply";
  if (!fs::exists(ply)) throw std::runtime_error(fmt::format("'{}' is missing (known-map mode needs it)", ply.string()));
  const io::PointCloud cloud = io::ReadPly(ply.string());
  if (cloud.ids.size() != cloud.points.size())
    throw std::runtime_error(fmt::format("'{}' has no per-point 'id' property", ply.string()));
  for (size_t i = 0; i < cloud.points.size(); ++i) in.map[cloud.ids[i]] = cloud.points[i];
  return in;
}

KnownMapInput KnownMapInputFromSequence(const sim::SyntheticSequence& seq) {
  KnownMapInput in;
  in.camera = seq.camera;
  in.frames = ToSlamFrames(sim::ToObservationFrames(seq));
  for (size_t i = 0; i < seq.points_in_world.size(); ++i) in.map[static_cast<int64_t>(i)] = seq.points_in_world[i];
  in.groundtruth = sim::ToTrajectory(seq);
  return in;
}

std::vector<slam::FrameResult> RunKnownMap(const KnownMapInput& input, const slam::KnownMapOptions& options,
                                           std::unique_ptr<compute::PoseKernel> kernel,
                                           const std::function<void(const slam::FrameResult&)>& on_frame,
                                           const std::function<bool()>& stop) {
  if (input.frames.empty()) throw std::runtime_error("no frames to track");
  // The first pose is given, as in the paper's precision test: the ground-truth pose of the first frame.
  const double t0 = input.frames.front().stamp_s;
  const int best = io::NearestStampIndex(input.groundtruth, t0, 1e-3);
  if (best < 0)
    throw std::runtime_error(fmt::format(
        "known-map tracking needs the pose of the first frame (t = {:.6f} s) in the ground truth, and none is within 1 ms",
        t0));

  slam::KnownMapTracker tracker(input.camera, input.map, options, std::move(kernel));
  std::vector<slam::FrameResult> results;
  results.reserve(input.frames.size());
  results.push_back(tracker.Start(input.frames.front(), input.groundtruth.world_from_cam[best].Inverse()));
  if (on_frame) on_frame(results.back());
  for (size_t i = 1; i < input.frames.size(); ++i) {
    if (stop && stop()) break;
    results.push_back(tracker.Track(input.frames[i]));
    if (on_frame) on_frame(results.back());
  }
  return results;
}

io::Trajectory ResultsToTrajectory(const std::vector<slam::FrameResult>& results, bool smoothed) {
  io::Trajectory t;
  for (const slam::FrameResult& r : results) {
    if (!r.estimate.tracked) continue;
    t.stamps_s.push_back(r.stamp_s);
    t.world_from_cam.push_back((smoothed ? r.smoothed_cam_from_world : r.estimate.cam_from_world).Inverse());
  }
  return t;
}

slam::FrameReport ToFrameReport(const slam::FrameResult& result) {
  const slam::PoseEstimate& e = result.estimate;
  slam::FrameReport r;
  r.index = result.index;
  r.stamp_s = result.stamp_s;
  r.status = e.tracked ? slam::FrameStatus::kTracked : slam::FrameStatus::kLost;
  r.has_pose = e.tracked;
  r.cam_from_world = e.cam_from_world;
  r.smoothed_cam_from_world = result.smoothed_cam_from_world;
  r.keyframe = e.keyframe;
  r.initialisation = result.given;
  r.scored = e.scored;
  r.inliers = e.inliers;
  r.score = e.score;
  r.sigma_t = e.sigma_t;
  r.map_points = result.observed_map_points;
  r.reproj_mean_px = e.mean_inlier_residual_px;
  r.track_ms = result.time_ms;
  r.note = result.given ? "pose given (the ground truth's)" : e.lost_reason;
  return r;
}

}  // namespace mcslam::apps
