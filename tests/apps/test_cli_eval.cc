// `mcslam eval`: runs the built binary on trajectories made here and checks its one-line summary and refusals.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cmath>
#include <string>

#include "../test_util.h"
#include "cli_report.h"
#include "io/trajectory_io.h"

namespace mcslam {
namespace {

using testing::Field;
using testing::ReadText;
using testing::RunMcslam;
using testing::TempDir;

// 100 poses on a smooth, non-planar path, 30 Hz stamps.
io::Trajectory MakeGroundTruth() {
  io::Trajectory t;
  for (int i = 0; i < 100; ++i) {
    const double a = 0.06 * i;
    t.stamps_s.push_back(1341847980.7 + i / 30.0);
    t.world_from_cam.emplace_back(
        QuaternionFromRotationVector(Eigen::Vector3d(0.3 * std::sin(a), 0.2 * std::cos(a), 0.5 * a)),
        Eigen::Vector3d(2.0 * std::cos(a), 1.5 * std::sin(a), 0.3 * std::sin(2.0 * a)));
  }
  return t;
}

// The estimate a monocular system could output: the ground truth seen through an unknown Sim(3),
// p_est = s R p_gt + t, R_est = R R_gt (scale 0.37, so the estimate is in arbitrary units).
io::Trajectory MoveBySim3(const io::Trajectory& gt) {
  const double s = 0.37;
  const Eigen::Quaterniond q = QuaternionFromRotationVector(Eigen::Vector3d(0.5, -0.8, 1.9));
  const Eigen::Vector3d t(10.0, -3.0, 7.5);
  io::Trajectory est = gt;
  for (Pose& p : est.world_from_cam) {
    p.t = s * (q * p.t) + t;
    p.q = (q * p.q).normalized();
  }
  return est;
}


TEST(CliEval, Sim3MovedCopyHasZeroAte) {
  TempDir dir;
  const io::Trajectory gt = MakeGroundTruth();
  io::WriteTum(dir / "gt.txt", gt);
  io::WriteTum(dir / "est.txt", MoveBySim3(gt));
  const auto r = RunMcslam("eval " + (dir / "gt.txt") + " " + (dir / "est.txt") + " --csv " + (dir / "err.csv"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // Exact Sim(3) copy, written with 17 digits: only rounding is left, ~1e-15 m; 1e-6 m is the brief's bound.
  EXPECT_LT(Field(r.output, "ate_rmse"), 1e-6) << r.output;
  EXPECT_LT(Field(r.output, "rot_mean_deg"), 1e-6) << r.output;  // as above, in degrees
  EXPECT_EQ(Field(r.output, "matched"), 100) << r.output;
  EXPECT_NEAR(Field(r.output, "scale"), 1.0 / 0.37, 1e-5) << r.output;  // 6 significant digits printed
  EXPECT_NE(r.output.find("align=sim3"), std::string::npos) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << "one line: " << r.output;
  const std::string csv = ReadText(dir / "err.csv");
  EXPECT_EQ(csv.rfind("stamp,gt_x,gt_y,gt_z,est_x,est_y,est_z,trans_err_m,rot_err_deg\n", 0), 0u);
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 101);
}

TEST(CliEval, NoAlignmentOnMovedCopyIsLarge) {
  TempDir dir;
  const io::Trajectory gt = MakeGroundTruth();
  io::WriteTum(dir / "gt.txt", gt);
  io::WriteTum(dir / "est.txt", MoveBySim3(gt));
  auto r = RunMcslam("eval " + (dir / "gt.txt") + " " + (dir / "est.txt") + " --align none");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_GT(Field(r.output, "ate_rmse"), 1.0) << r.output;  // moved by ~13 m
  // SE(3) cannot undo the scale: errors of the order of the path size (~2 m) remain.
  r = RunMcslam("eval " + (dir / "gt.txt") + " " + (dir / "est.txt") + " --align se3 --delta 3");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_GT(Field(r.output, "ate_rmse"), 0.1) << r.output;
  EXPECT_EQ(Field(r.output, "rpe_delta"), 3) << r.output;
}

TEST(CliEval, SegmentsShowAScaleDrift) {
  TempDir dir;
  const io::Trajectory gt = MakeGroundTruth();
  io::Trajectory est = MoveBySim3(gt);
  // The second half drifts to 1.25 times the first half's size (about the Sim(3)'s translation point).
  const Eigen::Vector3d t(10.0, -3.0, 7.5);
  for (size_t i = 50; i < est.world_from_cam.size(); ++i)
    est.world_from_cam[i].t = t + 1.25 * (est.world_from_cam[i].t - t);
  io::WriteTum(dir / "gt.txt", gt);
  io::WriteTum(dir / "est.txt", est);
  const auto r = RunMcslam("eval " + (dir / "gt.txt") + " " + (dir / "est.txt") + " --segments 2");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // The summary first (its scale is the whole run's), then the drift and one line per segment.
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 4) << r.output;
  EXPECT_EQ(Field(r.output, "segments"), 2) << r.output;
  // 6 significant digits printed.
  EXPECT_NEAR(Field(r.output, "scale_max_over_min"), 1.25, 1e-5) << r.output;
  EXPECT_NE(r.output.find("segment=1 poses=50-99 first_stamp="), std::string::npos) << r.output;
  // The segments' figures have keys of their own: the summary's scale is still the first and only scale=.
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '='), 17 + 2 + 2 * 7) << r.output;  // summary, segments, 2 x 7
  EXPECT_EQ(r.output.find(" scale=", r.output.find('\n')), std::string::npos) << r.output;
  EXPECT_GT(Field(r.output, "ate_rmse"), 0.01) << r.output;  // the whole run's, hiding the drift
  EXPECT_EQ(Field(r.output, "mirrored"), 0) << r.output;     // a drifting scale is no mirror image
  // Too many segments for 100 poses: an error, and nothing printed as if it had worked.
  const auto bad = RunMcslam("eval " + (dir / "gt.txt") + " " + (dir / "est.txt") + " --segments 40");
  EXPECT_EQ(bad.exit_code, 1) << bad.output;
  EXPECT_NE(bad.output.find("40 segments need at least 120"), std::string::npos) << bad.output;
  EXPECT_EQ(bad.output.find("matched="), std::string::npos) << bad.output;
}

