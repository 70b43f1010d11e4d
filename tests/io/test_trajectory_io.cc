#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <string>

#include "io/trajectory_io.h"
#include "../test_util.h"

namespace mcslam::io {
namespace {

using mcslam::testing::ExpectThrowsWith;

using mcslam::testing::ReadText;
using mcslam::testing::TempDir;
using mcslam::testing::WriteText;

// A smooth trajectory with real-looking epoch stamps and non-trivial orientations.
Trajectory MakeTrajectory(int n, double t0 = 1403636579.758555392) {
  Trajectory traj;
  for (int i = 0; i < n; ++i) {
    const double a = 0.1 * i;
    traj.stamps_s.push_back(t0 + 0.05 * i);
    const Eigen::Vector3d w(0.3 * std::sin(a), 0.2 * std::cos(0.7 * a), 0.5 * a);
    traj.world_from_cam.emplace_back(QuaternionFromRotationVector(w),
                                     Eigen::Vector3d(2.0 * std::cos(a), 1.5 * std::sin(a), 0.1 * i + 1.0 / 3.0));
  }
  return traj;
}

// Messages must point at the place: "<path>:<line>: ...".

void ExpectSamePoses(const Trajectory& a, const Trajectory& b, double tol_pos, double tol_rot_rad) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_LE((a.world_from_cam[i].t - b.world_from_cam[i].t).norm(), tol_pos) << "pose " << i;
    EXPECT_LE(AngularDistanceRad(a.world_from_cam[i].q, b.world_from_cam[i].q), tol_rot_rad) << "pose " << i;
  }
}

TEST(TrajectoryIo, TumRoundTripIsExact) {
  TempDir dir;
  const Trajectory traj = MakeTrajectory(50);
  WriteTum(dir / "t.txt", traj);
  const Trajectory back = ReadTum(dir / "t.txt");
  EXPECT_TRUE(back.has_stamps);
  ASSERT_EQ(back.size(), traj.size());
  // Stamps and positions are printed so that they read back to the same double: exact equality.
  for (size_t i = 0; i < traj.size(); ++i) {
    EXPECT_EQ(back.stamps_s[i], traj.stamps_s[i]);
    EXPECT_EQ(back.world_from_cam[i].t, traj.world_from_cam[i].t);
  }
  // Quaternions are renormalised on read, which may move the last bit: a few ulp of angle.
  ExpectSamePoses(traj, back, 0.0, 1e-15);
  EXPECT_EQ(ReadTrajectory(dir / "t.txt").size(), traj.size());  // auto-detected as TUM
}

TEST(TrajectoryIo, TumStampsWithFewDigitsStayShort) {
  TempDir dir;
  Trajectory traj = MakeTrajectory(3, 0.0);
  WriteTum(dir / "t.txt", traj);
  EXPECT_NE(ReadText(dir / "t.txt").find("\n0.050000000 "), std::string::npos) << ReadText(dir / "t.txt");
}

TEST(TrajectoryIo, KittiRoundTripWithoutTimes) {
  TempDir dir;
  const Trajectory traj = MakeTrajectory(30);
  WriteKitti(dir / "poses.txt", traj);
  const Trajectory back = ReadKitti(dir / "poses.txt");
  EXPECT_FALSE(back.has_stamps);
  ASSERT_EQ(back.size(), traj.size());
  for (size_t i = 0; i < back.size(); ++i) EXPECT_EQ(back.stamps_s[i], static_cast<double>(i));
  // Rotation goes quaternion -> matrix -> SVD -> quaternion: ~1e-16 per step, 1e-13 leaves ample room.
  ExpectSamePoses(traj, back, 0.0, 1e-13);
  EXPECT_EQ(DetectTrajectoryFormat(dir / "poses.txt"), TrajectoryFormat::kKitti);
}

