// Trajectory readers (TUM, KITTI with and without a times file, EuRoC, auto-detected): what they accept is
// written back in its format and read again to the same poses.
#include "fuzz_util.h"
#include "io/trajectory_io.h"

using namespace mcslam;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const fuzz::Input in = fuzz::Split(data, size);
  const fuzz::Workspace& ws = fuzz::TheWorkspace();
  static const io::TrajectoryFormat kFormats[] = {io::TrajectoryFormat::kTum, io::TrajectoryFormat::kKitti,
                                                  io::TrajectoryFormat::kEuroc, io::TrajectoryFormat::kAuto};
  const io::TrajectoryFormat format = kFormats[in.selector % 4];
  const bool with_times = format == io::TrajectoryFormat::kKitti && in.parts.size() > 1;
  const std::string path = ws.Write(format == io::TrajectoryFormat::kEuroc ? "traj.csv" : "traj.txt", in.parts[0]);
  const std::string times = with_times ? ws.Write("times.txt", in.parts[1]) : "";
  io::Trajectory t;
  try {
    t = io::ReadTrajectory(path, format, times);
  } catch (const std::exception&) {
    return 0;
  }
  fuzz::Require(t.stamps_s.empty() || t.stamps_s.size() == t.world_from_cam.size(), "one stamp per pose");
  const io::TrajectoryFormat written = format != io::TrajectoryFormat::kAuto ? format
                                       : t.stamps_s.empty()                 ? io::TrajectoryFormat::kKitti
                                                                            : io::TrajectoryFormat::kTum;
  if (t.empty()) return 0;
  try {
    const std::string again = ws.Path(written == io::TrajectoryFormat::kEuroc ? "again.csv" : "again.txt");
    io::WriteTrajectory(again, t, written);
    const io::Trajectory back = io::ReadTrajectory(again, written);
    fuzz::Require(back.size() == t.size(), "a trajectory read back has as many poses as was written");
  } catch (const std::exception& e) {
    // A trajectory the reader accepted must be writable and readable again.
    std::fprintf(stderr, "round trip refused: %s\n", e.what());
    fuzz::Require(false, "what a reader accepts, its writer writes and the reader reads again");
  }
  return 0;
}
