#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <fmt/format.h>

#include "io/camera_io.h"
#include "io/observations_io.h"
#include "io/ply.h"
#include "io/trajectory_io.h"
#include "cli_report.h"
#include "test_util.h"
#include <filesystem>

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

// The rendered rotation scenario at 640x480 (a pan, then the first steps): its first two-view window is explained
// a little better by the scene's mirror in depth than by the scene (frames 3-41 of seed 1, by a chi-square of 51;
// seed 3 too): the map is made mirrored. Three frames later the settling window tells (the mirror's mean squared
// residual 0.019 px^2 against the map's 0.041, a chi-square of 177 over its 149 tracks, judged on 20 of those
// frames): the map is flipped, said in the log and in report.json. Measured, 50 frames: without the flip the
// orientations end 127 deg (seed 3: 166) off and the map is mirrored; with it 1.65 deg (seed 3: 1.69). Bound
// 10 deg: 6x the flipped runs, a tenth of the mirrored ones.
TEST(CliRun, AMapMadeOnTheMirrorOfTheSceneIsFlippedWhenTheFramesAfterItTell) {
  // Both seeds made their maps mirrored here; which frames the first try takes can differ on another CPU (its
  // vector width rounds the tracks otherwise), so each run must end unmirrored, and the two together must
  // have flipped a map at least once (the test of the flip, wherever the initialisation went wrong).
  TempDir dir;
  size_t reversals = 0;
  for (const std::string seed : {"1", "3"}) {
    const auto synth = RunMcslam("synth --scenario rotation --image-scale 2 --frames 50 --seed " + seed +
                                 " --render --out " + dir / ("s" + seed));
    ASSERT_EQ(synth.exit_code, 0) << synth.output;
    const auto r = RunMcslam("run " + dir / ("s" + seed) + " --dataset synthetic --out " + dir / ("r" + seed));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const nlohmann::json j = testing::ReadJson(dir / ("r" + seed + "/report.json"));
    const io::Trajectory est = io::ReadTum(dir / ("r" + seed + "/trajectory.txt"));
    const io::Trajectory smooth = io::ReadTum(dir / ("r" + seed + "/trajectory_smoothed.txt"));
    ASSERT_EQ(est.size(), 50u) << r.output;  // every frame posed: row k is frame k
    ASSERT_EQ(smooth.size(), 50u);
    for (const nlohmann::json& d : j["depth_reversals"]) {
      const int frame = d["frame"].get<int>();
      EXPECT_LE(frame, 50);
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
    EXPECT_EQ(j["tracked"], 50) << r.output;
    EXPECT_FALSE(j["ground_truth"]["mirrored"].get<bool>()) << seed << ": " << j["ground_truth"].dump();
    EXPECT_LT(j["ground_truth"]["rot_deg"]["mean"].get<double>(), 10.0) << seed << ": " << j["ground_truth"].dump();
  }
  EXPECT_GE(reversals, 1u);
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

TEST(CliRun, RenderedPaperScenarioEndToEndFromImages) {
  // mcslam synth --render: the textured box ray-cast for each exact pose; then the whole pipeline, front end
  // included, from the images alone.
  TempDir dir;
  const auto s = RunMcslam("synth --scenario paper --frames 90 --render --out " + dir / "s");
  ASSERT_EQ(s.exit_code, 0) << s.output;
  ASSERT_TRUE(std::filesystem::exists(dir / "s/images/000089.png"));
  const auto r = RunMcslam("run " + dir / "s --dataset synthetic --hypotheses 65536 --out " + dir / "r");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("tracked=90 lost=0"), std::string::npos) << r.output;
  // Measured 4.6 mm (Sim(3) RMSE) on this 90-frame run; 2 cm, the paper's bound, leaves a 4x margin.
  const double ate = std::stod(r.output.substr(r.output.find("ate_rmse=") + 9));
  EXPECT_LT(ate, 0.02);
  // --gt-scale on the image path: the first baseline gets its true length, so the Sim(3) alignment needs
  // (almost) no scale. Scale drift over 90 frames stays within 25 % here.
  const auto g = RunMcslam("run " + dir / "s --dataset synthetic --gt-scale --hypotheses 65536 --out " + dir / "g");
  ASSERT_EQ(g.exit_code, 0) << g.output;
  const double scale = std::stod(g.output.substr(g.output.find(" scale=") + 7));
  EXPECT_NEAR(scale, 1.0, 0.25) << g.output;
}

// The target for the rendered paper scenario (`make demo`): the whole 300-frame sequence from its
// images, mean translation error <= 2 cm and mean rotation error <= 1 degree after Sim(3) alignment.
TEST(CliRun, RenderedPaperScenarioMeetsThePapersPrecisionFromImages) {
  TempDir dir;
  const auto s = RunMcslam("synth --scenario paper --seed 1 --render --out " + dir / "s");
  ASSERT_EQ(s.exit_code, 0) << s.output;
  const auto r = RunMcslam("run " + dir / "s --dataset synthetic --out " + dir / "r");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("tracked=300 lost=0"), std::string::npos) << r.output;
  // Measured 0.65 cm and 0.60 deg (seed 1; seeds 2 and 3: 0.30 cm / 0.13 deg, 1.8 cm / 0.98 deg). Before the
  // tracks were aligned with their birth patch (--anchor-every 0) 8.2 cm and 3.5 deg: the bounds are the issue's.
  EXPECT_LT(Field(r.output, "ate_mean"), 0.02) << r.output;
  EXPECT_LT(Field(r.output, "rot_mean_deg"), 1.0) << r.output;
}

