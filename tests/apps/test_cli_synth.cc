// `mcslam synth`: the files it writes, read back with the io readers, and its refusals of bad flags.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <sstream>
#include <string>

#include <opencv2/imgcodecs.hpp>

#include "io/camera_io.h"
#include "io/observations_io.h"
#include "io/ply.h"
#include "io/trajectory_io.h"
#include "../test_util.h"

namespace mcslam {
namespace {

using testing::ReadText;
using testing::RunMcslam;
using testing::TempDir;

// Lines that are neither blank nor comments.
int DataLines(const std::string& text) {
  std::istringstream in(text);
  std::string line;
  int n = 0;
  while (std::getline(in, line)) {
    const auto first = line.find_first_not_of(" \t\r");
    if (first != std::string::npos && line[first] != '#') ++n;
  }
  return n;
}

TEST(CliSynth, PaperScenarioWritesTheFourFiles) {
  TempDir tmp;
  const std::string out = tmp / "seq";
  const auto r = RunMcslam("synth --scenario paper --frames 20 --out " + out);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("20 frames"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("400 points"), std::string::npos) << r.output;

  const io::Trajectory gt = io::ReadTum(out + "/groundtruth.txt");
  ASSERT_EQ(gt.size(), 20u);
  EXPECT_EQ(DataLines(ReadText(out + "/groundtruth.txt")), 20);
  for (size_t i = 0; i < gt.size(); ++i) {
    // Stamps are i/30 s, written in full precision.
    EXPECT_NEAR(gt.stamps_s[i], i / 30.0, 1e-12);
    // The camera is about 3 m from the box at the origin (world_from_cam: t is the camera centre).
    EXPECT_NEAR(gt.world_from_cam[i].t.norm(), 3.0, 0.3);
  }

  const PinholeCamera cam = io::ReadCameraYaml(out + "/camera.yaml");
  EXPECT_EQ(cam.fx, 500.0);
  EXPECT_EQ(cam.width, 320);
  EXPECT_EQ(cam.height, 240);
  EXPECT_EQ(cam.cx, 159.5);

  const io::PointCloud map = io::ReadPly(out + "/map_gt.ply");
  ASSERT_EQ(map.points.size(), 400u);
  ASSERT_EQ(map.ids.size(), 400u);
  for (size_t i = 0; i < map.ids.size(); ++i) EXPECT_EQ(map.ids[i], static_cast<int64_t>(i));

  const std::vector<io::ObservationFrame> frames = io::ReadObservations(out + "/observations.txt");
  ASSERT_EQ(frames.size(), 20u);
  size_t total = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(frames[i].index, static_cast<int64_t>(i));
    EXPECT_GE(frames[i].observations.size(), 100u);  // the scenario's promise, with 400 points
    total += frames[i].observations.size();
    for (const auto& ob : frames[i].observations) {
      EXPECT_LT(ob.feature_id, 400);
      EXPECT_TRUE(cam.InImage({ob.u_px, ob.v_px}));
    }
  }
  EXPECT_EQ(DataLines(ReadText(out + "/observations.txt")), static_cast<int>(total));
  EXPECT_NE(r.output.find(std::to_string(total) + " observations"), std::string::npos) << r.output;
}

TEST(CliSynth, SameSeedSameFilesAndNoisyOptionsWork) {
  TempDir tmp;
  const std::string flags = " --scenario paper --frames 10 --noise 1 --outliers 0.1 --speed 1.5 --points 300";
  ASSERT_EQ(RunMcslam("synth" + flags + " --seed 5 --out " + tmp / "a").exit_code, 0);
  ASSERT_EQ(RunMcslam("synth" + flags + " --seed 5 --out " + tmp / "b").exit_code, 0);
  ASSERT_EQ(RunMcslam("synth" + flags + " --seed 6 --out " + tmp / "c").exit_code, 0);
  for (const char* f : {"groundtruth.txt", "map_gt.ply", "camera.yaml", "observations.txt"}) {
    EXPECT_EQ(ReadText(tmp / ("a/" + std::string(f))), ReadText(tmp / ("b/" + std::string(f)))) << f;
  }
  EXPECT_NE(ReadText(tmp / "a/observations.txt"), ReadText(tmp / "c/observations.txt"));
  EXPECT_EQ(io::ReadPly(tmp / "a/map_gt.ply").points.size(), 300u);
}

TEST(CliSynth, FramesWithNothingSeenAreStillListed) {
  // One point, and noise so large that its noisy pixel nearly always leaves the image and is dropped: most
  // frames have no observation, yet each must be in the file (as a 2-column "index stamp" line).
  TempDir tmp;
  const auto r = RunMcslam("synth --frames 30 --points 1 --noise 1000 --out " + tmp / "empty");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto frames = io::ReadObservations(tmp / "empty/observations.txt");
  ASSERT_EQ(frames.size(), 30u);
  int empty = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(frames[i].index, static_cast<int64_t>(i));
    EXPECT_NEAR(frames[i].stamp_s, i / 30.0, 1e-12);  // written in full precision
    empty += frames[i].observations.empty();
  }
  EXPECT_GT(empty, 0);
}

void ExpectRefused(const std::string& flags, const std::string& named) {
  TempDir tmp;
  const auto r = RunMcslam("synth " + flags + " --out " + tmp / "x");
  EXPECT_NE(r.exit_code, 0) << flags << "\n" << r.output;
  EXPECT_NE(r.output.find(named), std::string::npos) << flags << "\n" << r.output;
  EXPECT_FALSE(std::filesystem::exists(tmp / "x/observations.txt")) << flags;
}

