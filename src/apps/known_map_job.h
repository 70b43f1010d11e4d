#pragma once
// The known-map pose tracking job (paper §8.1 precision test), shared by `mcslam run --known-map` and the
// hypothesis sweep of `mcslam bench`.
#include <functional>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/camera.h"
#include "io/trajectory_io.h"
#include "sim/paper_scenario.h"
#include "slam/known_map_tracking.h"
#include "slam/system.h"

namespace mcslam::apps {

// A folder of observations as `mcslam synth` writes it (or any front end could).
struct SequenceInput {
  PinholeCamera camera;
  std::vector<FrameObservations> frames;
  io::Trajectory groundtruth;  // world_from_cam; empty when the folder has none
};
// Reads DIR/camera.yaml, DIR/observations.txt and (when present) DIR/groundtruth.txt. Throws naming the
// missing or bad file; an observation file with no frame is an error.
SequenceInput LoadSequenceInput(const std::string& dir);

struct KnownMapInput : SequenceInput {
  std::unordered_map<int64_t, Eigen::Vector3d> map;
};

// LoadSequenceInput plus DIR/map_gt.ply (with point ids).
KnownMapInput LoadKnownMapInput(const std::string& dir);
KnownMapInput KnownMapInputFromSequence(const sim::SyntheticSequence& sequence);
std::vector<FrameObservations> ToSlamFrames(const std::vector<io::ObservationFrame>& frames);

// Tracks every frame; the first frame's pose comes from the ground truth (nearest stamp within 1 ms).
// `on_frame` (optional) sees each result as it is made. Stops early, keeping what it has, when
// `stop` (optional) returns true.
std::vector<slam::FrameResult> RunKnownMap(const KnownMapInput& input, const slam::KnownMapOptions& options,
                                           std::unique_ptr<compute::PoseKernel> kernel,
                                           const std::function<void(const slam::FrameResult&)>& on_frame = {},
                                           const std::function<bool()>& stop = {});

// The tracked frames as a trajectory (world_from_cam); lost frames are left out, never invented.
io::Trajectory ResultsToTrajectory(const std::vector<slam::FrameResult>& results, bool smoothed);
// A pose step's result as a frame report of the SLAM system, for the one frames.csv schema: the given first pose
// is the initialisation, the map points are those the frame observed, the note why it was lost.
slam::FrameReport ToFrameReport(const slam::FrameResult& result);

}  // namespace mcslam::apps
