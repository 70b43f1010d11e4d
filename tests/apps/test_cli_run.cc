#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "io/camera_io.h"
#include "io/observations_io.h"
#include "io/ply.h"
#include "io/trajectory_io.h"
#include "cli_report.h"
#include "test_util.h"

namespace mcslam {
namespace {

using testing::CountDataLines;
using testing::ExpectSaneRunTimes;
using testing::Field;
using testing::ReadText;
using testing::RunMcslam;
using testing::TempDir;

TEST(CliRun, KnownMapWritesTrajectoriesAndReportsAccuracy) {
  TempDir dir;
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 40 --noise 1 --outliers 0.1 --out " + dir / "s").exit_code, 0);
  const auto r = RunMcslam("run " + dir / "s" + " --known-map --hypotheses 65536 --out " + dir / "r");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("tracked=40 lost=0"), std::string::npos) << r.output;
  const io::Trajectory est = io::ReadTum(dir / "r/trajectory.txt");
  const io::Trajectory smooth = io::ReadTum(dir / "r/trajectory_smoothed.txt");
  EXPECT_EQ(est.size(), 40u);
  EXPECT_EQ(smooth.size(), 40u);
  EXPECT_EQ(CountDataLines(dir / "r/frames.csv"), 41);  // header + 40 frames
  ExpectSaneRunTimes(r.output, dir / "r/report.json");
  const nlohmann::json j = testing::ReadJson(dir / "r/report.json");
  EXPECT_EQ(j["mode"], "known_map");
  EXPECT_EQ(j["frames"], 40);
  EXPECT_EQ(j["options"]["backend"], "cpu");
  // Every option of the mode, the flags given included.
  EXPECT_EQ(j["options"]["known_map"]["tracker"]["hypotheses"], 65536) << j["options"].dump();
  EXPECT_TRUE(j["options"]["known_map"]["smoother"].contains("alpha")) << j["options"].dump();
  // mcslam eval on the output: the paper's bounds hold on this short run too (2 cm, 1 degree).
  const auto e = RunMcslam("eval " + dir / "s/groundtruth.txt " + dir / "r/trajectory.txt --align none");
  ASSERT_EQ(e.exit_code, 0) << e.output;
  const double ate_mean = std::stod(e.output.substr(e.output.find("ate_mean=") + 9));
  const double rot_mean = std::stod(e.output.substr(e.output.find("rot_mean_deg=") + 13));
  EXPECT_LT(ate_mean, 0.02);
  EXPECT_LT(rot_mean, 1.0);
  // frames.csv: the schema of every run (front-end cells empty), a row per frame with its own error, whose
  // mean is the evaluation's (cells printed to 6 significant digits: 1e-5 relative).
  EXPECT_EQ(testing::CsvShapeErrors(dir / "r/frames.csv"), std::vector<std::string>{});
  EXPECT_EQ(testing::CsvColumn(dir / "r/frames.csv", "fe_total_ms"), std::vector<std::string>(40));
  const std::vector<std::string> status = testing::CsvColumn(dir / "r/frames.csv", "status");
  const std::vector<std::string> terr = testing::CsvColumn(dir / "r/frames.csv", "trans_err_m");
  ASSERT_EQ(terr.size(), 40u);
  double sum = 0;
  for (size_t i = 0; i < terr.size(); ++i) {
    EXPECT_EQ(status[i], "tracked") << i;
    ASSERT_FALSE(terr[i].empty()) << "frame " << i << " has no error";
    sum += std::stod(terr[i]);
  }
  EXPECT_NEAR(sum / 40, ate_mean, 1e-5 * ate_mean);
  EXPECT_EQ(testing::CsvColumn(dir / "r/frames.csv", "init")[0], "1");  // the given first pose
}

TEST(CliRun, SameSeedSameTrajectory) {
  TempDir dir;
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 15 --noise 1 --out " + dir / "s").exit_code, 0);
  ASSERT_EQ(RunMcslam("run " + dir / "s --known-map --hypotheses 8192 --seed 5 --out " + dir / "a").exit_code, 0);
  ASSERT_EQ(RunMcslam("run " + dir / "s --known-map --hypotheses 8192 --seed 5 --out " + dir / "b").exit_code, 0);
  ASSERT_EQ(RunMcslam("run " + dir / "s --known-map --hypotheses 8192 --seed 6 --out " + dir / "c").exit_code, 0);
  EXPECT_EQ(ReadText(dir / "a/trajectory.txt"), ReadText(dir / "b/trajectory.txt"));
  EXPECT_NE(ReadText(dir / "a/trajectory.txt"), ReadText(dir / "c/trajectory.txt"));
}

TEST(CliRun, FrameWithTooFewPointsIsCountedLostAndTrackingGoesOn) {
  TempDir dir;
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 12 --out " + dir / "s").exit_code, 0);
  // Keep only 3 observations of frame 5: too few to score, so that frame is lost; the others are tracked.
  std::istringstream in(ReadText(dir / "s/observations.txt"));
  std::ostringstream out;
  std::string line;
  int kept5 = 0;
  while (std::getline(in, line)) {
    if (line.rfind("5 ", 0) == 0 && kept5++ >= 3) continue;
    out << line << "\n";
  }
  testing::WriteText(dir / "s/observations.txt", out.str());
  const auto r = RunMcslam("run " + dir / "s --known-map --hypotheses 16384 --out " + dir / "r");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("tracked=11 lost=1"), std::string::npos) << r.output;
  EXPECT_EQ(io::ReadTum(dir / "r/trajectory.txt").size(), 11u);  // no invented pose for the lost frame
}

