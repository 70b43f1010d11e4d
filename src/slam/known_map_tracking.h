#pragma once
// Pose tracking against a given map (the paper's precision test, §8.1): the map is known, the pose of every
// frame is found by the Monte Carlo pose estimator, the inlier flags of the points carry from frame to frame.
#include <cstdint>
#include <memory>
#include <unordered_map>
#include <vector>

#include "core/camera.h"
#include "slam/pose_smoother.h"
#include "slam/pose_tracker.h"
#include "core/observations.h"

namespace mcslam::slam {

struct KnownMapOptions {
  PoseTrackerOptions tracker;
  PoseSmootherOptions smoother;
};

struct FrameResult {
  int64_t index = 0;
  double stamp_s = 0;
  PoseEstimate estimate;          // estimate.tracked false: lost, no pose for this frame
  Pose smoothed_cam_from_world;   // DESP output (valid when tracked)
  int observed_map_points = 0;    // observations of this frame that belong to the map
  double time_ms = 0;             // wall time of the pose step
  bool given = false;             // the pose was given (first frame), not estimated
};

class KnownMapTracker {
 public:
  KnownMapTracker(const PinholeCamera& camera, std::unordered_map<int64_t, Eigen::Vector3d> points_in_world,
                  const KnownMapOptions& options, std::unique_ptr<compute::PoseKernel> kernel);
  // The first frame with its pose given (initialises the inlier flags and the smoother).
  FrameResult Start(const FrameObservations& frame, const Pose& cam_from_world);
  // Every following frame.
  FrameResult Track(const FrameObservations& frame);

  const Pose& last_cam_from_world() const { return last_; }
  PoseTracker& tracker() { return tracker_; }

 private:
  void Gather(const FrameObservations& frame);
  void Commit(const std::vector<uint8_t>& inliers);

  PinholeCamera camera_;
  std::unordered_map<int64_t, int> index_of_id_;
  std::vector<Eigen::Vector3d> points_;
  std::vector<uint8_t> inlier_flag_;  // per map point, carried to the next frame
  PoseTracker tracker_;
  PoseSmoother smoother_;
  Pose last_;
  // Reused per frame.
  std::vector<PointObservation> obs_;
  std::vector<int> obs_point_;
  std::vector<double> residuals_;
  std::vector<uint8_t> inliers_;
};

}  // namespace mcslam::slam