// A second of unreadable frames (120-149 of 170). Most tracks survive the jump, but the pose is too far from
// the last one for the Monte Carlo search around it: frame 150 finds 10 of 37 points agreeing (lost: before
// the inlier-ratio rule that was taken as tracking, 0.77 m off, and every later frame followed it, 0.5-0.8 m).
// Relocalisation, tried after skipped frames (RANSAC PnP on the frame's features matched to map points),
// finds the pose at frame 150 with 36 of 37, and tracking goes on (measured: 140 tracked, worst 1.3 cm);
// without it every frame after the gap is lost. Either way no frame is tracked wrong.
struct GapRun {
  int tracked_after_gap = 0;
  double worst_m = 0;
  std::string output;
};
GapRun RunOverAGap(const std::string& scenario, const std::string& out, const std::string& flags) {
  GapRun g;
  const auto r = RunMcslam("run " + scenario + " --dataset synthetic --out " + out + " " + flags);
  g.output = r.output;
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(Field(r.output, "skipped"), 30) << r.output;
  const std::string csv = out + "/frames.csv";
  const std::vector<std::string> index = testing::CsvColumn(csv, "index"), status = testing::CsvColumn(csv, "status"),
                                 terr = testing::CsvColumn(csv, "trans_err_m");  // after the Sim(3) alignment
  EXPECT_FALSE(index.empty());
  for (size_t i = 0; i < index.size(); ++i) {
    if (status[i] != "tracked") continue;
    if (terr[i].empty()) {
      ADD_FAILURE() << "tracked frame " << index[i] << " has no error against the ground truth";
      continue;
    }
    g.tracked_after_gap += std::stoi(index[i]) >= 150;
    g.worst_m = std::max(g.worst_m, std::stod(terr[i]));
  }
  return g;
}

// Renders the rotation scenario of `seed` into dir/s and runs it with default settings (and `extra`) into dir/r;
// the run's result (its exit code asserted by the caller).
testing::CommandResult RunRenderedRotation(const TempDir& dir, int seed, const std::string& extra = "") {
  const auto s = RunMcslam(fmt::format("synth --scenario rotation --seed {} --render --out {}", seed, dir / "s"));
  EXPECT_EQ(s.exit_code, 0) << s.output;
  return RunMcslam(fmt::format("run {} --dataset synthetic --seed {} {} --out {}", dir / "s", seed, extra, dir / "r"));
}

