#include <filesystem>
#include <stdexcept>
#include <system_error>

#include "io/camera_io.h"
#include "io/observations_io.h"
#include "io/ply.h"
#include "io/trajectory_io.h"
#include "sim/paper_scenario.h"

// Kept apart from paper_scenario.cc so that code that only builds sequences does not pull in the file writers.
namespace mcslam::sim {

void WriteSyntheticSequence(const SyntheticSequence& sequence, const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir)) {
    throw std::runtime_error("cannot create output folder " + dir + (ec ? ": " + ec.message() : ""));
  }
  const std::filesystem::path d(dir);
  io::WriteTum((d / "groundtruth.txt").string(), ToTrajectory(sequence));
  io::WritePly((d / "map_gt.ply").string(), ToPointCloud(sequence));
  io::WriteCameraYaml((d / "camera.yaml").string(), sequence.camera, sequence.fps);
  io::WriteObservations((d / "observations.txt").string(), ToObservationFrames(sequence));
}

}  // namespace mcslam::sim