TEST(CliRun, BadInputIsAClearError) {
  TempDir dir;
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 5 --out " + dir / "s").exit_code, 0);
  std::string obs = ReadText(dir / "s/observations.txt");
  const size_t pos = obs.find("\n1 ");
  obs.insert(pos + 1, "1 0.033333333 7 nan 12.0\n");
  testing::WriteText(dir / "s/observations.txt", obs);
  auto r = RunMcslam("run " + dir / "s --known-map --hypotheses 1024 --out " + dir / "r");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("observations.txt:"), std::string::npos) << r.output;

  r = RunMcslam("run " + dir / "missing --known-map --out " + dir / "r");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("missing"), std::string::npos) << r.output;

  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 5 --out " + dir / "t").exit_code, 0);
  std::filesystem::remove(dir / "t/map_gt.ply");
  r = RunMcslam("run " + dir / "t --known-map --out " + dir / "r");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("map_gt.ply"), std::string::npos) << r.output;

  r = RunMcslam("run " + dir / "t --known-map --hypotheses 0 --out " + dir / "r");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--hypotheses"), std::string::npos) << r.output;

  // A negative seed is refused, not wrapped to 2^64 - 1 (issue #20); so is one past 64 bits.
  for (const std::string seed : {"-1", "18446744073709551616"}) {
    r = RunMcslam("run " + dir / "t --seed " + seed + " --out " + dir / "r");
    EXPECT_NE(r.exit_code, 0) << seed;
    EXPECT_NE(r.output.find("--seed"), std::string::npos) << r.output;
  }
}

// A flag that does nothing in the mode the input selects is an error naming it (issue #20: on a folder of
// observations --overlay, --plot, --camera, --start/--end, --gt (even a missing file) and --format were
// ignored without a word; with --known-map so were the map-building flags; and --sigma-trans-floor where the run
// builds its map, whose floor the System sets from the map's depth). Nothing is run or written.
TEST(CliRun, FlagsWithoutEffectInTheModeAreRefusedNamingThem) {
  TempDir dir;
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 5 --out " + dir / "s").exit_code, 0);
  for (const auto& [flags, named, why] : std::vector<std::tuple<std::string, std::string, std::string>>{
           {"--overlay " + dir / "o.mp4", "--overlay", "on a folder of observations"},
           {"--plot " + dir / "p.png", "--plot", "on a folder of observations"},
           {"--camera \"500 500 160 120\"", "--camera", "on a folder of observations"},
           {"--start 2", "--start", "on a folder of observations"},
           {"--end 3", "--end", "on a folder of observations"},
           {"--gt " + dir / "missing.txt", "--gt", "on a folder of observations"},
           {"--format kitti", "--format", "on a folder of observations"},
           {"--max-features 100", "--max-features", "on a folder of observations"},
           {"--known-map --end 3", "--end", "on a folder of observations"},
           {"--known-map --window 5", "--window", "with --known-map"},
           {"--known-map --init-method 5point", "--init-method", "with --known-map"},
           {"--sigma-trans-floor 0.01", "--sigma-trans-floor", "where the run builds its map"},
           {"--dataset synthetic --sigma-trans-floor 0.01", "--sigma-trans-floor", "where the run builds its map"},
       }) {
    const auto r = RunMcslam("run " + dir / "s " + flags + " --out " + dir / "r");
    EXPECT_EQ(r.exit_code, 1) << flags << "\n" << r.output;
    EXPECT_NE(r.output.find(named + ": has no effect " + why), std::string::npos) << flags << "\n" << r.output;
    EXPECT_FALSE(std::filesystem::exists(dir / "r")) << flags;
  }
  // The flags of each mode still work in it.
  const auto known = RunMcslam("run " + dir / "s --known-map --smooth-alpha 0.3 --hypotheses 1024 " +
                               "--sigma-trans-floor 0.01 --out " + dir / "k");
  EXPECT_EQ(known.exit_code, 0) << known.output;
}