// The rendered rotation scenario: the camera pans away from everything mapped (a turn, tracked about the last
// centre), moves on through the unmapped half of the room, and pans back. Before the bridge every frame of the
// move was lost (205 and 200 of 270 frames tracked on seeds 3 and 4); now a provisional map made from two views
// at the turn's end carries the track (settled as the first map is), and joins the map when the pan back
// relocalises a frame against it: scaled about the anchor (seeds 1 and 3: its scale had been guessed 0.959x and
// 1.457x off), then its keyframes adjusted between the anchor and the joining frame. Seed 1 also anchors the
// provisional map one frame before the turn's last accepted one, where the tracks had begun to disagree (0.29
// px rms against 0.1). Measured 270 / 270 frames tracked on both seeds, ATE 0.71 / 0.27 cm (seed 1 was 35 cm at
// e47f435 and 4.0 cm with the anchor alone, the join scaled but not adjusted; seeds 1 and 3-10 now 0.27-3.0 cm,
// docs/rotation_only.md). Bounds: every frame tracked but 3; ATE under 2 cm (3x seed 1, and under the median of
// the seeds without the adjustment, 3.3 cm); the join adjusted the bridge's keyframes.
TEST(CliRun, AProvisionalMapBridgesTheMoveAfterATurnAwayFromTheMapAndJoinsIt) {
  for (const int seed : {1, 3}) {
    TempDir dir;
    const auto r = RunRenderedRotation(dir, seed);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_GE(Field(r.output, "tracked"), 267) << "seed " << seed << ": " << r.output;
    EXPECT_LT(Field(r.output, "ate_rmse"), 0.02) << "seed " << seed << ": " << r.output;
    const nlohmann::json report = testing::ReadJson(dir / "r/report.json");
    EXPECT_GT(report["provisional"].get<int>(), 20) << "seed " << seed;
    int made = 0, joined = 0, adjusted = 0;
    for (const std::string& note : testing::CsvColumn(dir / "r/frames.csv", "note")) {
      made += note.find("provisional map from frames") != std::string::npos;
      joined += note.find("the provisional map joins it") != std::string::npos;
      if (const size_t at = note.find(" of its keyframes adjusted"); at != std::string::npos) {
        const size_t from = note.rfind(' ', at - 1) + 1;
        adjusted = std::max(adjusted, std::stoi(note.substr(from, at - from)));
      }
    }
    EXPECT_GE(made, 1) << "seed " << seed;  // measured: one each, joined once
    EXPECT_GE(joined, 1) << "seed " << seed;
    EXPECT_GT(adjusted, 20) << "seed " << seed;  // measured: 70 on both
    // Joined, no frame keeps the guessed scale.
    EXPECT_EQ(report["guessed_scale"].get<int>(), 0) << "seed " << seed;
    const std::vector<std::string> guessed = testing::CsvColumn(dir / "r/frames.csv", "guessed_scale");
    EXPECT_EQ(std::count(guessed.begin(), guessed.end(), "1"), 0) << "seed " << seed;
  }
}

// A provisional map that never joins the map (the run ends first, here; or it is lost) leaves its frames at the
// scale it guessed, a Sim(3) away from the map's: frames.csv's guessed_scale and report.json's say which and how
// many. Seed 1 cut at frame 180, before its join at 191: measured 59 frames (122-180, the provisional map's from
// its anchor on) flagged, all of the run's provisional ones, and its ATE 5.5 cm (the scale guessed 1.28x off)
// against 0.5 cm for the whole run. Bounds: at least 20 flagged, exactly the provisional frames, none before the
// note that made the provisional map's anchor; the whole run flags none (the test above).
TEST(CliRun, AProvisionalMapThatNeverJoinsLeavesItsFramesFlaggedAsAGuessedScale) {
  TempDir dir;
  const auto r = RunRenderedRotation(dir, 1, "--end 180");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json report = testing::ReadJson(dir / "r/report.json");
  EXPECT_GE(report["guessed_scale"].get<int>(), 20) << r.output;
  EXPECT_EQ(report["guessed_scale"].get<int>(), report["provisional"].get<int>());
  const std::vector<std::string> index = testing::CsvColumn(dir / "r/frames.csv", "index"),
                                 guessed = testing::CsvColumn(dir / "r/frames.csv", "guessed_scale"),
                                 note = testing::CsvColumn(dir / "r/frames.csv", "note");
  ASSERT_EQ(guessed.size(), index.size());
  EXPECT_EQ(std::count(guessed.begin(), guessed.end(), "1"), report["guessed_scale"].get<int>());
  // The anchor, as the note that made the provisional map names it: "provisional map from frames A (...".
  int anchor = -1;
  for (const std::string& n : note)
    if (const size_t at = n.find("provisional map from frames "); at != std::string::npos && anchor < 0)
      anchor = std::stoi(n.substr(at + std::string("provisional map from frames ").size()));
  ASSERT_GE(anchor, 0);
  for (size_t i = 0; i < index.size(); ++i)
    if (guessed[i] == "1") {
      EXPECT_GT(std::stoi(index[i]), anchor) << "frame " << index[i];
    }
}

