#pragma once
// Trajectory files in the formats users already have: TUM (timestamp tx ty tz qx qy qz qw), KITTI
// (12 numbers a line, row-major 3x4 [R|t], optional times file) and EuRoC CSV (timestamp in ns, p, q as w x y z).
// Every pose held here is `world_from_cam` (camera-to-world), as all three formats store it.
#include <string>
#include <vector>

#include "core/pose.h"

namespace mcslam::io {

enum class TrajectoryFormat { kAuto, kTum, kKitti, kEuroc };

struct Trajectory {
  std::vector<double> stamps_s;         // seconds; for KITTI without a times file: the frame index
  std::vector<Pose> world_from_cam;     // same length as stamps_s
  bool has_stamps = true;               // false for KITTI files read without a times file
  size_t size() const { return world_from_cam.size(); }
  bool empty() const { return world_from_cam.empty(); }
};

// Index of the pose whose stamp is nearest to t, if within max_dt_s (the first of equally near ones);
// -1 when no pose is that near.
int NearestStampIndex(const Trajectory& traj, double t, double max_dt_s);

// Parses "tum" | "kitti" | "euroc" | "auto"; throws std::invalid_argument naming the value.
TrajectoryFormat ParseTrajectoryFormat(const std::string& name);
std::string ToString(TrajectoryFormat f);
// Guesses from the extension (.csv -> EuRoC) and the number of columns of the first data line
// (8 -> TUM, 12 -> KITTI). Throws std::runtime_error naming the file when it cannot tell.
TrajectoryFormat DetectTrajectoryFormat(const std::string& path);

// Readers throw std::runtime_error with "<path>:<line>: <what>" for a missing file, a malformed line,
// a non-finite number, or a zero-length quaternion. Comment lines (#) and blank lines are skipped.
Trajectory ReadTrajectory(const std::string& path, TrajectoryFormat format = TrajectoryFormat::kAuto,
                          const std::string& kitti_times_path = "");
Trajectory ReadTum(const std::string& path);
Trajectory ReadKitti(const std::string& path, const std::string& times_path = "");
Trajectory ReadEuroc(const std::string& path);

// Writers throw std::runtime_error naming the file when it cannot be written. Full double precision.
void WriteTrajectory(const std::string& path, const Trajectory& traj, TrajectoryFormat format);
void WriteTum(const std::string& path, const Trajectory& traj);
// Writes poses to `path`; when times_path is not empty, the stamps there (one a line).
void WriteKitti(const std::string& path, const Trajectory& traj, const std::string& times_path = "");
void WriteEuroc(const std::string& path, const Trajectory& traj);

}  // namespace mcslam::io
