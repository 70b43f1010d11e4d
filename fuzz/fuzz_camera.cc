// Camera readers: ORB-SLAM/OpenCV-style YAML, the one-line text camera, a 3x3 intrinsics matrix. A camera they
// accept passes PinholeCamera::Check (no reader hands on a camera the rest of mcslam would refuse), and a YAML
// camera survives WriteCameraYaml and a second read.
#include "core/camera.h"
#include "fuzz_util.h"
#include "io/camera_io.h"
#include "io/datasets.h"

using namespace mcslam;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const fuzz::Input in = fuzz::Split(data, size);
  const fuzz::Workspace& ws = fuzz::TheWorkspace();
  const int which = in.selector % 3;
  const std::string path = ws.Write(which == 0 ? "camera.yaml" : "camera.txt", in.parts[0]);
  PinholeCamera camera;
  try {
    camera = which == 0 ? io::ReadCameraYaml(path)
             : which == 1 ? io::ReadCameraText(path, 640, 480)
                          : io::ReadIntrinsicsMatrix(path, 640, 480);
  } catch (const std::exception&) {
    return 0;
  }
  try {
    camera.Check();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "accepted camera fails Check: %s\n", e.what());
    fuzz::Require(false, "a camera a reader accepts passes Check");
  }
  if (which == 0) {
    try {
      const std::string again = ws.Path("again.yaml");
      io::WriteCameraYaml(again, camera);
      const PinholeCamera back = io::ReadCameraYaml(again);
      fuzz::Require(back.width == camera.width && back.height == camera.height && back.fx == camera.fx &&
                        back.cy == camera.cy,
                    "a YAML camera read back is the camera written");
    } catch (const std::exception& e) {
      std::fprintf(stderr, "round trip refused: %s\n", e.what());
      fuzz::Require(false, "a YAML camera written is read again");
    }
  }
  return 0;
}