// SIGTERM (what `timeout`, `kill` and job schedulers send) stops a run like Ctrl-C: what was done is written,
// report.json says it was interrupted, and the exit status is 128 + the signal with a message naming it (issue #20:
// the output folder was left empty).
TEST(CliRun, SigtermWritesWhatWasDone) {
  TempDir dir;
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 3000 --out " + dir / "s").exit_code, 0);
  // The shell starts the run, waits until its log shows frames being done (the handler is installed once the
  // input is read, before the first frame; a fixed wait raced with slow builds: under AddressSanitizer reading
  // the input took longer than 3 s), then sends SIGTERM and reports the run's exit status.
  const std::string log = dir / "log.txt";
  const std::string cmd = std::string(MCSLAM_BIN) + " run " + dir / "s" + " --out " + dir / "r" + " > " + log +
                          " 2>&1 & pid=$!; for i in $(seq 1200); do grep -q 'frame [0-9]*/3000' " + log +
                          " && break; sleep 0.25; done; kill -TERM $pid; wait $pid; echo rc=$?";
  const std::string out = testing::RunShell(cmd).output;
  ASSERT_TRUE(std::filesystem::exists(dir / "r/report.json")) << out << ReadText(dir / "log.txt");
  const nlohmann::json report = testing::ReadJson(dir / "r/report.json");
  if (!report["interrupted"].get<bool>()) GTEST_SKIP() << "the run finished its 3000 frames before the signal";
  EXPECT_EQ(out, "rc=143\n") << ReadText(dir / "log.txt");  // 128 + SIGTERM, as a shell reports a killed job
  EXPECT_NE(ReadText(dir / "log.txt").find("interrupted by SIGTERM (outputs written)"), std::string::npos);
  const int frames = report["frames"].get<int>();
  EXPECT_GT(frames, 0);
  EXPECT_LT(frames, 3000);
  // Every frame done is in the trajectory (one line each, after the header).
  const std::string traj = ReadText(dir / "r/trajectory.txt");
  EXPECT_EQ(std::count(traj.begin(), traj.end(), '\n'), frames + 1) << traj.substr(0, 200);
}

// Logs and warnings go to stderr, the results to stdout (issue #20: they were mixed on stdout): a script that
// reads a run's stdout gets its summary line and nothing else, and the log is still there on stderr.
TEST(CliRun, StdoutCarriesOnlyTheResult) {
  TempDir dir;
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 30 --out " + dir / "s").exit_code, 0);
  auto capture = [](const std::string& cmd) { return testing::RunShell(cmd).output; };
  const std::string run = std::string(MCSLAM_BIN) + " run " + dir / "s" + " --hypotheses 16384 --out " + dir / "r";
  const std::string out = capture(run + " 2>/dev/null");
  EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 1) << out;
  EXPECT_EQ(out.rfind("frames=30 ", 0), 0u) << out;
  const std::string err = capture(run + " 2>&1 >/dev/null");
  EXPECT_NE(err.find("[info] initialised from frames"), std::string::npos) << err;
  EXPECT_EQ(err.find("frames=30 "), std::string::npos) << err;
}

TEST(CliRun, FullSlamWritesTrajectoryMapAndPerFrameErrors) {
  TempDir dir;
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 60 --out " + dir / "s").exit_code, 0);
  const auto r = RunMcslam("run " + dir / "s --gt-scale --hypotheses 65536 --out " + dir / "r");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("tracked=60 lost=0"), std::string::npos) << r.output;
  EXPECT_EQ(io::ReadTum(dir / "r/trajectory.txt").size(), 60u);
  EXPECT_EQ(io::ReadTum(dir / "r/trajectory_smoothed.txt").size(), 60u);
  EXPECT_GT(io::ReadPly(dir / "r/map.ply").points.size(), 100u);
  const std::string csv = ReadText(dir / "r/frames.csv");
  EXPECT_EQ(CountDataLines(dir / "r/frames.csv"), 61);
  EXPECT_NE(csv.find("trans_err_m"), std::string::npos);
  EXPECT_NE(csv.find("initialised from frames"), std::string::npos);
  // One frames.csv schema for every run that builds a map: the front end's columns are there, empty.
  EXPECT_NE(csv.find(",fe_tracked,"), std::string::npos);
  EXPECT_EQ(testing::CsvShapeErrors(dir / "r/frames.csv"), std::vector<std::string>{});
  ExpectSaneRunTimes(r.output, dir / "r/report.json");
  // Every option of the System, the flags given included.
  const nlohmann::json options = testing::ReadJson(dir / "r/report.json")["options"]["system"];
  EXPECT_EQ(options["tracker"]["hypotheses"], 65536) << options.dump();
  EXPECT_EQ(options["init"]["method"], "8point") << options.dump();
  EXPECT_EQ(options["mapping"]["window"], 12) << options.dump();
  const nlohmann::json j = testing::ReadJson(dir / "r/report.json");
  EXPECT_EQ(j["mode"], "slam");
  EXPECT_EQ(j["tracked"], 60);
  EXPECT_TRUE(j["initialised"].get<bool>());
  const double trans_mean = j["ground_truth"]["trans_mean_m"];
  EXPECT_NEAR(Field(r.output, "trans_mean_m"), trans_mean, 1e-5 * trans_mean);  // 6 significant digits printed
  // Clean data: the paper's bounds with a wide margin (measured ~2 mm / 0.05 deg).
  const double ate = std::stod(r.output.substr(r.output.find("trans_mean_m=") + 13));
  EXPECT_LT(ate, 0.01);
}

