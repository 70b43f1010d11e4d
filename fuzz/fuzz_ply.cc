// PLY point clouds (map.ply, map_gt.ply): what the reader accepts is written back and read again to the same
// number of points.
#include "fuzz_util.h"
#include "io/ply.h"

using namespace mcslam;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const fuzz::Input in = fuzz::Split(data, size);
  const fuzz::Workspace& ws = fuzz::TheWorkspace();
  const std::string path = ws.Write("map.ply", in.parts[0]);
  io::PointCloud cloud;
  try {
    cloud = io::ReadPly(path);
  } catch (const std::exception&) {
    return 0;
  }
  try {
    const std::string again = ws.Path("again.ply");
    io::WritePly(again, cloud);
    fuzz::Require(io::ReadPly(again).points.size() == cloud.points.size(), "a cloud read back has every point");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "round trip refused: %s\n", e.what());
    fuzz::Require(false, "what the reader accepts, the writer writes and the reader reads again");
  }
  return 0;
}