TEST(TrajectoryIo, KittiRoundTripWithTimes) {
  TempDir dir;
  const Trajectory traj = MakeTrajectory(30, 0.0);
  WriteKitti(dir / "poses.txt", traj, dir / "times.txt");
  const Trajectory back = ReadTrajectory(dir / "poses.txt", TrajectoryFormat::kAuto, dir / "times.txt");
  EXPECT_TRUE(back.has_stamps);
  ASSERT_EQ(back.size(), traj.size());
  for (size_t i = 0; i < back.size(); ++i) EXPECT_EQ(back.stamps_s[i], traj.stamps_s[i]);
  ExpectSamePoses(traj, back, 0.0, 1e-13);  // as above: matrix and SVD round trip
}

TEST(TrajectoryIo, KittiRotationIsReorthonormalised) {
  TempDir dir;
  // A rotation about z by 0.3 rad, printed with 4 digits as some tools do: not quite orthonormal.
  WriteText(dir / "p.txt", "0.9553 -0.2955 0 1 0.2955 0.9553 0 2 0 0 1 3\n");
  const Trajectory t = ReadKitti(dir / "p.txt");
  ASSERT_EQ(t.size(), 1u);
  const Eigen::Matrix3d R = t.world_from_cam[0].R();
  // Orthonormal to rounding (~1e-16 per entry).
  EXPECT_LT((R.transpose() * R - Eigen::Matrix3d::Identity()).norm(), 1e-14);
  // The 4-digit input is off by up to 5e-5 from the true rotation.
  EXPECT_NEAR(std::atan2(R(1, 0), R(0, 0)), 0.3, 1e-4);
  EXPECT_EQ(t.world_from_cam[0].t, Eigen::Vector3d(1, 2, 3));
}

TEST(TrajectoryIo, EurocRoundTrip) {
  TempDir dir;
  const Trajectory traj = MakeTrajectory(40);
  WriteEuroc(dir / "data.csv", traj);
  const std::string text = ReadText(dir / "data.csv");
  EXPECT_EQ(text.substr(0, text.find('\n')),
            "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []");
  // Integer ns; the last two digits depend on the double nearest to the stamp (one ulp = 238 ns here).
  EXPECT_NE(text.find("\n14036365797585554"), std::string::npos) << "stamps in integer ns";
  const Trajectory back = ReadTrajectory(dir / "data.csv");  // auto: .csv -> EuRoC
  ASSERT_EQ(back.size(), traj.size());
  // The file holds whole ns and a double holds 1.4e9 s only to 2.4e-7 s (one ulp): 3e-7 s covers both.
  for (size_t i = 0; i < back.size(); ++i) EXPECT_NEAR(back.stamps_s[i], traj.stamps_s[i], 3e-7);
  ExpectSamePoses(traj, back, 0.0, 1e-15);  // positions exact; quaternions renormalised (a few ulp)
}

TEST(TrajectoryIo, EurocGroundTruthWith17ColumnsReadsThePose) {
  TempDir dir;
  WriteText(dir / "gt.csv",
            "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
            "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], "
            "b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]\n"
            "1403636580838555648,4.688319,-1.786938,0.783338,0.534108,-0.153029,-0.827383,-0.082152,-0.027876,"
            "0.033207,0.800006,-0.003172,0.021267,0.078502,-0.025266,0.136696,0.075593\n"
            "1403636580843555328,4.688177,-1.786770,0.787350,0.534640,-0.152990,-0.826976,-0.082863,-0.029272,"
            "0.033992,0.804740,-0.003172,0.021267,0.078502,-0.025266,0.136696,0.075593\n");
  const Trajectory t = ReadTrajectory(dir / "gt.csv");
  ASSERT_EQ(t.size(), 2u);
  // 1403636580.838555648 s as a double: one ulp at 1.4e9 is 2.4e-7 s.
  EXPECT_NEAR(t.stamps_s[0], 1403636580.838555648, 2.4e-7);
  EXPECT_NEAR(t.stamps_s[1] - t.stamps_s[0], 0.00499968, 5e-7);  // difference of two such doubles
  EXPECT_EQ(t.world_from_cam[0].t, Eigen::Vector3d(4.688319, -1.786938, 0.783338));
  const Eigen::Quaterniond q_expected = Eigen::Quaterniond(0.534108, -0.153029, -0.827383, -0.082152).normalized();
  EXPECT_LT(AngularDistanceRad(t.world_from_cam[0].q, q_expected), 1e-15);  // same normalisation, a few ulp
}