// Observations through a lens with k1 = -0.25 that the camera file does not declare (8-9 px at the corners of
// 320x240 at f = 500 px): the run measures it when its first map settles, says so, goes on with it, reports it
// and writes the camera it used. tests/slam/test_system.cc checks the accuracy it buys.
TEST(CliRun, AnUndeclaredLensDistortionIsSelfCalibratedAndReported) {
  TempDir dir;
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 150 --noise 0.5 --out " + dir / "s").exit_code, 0);
  const PinholeCamera camera = io::ReadCameraYaml(dir / "s/camera.yaml");
  PinholeCamera lens = camera;
  lens.dist.k1 = -0.25;
  std::vector<io::ObservationFrame> frames = io::ReadObservations(dir / "s/observations.txt");
  for (io::ObservationFrame& f : frames)
    for (io::Observation& o : f.observations) {
      const Eigen::Vector2d uv = lens.NormalizedToPixel(lens.Distort(camera.PixelToNormalized({o.u_px, o.v_px})));
      o.u_px = uv.x(), o.v_px = uv.y();
    }
  io::WriteObservations(dir / "s/observations.txt", frames);
  const auto r = RunMcslam("run " + dir / "s --hypotheses 65536 --out " + dir / "r");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("lens distortion k1 self-calibrated"), std::string::npos) << r.output;
  const nlohmann::json c = testing::ReadJson(dir / "r/report.json")["self_calibration"];
  ASSERT_TRUE(c.is_object()) << c.dump();
  EXPECT_TRUE(c["accepted"].get<bool>()) << c.dump();
  EXPECT_EQ(c["k1_given"], 0.0);
  EXPECT_NEAR(c["k1_measured"].get<double>(), -0.25, 0.04) << c.dump();  // as in the System's test
  const PinholeCamera used = io::ReadCameraYaml(dir / "r/camera_selfcalibrated.yaml");
  EXPECT_NEAR(used.dist.k1, c["k1_measured"].get<double>(), 1e-9);
  EXPECT_EQ(used.fx, camera.fx);
  // Off: nothing measured, nothing written.
  const auto off = RunMcslam("run " + dir / "s --hypotheses 65536 --no-self-calibration --out " + dir / "o");
  ASSERT_EQ(off.exit_code, 0) << off.output;
  EXPECT_TRUE(testing::ReadJson(dir / "o/report.json")["self_calibration"].is_null());
  EXPECT_FALSE(std::filesystem::exists(dir / "o/camera_selfcalibrated.yaml"));
}

// Images rendered through a EuRoC-like lens (k1 -0.28, k2 0.07: 9 px at the corners of 320x240 at f = 500 px),
// through the whole pipeline: the front end finds and tracks its features in the bent image, the back end
// works on them undistorted. Measured over seeds 1-6 (150 frames): ATE 2.8-3.9 mm with the lens declared (the
// same scenes without a lens: 2.5-4.8 mm over seeds 1-3), the self-calibration's check keeping the given k1 at
// 0.6-4.6 sigma (it takes a k1 at 10); with the camera file silent about the lens, k1 measured -0.21 to -0.25
// (it also takes up the quartic term it does not model) at 17-46 sigma and ATE 3.8-9.2 mm over seeds 1-3.
// Bounds: 2.5x and 2x the worst seed; k1 within 0.07 of the nearest one measured.
TEST(CliRun, ImagesThroughALensAreTrackedWhetherTheCameraFileDeclaresItOrNot) {
  TempDir dir;
  const auto synth =
      RunMcslam("synth --scenario paper --frames 150 --distortion -0.28 0.07 0 0 --render --out " + dir / "s");
  ASSERT_EQ(synth.exit_code, 0) << synth.output;
  const PinholeCamera camera = io::ReadCameraYaml(dir / "s/camera.yaml");
  EXPECT_EQ(camera.dist.k1, -0.28);
  EXPECT_EQ(camera.dist.k2, 0.07);

  const auto declared = RunMcslam("run " + dir / "s --dataset synthetic --out " + dir / "d");
  ASSERT_EQ(declared.exit_code, 0) << declared.output;
  const nlohmann::json d = testing::ReadJson(dir / "d/report.json");
  EXPECT_EQ(d["tracked"], 150) << declared.output;
  EXPECT_LT(d["ground_truth"]["ate_m"]["rmse"].get<double>(), 0.01) << declared.output;
  EXPECT_FALSE(d["self_calibration"]["accepted"].get<bool>()) << d["self_calibration"].dump();
  EXPECT_EQ(d["self_calibration"]["k1_given"], -0.28);

  const auto silent =
      RunMcslam("run " + dir / "s --dataset synthetic --camera \"500 500 159.5 119.5\" --out " + dir / "u");
  ASSERT_EQ(silent.exit_code, 0) << silent.output;
  const nlohmann::json u = testing::ReadJson(dir / "u/report.json");
  EXPECT_EQ(u["tracked"], 150) << silent.output;
  EXPECT_LT(u["ground_truth"]["ate_m"]["rmse"].get<double>(), 0.02) << silent.output;
  EXPECT_TRUE(u["self_calibration"]["accepted"].get<bool>()) << u["self_calibration"].dump();
  EXPECT_GT(u["self_calibration"]["k1_measured"].get<double>(), -0.32) << u["self_calibration"].dump();
  EXPECT_LT(u["self_calibration"]["k1_measured"].get<double>(), -0.14) << u["self_calibration"].dump();
}