TEST(CliSynth, BadFlagsFailNamingTheFlag) {
  ExpectRefused("--scenario paper --noise -1", "--noise");
  ExpectRefused("--scenario paper --outliers 1.5", "--outliers");
  ExpectRefused("--scenario paper --outliers -0.5", "--outliers");
  ExpectRefused("--scenario paper --frames 0", "--frames");
  ExpectRefused("--scenario paper --points 0", "--points");
  ExpectRefused("--scenario paper --speed 0", "--speed");
  ExpectRefused("--scenario paper --speed -1", "--speed");
  ExpectRefused("--scenario cube", "--scenario");
  ExpectRefused("--noise nan", "--noise");
  ExpectRefused("--seed -3", "--seed");
  ExpectRefused("--distortion -0.28 0.07", "--distortion");            // 4 or 5 coefficients
  ExpectRefused("--distortion -0.28 0.07 0 0 0 0", "--distortion");
  ExpectRefused("--distortion nan 0 0 0", "--distortion");
  ExpectRefused("--scenario forward --distortion -0.5 0 0 0", "--distortion");  // turns back inside the image
  ExpectRefused("--fisheye -0.3 0 0", "--fisheye");                   // 4 coefficients
  ExpectRefused("--fisheye -0.3 0 0 0 --distortion -0.28 0.07 0 0", "--fisheye");  // one lens
  ExpectRefused("--fisheye -3 0 0 0", "--fisheye");                    // turns back inside the image
  ExpectRefused("--image-scale 0", "--image-scale");
  ExpectRefused("--image-scale 100", "--image-scale");
  const auto r = RunMcslam("synth --scenario paper --frames 5");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--out"), std::string::npos) << r.output;
}

TEST(CliSynth, EveryScenarioWritesItsDefaultsAndOneSummaryLine) {
  // name, default frames, camera width: each scenario's own defaults when no flag is given.
  const struct {
    const char* name;
    int frames;
    int width;
  } kScenarios[] = {{"paper", 300, 320},  {"forward", 120, 620},     {"rotation", 270, 320}, {"planar", 300, 320},
                    {"fast", 150, 320}, {"still-start", 300, 320}, {"stop-and-go", 300, 320}, {"sparse", 300, 320}};
  for (const auto& s : kScenarios) {
    TempDir tmp;
    const std::string out = tmp / "seq";
    const auto r = RunMcslam(std::string("synth --scenario ") + s.name + " --out " + out);
    ASSERT_EQ(r.exit_code, 0) << s.name << "\n" << r.output;
    // Exactly the summary line, in the format scripts parse.
    EXPECT_EQ(r.output.rfind(std::string(s.name) + " scenario written to " + out + ": " + std::to_string(s.frames) +
                                 " frames, ",
                             0),
              0u)
        << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
    EXPECT_EQ(io::ReadTum(out + "/groundtruth.txt").size(), static_cast<size_t>(s.frames)) << s.name;
    EXPECT_EQ(io::ReadCameraYaml(out + "/camera.yaml").width, s.width) << s.name;
    EXPECT_EQ(io::ReadObservations(out + "/observations.txt").size(), static_cast<size_t>(s.frames)) << s.name;
  }
}

TEST(CliSynth, RenderedScenariosAreDeterministicPerSeed) {
  TempDir tmp;
  for (const std::string seed : {"2", "2", "3"}) {
    const std::string dir = tmp / ("forward_" + seed + (std::filesystem::exists(tmp / ("forward_" + seed)) ? "b" : ""));
    const auto r = RunMcslam("synth --scenario forward --frames 3 --render --seed " + seed + " --out " + dir);
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  const cv::Mat a = cv::imread(tmp / "forward_2/images/000002.png", cv::IMREAD_UNCHANGED);
  const cv::Mat b = cv::imread(tmp / "forward_2b/images/000002.png", cv::IMREAD_UNCHANGED);
  const cv::Mat c = cv::imread(tmp / "forward_3/images/000002.png", cv::IMREAD_UNCHANGED);
  ASSERT_EQ(a.cols, 620);
  ASSERT_EQ(a.rows, 188);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(a, c, cv::NORM_L1), 0.0);
  EXPECT_EQ(ReadText(tmp / "forward_2/observations.txt"), ReadText(tmp / "forward_2b/observations.txt"));
  EXPECT_NE(ReadText(tmp / "forward_2/groundtruth.txt"), ReadText(tmp / "forward_3/groundtruth.txt"));
}

TEST(CliSynth, ScenarioOptionsThatDoNotFitAreRefusedNamingTheFlag) {
  // forward's street is 160 m: at 1 m a frame, 161 frames; more runs off the world.
  ExpectRefused("--scenario forward --frames 500", "--frames");
  ExpectRefused("--scenario forward --speed 3", "--frames");  // its 120 default frames no longer fit
  ExpectRefused("--scenario street", "--scenario");
  TempDir tmp;
  EXPECT_EQ(RunMcslam("synth --scenario forward --frames 300 --speed 0.5 --out " + tmp / "ok").exit_code, 0);
}

// A length no machine's memory holds (2e9 frames of ~28 kB each) is refused before any work, naming the flag and
// the memory it would need, instead of growing until the kernel kills the process (issue #20: exit 137 after
// 24 GB). The refusal must come from the estimate, not from running: the output folder is never created.
TEST(CliSynth, ALengthTheMemoryCannotHoldIsRefusedBeforeAnyWork) {
  TempDir tmp;
  const auto r = RunMcslam("synth --scenario paper --frames 2000000000 --out " + tmp / "huge");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("--frames 2000000000"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("GiB of memory"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(tmp / "huge"));
}

TEST(CliSynth, UnwritableOutputFolderFailsNamingIt) {
  TempDir tmp;
  testing::WriteText(tmp / "file", "not a folder");
  const auto r = RunMcslam("synth --frames 2 --out " + tmp / "file/sub");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find(tmp / "file/sub"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace mcslam