// Found by fuzz_trajectory (fuzz/corpus/trajectory/regress_euroc_ns_beyond_int64): a stamp of 1.4e19 ns (one
// digit too many) was read as a float and accepted, and the trajectory could then not be written back as EuRoC.
// It is refused naming the file, the line and the stamp.
TEST(TrajectoryIo, EurocStampBeyond64BitsIsRefused) {
  TempDir dir;
  WriteText(dir / "gt.csv", "#timestamp,x,y,z,qw,qx,qy,qz\n14036365797458555392,4.688,-1.786,0.783,1,0,0,0\n");
  ExpectThrowsWith([&] { ReadEuroc(dir / "gt.csv"); }, "gt.csv:2: timestamp 14036365797458555392 ns does not fit");
}

TEST(TrajectoryIo, EurocHeaderWithoutHashIsSkipped) {
  TempDir dir;
  WriteText(dir / "est.csv", "timestamp,x,y,z,qw,qx,qy,qz\n1500000000,1,2,3,1,0,0,0\n2500000000,4,5,6,1,0,0,0\n");
  const Trajectory t = ReadEuroc(dir / "est.csv");
  ASSERT_EQ(t.size(), 2u);
  EXPECT_EQ(t.stamps_s[1], 2.5);  // 2 + 5e8 * 1e-9, and that product rounds to exactly 0.5
  // Only the first data line may be a header: a later word is an error at its line.
  WriteText(dir / "bad.csv", "#h\n1500000000,1,2,3,1,0,0,0\nword,1,2,3,1,0,0,0\n");
  ExpectThrowsWith([&] { ReadEuroc(dir / "bad.csv"); }, dir / "bad.csv:3:", "'word'");
}

TEST(TrajectoryIo, QuaternionIsNormalisedOnRead) {
  TempDir dir;
  WriteText(dir / "t.txt", "# stamp x y z qx qy qz qw\n\n1.0 0 0 0 0 0 0 2\n2.0 0 0 0 0 0 3 3\n");
  const Trajectory t = ReadTum(dir / "t.txt");
  ASSERT_EQ(t.size(), 2u);
  EXPECT_DOUBLE_EQ(t.world_from_cam[0].q.w(), 1.0);  // 2/2: exact up to one rounding
  EXPECT_NEAR(t.world_from_cam[1].q.norm(), 1.0, 1e-15);  // one division by the norm: ~1 ulp
}

TEST(TrajectoryIo, DetectsFormats) {
  TempDir dir;
  WriteText(dir / "a.txt", "# c\n1 2 3 4 0 0 0 1\n");
  WriteText(dir / "b.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n");
  WriteText(dir / "c.data", "1000,1,2,3,1,0,0,0\n");
  WriteText(dir / "d.txt", "1 2 3 4 5\n");
  WriteText(dir / "empty.txt", "# nothing\n");
  EXPECT_EQ(DetectTrajectoryFormat(dir / "a.txt"), TrajectoryFormat::kTum);
  EXPECT_EQ(DetectTrajectoryFormat(dir / "b.txt"), TrajectoryFormat::kKitti);
  EXPECT_EQ(DetectTrajectoryFormat(dir / "c.data"), TrajectoryFormat::kEuroc);
  ExpectThrowsWith([&] { DetectTrajectoryFormat(dir / "d.txt"); }, dir / "d.txt:1:", "5 columns");
  ExpectThrowsWith([&] { DetectTrajectoryFormat(dir / "empty.txt"); }, dir / "empty.txt", "no data lines");
}