// An exact camera is kept where few tracks make a lens look likely: the sparse scenario (70 points in the room,
// 15-25 a frame) settles on ~18 points, and on seed 3 (AVX-512 machine, 2026-11-29) the window's k1 came out at
// -0.353, 10.3 sigma, 13.6 px at the corner: past both thresholds, so it was taken and bent the map. Each half of
// the points alone measured -0.666 and +0.173: not a lens, which bends every ray alike, and now kept
// (InitOptions::calibration_min_half_share). Over the sparse seeds 1-10 every run keeps the rendered camera's
// k1 = 0 (z 0.5-10.3); the rule's other side, a real lens taken, is held by the test above and the 7-Scenes one.
TEST(CliRun, AnExactCameraIsKeptWhereAFewTracksFitALens) {
  TempDir dir;
  const auto synth = RunMcslam("synth --scenario sparse --seed 3 --render --out " + dir / "s");
  ASSERT_EQ(synth.exit_code, 0) << synth.output;
  const auto run = RunMcslam("run " + dir / "s --dataset synthetic --seed 3 --out " + dir / "r");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const nlohmann::json c = testing::ReadJson(dir / "r/report.json")["self_calibration"];
  ASSERT_TRUE(c.is_object()) << run.output;
  std::printf("[ k1       ] %s\n", c["note"].get<std::string>().c_str());
  EXPECT_FALSE(c["accepted"].get<bool>()) << c.dump();
  EXPECT_FALSE(std::filesystem::exists(dir / "r/camera_selfcalibrated.yaml"));
}

// An exact camera is kept where one half of the points measures no lens: the planar scenario rendered at 160x120,
// seed 2, measured k1 -0.223 at 38.9 sigma, 3.9 px at the corner, from halves of -0.258 (8.0 sigma) and -0.353, whose
// k1-free fit did not lower its cost at all (0 sigma); the shares (1.16, 1.58) passed, the lens was taken and the map
// ended 20.5 cm off (6.3 % of the path, 13 deg); with the camera kept, 3.5 cm (the same on AVX2 and AVX-512).
// InitOptions::calibration_min_half_z. Bound: 7 cm, twice the kept camera's, a third of the taken one's.
TEST(CliRun, AnExactCameraIsKeptWhereOneHalfOfThePointsMeasuresNoLens) {
  TempDir dir;
  const auto synth = RunMcslam("synth --scenario planar --seed 2 --render --image-scale 0.5 --out " + dir / "s");
  ASSERT_EQ(synth.exit_code, 0) << synth.output;
  const auto run = RunMcslam("run " + dir / "s --dataset synthetic --seed 2 --out " + dir / "r");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const nlohmann::json r = testing::ReadJson(dir / "r/report.json");
  const nlohmann::json& c = r["self_calibration"];
  ASSERT_TRUE(c.is_object()) << run.output;
  std::printf("[ k1       ] %s\n", c["note"].get<std::string>().c_str());
  EXPECT_FALSE(c["accepted"].get<bool>()) << c.dump();
  EXPECT_LT(c["min_half_z"].get<double>(), 3.0) << c.dump();
  EXPECT_LT(r["ground_truth"]["ate_m"]["rmse"].get<double>(), 0.07) << run.output;
}

