// Dataset folders as users bring them: the text files of a KITTI odometry sequence (calib.txt, times.txt,
// poses.txt), a TUM RGB-D sequence (rgb.txt, groundtruth.txt), an EuRoC MAV sequence (cam0/data.csv,
// cam0/sensor.yaml, the ground truth's data.csv), and a bare times file; the images are real (two small
// PNGs each, written once). A dataset that opens gives frames whose stamps never go back.
#include <opencv2/imgcodecs.hpp>

#include "fuzz_util.h"
#include "io/datasets.h"
#include "io/image_source.h"

using namespace mcslam;

namespace {

struct Layout {
  const char* root;
  std::vector<const char*> files;  // fuzzed parts, in order
  std::vector<const char*> images;
};

const std::vector<Layout>& Layouts() {
  static const std::vector<Layout> layouts = {
      {"kitti", {"calib.txt", "times.txt", "poses.txt"}, {"image_0/000000.png", "image_0/000001.png"}},
      {"tum", {"rgb.txt", "groundtruth.txt"}, {"rgb/0.png", "rgb/1.png"}},
      {"euroc",
       {"mav0/cam0/data.csv", "mav0/cam0/sensor.yaml", "mav0/state_groundtruth_estimate0/data.csv"},
       {"mav0/cam0/data/0.png", "mav0/cam0/data/1.png"}},
  };
  return layouts;
}

void WriteImagesOnce(const fuzz::Workspace& ws) {
  static bool done = false;
  if (done) return;
  done = true;
  const cv::Mat image(24, 32, CV_8U, cv::Scalar(100));
  for (const Layout& l : Layouts())
    for (const char* name : l.images) {
      ws.Write(std::string(l.root) + "/" + name, "");
      cv::imwrite(ws.Path(std::string(l.root) + "/" + name), image);
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const fuzz::Input in = fuzz::Split(data, size);
  const fuzz::Workspace& ws = fuzz::TheWorkspace();
  WriteImagesOnce(ws);
  const size_t which = in.selector % (Layouts().size() + 1);
  if (which == Layouts().size()) {
    try {
      const std::vector<double> stamps = io::ReadTimestampsFile(ws.Write("times_only.txt", in.parts[0]));
      for (size_t i = 1; i < stamps.size(); ++i) fuzz::Require(stamps[i] >= stamps[i - 1], "times never go back");
    } catch (const std::exception&) {
    }
    return 0;
  }
  const Layout& layout = Layouts()[which];
  for (size_t k = 0; k < layout.files.size(); ++k) {
    const std::string rel = std::string(layout.root) + "/" + layout.files[k];
    if (k < in.parts.size())
      ws.Write(rel, in.parts[k]);
    else
      ws.Remove(rel);
  }
  try {
    io::Dataset d = io::OpenDataset(ws.Path(layout.root));
    io::Frame frame;
    double last = -1e300;
    for (int i = 0; i < 4 && d.source->Next(&frame); ++i) {
      fuzz::Require(frame.stamp_s >= last, "frame stamps never go back");
      last = frame.stamp_s;
    }
  } catch (const std::exception&) {
  }
  return 0;
}