TEST(CliEval, MixedFormatsAndKittiTimes) {
  TempDir dir;
  const io::Trajectory gt = MakeGroundTruth();
  io::WriteEuroc(dir / "gt.csv", gt);
  io::WriteKitti(dir / "est.txt", MoveBySim3(gt), dir / "times.txt");
  auto r = RunMcslam("eval " + (dir / "gt.csv") + " " + (dir / "est.txt") + " --est-times " + (dir / "times.txt") +
                     " --est-format kitti --max-dt 0.001");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(Field(r.output, "matched"), 100) << r.output;
  EXPECT_LT(Field(r.output, "ate_rmse"), 1e-6) << r.output;  // as above: rounding only
  // Without the times file the KITTI estimate is matched by index, which also pairs all 100.
  r = RunMcslam("eval " + (dir / "gt.csv") + " " + (dir / "est.txt"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_LT(Field(r.output, "ate_rmse"), 1e-6) << r.output;
}

TEST(CliEval, MissingFileNamesIt) {
  TempDir dir;
  io::WriteTum(dir / "gt.txt", MakeGroundTruth());
  const std::string missing = dir / "does_not_exist.txt";
  const auto r = RunMcslam("eval " + (dir / "gt.txt") + " " + missing);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find(missing), std::string::npos) << r.output;
}

// What is not a plain file is refused naming it, before anything reads it: a folder (it used to read as "read
// error after line 0") and a pipe with no writer (opening it blocked forever; `timeout` turns a hang into a
// failure here instead of a ctest timeout).
TEST(CliEval, FoldersAndPipesAreRefusedNamingThem) {
  TempDir dir;
  io::WriteTum(dir / "gt.txt", MakeGroundTruth());
  auto r = RunMcslam("eval " + (dir / "gt.txt") + " " + dir.path().string());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find(dir.path().string() + ": is a folder, not a file"), std::string::npos) << r.output;
  const std::string fifo = dir / "pipe.txt";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  r = testing::RunShell("timeout 30 " + std::string(MCSLAM_BIN) + " eval " + fifo + " " + (dir / "gt.txt") + " 2>&1");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find(fifo + ": is not a regular file"), std::string::npos) << r.output;
}

TEST(CliEval, BadFlagsNameTheFlag) {
  TempDir dir;
  io::WriteTum(dir / "gt.txt", MakeGroundTruth());
  // Built piecewise: GCC 12 misreads `" " + std::string(...)` here as an overlapping copy (-Wrestrict).
  std::string files = " ";
  files += dir / "gt.txt";
  files += " ";
  files += dir / "gt.txt";
  for (const auto& [flags, name] : std::vector<std::pair<std::string, std::string>>{
           {"--align foo", "--align"},
           {"--delta 0", "--delta"},
           {"--max-dt -1", "--max-dt"},
           {"--gt-format xyz", "--gt-format"},
           {"--segments -1", "--segments"},
           {"--max-dt inf", "--max-dt: must be >= 0, got inf"},
           {"--max-dt 1e400", "--max-dt: must be >= 0, got 1e400"},
           {"--max-dt abc", "--max-dt: must be a number >= 0, got 'abc'"},
       }) {
    const auto r = RunMcslam("eval" + files + " " + flags);
    EXPECT_NE(r.exit_code, 0) << flags;
    EXPECT_NE(r.output.find(name), std::string::npos) << flags << ": " << r.output;
  }
}

// RPE over a delta as long as the run or longer has no pair of poses: an error naming the flag, not
// rpe_trans_rmse=nan with exit 0 (issue #20).
TEST(CliEval, DeltaBeyondTheRunIsAnError) {
  TempDir dir;
  io::WriteTum(dir / "gt.txt", MakeGroundTruth());  // 100 poses
  std::string files = " ";
  files += dir / "gt.txt";
  files += " ";
  files += dir / "gt.txt";
  for (const int delta : {100, 100000}) {
    const auto r = RunMcslam("eval" + files + " --delta " + std::to_string(delta));
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find("--delta " + std::to_string(delta) + ": only 100 poses matched"), std::string::npos)
        << r.output;
    EXPECT_EQ(r.output.find("matched="), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("nan"), std::string::npos) << r.output;
  }
  const auto ok = RunMcslam("eval" + files + " --delta 99");
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_EQ(ok.output.find("nan"), std::string::npos) << ok.output;
}

TEST(CliEval, NoOverlapIsAnError) {
  TempDir dir;
  const io::Trajectory gt = MakeGroundTruth();
  io::Trajectory est = gt;
  for (double& s : est.stamps_s) s += 1000.0;
  io::WriteTum(dir / "gt.txt", gt);
  io::WriteTum(dir / "est.txt", est);
  const auto r = RunMcslam("eval " + (dir / "gt.txt") + " " + (dir / "est.txt"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("mcslam: error:"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("no estimated pose"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace mcslam