TEST(TrajectoryIo, ParsesFormatNames) {
  EXPECT_EQ(ParseTrajectoryFormat("TUM"), TrajectoryFormat::kTum);
  EXPECT_EQ(ParseTrajectoryFormat("kitti"), TrajectoryFormat::kKitti);
  EXPECT_EQ(ParseTrajectoryFormat("euroc"), TrajectoryFormat::kEuroc);
  EXPECT_EQ(ParseTrajectoryFormat("auto"), TrajectoryFormat::kAuto);
  EXPECT_THROW(ParseTrajectoryFormat("bogus"), std::invalid_argument);
  for (auto f : {TrajectoryFormat::kTum, TrajectoryFormat::kKitti, TrajectoryFormat::kEuroc, TrajectoryFormat::kAuto})
    EXPECT_EQ(ParseTrajectoryFormat(ToString(f)), f);
}

TEST(TrajectoryIo, MissingFileNamesIt) {
  TempDir dir;
  const std::string path = dir / "nope.txt";
  ExpectThrowsWith([&] { ReadTum(path); }, path, "cannot open");
  ExpectThrowsWith([&] { ReadTrajectory(path); }, path, "cannot open");
  ExpectThrowsWith([&] { ReadKitti(path); }, path);
  ExpectThrowsWith([&] { ReadEuroc(dir / "nope.csv"); }, dir / "nope.csv");
}

TEST(TrajectoryIo, MalformedLinesNameFileAndLine) {
  TempDir dir;
  const std::string p = dir / "t.txt";
  WriteText(p, "# header\n1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n");
  ExpectThrowsWith([&] { ReadTum(p); }, p + ":3:", "expected 8 columns");
  WriteText(p, "1 0 0 0 0 0 0 1\n2 0 zero 0 0 0 0 1\n");
  ExpectThrowsWith([&] { ReadTum(p); }, p + ":2:", "'zero' is not a number");
  WriteText(p, "1 0 0 0 0 0 0 1\n2 0 1.5x 0 0 0 0 1\n");  // trailing garbage in a number
  ExpectThrowsWith([&] { ReadTum(p); }, p + ":2:", "1.5x");
  WriteText(p, "1 0 0 0 0 0 0 1\n\n2 0 nan 0 0 0 0 1\n");
  ExpectThrowsWith([&] { ReadTum(p); }, p + ":3:", "not finite");
  WriteText(p, "1 0 0 inf 0 0 0 1\n");
  ExpectThrowsWith([&] { ReadTum(p); }, p + ":1:", "not finite");
  WriteText(p, "1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 0\n");
  ExpectThrowsWith([&] { ReadTum(p); }, p + ":2:", "zero length");

  const std::string k = dir / "k.txt";
  WriteText(k, "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n");
  ExpectThrowsWith([&] { ReadKitti(k); }, k + ":2:", "expected 12 columns");
  WriteText(k, "1 0 0 0 0 1 0 0 0 0 1 NaN\n");
  ExpectThrowsWith([&] { ReadKitti(k); }, k + ":1:", "not finite");

  const std::string e = dir / "e.csv";
  WriteText(e, "#timestamp,x,y,z,qw,qx,qy,qz\n1000,1,2,3,1,0,0\n");
  ExpectThrowsWith([&] { ReadEuroc(e); }, e + ":2:", "at least 8");
  WriteText(e, "#h\n1000,1,2,3,0,0,0,0\n");
  ExpectThrowsWith([&] { ReadEuroc(e); }, e + ":2:", "zero length");
  WriteText(e, "#h\n1000,1,,3,1,0,0,0\n");
  ExpectThrowsWith([&] { ReadEuroc(e); }, e + ":2:", "py");
}