// Images rendered through a fisheye lens (the equidistant / Kannala-Brandt model with k1 -0.3: 23 px from a pinhole
// at the corners of 320x240 at f = 500 px): synth writes camera.yaml as ORB-SLAM3 does (Camera.type
// KannalaBrandt8), and the run follows it. Measured over seeds 1-4 (150 frames): ATE 1.6-3.9 mm with the lens
// declared; with the camera given as a pinhole and the self-calibration off, 20-60 mm. Bounds: 1 cm, 2.5x the
// worst declared seed and half the best pinhole one.
TEST(CliRun, AFisheyeCameraFileIsFollowed) {
  TempDir dir;
  const auto synth = RunMcslam("synth --scenario paper --frames 150 --fisheye -0.3 0 0 0 --render --out " + dir / "s");
  ASSERT_EQ(synth.exit_code, 0) << synth.output;
  EXPECT_NE(ReadText(dir / "s/camera.yaml").find("KannalaBrandt8"), std::string::npos);
  const PinholeCamera camera = io::ReadCameraYaml(dir / "s/camera.yaml");
  EXPECT_TRUE(camera.dist.IsFisheye());
  EXPECT_EQ(camera.dist.k1, -0.3);

  const auto declared = RunMcslam("run " + dir / "s --dataset synthetic --out " + dir / "d");
  ASSERT_EQ(declared.exit_code, 0) << declared.output;
  const nlohmann::json d = testing::ReadJson(dir / "d/report.json");
  EXPECT_EQ(d["tracked"], 150) << declared.output;
  EXPECT_LT(d["ground_truth"]["ate_m"]["rmse"].get<double>(), 0.01) << declared.output;

  const auto pinhole = RunMcslam("run " + dir / "s --dataset synthetic --camera \"500 500 159.5 119.5\" "
                                 "--no-self-calibration --out " + dir / "p");
  ASSERT_EQ(pinhole.exit_code, 0) << pinhole.output;
  EXPECT_GT(testing::ReadJson(dir / "p/report.json")["ground_truth"]["ate_m"]["rmse"].get<double>(), 0.01)
      << pinhole.output;
}

// The rendered rotation scenario at 640x480 (a pan, then the first steps): its first two-view window is explained
// a little better by the scene's mirror in depth than by the scene (frames 3-41 of seed 1, by a chi-square of 51;
// seed 3 too): the map is made mirrored. Three frames later the settling window tells (the mirror's mean squared
// residual 0.019 px^2 against the map's 0.041, a chi-square of 177 over its 149 tracks, judged on 20 of those
// frames): the map is flipped, said in the log and in report.json. Measured, 50 frames: without the flip the
// orientations end 127 deg (seed 3: 166) off and the map is mirrored; with it 1.65 deg (seed 3: 1.69). Bound
// 10 deg: 6x the flipped runs, a tenth of the mirrored ones. The mirror's lead is taken when the next settling step
// confirms it grown (AVX2, seed 1: 2.3x at frame 44, 7.7x at 49, flipped there): 70 frames leave room for it.
TEST(CliRun, AMapMadeOnTheMirrorOfTheSceneIsFlippedWhenTheFramesAfterItTell) {
  constexpr int kFrames = 70;
  // Both seeds made their maps mirrored here; which frames the first try takes can differ on another CPU (its
  // vector width rounds the tracks otherwise), so each run must end unmirrored, and the two together must
  // have flipped a map at least once (the test of the flip, wherever the initialisation went wrong).
  TempDir dir;
  size_t reversals = 0;
  for (const std::string seed : {"1", "3"}) {
    const auto synth = RunMcslam("synth --scenario rotation --image-scale 2 --frames " + std::to_string(kFrames) +
                                 " --seed " + seed +
                                 " --render --out " + dir / ("s" + seed));
    ASSERT_EQ(synth.exit_code, 0) << synth.output;
    const auto r = RunMcslam("run " + dir / ("s" + seed) + " --dataset synthetic --out " + dir / ("r" + seed));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const nlohmann::json j = testing::ReadJson(dir / ("r" + seed + "/report.json"));
    const io::Trajectory est = io::ReadTum(dir / ("r" + seed + "/trajectory.txt"));
    const io::Trajectory smooth = io::ReadTum(dir / ("r" + seed + "/trajectory_smoothed.txt"));
    ASSERT_EQ(est.size(), static_cast<size_t>(kFrames)) << r.output;  // every frame posed: row k is frame k
    ASSERT_EQ(smooth.size(), static_cast<size_t>(kFrames));
    for (const nlohmann::json& d : j["depth_reversals"]) {
      const int frame = d["frame"].get<int>();
      EXPECT_LT(frame, kFrames);
      EXPECT_NE(r.output.find("the map was the mirror of the scene in depth: flipped"), std::string::npos) << r.output;
      // The smoothed (AR) pose starts again at the flipped map's: within 1 deg of the pose at the flip and the
      // frame after it (measured 0.0 and 0.14 deg on seed 1; carried over from the mirrored map, 7.1 and 2.0).
      for (int k = frame; k <= frame + 1 && k < static_cast<int>(est.size()); ++k) {
        ASSERT_DOUBLE_EQ(est.stamps_s[static_cast<size_t>(k)], smooth.stamps_s[static_cast<size_t>(k)]);
        const double deg = est.world_from_cam[static_cast<size_t>(k)].q.angularDistance(
                               smooth.world_from_cam[static_cast<size_t>(k)].q) * 180.0 / M_PI;
        EXPECT_LT(deg, 1.0) << "seed " << seed << " frame " << k;
      }
    }
    reversals += j["depth_reversals"].size();
    EXPECT_EQ(j["tracked"], kFrames) << r.output;
    EXPECT_FALSE(j["ground_truth"]["mirrored"].get<bool>()) << seed << ": " << j["ground_truth"].dump();
    EXPECT_LT(j["ground_truth"]["rot_deg"]["mean"].get<double>(), 10.0) << seed << ": " << j["ground_truth"].dump();
  }
  EXPECT_GE(reversals, 1u);
}