// The bas-relief valley of a small-parallax window: held-out rotation seed 15 makes its provisional map from frames
// 121-130 at 3.7 deg of parallax, where the two views' cost has two minima along the valley and every two-view
// seed (8-point, 5-point) stopped in the wrong one: its rotation 6.6 deg where the camera turned 3.9, the move 55
// deg off; that map was lost at frame 206 and the trajectory ended 64 cm off (21 % of the 2.97 m path).
// The multi-start search of the valley (geometry::RelativePoseMinima) finds the other minimum, the true motion's,
// which explains the window better (mean squared residual 0.0068 against 0.0084 px^2) but, refined, falls short
// of the parallax asked for: it cannot be taken, and it stands against the wrong one, so the provisional map
// waits ("ambiguous initialisation", frames 130-140) and is made at frame 141 from 11.9 deg of parallax. Measured:
// the run to frame 210 (the provisional map joined at 196): 211 / 211 tracked, no frame at a guessed scale, ATE
// 1.31 cm (0.69 % of the 1.90 m path); with the run's seeds 1-8 on this scene 0.84-2.34 cm (0.44-1.23 %).
// Bounds: every frame tracked; none at a guessed scale; ATE under 3 % of the path (2.4x the worst run seed; the
// wrong minimum's map was lost at 206). The run stops at 210 because what follows the join is a stage of its own
// and chaotic on this scene: at frame 216 82 points are removed and the next ten frames are tracked on 10-20
// inliers, and one remap more or less there moved the whole run's ATE from 2.2 to 4.3 cm (measured 2026-11-28).
TEST(CliRun, ASmallParallaxProvisionalMapTakesTheBetterMinimumOfTheBasReliefValley) {
  TempDir dir;
  const auto r = RunRenderedRotation(dir, 15, "--end 210");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(Field(r.output, "tracked"), 211) << r.output;
  EXPECT_LT(Field(r.output, "ate_rmse"), 0.03 * 1.90) << r.output;
  const nlohmann::json report = testing::ReadJson(dir / "r/report.json");
  EXPECT_GT(report["provisional"].get<int>(), 20) << r.output;
  EXPECT_EQ(report["guessed_scale"].get<int>(), 0) << r.output;
}

// A car at 1 m a frame (the forward scenario, rendered: a 90-degree bend, 119 m): the map renews itself every few
// frames, and with the paper's back end alone (poses and points never refined together) each generation of
// points passes its scale and heading errors on to the next. The local bundle adjustment after each keyframe
// holds them. Seed 9, measured: 120 / 120 tracked, ATE 16.5 cm with it; 117 / 120 and 5.2 m without (the
// scale grew 1.9x after the bend). Over seeds 1-10 with it, 3-24 cm (docs/robustness.md). Bounds: every frame
// tracked; ATE under 0.5 m (0.4 % of the path; ~2x the worst seed); the run without it at least 5x worse.
TEST(CliRun, TheLocalBundleAdjustmentKeepsACarsScaleThroughItsBend) {
  TempDir dir;
  const auto s = RunMcslam("synth --scenario forward --seed 9 --render --out " + dir / "s");
  ASSERT_EQ(s.exit_code, 0) << s.output;
  const auto with = RunMcslam(fmt::format("run {} --dataset synthetic --seed 9 --out {}", dir / "s", dir / "r"));
  ASSERT_EQ(with.exit_code, 0) << with.output;
  EXPECT_EQ(Field(with.output, "tracked"), 120) << with.output;
  EXPECT_LT(Field(with.output, "ate_rmse"), 0.5) << with.output;
  const auto without = RunMcslam(
      fmt::format("run {} --dataset synthetic --seed 9 --local-ba-keyframes 0 --out {}", dir / "s", dir / "n"));
  ASSERT_EQ(without.exit_code, 0) << without.output;
  EXPECT_GT(Field(without.output, "ate_rmse"), 5 * Field(with.output, "ate_rmse")) << without.output;
}

