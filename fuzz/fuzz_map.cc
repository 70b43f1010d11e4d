// Map files (--load-map): what the reader accepts, once written, reads back and writes again to the same bytes
// (the writer's output is canonical; the input need not be) and keeps every point.
#include <vector>

#include "fuzz_util.h"
#include "io/map_file.h"

using namespace mcslam;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::vector<uint8_t> bytes(data, data + size);
  io::MapFile map;
  try {
    map = io::ParseMapFile(bytes, "fuzz.map");
  } catch (const std::exception&) {
    return 0;
  }
  try {
    const std::vector<uint8_t> once = io::SerialiseMapFile(map);
    const std::vector<uint8_t> twice = io::SerialiseMapFile(io::ParseMapFile(once, "again.map"));
    fuzz::Require(once == twice, "a map written, read and written again is the same bytes");
    fuzz::Require(io::ParseMapFile(once, "again.map").points.size() == map.points.size(), "every point read back");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "round trip refused: %s\n", e.what());
    fuzz::Require(false, "what the reader accepts, the writer writes and the reader reads again");
  }
  return 0;
}