TEST(TrajectoryIo, KittiTimesLengthMismatchIsAnError) {
  TempDir dir;
  WriteKitti(dir / "poses.txt", MakeTrajectory(5));
  WriteText(dir / "times.txt", "0\n0.1\n0.2\n0.3\n");
  ExpectThrowsWith([&] { ReadKitti(dir / "poses.txt", dir / "times.txt"); }, dir / "times.txt", "4 timestamps");
  WriteText(dir / "times.txt", "0\n0.1\n0.2 0.25\n0.3\n0.4\n");
  ExpectThrowsWith([&] { ReadKitti(dir / "poses.txt", dir / "times.txt"); }, dir / "times.txt:3:");
  ExpectThrowsWith([&] { ReadKitti(dir / "poses.txt", dir / "missing_times.txt"); }, dir / "missing_times.txt");
}

TEST(TrajectoryIo, TimesFileForNonKittiIsAnError) {
  TempDir dir;
  WriteTum(dir / "t.txt", MakeTrajectory(3));
  WriteText(dir / "times.txt", "0\n1\n2\n");
  ExpectThrowsWith([&] { ReadTrajectory(dir / "t.txt", TrajectoryFormat::kAuto, dir / "times.txt"); }, "not KITTI");
}

TEST(TrajectoryIo, WritersRefuseBadInput) {
  TempDir dir;
  Trajectory t = MakeTrajectory(3);
  t.world_from_cam[1].t.x() = std::nan("");
  EXPECT_THROW(WriteTum(dir / "t.txt", t), std::invalid_argument);
  t = MakeTrajectory(3);
  t.stamps_s.pop_back();
  EXPECT_THROW(WriteEuroc(dir / "t.csv", t), std::invalid_argument);
  ExpectThrowsWith([&] { WriteTum(dir / "no_such_dir/t.txt", MakeTrajectory(2)); }, dir / "no_such_dir/t.txt");
}

TEST(TrajectoryIo, WriteTrajectoryDispatchesOnFormat) {
  TempDir dir;
  const Trajectory traj = MakeTrajectory(4);
  WriteTrajectory(dir / "a.csv", traj, TrajectoryFormat::kAuto);
  EXPECT_EQ(DetectTrajectoryFormat(dir / "a.csv"), TrajectoryFormat::kEuroc);
  WriteTrajectory(dir / "a.txt", traj, TrajectoryFormat::kAuto);
  EXPECT_EQ(DetectTrajectoryFormat(dir / "a.txt"), TrajectoryFormat::kTum);
  WriteTrajectory(dir / "k.txt", traj, TrajectoryFormat::kKitti);
  EXPECT_EQ(DetectTrajectoryFormat(dir / "k.txt"), TrajectoryFormat::kKitti);
}

// The real sequences beside the source tree, when present: their files must read as they are.
TEST(TrajectoryIo, ReadsRealGroundTruthFiles) {
  const std::string data = mcslam::testing::DataDir();
  if (data.empty()) GTEST_SKIP() << "no data folder (set MCSLAM_DATA)";
  const std::string kitti = data + "/kitti_odometry_06_frames000-050";
  if (std::filesystem::exists(kitti + "/poses.txt")) {
    const Trajectory t = ReadTrajectory(kitti + "/poses.txt", TrajectoryFormat::kAuto, kitti + "/times.txt");
    EXPECT_EQ(t.size(), 51u);
    EXPECT_TRUE(t.has_stamps);
    EXPECT_GT(t.world_from_cam.back().t.z(), 50.0);  // a straight drive of about 60 m forward
  }
  const std::string tum = data + "/tum_rgbd_fr3_long_office_household_1hz/groundtruth.txt";
  if (std::filesystem::exists(tum)) {
    EXPECT_EQ(DetectTrajectoryFormat(tum), TrajectoryFormat::kTum);
    const Trajectory t = ReadTrajectory(tum);
    EXPECT_GT(t.size(), 8000u);
  }
}

}  // namespace
}  // namespace mcslam::io