// Frames 120-149 of the rendered paper scene unreadable: the camera moved on meanwhile. Scene seeds 1 and 2: on
// seed 2, with relocalisation off, the first try at frame 150 (normal spread) took a pose 50-55 cm off from 25
// of 46 stale tracks fitting loosely, until a first try after frames without a pose was checked as the second
// try's is (PoseTracker::FitLimitPx). Measured over scene seeds 1-6: the default run's worst tracked frame
// 1.3 / 1.4 / 2.7 / 4.0 / 7.0 / 1.7 cm (seed 5's: a frame relocalised from 32 matches all in one part of the
// image, 7 cm and 2 degrees off, a weakness of relocalisation left open); no frame tracked wrong in the runs
// without relocalisation.
TEST(CliRun, AfterAGapTheMapIsFoundAgainAndNoFrameIsTrackedWrong) {
  for (const int seed : {1, 2}) {
    SCOPED_TRACE(fmt::format("scene seed {}", seed));
    TempDir dir;
    const auto s = RunMcslam(fmt::format("synth --scenario paper --seed {} --render --frames 170 --out {}", seed,
                                         dir / "s"));
    ASSERT_EQ(s.exit_code, 0) << s.output;
    for (int i = 120; i < 150; ++i) testing::WriteText(dir / fmt::format("s/images/{:06d}.png", i), "");
    const GapRun with = RunOverAGap(dir / "s", dir / "r", "");
    EXPECT_GE(Field(with.output, "tracked"), 120 + 18) << with.output;  // all before; all but 1-2 after
    EXPECT_GE(with.tracked_after_gap, 18) << with.output;
    // A frame tracked wrong is tens of centimetres off; the runs before the gap alone have 1.1 cm at worst.
    EXPECT_LT(with.worst_m, 0.05);
    const nlohmann::json report = testing::ReadJson(dir / "r/report.json");
    EXPECT_GE(report["relocalisation"]["tracked"].get<int>(), 1) << report["relocalisation"].dump();
    EXPECT_NE(with.output.find("relocalised from"), std::string::npos) << with.output;

    // Neither relocalisation nor the pose step's wider second try: nothing after the gap (seed 2's first try is
    // refused: its loose fit is what the check is for).
    const GapRun without = RunOverAGap(dir / "s", dir / "n", "--no-relocalise --retry-rot-scale 0");
    EXPECT_EQ(without.tracked_after_gap, 0) << without.output;
    EXPECT_EQ(Field(without.output, "tracked"), 120) << without.output;
    EXPECT_LT(without.worst_m, 0.05);
    // The second try alone (4x the rotation spread) reaches across this gap too, and nothing it tracks is wrong:
    // its loose fits are refused (PoseTrackerOptions::retry_max_residual_ratio; measured on seed 1: frames 150 and
    // 151, 36 and 32 inliers at medians of 1.18 and 1.02 px against the recent frames' 0.08), then a frame is
    // found and 18-20 frames after the gap are tracked. Taken unchecked, frame 150 came out 47 cm off in one build.
    const GapRun wider = RunOverAGap(dir / "s", dir / "w", "--no-relocalise");
    EXPECT_GE(wider.tracked_after_gap, 10) << wider.output;
    EXPECT_LT(wider.worst_m, 0.05);
  }
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

TEST(CliBench, PosePrintsEvaluationsPerSecond) {
  const auto r = RunMcslam("bench pose --hypotheses 4096 --points 50 --repeats 3");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const size_t at = r.output.find("evals_per_s=");
  ASSERT_NE(at, std::string::npos);
  EXPECT_GT(std::stod(r.output.substr(at + 12)), 1e6);  // any working kernel does far more than 1e6/s
  EXPECT_EQ(Field(r.output, "rounds"), 1.0) << r.output;  // the paper's one-shot sampling unless asked
  // A frame as `mcslam run` searches it: the same hypotheses in 3 rounds.
  const auto rounds = RunMcslam("bench pose --hypotheses 4096 --points 50 --repeats 3 --rounds 3");
  ASSERT_EQ(rounds.exit_code, 0) << rounds.output;
  EXPECT_EQ(Field(rounds.output, "rounds"), 3.0) << rounds.output;
  EXPECT_EQ(Field(rounds.output, "hypotheses"), 4096.0) << rounds.output;
  // Two backends side by side (here the CPU twice) compare their answers on a tracking frame's problem (the
  // camera moved from the prior, noisy features): the winner is a sampled hypothesis, not the centre (row 0,
  // which wins only when the features are the prior's exact projections), and the same kernel twice agrees
  // exactly.
  const auto two = RunMcslam("bench pose --hypotheses 4096 --points 50 --repeats 2 --warm-s 0 --backend cpu,cpu");
  ASSERT_EQ(two.exit_code, 0) << two.output;
  const size_t at_index = two.output.find("best_index=");
  ASSERT_NE(at_index, std::string::npos) << two.output;
  const int first = std::stoi(two.output.substr(at_index + 11));
  EXPECT_GT(first, 0) << two.output;
  EXPECT_NE(two.output.find(fmt::format("best_index={}/{} ", first, first)), std::string::npos) << two.output;
  EXPECT_EQ(Field(two.output, "score_diff_px_per_point_max"), 0.0) << two.output;
  const auto bad = RunMcslam("bench pose --hypotheses 2 --points 5 --rounds 3");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("--rounds (3) must not exceed --hypotheses (2)"), std::string::npos) << bad.output;
}

