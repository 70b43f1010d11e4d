// observations.txt (the observation folders `mcslam synth` writes and `mcslam run` reads): what the reader
// accepts is written back and read again to the same frames and observations.
#include "fuzz_util.h"
#include "io/observations_io.h"

using namespace mcslam;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const fuzz::Input in = fuzz::Split(data, size);
  const fuzz::Workspace& ws = fuzz::TheWorkspace();
  const std::string path = ws.Write("observations.txt", in.parts[0]);
  std::vector<io::ObservationFrame> frames;
  try {
    frames = io::ReadObservations(path);
  } catch (const std::exception&) {
    return 0;
  }
  size_t count = 0;
  for (const auto& f : frames) count += f.observations.size();
  try {
    const std::string again = ws.Path("again.txt");
    io::WriteObservations(again, frames);
    const std::vector<io::ObservationFrame> back = io::ReadObservations(again);
    size_t back_count = 0;
    for (const auto& f : back) back_count += f.observations.size();
    fuzz::Require(back_count == count, "observations read back are as many as were written");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "round trip refused: %s\n", e.what());
    fuzz::Require(false, "what the reader accepts, the writer writes and the reader reads again");
  }
  return 0;
}
