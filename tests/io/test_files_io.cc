#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <stdexcept>
#include <string>

#include "io/camera_io.h"
#include "io/image_source.h"
#include "io/observations_io.h"
#include "io/ply.h"
#include "../test_util.h"

namespace mcslam::io {
namespace {

using mcslam::testing::ExpectThrowsWith;

using mcslam::testing::ReadText;
using mcslam::testing::TempDir;
using mcslam::testing::WriteText;


// ---- PLY ---------------------------------------------------------------------------------------------

PointCloud MakeCloud(int n, bool ids, bool rgb) {
  PointCloud c;
  for (int i = 0; i < n; ++i) {
    c.points.emplace_back(0.1 * i + 1.0 / 3.0, -2.0 * std::sin(i), 1e-7 * i + 5.0);
    if (ids) c.ids.push_back(1000 + 7 * i);
    if (rgb) c.rgb.emplace_back(uint8_t(i % 256), uint8_t(255 - i % 256), uint8_t(17));
  }
  return c;
}

TEST(Ply, RoundTripPointsOnly) {
  TempDir dir;
  const PointCloud c = MakeCloud(25, false, false);
  WritePly(dir / "p.ply", c);
  const std::string text = ReadText(dir / "p.ply");
  EXPECT_EQ(text.rfind("ply\nformat ascii 1.0\ncomment mcslam\nelement vertex 25\nproperty double x\n", 0), 0u) << text;
  const PointCloud back = ReadPly(dir / "p.ply");
  EXPECT_TRUE(back.ids.empty());
  EXPECT_TRUE(back.rgb.empty());
  // %.17g reads back to the same double: exact.
  EXPECT_EQ(back.points, c.points);
}

TEST(Ply, RoundTripWithIdsAndColour) {
  TempDir dir;
  for (auto [ids, rgb] : {std::pair{true, false}, std::pair{false, true}, std::pair{true, true}}) {
    const PointCloud c = MakeCloud(12, ids, rgb);
    WritePly(dir / "p.ply", c);
    const PointCloud back = ReadPly(dir / "p.ply");
    EXPECT_EQ(back.points, c.points);  // exact, as above
    EXPECT_EQ(back.ids, c.ids);
    EXPECT_EQ(back.rgb, c.rgb);
  }
}

TEST(Ply, ReadsOtherToolsFilesByPropertyName) {
  TempDir dir;
  // Float coordinates after other properties, normals, a list property, and faces after the vertices.
  WriteText(dir / "m.ply",
            "ply\nformat ascii 1.0\ncomment from elsewhere\nobj_info x\nelement vertex 2\nproperty float nx\n"
            "property list uchar int idx\nproperty float z\nproperty float y\nproperty float x\nproperty uchar red\n"
            "property uchar green\nproperty uchar blue\nproperty int id\nelement face 1\n"
            "property list uchar int vertex_indices\nend_header\n"
            "0.5 2 7 8 3 2 1 10 20 30 5\n"
            "0.5 0 6 5 4 40 50 60 6\n"
            "3 0 1 1\n");
  const PointCloud c = ReadPly(dir / "m.ply");
  ASSERT_EQ(c.points.size(), 2u);
  EXPECT_EQ(c.points[0], Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(c.points[1], Eigen::Vector3d(4, 5, 6));
  ASSERT_EQ(c.ids.size(), 2u);
  EXPECT_EQ(c.ids[1], 6);
  ASSERT_EQ(c.rgb.size(), 2u);
  EXPECT_EQ(int(c.rgb[1][2]), 60);
}

TEST(Ply, ErrorsAreClear) {
  TempDir dir;
  const std::string p = dir / "bad.ply";
  ExpectThrowsWith([&] { ReadPly(dir / "missing.ply"); }, dir / "missing.ply", "cannot open");
  WriteText(p, "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n");
  ExpectThrowsWith([&] { ReadPly(p); }, p + ":2:", "binary PLY not supported");
  WriteText(p, "not a ply\n");
  ExpectThrowsWith([&] { ReadPly(p); }, p + ":1:", "not a PLY file");
  WriteText(p, "ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double z\nend_header\n1 2\n");
  ExpectThrowsWith([&] { ReadPly(p); }, p, "no 'y' property");
  WriteText(p, "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\n"
               "end_header\n1 2 3\n4 5 6\n");
  ExpectThrowsWith([&] { ReadPly(p); }, p, "file ends before all 3 vertices were read");
  WriteText(p, "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\n"
               "end_header\n1 2 3\n4 five 6\n");
  ExpectThrowsWith([&] { ReadPly(p); }, p + ":9:", "'five'");
  WriteText(p, "ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double y\nproperty double z\n"
               "end_header\n1 2 3 4\n");
  ExpectThrowsWith([&] { ReadPly(p); }, p + ":8:", "4 values");
  WriteText(p, "ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double y\nproperty double z\n");
  ExpectThrowsWith([&] { ReadPly(p); }, p, "end_header");
}

TEST(Ply, WriterRefusesInconsistentClouds) {
  TempDir dir;
  PointCloud c = MakeCloud(3, true, false);
  c.ids.pop_back();
  EXPECT_THROW(WritePly(dir / "p.ply", c), std::invalid_argument);
  c = MakeCloud(3, true, false);
  c.ids[0] = int64_t{1} << 40;  // beyond PLY's 32-bit int
  EXPECT_THROW(WritePly(dir / "p.ply", c), std::invalid_argument);
}

// ---- camera YAML -------------------------------------------------------------------------------------

PinholeCamera TumCamera() {
  return PinholeCamera(517.306408, 516.469215, 318.643040, 255.313989, 640, 480,
                       Distortion{0.262383, -0.953104, -0.005358, 0.002628, 1.163314});
}

void ExpectSameCamera(const PinholeCamera& a, const PinholeCamera& b) {
  // Written with shortest round-trip formatting: every value reads back exactly.
  EXPECT_EQ(a.fx, b.fx);
  EXPECT_EQ(a.fy, b.fy);
  EXPECT_EQ(a.cx, b.cx);
  EXPECT_EQ(a.cy, b.cy);
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  EXPECT_EQ(a.dist.k1, b.dist.k1);
  EXPECT_EQ(a.dist.k2, b.dist.k2);
  EXPECT_EQ(a.dist.p1, b.dist.p1);
  EXPECT_EQ(a.dist.p2, b.dist.p2);
  EXPECT_EQ(a.dist.k3, b.dist.k3);
  EXPECT_EQ(a.dist.k4, b.dist.k4);
  EXPECT_EQ(a.dist.model, b.dist.model);
}

TEST(CameraYaml, OrbSlam2RoundTrip) {
  TempDir dir;
  const PinholeCamera cam = TumCamera();
  WriteCameraYaml(dir / "cam.yaml", cam, 30.0);
  const std::string text = ReadText(dir / "cam.yaml");
  EXPECT_EQ(text.rfind("%YAML:1.0\n", 0), 0u);
  EXPECT_NE(text.find("\nCamera.fx: 517.306408\n"), std::string::npos) << text;
  EXPECT_NE(text.find("\nCamera.width: 640\n"), std::string::npos) << text;
  EXPECT_NE(text.find("\nCamera.fps: 30.0\n"), std::string::npos) << text;  // reals keep their '.0'
  ExpectSameCamera(ReadCameraYaml(dir / "cam.yaml"), cam);

  PinholeCamera plain(500, 500, 320, 240, 640, 480);
  WriteCameraYaml(dir / "plain.yaml", plain);
  EXPECT_NE(ReadText(dir / "plain.yaml").find("\nCamera.fx: 500.0\n"), std::string::npos);
  EXPECT_EQ(ReadText(dir / "plain.yaml").find("Camera.fps"), std::string::npos);
  ExpectSameCamera(ReadCameraYaml(dir / "plain.yaml"), plain);
}

TEST(CameraYaml, ReadsOrbSlam3PinHole) {
  TempDir dir;
  // As in ORB-SLAM3's Examples/Monocular/EuRoC.yaml (values of EuRoC cam0), with an OpenCV matrix node.
  WriteText(dir / "euroc.yaml", R"(%YAML:1.0

#--------------------------------------------------------------------------------------------
# Camera Parameters. Adjust them!
#--------------------------------------------------------------------------------------------
File.version: "1.0"

Camera.type: "PinHole"

# Camera calibration and distortion parameters (OpenCV)
Camera1.fx: 458.654
Camera1.fy: 457.296
Camera1.cx: 367.215
Camera1.cy: 248.375

Camera1.k1: -0.28340811
Camera1.k2: 0.07395907
Camera1.p1: 0.00019359
Camera1.p2: 1.76187114e-05

# Camera resolution
Camera.width: 752
Camera.height: 480

Camera.newWidth: 600
Camera.newHeight: 350

# Camera frames per second
Camera.fps: 20

# Color order of the images (0: BGR, 1: RGB. It is ignored if images are grayscale)
Camera.RGB: 1

Tbc: !!opencv-matrix
   rows: 4
   cols: 4
   dt: f
   data: [1.0, 0.0, 0.0, 0.0,
          0.0, 1.0, 0.0, 0.0,
          0.0, 0.0, 1.0, 0.0,
          0.0, 0.0, 0.0, 1.0]

ORBextractor.nFeatures: 1000
ORBextractor.scaleFactor: 1.2
)");
  const PinholeCamera cam = ReadCameraYaml(dir / "euroc.yaml");
  const PinholeCamera expected(458.654, 457.296, 367.215, 248.375, 752, 480,
                               Distortion{-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05, 0.0});
  ExpectSameCamera(cam, expected);
}

// A fisheye in ORB-SLAM3's form (TUM-VI's calibration: Camera.type KannalaBrandt8, k1-k4 of the equidistant model)
// and in mcslam's (`model: equidistant`); written back in ORB-SLAM's form, it reads back the same.
TEST(CameraYaml, ReadsAndWritesTheKannalaBrandtFisheye) {
  TempDir dir;
  WriteText(dir / "fisheye.yaml",
            "%YAML:1.0\nCamera.type: \"KannalaBrandt8\"\nCamera1.fx: 190.97\nCamera1.fy: 190.97\nCamera1.cx: 254.93\n"
            "Camera1.cy: 256.89\nCamera1.k1: 0.0034\nCamera1.k2: 0.0007\nCamera1.k3: -0.002\nCamera1.k4: 0.0002\n"
            "Camera.width: 512\nCamera.height: 512\n");
  const PinholeCamera expected(190.97, 190.97, 254.93, 256.89, 512, 512,
                               Distortion::Equidistant(0.0034, 0.0007, -0.002, 0.0002));
  const PinholeCamera cam = ReadCameraYaml(dir / "fisheye.yaml");
  ExpectSameCamera(cam, expected);
  WriteCameraYaml(dir / "back.yaml", cam, 20.0);
  ExpectSameCamera(ReadCameraYaml(dir / "back.yaml"), expected);
  WriteText(dir / "mcslam.yaml", "model: equidistant\nfx: 190.97\nfy: 190.97\ncx: 254.93\ncy: 256.89\nwidth: 512\n"
                                 "height: 512\nk1: 0.0034\nk2: 0.0007\nk3: -0.002\nk4: 0.0002\n");
  ExpectSameCamera(ReadCameraYaml(dir / "mcslam.yaml"), expected);
  // Another model is refused, naming it.
  WriteText(dir / "other.yaml", "%YAML:1.0\nCamera.type: \"MEI\"\nCamera.fx: 190\nCamera.fy: 190\nCamera.cx: 250\n"
                                "Camera.cy: 250\nCamera.width: 512\nCamera.height: 512\n");
  ExpectThrowsWith([&] { ReadCameraYaml(dir / "other.yaml"); }, dir / "other.yaml", "MEI");
}

TEST(CameraYaml, ReadsPlainMcslamYaml) {
  TempDir dir;
  WriteText(dir / "cam.yaml", "# mcslam camera\nfx: 525\nfy: 525.5\ncx: 319.5\ncy: 239.5\nwidth: 640\nheight: 480\n");
  ExpectSameCamera(ReadCameraYaml(dir / "cam.yaml"), PinholeCamera(525, 525.5, 319.5, 239.5, 640, 480));
  WriteText(dir / "cam2.yaml", "fx: 525\nfy: 525\ncx: 320\ncy: 240\nwidth: 640.0\nheight: 480\nk1: 0.1\nk3: -0.01\n");
  ExpectSameCamera(ReadCameraYaml(dir / "cam2.yaml"),
                   PinholeCamera(525, 525, 320, 240, 640, 480, Distortion{0.1, 0, 0, 0, -0.01}));
}

TEST(CameraYaml, ErrorsNameFileAndKey) {
  TempDir dir;
  const std::string p = dir / "cam.yaml";
  ExpectThrowsWith([&] { ReadCameraYaml(dir / "missing.yaml"); }, dir / "missing.yaml", "cannot open");
  // ORB-SLAM2 files often have no image size.
  WriteText(p, "%YAML:1.0\nCamera.fx: 500.0\nCamera.fy: 500.0\nCamera.cx: 320.0\nCamera.cy: 240.0\n");
  ExpectThrowsWith([&] { ReadCameraYaml(p); }, p, "Camera.width");
  WriteText(p, "%YAML:1.0\nCamera.fx: 500.0\nCamera.cx: 320.0\nCamera.cy: 240.0\nCamera.width: 640\n"
               "Camera.height: 480\n");
  ExpectThrowsWith([&] { ReadCameraYaml(p); }, p, "missing key 'Camera.fy'");
  WriteText(p, "fx: 500\nfy: abc\ncx: 320\ncy: 240\nwidth: 640\nheight: 480\n");
  ExpectThrowsWith([&] { ReadCameraYaml(p); }, p + ":2:", "key 'fy' is not a number");
  WriteText(p, "fx: 500\nfy: 500\ncx: 320\ncy: 240\nwidth: 640.5\nheight: 480\n");
  ExpectThrowsWith([&] { ReadCameraYaml(p); }, p + ":5:", "width");
  WriteText(p, "fx: -500\nfy: 500\ncx: 320\ncy: 240\nwidth: 640\nheight: 480\n");
  ExpectThrowsWith([&] { ReadCameraYaml(p); }, p, "fx must be positive");
  WriteText(p, "focal: 500\n");
  ExpectThrowsWith([&] { ReadCameraYaml(p); }, p, "no camera intrinsics");
  WriteText(p, "fx: [500\n");
  ExpectThrowsWith([&] { ReadCameraYaml(p); }, p, "YAML syntax error");
}

// ---- observations ------------------------------------------------------------------------------------

std::vector<ObservationFrame> MakeObservations() {
  std::vector<ObservationFrame> frames;
  for (int f = 0; f < 6; ++f) {
    ObservationFrame frame;
    frame.index = f == 5 ? 9 : f;  // a gap: frames 5..8 absent
    frame.stamp_s = 1341847980.722988 + f / 30.0;
    if (f != 3)  // frame 3: declared, no observations
      for (int k = 0; k < 4; ++k) frame.observations.push_back({100 + 3 * k + f, 10.0 * k + f / 7.0, 200.5 - k * 1e-3});
    frames.push_back(frame);
  }
  return frames;
}

TEST(Observations, RoundTripIsExact) {
  TempDir dir;
  const auto frames = MakeObservations();
  WriteObservations(dir / "obs.txt", frames);
  const auto back = ReadObservations(dir / "obs.txt");
  ASSERT_EQ(back.size(), frames.size());
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(back[i].index, frames[i].index);
    EXPECT_EQ(back[i].stamp_s, frames[i].stamp_s);  // exact: stamps printed to read back exactly
    ASSERT_EQ(back[i].observations.size(), frames[i].observations.size());
    for (size_t k = 0; k < frames[i].observations.size(); ++k) {
      EXPECT_EQ(back[i].observations[k].feature_id, frames[i].observations[k].feature_id);
      EXPECT_EQ(back[i].observations[k].u_px, frames[i].observations[k].u_px);  // exact: %.17g
      EXPECT_EQ(back[i].observations[k].v_px, frames[i].observations[k].v_px);
    }
  }
}

TEST(Observations, ReadsHandWrittenFile) {
  TempDir dir;
  WriteText(dir / "o.txt", "# frame stamp id u v\n0 0.0 1 10 20\n0 0.0 2 11 21\n\n1 0.5\n2 1.0 1 12.5 22.5\n");
  const auto f = ReadObservations(dir / "o.txt");
  ASSERT_EQ(f.size(), 3u);
  EXPECT_EQ(f[0].observations.size(), 2u);
  EXPECT_TRUE(f[1].observations.empty());
  EXPECT_EQ(f[1].stamp_s, 0.5);
  EXPECT_EQ(f[2].observations[0].u_px, 12.5);
}

TEST(Observations, ErrorsNameFileAndLine) {
  TempDir dir;
  const std::string p = dir / "o.txt";
  ExpectThrowsWith([&] { ReadObservations(dir / "missing.txt"); }, dir / "missing.txt", "cannot open");
  WriteText(p, "0 0.0 1 10 20\n0 0.0 2 11\n");
  ExpectThrowsWith([&] { ReadObservations(p); }, p + ":2:", "found 4");
  WriteText(p, "0 0.0 1 10 20\n1 0.1 1 10 20\n0 0.2 1 10 20\n");
  ExpectThrowsWith([&] { ReadObservations(p); }, p + ":3:", "must not decrease");
  WriteText(p, "0 0.0 1 10 20\n0 0.1 2 10 20\n");
  ExpectThrowsWith([&] { ReadObservations(p); }, p + ":2:", "timestamp");
  WriteText(p, "# c\n0 0.0 1 10 20\n0 0.0 1 11 21\n");
  ExpectThrowsWith([&] { ReadObservations(p); }, p + ":3:", "observed twice");
  WriteText(p, "0 0.0 1 nan 20\n");
  ExpectThrowsWith([&] { ReadObservations(p); }, p + ":1:", "not finite");
  WriteText(p, "0 0.0 1.5 10 20\n");
  ExpectThrowsWith([&] { ReadObservations(p); }, p + ":1:", "not an integer");
  WriteText(p, "-1 0.0 1 10 20\n");
  ExpectThrowsWith([&] { ReadObservations(p); }, p + ":1:", "negative");
  // A timestamp going backwards (issue #20: it was accepted and written to the trajectory).
  WriteText(p, "0 0.5 1 10 20\n1 0.2 1 10 20\n");
  ExpectThrowsWith([&] { ReadObservations(p); }, p + ":2:", "goes back in time");
  WriteText(p, "0 0.5 1 10 20\n1 0.5 1 10 20\n");  // equal stamps: allowed (some logs round them)
  EXPECT_EQ(ReadObservations(p).size(), 2u);
  // The same in a times file (KITTI's times.txt, --timestamps).
  WriteText(p, "0.0\n0.1\n0.05\n");
  ExpectThrowsWith([&] { ReadTimestampsFile(p); }, p + ":3:", "goes back in time");
}

TEST(Observations, WriterRefusesWhatTheReaderWould) {
  TempDir dir;
  auto frames = MakeObservations();
  std::swap(frames[1], frames[2]);
  EXPECT_THROW(WriteObservations(dir / "o.txt", frames), std::invalid_argument);
  frames = MakeObservations();
  frames[0].observations[1].feature_id = frames[0].observations[0].feature_id;
  EXPECT_THROW(WriteObservations(dir / "o.txt", frames), std::invalid_argument);
  frames = MakeObservations();
  frames[1].stamp_s = frames[0].stamp_s - 1.0;
  EXPECT_THROW(WriteObservations(dir / "o.txt", frames), std::invalid_argument);
}

// The writer a run appends to frame by frame (mcslam run --save-tracks): what it appended reads back as the batch
// writer's file would, a frame it refuses leaves what came before it readable, and a refused batch write leaves
// the file it would have replaced as it was.
TEST(Observations, FrameByFrameWriterMatchesTheBatchWriterAndKeepsWhatCameBefore) {
  TempDir dir;
  const auto frames = MakeObservations();
  WriteObservations(dir / "batch.txt", frames);
  {
    ObservationWriter w(dir / "appended.txt");
    for (const auto& f : frames) w.Append(f);
    ObservationFrame back = frames.front();  // an index that goes back
    ExpectThrowsWith([&] { w.Append(back); }, dir / "appended.txt", "increasing");
    w.Close();
  }
  EXPECT_EQ(ReadText(dir / "appended.txt"), ReadText(dir / "batch.txt"));
  auto bad = frames;
  bad[1].observations[0].u_px = std::nan("");
  EXPECT_THROW(WriteObservations(dir / "batch.txt", bad), std::invalid_argument);
  EXPECT_EQ(ReadObservations(dir / "batch.txt").size(), frames.size());
}

}  // namespace
}  // namespace mcslam::io