// A plane seen through a narrow view: the map and its mirror in depth fit the settling window nearly alike, and the
// tracks' errors may give the mirror a lead that does not grow as the parallax does. The planar scenario rendered at
// 160x120, seed 5: the mirror ahead by 1.89x at frame 30 and 1.62x at 33 (a chi-square of 60 and 42); flipped at
// 30, the map ended 23.5 cm and 113 deg off; kept, 0.51 cm and 0.33 deg (AVX2, 2026-12-07). Bound: 2 cm, 4x the kept
// map, a tenth of the flipped one.
TEST(CliRun, APlanesMirrorIsNotTakenOnALeadThatDoesNotGrow) {
  TempDir dir;
  const auto synth = RunMcslam("synth --scenario planar --seed 5 --render --image-scale 0.5 --out " + dir / "s");
  ASSERT_EQ(synth.exit_code, 0) << synth.output;
  const auto run = RunMcslam("run " + dir / "s --dataset synthetic --seed 5 --out " + dir / "r");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const nlohmann::json r = testing::ReadJson(dir / "r/report.json");
  EXPECT_TRUE(r["depth_reversals"].empty()) << r["depth_reversals"].dump();
  EXPECT_LT(r["ground_truth"]["ate_m"]["rmse"].get<double>(), 0.02) << run.output;
  EXPECT_FALSE(r["ground_truth"]["mirrored"].get<bool>()) << r["ground_truth"].dump();
}

TEST(CliRun, SequenceThatNeverInitialisesFailsButKeepsItsOutputs) {
  TempDir dir;
  // A camera 10^4 times slower than a hand-held one: the features never move enough.
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 30 --speed 0.0001 --out " + dir / "s").exit_code, 0);
  const auto r = RunMcslam("run " + dir / "s --out " + dir / "r");
  EXPECT_EQ(r.exit_code, 3) << r.output;  // kExitNotInitialised: not the status of a bad input (1)
  EXPECT_NE(r.output.find("never moved enough to initialise"), std::string::npos) << r.output;
  EXPECT_EQ(CountDataLines(dir / "r/frames.csv"), 31);  // every frame reported, as waiting
  EXPECT_TRUE(std::filesystem::exists(dir / "r/trajectory.txt"));
  // report.json counts the waiting frames by what held each back: every one but the reference by the motion.
  const nlohmann::json j = testing::ReadJson(dir / "r/report.json");
  const nlohmann::json& w = j["waiting_for_init"];
  EXPECT_EQ(w["reference"].get<int>(), 1) << w.dump();
  EXPECT_EQ(w["motion"].get<int>(), j["not_initialised"].get<int>() - 1) << w.dump();
}

// A camera that moves as a hand-held one does, in a scene of 8 points: the run never initialises, and its message
// names the missing features as the cause, not the motion (it said "never moved enough" before).
TEST(CliRun, SequenceWithTooFewFeaturesSaysSo) {
  TempDir dir;
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 30 --points 8 --out " + dir / "s").exit_code, 0);
  const auto r = RunMcslam("run " + dir / "s --out " + dir / "r");
  EXPECT_EQ(r.exit_code, 3) << r.output;  // kExitNotInitialised
  EXPECT_NE(r.output.find("the first map was never made: too few features to track (30 frames"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("in 29 too few features were shared with the reference frame"), std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("never moved enough"), std::string::npos) << r.output;
  EXPECT_EQ(CountDataLines(dir / "r/frames.csv"), 31);
  const nlohmann::json w = testing::ReadJson(dir / "r/report.json")["waiting_for_init"];
  EXPECT_EQ(w["few_shared"].get<int>(), 29) << w.dump();
  EXPECT_EQ(w["motion"].get<int>(), 0) << w.dump();
}

TEST(CliRun, BaselineFlagsSelectTheMethodsAndRejectUnknownOnes) {
  TempDir dir;
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 40 --out " + dir / "s").exit_code, 0);
  const auto r = RunMcslam("run " + dir / "s --gt-scale --pose pnp --structure ba --out " + dir / "r");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("tracked=40 lost=0"), std::string::npos) << r.output;
  const auto bad = RunMcslam("run " + dir / "s --structure lm --out " + dir / "x");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("--structure"), std::string::npos) << bad.output;
}