TEST(CliBench, PointsPrintsLatencyAndEvaluationsPerSecond) {
  const auto r = RunMcslam("bench points --points 50 --samples 4096 --window 6 --repeats 3");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_NE(r.output.find("bench points backend=cpu threads="), std::string::npos) << r.output;
  EXPECT_EQ(Field(r.output, "observations"), 300.0) << r.output;  // every point seen by every keyframe
  const double ms = Field(r.output, "call_ms_median"), min_ms = Field(r.output, "call_ms_min");
  const double evals = Field(r.output, "evals_per_s");
  EXPECT_GT(ms, 0.0) << r.output;
  EXPECT_LE(min_ms, ms) << r.output;
  // samples x observations per call over the median call. Tolerance: the rounding of the printed figures
  // (evals to 4 significant digits: 5e-4 relative; ms to 3 decimals: 5e-4 ms absolute).
  EXPECT_NEAR(evals, 4096.0 * 300 / (ms * 1e-3), evals * (5e-4 + 5e-4 / ms)) << r.output;
  EXPECT_GT(evals, 1e6);  // any working kernel does far more than 1e6/s
  // Several sizes: one line each, in order.
  const auto two = RunMcslam("bench points --points 10 20 --samples 256 --window 3 --repeats 1");
  ASSERT_EQ(two.exit_code, 0) << two.output;
  const size_t a = two.output.find("points=10 keyframes=3 observations=30 "), b = two.output.find("points=20 keyframes=3 observations=60 ");
  EXPECT_NE(a, std::string::npos) << two.output;
  EXPECT_NE(b, std::string::npos) << two.output;
  EXPECT_LT(a, b);
  const auto bad = RunMcslam("bench points --window 0");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("--window"), std::string::npos) << bad.output;
}

