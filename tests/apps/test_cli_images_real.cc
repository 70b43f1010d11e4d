// `mcslam run` on the real sequences of ../shared/data (KITTI 06, 7-Scenes RedKitchen, the Middlebury temple ring;
// skipped where the data folder is not there): frames tracked, accuracy, relocalisation after unreadable frames, the
// same frames as a video, a camera circling what it looks at.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "cli_report.h"
#include "test_util.h"

namespace mcslam {
namespace {

namespace fs = std::filesystem;
using testing::ReadJson;
using testing::RunMcslam;
using testing::TempDir;

// ---- the real sequences (../shared/data) ------------------------------------------------------------------

struct RealRun {
  std::string output;     // what mcslam printed
  nlohmann::json report;  // its report.json; null when the run failed (a test failure already)
};

// `mcslam run SEQ --out DIR/o FLAGS`, which must succeed.
RealRun RunOnRealSequence(const std::string& seq, const TempDir& dir, const std::string& flags) {
  const auto r = RunMcslam(fmt::format("run {} --out {} {}", seq, dir / "o", flags));
  if (r.exit_code != 0) {
    ADD_FAILURE() << "exit code " << r.exit_code << ": " << r.output;
    return {r.output, nullptr};
  }
  return {r.output, ReadJson(dir / "o/report.json")};
}

TEST(CliImagesReal, Kitti06AllFramesTracked) {
  REAL_SEQUENCE_OR_SKIP(seq, "kitti_odometry_06_frames000-050");
  TempDir dir;
  // Default settings: at 10 Hz forward a tenth of the tracks no longer match their birth patch one frame later,
  // and the front end measures it and gives them new patches (dropping them starves the initialisation:
  // measured, frames 0-8 without a pose with --anchor-mismatch drop).
  const RealRun run = RunOnRealSequence(seq, dir, "--hypotheses 65536");
  if (run.report.is_null()) return;
  EXPECT_EQ(run.report["tracked"], 51) << run.output;  // the target: every frame
  // The target is 0.10 m. Measured with these flags: 0.023 m (seed 1), 0.023-0.056 m over seeds 1-3
  // (without the anchoring, --anchor-every 0: 0.048-0.073 m over seeds 1-5).
  EXPECT_LT(run.report["ground_truth"]["ate_m"]["rmse"].get<double>(), 0.10) << run.output;
}

// Relocalisation on real images: a copy of the sequence with frames 25 and 26 unreadable (0.2 s, ~2 m of
// driving). The Monte Carlo search around frame 24's pose cannot reach frame 27 (6 inliers); RANSAC PnP on
// its features matched to the map can (26 of 52), and every later frame is tracked. Measured: 49/49 tracked,
// ATE 7.2 cm (no jump at the gap: 8-11 cm on either side of it after the alignment); without relocalisation
// 25 tracked and the rest lost.
TEST(CliImagesReal, Kitti06RelocalisesAfterUnreadableFrames) {
  REAL_SEQUENCE_OR_SKIP(seq, "kitti_odometry_06_frames000-050");
  TempDir dir;
  const fs::path copy = fs::path(dir / "kitti");
  fs::copy(seq, copy, fs::copy_options::recursive);
  for (int i : {25, 26}) testing::WriteText((copy / "image_0" / fmt::format("{:06d}.png", i)).string(), "");
  const std::string flags = "--hypotheses 65536";
  const RealRun run = RunOnRealSequence(copy.string(), dir, flags);
  if (run.report.is_null()) return;
  EXPECT_EQ(run.report["skipped"], 2) << run.output;
  EXPECT_EQ(run.report["tracked"], 49) << run.output;  // every readable frame
  EXPECT_GE(run.report["relocalisation"]["tracked"].get<int>(), 1) << run.report["relocalisation"].dump();
  // The bound for the whole sequence (measured 0.072 m; 0.023 m without the gap).
  EXPECT_LT(run.report["ground_truth"]["ate_m"]["rmse"].get<double>(), 0.10) << run.output;
  TempDir off;
  const RealRun without = RunOnRealSequence(copy.string(), off, flags + " --no-relocalise");
  if (without.report.is_null()) return;
  EXPECT_LE(without.report["tracked"].get<int>(), 30) << without.output;
}

// The paper's baselines (§8) end to end on real images: PnP for the pose step, local bundle adjustment for the
// structure step, through the same front end and initialisation as the Monte Carlo steps (scripts/compare.sh).
TEST(CliImagesReal, Kitti06PnpPoseAndBundleAdjustment) {
  REAL_SEQUENCE_OR_SKIP(seq, "kitti_odometry_06_frames000-050");
  TempDir dir;
  const RealRun run = RunOnRealSequence(seq, dir, "--pose pnp --structure ba");
  if (run.report.is_null()) return;
  EXPECT_EQ(run.report["options"]["pose"], "pnp");
  EXPECT_EQ(run.report["options"]["structure"], "ba");
  EXPECT_EQ(run.report["tracked"], 51) << run.output;
  EXPECT_EQ(run.report["lost"], 0);
  // Measured 0.019 m (0.052 m before the tracks were aligned with their birth patch), the same for every seed
  // (neither step samples, and the initialisation came out the same);
  // the margin is for other CPUs and library versions (OpenCV's RANSAC, Ceres). A bundle adjustment that
  // drifted or a PnP that failed on a few frames costs more than that (the Monte Carlo steps: 0.048-0.073 m).
  EXPECT_LT(run.report["ground_truth"]["ate_m"]["rmse"].get<double>(), 0.07) << run.output;
  // Frame-to-frame rotation, which needs no alignment (the road is straight, so the alignment's rotation about
  // it is loose): measured 0.044 degrees; 0.1 is twice that, and below the Monte Carlo pose step's 0.076.
  EXPECT_LT(run.report["ground_truth"]["rpe_rot_deg"]["mean"].get<double>(), 0.1) << run.output;
  // The structure step was the bundle adjustment: it counts every point of its window as adjusted (measured
  // 657 a keyframe after the initialisation), where the Monte Carlo step counts the points it re-sampled
  // (measured 7.5 a keyframe with --structure mc).
  const std::string csv = dir / "o/frames.csv";
  const std::vector<std::string> keyframe = testing::CsvColumn(csv, "keyframe"), init = testing::CsvColumn(csv, "init"),
                                 adjusted = testing::CsvColumn(csv, "adjusted");
  ASSERT_EQ(testing::CsvShapeErrors(csv), std::vector<std::string>{});
  ASSERT_FALSE(keyframe.empty());
  int keyframes = 0, adjusted_sum = 0;
  for (size_t i = 0; i < keyframe.size(); ++i)
    if (keyframe[i] == "1" && init[i] == "0") ++keyframes, adjusted_sum += std::stoi(adjusted[i]);
  ASSERT_GT(keyframes, 0);
  EXPECT_GT(adjusted_sum / keyframes, 100) << adjusted_sum << " adjusted over " << keyframes << " keyframes";
}

// Real users bring compressed video: the same 300 frames encoded as H.264 (OpenCV's FFmpeg writer, its default
// quality: 1.4 MB, ~1.1 Mbit/s, as ffmpeg's defaults give) and run as a video with the same camera and seed as
// the JPEG frames were. Measured (seed 1, both self-calibrating their lens): video 0.033 m against the JPEG frames'
// 0.039 m, 0.86x (before the self-calibration, seeds 1-3: 1.01-1.05x). Bound: the 1.5x of the JPEG run.
void ExpectH264VideoAsGoodAs(const std::string& seq, const std::string& camera_flag, const RealRun& jpeg) {
  TempDir dir;
  std::vector<fs::path> frames;
  for (const auto& e : fs::directory_iterator(fs::path(seq) / "color")) frames.push_back(e.path());
  std::sort(frames.begin(), frames.end());
  ASSERT_EQ(frames.size(), 300u);
  const std::string video = dir / "redkitchen.mp4";
  {
    cv::VideoWriter writer(video, cv::VideoWriter::fourcc('a', 'v', 'c', '1'), 30.0, cv::Size(640, 480), true);
    if (!writer.isOpened()) GTEST_SKIP() << "the H.264 part: this OpenCV cannot write H.264 (no FFmpeg encoder for avc1)";
    for (const fs::path& f : frames) writer.write(cv::imread(f.string(), cv::IMREAD_COLOR));
  }
  const RealRun mp4 =
      RunOnRealSequence(video, dir, fmt::format("{} --gt {}/groundtruth_tum.txt", camera_flag, seq));  // stamps i / 30 s
  if (mp4.report.is_null()) return;
  EXPECT_EQ(mp4.report["frames"], 300) << mp4.output;
  // Every frame but one at most: at 3eee81e seeds 2-6 tracked 300 of 300, seed 1 299 (frame 136 found 33 of its 84
  // map points where the frames beside it fit 80-90, and the next frame was tracked again); at 1fd6634's parent
  // seed 1 tracked all 300. A run that loses its way loses tens of frames.
  EXPECT_GE(mp4.report["tracked"].get<int>(), 299) << mp4.output;
  const double a = jpeg.report["ground_truth"]["ate_m"]["rmse"].get<double>();
  const double b = mp4.report["ground_truth"]["ate_m"]["rmse"].get<double>();
  std::printf("7-Scenes ATE: JPEG frames %.4f m, H.264 video %.4f m (%.2fx)\n", a, b, b / a);
  EXPECT_LT(b, 1.5 * a) << mp4.output;
}

// The JPEG frames with the colour camera, then the same frames as an H.264 video against that run (one JPEG run
// serves both: the same flags and seed give the same run).
TEST(CliImagesReal, SevenScenesRedKitchenFromJpegsAndAsH264Video) {
  REAL_SEQUENCE_OR_SKIP(seq, "7scenes_redkitchen_frames000-299");
  TempDir dir;
  // The colour camera as SOURCE.md recommends (the folder's camera-intrinsics.txt is the depth camera's), and
  // nothing else: default settings, as a user meets the system.
  testing::WriteText(dir / "camera.txt", "525 525 320 240\n");
  const std::string camera = fmt::format("--camera {}", dir / "camera.txt");
  const RealRun run = RunOnRealSequence(seq, dir, camera);
  if (run.report.is_null()) return;
  EXPECT_EQ(run.report["tracked"].get<int>(), 300) << run.output;  // measured: 300 on every seed tried
  EXPECT_FALSE(run.report["ground_truth"]["mirrored"].get<bool>());
  // The nominal camera has no distortion; the lens has some, which the first settled map measures and the run
  // takes (docs/self_calibration.md). Measured over seeds 1-10 (robustness matrix): k1 -0.026 to -0.033 at 14.1 to
  // 16.6 sigma (the System takes >= 10), 6-8 px at the corners. Bounds: k1 in [-0.045, -0.015], twice the spread's
  // half-width around its middle and more.
  const nlohmann::json& cal = run.report["self_calibration"];
  ASSERT_TRUE(cal.is_object()) << run.output;
  EXPECT_TRUE(cal["accepted"].get<bool>()) << cal.dump();
  EXPECT_GT(cal["k1_measured"].get<double>(), -0.045) << cal.dump();
  EXPECT_LT(cal["k1_measured"].get<double>(), -0.015) << cal.dump();
  // Measured at the default 2^18 hypotheses, seeds 1-10: 0.0376-0.0404 m (4.87-5.29 cm with the camera kept as
  // given; the rest is scale drift on this 10 s hand-held survey). The bound is 1.36x the worst seed, 0.055 m: a
  // run that lost the self-calibration's gain and a little more fails it.
  EXPECT_LT(run.report["ground_truth"]["ate_m"]["rmse"].get<double>(), 0.055) << run.output;
  ExpectH264VideoAsGoodAs(seq, camera, run);
}

// A map that runs dry: with the tracks dropped whenever they no longer match their birth patch
// (--anchor-mismatch drop), new points asked for 8 degrees of parallax and lost points looked for with their
// birth descriptors only (--descriptor-refresh-frames 0: with refreshed descriptors enough of them are found
// again that this map no longer runs dry, 300/300 even without the fallback), the hand-held tracks end before
// they reach it; without the fallback (--starving-inliers 0) the map runs dry and every later frame is lost
// (measured 114/300 tracked; with the provisional map after a turn, which this run's loss starts with, 300/300 and
// 5.2 cm: --no-provisional-map leaves the fallback alone to be measured). With it (default 30) keyframes with fewer
// inliers take new points from 2 degrees (measured 300/300). The local adjustment's keyframes are consecutive here
// (--local-ba-min-step 0): with them spaced by the scene's depth (the default) even the run without the fallback
// held, 299/300.
TEST(CliImagesReal, SevenScenesMapDoesNotRunDry) {
  REAL_SEQUENCE_OR_SKIP(seq, "7scenes_redkitchen_frames000-299");
  TempDir dir;
  testing::WriteText(dir / "camera.txt", "525 525 320 240\n");
  const std::string flags =
      fmt::format("--camera {} --hypotheses 65536 --min-parallax-deg 8 --anchor-mismatch drop "
                  "--descriptor-refresh-frames 0 --local-ba-min-step 0",
                  dir / "camera.txt");
  const RealRun run = RunOnRealSequence(seq, dir, flags);
  if (run.report.is_null()) return;
  EXPECT_EQ(run.report["tracked"], 300) << run.output;  // measured 300, ATE 5-7 cm over seeds 1-3
  TempDir dir2;
  const RealRun dry = RunOnRealSequence(seq, dir2, flags + " --starving-inliers 0 --no-provisional-map");
  if (dry.report.is_null()) return;
  EXPECT_LT(dry.report["tracked"].get<int>(), 200) << dry.output;
}

// ---- the Middlebury temple ring: a camera circling an object it keeps in view ---------------------------------

// Views `names` of the ring (templeR_par.txt: `name k11..k33 r11..r33 t1 t2 t3`, world to camera) as an image
// folder in that order, and their camera centres and orientations as a TUM ground truth at 30 Hz (the stamps
// `mcslam run` gives a folder without stamps).
void MakeTempleRun(const std::string& seq, const std::vector<std::string>& names, const fs::path& out) {
  std::ifstream par(fs::path(seq) / "templeR_par.txt");
  ASSERT_TRUE(par.good()) << seq;
  std::map<std::string, std::vector<double>> cams;
  std::string line;
  std::getline(par, line);  // the count
  while (std::getline(par, line)) {
    std::istringstream in(line);
    std::string name;
    std::vector<double> v(21);
    if (!(in >> name)) continue;
    for (double& x : v) in >> x;
    if (in) cams[name] = v;
  }
  fs::create_directories(out / "images");
  std::string gt;
  for (size_t i = 0; i < names.size(); ++i) {
    ASSERT_TRUE(cams.count(names[i])) << names[i] << " not in templeR_par.txt";
    const std::vector<double>& v = cams[names[i]];
    Eigen::Matrix3d cam_from_world;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) cam_from_world(r, c) = v[9 + 3 * r + c];
    const Eigen::Vector3d t(v[18], v[19], v[20]);
    const Eigen::Vector3d centre = -cam_from_world.transpose() * t;
    const Eigen::Quaterniond q(cam_from_world.transpose());
    gt += fmt::format("{:.6f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f}\n", i / 30.0, centre.x(), centre.y(),
                      centre.z(), q.x(), q.y(), q.z(), q.w());
    fs::copy_file(fs::path(seq) / "images" / names[i], out / "images" / fmt::format("{:06d}.png", i));
  }
  testing::WriteText((out / "gt.txt").string(), gt);
}

// The frame the map was made at ("initialised from frames A and B": B), -1 when none was.
int InitialisedAt(const std::string& output) {
  std::smatch m;
  if (!std::regex_search(output, m, std::regex("initialised from frames [0-9]+ and ([0-9]+)"))) return -1;
  return std::stoi(m[1].str());
}

// Two clean runs of the ring, 8 degrees of orbit a view about a 16 cm plaster temple 57 cm away, the camera
// fixating it through a narrow lens (24 degrees across, exact calibration): 0006-0012 (7 views, 45 cm of path) and
// 0030 back to 0013 (18 views, 1.28 m). The features barely move in the image while the parallax grows by 8
// degrees a view, so the median feature motion that starts the initialisation (2.3 degrees) came late or never:
// before the motion that no turn explains started it too, 0006-0012 never initialised (0 of 7 posed) and 0030-0013
// did at its 15th view (16 of 18 posed, ATE 1.6-1.8 cm and 2.3-2.5 degrees over seeds 1-3). Default settings, the
// camera only. Measured over seeds 1-10: initialised at the 3rd view on every one, 7/7 at ATE 2.3-2.8 mm and 18/18
// at 3.2-3.4 mm, none mirrored. Bounds: every view posed, the map from the first 4 views, ATE under 4 mm and 5 mm
// (1.4x the worst seed: a first map made from a worse pair of views, or one frame misplaced, exceeds them).
TEST(CliImagesReal, TempleRingOrbitsInitialiseInTheirFirstViews) {
  REAL_SEQUENCE_OR_SKIP(seq, "middlebury_templeRing");
  struct Run {
    int first, last;
    double max_ate_m;
  };
  for (const Run& r : {Run{6, 12, 0.004}, Run{30, 13, 0.005}}) {
    TempDir dir;
    std::vector<std::string> names;
    for (int i = r.first; i != r.last + (r.last > r.first ? 1 : -1); i += r.last > r.first ? 1 : -1)
      names.push_back(fmt::format("templeR{:04d}.png", i));
    MakeTempleRun(seq, names, dir.path() / "ring");
    const RealRun run = RunOnRealSequence(dir / "ring/images", dir,
                                          fmt::format("--camera \"1520.4 1525.9 302.32 246.87\" --gt {}", dir / "ring/gt.txt"));
    if (run.report.is_null()) return;
    const std::string what = fmt::format("views {:04d}-{:04d}", r.first, r.last);
    EXPECT_EQ(run.report["tracked"].get<int>(), static_cast<int>(names.size())) << what << "\n" << run.output;
    const int at = InitialisedAt(run.output);
    EXPECT_GE(at, 0) << what;
    EXPECT_LE(at, 3) << what << "\n" << run.output;
    EXPECT_FALSE(run.report["ground_truth"]["mirrored"].get<bool>()) << what;
    EXPECT_LT(run.report["ground_truth"]["ate_m"]["rmse"].get<double>(), r.max_ate_m) << what << "\n" << run.output;
  }
}

// The ring seen again upside down: views 0013-0030, then the other gantry configuration's views from 0042 (8 degrees
// beside 0013, the camera turned 180 degrees about its axis) on round the ring away from the map (0043-0047, 0032-
// 0034): a place seen again by a camera turned over, then new ground. The lost frame's upright descriptors match
// nothing there; turned by 180 degrees they do. Measured over seeds 1-10: 26 of 27 views posed (the first turned
// one lost: relocalisation starts after a lost frame), one relocalisation from turned descriptors, ATE 5.3-8.5 mm,
// none mirrored; with --no-turned-relocalisation 18 (the nine turned views lost). Bounds: 26 posed, a turned
// relocalisation, ATE under 1.2 cm (1.4x the worst seed); upright only, at most the 18 before the turn.
TEST(CliImagesReal, TempleRingSeenAgainUpsideDownRelocalises) {
  REAL_SEQUENCE_OR_SKIP(seq, "middlebury_templeRing");
  TempDir dir;
  std::vector<std::string> names;
  for (int i = 13; i <= 30; ++i) names.push_back(fmt::format("templeR{:04d}.png", i));
  for (int i : {42, 43, 44, 45, 46, 47, 32, 33, 34}) names.push_back(fmt::format("templeR{:04d}.png", i));
  MakeTempleRun(seq, names, dir.path() / "ring");
  const std::string flags = fmt::format("--camera \"1520.4 1525.9 302.32 246.87\" --gt {}", dir / "ring/gt.txt");
  const RealRun run = RunOnRealSequence(dir / "ring/images", dir, flags);
  if (run.report.is_null()) return;
  EXPECT_GE(run.report["tracked"].get<int>(), 26) << run.output;
  EXPECT_GE(run.report["relocalisation"]["pose_found_turned"].get<int>(), 1) << run.report["relocalisation"].dump();
  EXPECT_FALSE(run.report["ground_truth"]["mirrored"].get<bool>());
  EXPECT_LT(run.report["ground_truth"]["ate_m"]["rmse"].get<double>(), 0.012) << run.output;
  TempDir upright;
  const RealRun off = RunOnRealSequence(dir / "ring/images", upright, flags + " --no-turned-relocalisation");
  if (off.report.is_null()) return;
  EXPECT_LE(off.report["tracked"].get<int>(), 18) << off.output;
  EXPECT_EQ(off.report["relocalisation"]["pose_found_turned"].get<int>(), 0);
}

}  // namespace
}  // namespace mcslam