// A run reproduced from its report: --options-from takes every option of an earlier run's report.json, and the
// flags given that change an option from its default go on top.
TEST(CliRun, OptionsFromAReportReproduceTheRun) {
  TempDir dir;
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 40 --noise 1 --out " + dir / "s").exit_code, 0);
  ASSERT_EQ(RunMcslam("run " + dir / "s --out " + dir / "a --seed 3 --hypotheses 16384 --samples 1024 --window 8")
                .exit_code,
            0);
  const auto b = RunMcslam("run " + dir / "s --out " + dir / "b --options-from " + dir / "a/report.json");
  ASSERT_EQ(b.exit_code, 0) << b.output;
  EXPECT_EQ(ReadText(dir / "b/trajectory.txt"), ReadText(dir / "a/trajectory.txt"));
  const nlohmann::json ja = testing::ReadJson(dir / "a/report.json"), jb = testing::ReadJson(dir / "b/report.json");
  EXPECT_EQ(jb["options"]["system"], ja["options"]["system"]);
  // A flag on top: the seed changes, the rest is the report's.
  ASSERT_EQ(RunMcslam("run " + dir / "s --out " + dir / "c --seed 4 --options-from " + dir / "a/report.json").exit_code,
            0);
  const nlohmann::json jc = testing::ReadJson(dir / "c/report.json")["options"]["system"];
  EXPECT_EQ(jc["seed"], 4);
  EXPECT_EQ(jc["tracker"]["hypotheses"], 16384);
  EXPECT_EQ(jc["mapping"]["samples"], 1024);
  EXPECT_EQ(jc["mapping"]["window"], 8);
  // Images: the front end's options and relocalisation come back too.
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 30 --render --out " + dir / "r").exit_code, 0);
  const std::string images = "run " + dir / "r --dataset synthetic --out ";
  ASSERT_EQ(RunMcslam(images + dir / "ia --max-features 150 --hypotheses 16384 --no-relocalise").exit_code, 0);
  ASSERT_EQ(RunMcslam(images + dir / "ib --options-from " + dir / "ia/report.json").exit_code, 0);
  EXPECT_EQ(ReadText(dir / "ib/trajectory.txt"), ReadText(dir / "ia/trajectory.txt"));
  const nlohmann::json ib = testing::ReadJson(dir / "ib/report.json");
  EXPECT_EQ(ib["options"]["frontend"]["max_features"], 150);
  EXPECT_EQ(ib["relocalisation"]["enabled"], false);
  // What is not a report with options is refused, naming the file.
  testing::WriteText(dir / "empty.json", "{}");
  testing::WriteText(dir / "text.json", "not json");
  for (const auto& [file, needle] : std::vector<std::pair<std::string, std::string>>{
           {dir / "missing.json", "the file does not exist"}, {dir / "empty.json", "no options.system"},
           {dir / "text.json", "not JSON"}, {dir / "s", "not a regular file"}}) {
    const auto r = RunMcslam("run " + dir / "s --out " + dir / "x --options-from " + file);
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find("--options-from " + file + ": " + needle), std::string::npos) << r.output;
  }
  // A known-map run from a known-map run's report (its tracker's and smoother's options), and not from a report of
  // the other mode: neither holds the other's options.
  const std::string known = "run " + dir / "s --known-map --out ";
  ASSERT_EQ(RunMcslam(known + dir / "ka --seed 5 --hypotheses 16384 --smooth-alpha 0.3").exit_code, 0);
  const auto kb = RunMcslam(known + dir / "kb --options-from " + dir / "ka/report.json");
  ASSERT_EQ(kb.exit_code, 0) << kb.output;
  EXPECT_EQ(ReadText(dir / "kb/trajectory.txt"), ReadText(dir / "ka/trajectory.txt"));
  const nlohmann::json kbo = testing::ReadJson(dir / "kb/report.json")["options"]["known_map"];
  EXPECT_EQ(kbo, testing::ReadJson(dir / "ka/report.json")["options"]["known_map"]);
  EXPECT_EQ(kbo["tracker"]["hypotheses"], 16384);
  EXPECT_EQ(kbo["smoother"]["alpha"], 0.3);
  // The summary options at the report's top are the ones the run used too, not the flags'.
  const nlohmann::json kb_top = testing::ReadJson(dir / "kb/report.json")["options"];
  EXPECT_EQ(kb_top["hypotheses"], 16384);
  EXPECT_EQ(kb_top["seed"], 5);
  const auto km = RunMcslam(known + dir / "x --options-from " + dir / "a/report.json");
  EXPECT_EQ(km.exit_code, 1);
  EXPECT_NE(km.output.find("--options-from " + dir / "a/report.json: no options.known_map"), std::string::npos)
      << km.output;
  const auto mk = RunMcslam("run " + dir / "s --out " + dir / "x --options-from " + dir / "ka/report.json");
  EXPECT_EQ(mk.exit_code, 1);
  EXPECT_NE(mk.output.find("no options.system"), std::string::npos) << mk.output;
}

}  // namespace
}  // namespace mcslam