TEST(CliBench, PointsSuccessiveTimesKeyframesInTurn) {
  // Successive keyframes' adjustments (--successive), said on the line: the current keyframe's 40 points, each
  // older keyframe of the window seeing a twentieth of them (2) fewer: 40 + 38 + 36 + 34 + 32 observations. The
  // CPU backend sends nothing, so no bytes field.
  const auto r = RunMcslam("bench points --points 40 --samples 512 --window 5 --repeats 3 --successive");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("points=40 keyframes=5 observations=180 samples=512 calls=successive repeats=3 "),
            std::string::npos)
      << r.output;
  EXPECT_GT(Field(r.output, "evals_per_s"), 1e6) << r.output;
  EXPECT_EQ(r.output.find("bytes_sent_per_call"), std::string::npos) << r.output;
  // Without the flag the calls are one adjustment repeated, and the line does not say otherwise.
  const auto same = RunMcslam("bench points --points 40 --samples 512 --window 5 --repeats 1");
  ASSERT_EQ(same.exit_code, 0) << same.output;
  EXPECT_EQ(same.output.find("calls="), std::string::npos) << same.output;
}

TEST(CliBench, SoakPrintsEachWindowAndTheLastAgainstTheFirst) {
  TempDir dir;
  // The back end alone on the paper scenario's observations: three windows of 40 frames.
  const auto r = RunMcslam("bench soak --observations --frames 120 --window 40 --csv " + dir / "w.csv");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(Field(r.output, "frames"), 120.0) << r.output;
  EXPECT_EQ(testing::CsvShapeErrors(dir / "w.csv"), std::vector<std::string>{});
  const std::vector<std::string> first = testing::CsvColumn(dir / "w.csv", "first");
  EXPECT_EQ(first, (std::vector<std::string>{"0", "40", "80"}));
  const std::vector<std::string> med = testing::CsvColumn(dir / "w.csv", "median_ms");
  const std::vector<std::string> tracked = testing::CsvColumn(dir / "w.csv", "tracked");
  const std::vector<std::string> rss = testing::CsvColumn(dir / "w.csv", "rss_mib");
  ASSERT_EQ(med.size(), 3u);
  // The summary is the windows': tracked frames summed, the ratio of the last median to the first (printed to
  // 3 decimals, the CSV's to 4: 2e-3 relative covers both roundings at these few-ms medians).
  EXPECT_EQ(Field(r.output, "tracked"), std::stod(tracked[0]) + std::stod(tracked[1]) + std::stod(tracked[2]));
  const double ratio = std::stod(med[2]) / std::stod(med[0]);
  EXPECT_NEAR(Field(r.output, "last_over_first"), ratio, 2e-3 * ratio + 1e-3) << r.output;
  EXPECT_EQ(std::stod(tracked[2]), 40.0) << "the paper scenario is tracked throughout once initialised";
  EXPECT_GT(std::stod(rss[0]), 1.0);  // a process holds more than a MiB
  EXPECT_GE(Field(r.output, "rss_peak_mib"), std::stod(rss[2]) - 0.1) << r.output;
  // The noise-free scenario's trajectory is right to far better than 1 % of its path (measured 0.04 % on
  // the rendered run of 600 frames; observations are exact here).
  EXPECT_LT(Field(r.output, "ate_over_path"), 0.01) << r.output;
  const auto bad = RunMcslam("bench soak --frames 50 --window 100");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("--window 100 is longer than --frames 50"), std::string::npos) << bad.output;
}

TEST(CliBench, CudaWithoutDeviceIsAnErrorNotAFallback) {
  for (const std::string cmd : {"bench pose --hypotheses 1024 --backend cuda", "bench pose --hypotheses 1024 --compare",
                                "bench points --points 10 --backend cuda", "bench points --points 10 --compare"}) {
    const auto r = RunMcslam(cmd);
    if (r.exit_code == 0) GTEST_SKIP() << "a CUDA device is present";
    EXPECT_NE(r.output.find("--backend cuda"), std::string::npos) << cmd << ": " << r.output;
    // The error comes before anything is timed: no figure of the CPU either.
    EXPECT_EQ(r.output.find("backend=cpu"), std::string::npos) << cmd << ": " << r.output;
  }
}

}  // namespace
}  // namespace mcslam
