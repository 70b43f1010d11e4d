#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "../test_util.h"
#include "io/camera_io.h"
#include "io/datasets.h"
#include "io/image_source.h"
#include "io/trajectory_io.h"

namespace mcslam::io {
namespace {

using mcslam::testing::ExpectThrowsWith;

namespace fs = std::filesystem;
using mcslam::testing::TempDir;
using mcslam::testing::WriteText;


std::string DataSequence(const std::string& name) {
  const std::string data = mcslam::testing::DataDir();
  if (data.empty()) return "";
  const fs::path dir = fs::path(data) / name;
  return fs::is_directory(dir) ? dir.string() : "";
}

// A small gray image whose pixels say which frame it is.
void WriteImage(const std::string& path, cv::Size size, int value) {
  cv::Mat img(size, CV_8U, cv::Scalar(value));
  ASSERT_TRUE(cv::imwrite(path, img)) << path;
}

int CountFrames(ImageSource& src, int* unreadable = nullptr) {
  Frame f;
  int n = 0, bad = 0;
  while (src.Next(&f)) {
    ++n;
    if (!f.ok()) ++bad;
  }
  if (unreadable) *unreadable = bad;
  return n;
}

// ---- kinds, options ---------------------------------------------------------------------------------------

TEST(DatasetKind, ParsesAndPrints) {
  for (DatasetKind k :
       {DatasetKind::kAuto, DatasetKind::kImageFolder, DatasetKind::kVideo, DatasetKind::kWebcam, DatasetKind::kKitti,
        DatasetKind::kTum, DatasetKind::kEuroc, DatasetKind::kSevenScenes, DatasetKind::kSynthetic})
    EXPECT_EQ(ParseDatasetKind(ToString(k)), k);
  ExpectThrowsWith([] { ParseDatasetKind("kitty"); }, "kitty", "expected");
}

TEST(DatasetOptions, CheckNamesTheBadField) {
  DatasetOptions o;
  o.fps = -1;
  ExpectThrowsWith([&] { o.Check(); }, "fps");
  o = {};
  o.gt_max_dt_s = 0;
  ExpectThrowsWith([&] { o.Check(); }, "gt_max_dt_s");
  o = {};
  o.camera = PinholeCamera(-5, 5, 1, 1, 10, 10);
  ExpectThrowsWith([&] { o.Check(); }, "DatasetOptions.camera");
}

// ---- bad input --------------------------------------------------------------------------------------------

TEST(Datasets, MissingOrEmptyFolderIsAClearError) {
  TempDir dir;
  const std::string missing = dir / "no_such_folder";
  ExpectThrowsWith([&] { OpenDataset(missing); }, missing, "does not exist");
  ExpectThrowsWith([&] { OpenImageFolder(missing); }, missing, "does not exist");
  const std::string empty = dir / "empty";
  fs::create_directories(empty);
  ExpectThrowsWith([&] { OpenDataset(empty); }, empty, "cannot tell");
  ExpectThrowsWith([&] { OpenImageFolder(empty); }, empty, "no images");
  DatasetOptions o;
  o.kind = DatasetKind::kKitti;
  ExpectThrowsWith([&] { OpenDataset(empty, o); }, empty, "image_0");
  o.kind = DatasetKind::kTum;
  ExpectThrowsWith([&] { OpenDataset(empty, o); }, "rgb.txt");
}

TEST(Datasets, CorruptImageIsReportedNotFatal) {
  TempDir dir;
  const cv::Size size(32, 24);
  WriteImage(dir / "000.png", size, 10);
  WriteText(dir / "001.png", "this is not a png \x01\x02\x03 garbage");
  WriteImage(dir / "002.png", size, 30);
  WriteImage(dir / "003.png", cv::Size(16, 16), 40);  // readable, but the wrong size for this sequence
  auto src = OpenImageFolder(dir.path().string());
  ASSERT_EQ(src->FrameCount(), 4);
  ASSERT_TRUE(src->ImageSize().has_value());
  EXPECT_EQ(*src->ImageSize(), size);
  Frame f;
  ASSERT_TRUE(src->Next(&f));
  EXPECT_TRUE(f.ok());
  EXPECT_EQ(f.image.at<uchar>(0, 0), 10);
  ASSERT_TRUE(src->Next(&f));
  EXPECT_FALSE(f.ok());
  EXPECT_EQ(f.index, 1);
  EXPECT_NE(f.error.find("001.png"), std::string::npos) << f.error;
  ASSERT_TRUE(src->Next(&f));
  EXPECT_TRUE(f.ok());
  EXPECT_EQ(f.index, 2);
  ASSERT_TRUE(src->Next(&f));
  EXPECT_FALSE(f.ok());
  EXPECT_NE(f.error.find("16x16"), std::string::npos) << f.error;
  EXPECT_FALSE(src->Next(&f));

  // A corrupt first frame does not hide the sequence's size.
  TempDir dir2;
  WriteText(dir2 / "a0.png", "garbage");
  WriteImage(dir2 / "a1.png", size, 1);
  auto src2 = OpenImageFolder(dir2.path().string());
  ASSERT_TRUE(src2->ImageSize().has_value());
  EXPECT_EQ(*src2->ImageSize(), size);
  int bad = 0;
  EXPECT_EQ(CountFrames(*src2, &bad), 2);
  EXPECT_EQ(bad, 1);
}

// Reading ahead hands out what the source does, frame by frame: the same images, indices, stamps, names and
// errors, in order, and then the end, once and for good; how long each frame took to read is said. A source that
// throws throws out of the reader's Next for that frame, and nothing more is read from it.
TEST(Datasets, ReadingAheadHandsOutWhatTheSourceDoes) {
  TempDir dir;
  const cv::Size size(32, 24);
  for (int i = 0; i < 6; ++i) WriteImage(dir / fmt::format("{:03d}.png", i), size, 10 * i + 5);
  WriteText(dir / "003.png", "this is not a png");
  auto plain = OpenImageFolder(dir.path().string());
  auto ahead = OpenImageFolder(dir.path().string());
  PrefetchingSource reader(ahead.get());
  Frame a, b;
  int frames = 0;
  while (plain->Next(&a)) {
    double read_ms = -1;
    ASSERT_TRUE(reader.Next(&b, &read_ms)) << "frame " << a.index;
    EXPECT_EQ(b.index, a.index);
    EXPECT_EQ(b.stamp_s, a.stamp_s);
    EXPECT_EQ(b.name, a.name);
    EXPECT_EQ(b.error, a.error);
    ASSERT_EQ(b.ok(), a.ok()) << "frame " << a.index;
    if (a.ok()) {
      EXPECT_EQ(cv::norm(a.image, b.image, cv::NORM_INF), 0.0) << "frame " << a.index;
    }
    EXPECT_GT(read_ms, 0.0);
    ++frames;
  }
  EXPECT_EQ(frames, 6);
  EXPECT_FALSE(reader.Next(&b));
  EXPECT_FALSE(reader.Next(&b));

  // A source that throws at its third frame.
  struct Throwing : ImageSource {
    int next = 0;
    bool Next(Frame* f) override {
      if (next == 2) throw std::runtime_error("the disk went away at frame 2");
      f->index = next++;
      f->image = cv::Mat(2, 2, CV_8U, cv::Scalar(1));
      return true;
    }
    std::optional<cv::Size> ImageSize() override { return cv::Size(2, 2); }
    std::optional<int64_t> FrameCount() const override { return std::nullopt; }
    std::string Description() const override { return "throwing"; }
  } throwing;
  PrefetchingSource from_throwing(&throwing);
  ASSERT_TRUE(from_throwing.Next(&b));
  EXPECT_EQ(b.index, 0);
  ASSERT_TRUE(from_throwing.Next(&b));
  EXPECT_EQ(b.index, 1);
  ExpectThrowsWith([&] { from_throwing.Next(&b); }, "disk went away", "frame 2");
  EXPECT_FALSE(from_throwing.Next(&b));
  EXPECT_EQ(throwing.next, 2);  // nothing read after the throw
}

TEST(Datasets, VideoThatCannotBeOpenedIsAClearError) {
  TempDir dir;
  const std::string missing = dir / "missing.mp4";
  ExpectThrowsWith([&] { VideoSource::OpenFile(missing); }, missing, "does not exist");
  const std::string garbage = dir / "garbage.avi";
  WriteText(garbage, std::string(4096, 'x'));
  ExpectThrowsWith([&] { VideoSource::OpenFile(garbage); }, garbage, "cannot open");
  ExpectThrowsWith([&] { OpenDataset(garbage); }, garbage);
}

TEST(Datasets, WebcamThatCannotBeOpenedIsAClearError) {
  // Index 63: no machine running the tests has that many cameras.
  ExpectThrowsWith([] { OpenDataset("webcam:63"); }, "webcam 63", "cannot open");
  ExpectThrowsWith([] { VideoSource::OpenCamera(-1); }, "-1");
  DatasetOptions o;
  o.kind = DatasetKind::kWebcam;
  ExpectThrowsWith([&] { OpenDataset("not-a-number", o); }, "not-a-number", "webcam");
}

TEST(Datasets, VideoFileRoundTrip) {
  TempDir dir;
  const std::string path = dir / "clip.avi";
  const cv::Size size(64, 48);
  {
    cv::VideoWriter w(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 25.0, size, true);
    if (!w.isOpened()) GTEST_SKIP() << "this OpenCV cannot write MJPG AVI; skipping the video round trip";
    for (int k = 0; k < 5; ++k) w.write(cv::Mat(size, CV_8UC3, cv::Scalar(40 * k, 20, 200 - 30 * k)));
  }
  Dataset ds = OpenDataset(path);
  EXPECT_EQ(ds.kind, DatasetKind::kVideo);
  ASSERT_TRUE(ds.image_size.has_value());
  EXPECT_EQ(*ds.image_size, size);
  EXPECT_EQ(ds.source->FrameCount(), 5);
  Frame f;
  int n = 0;
  while (ds.source->Next(&f)) {
    ASSERT_TRUE(f.ok());
    EXPECT_EQ(f.index, n);
    EXPECT_NEAR(f.stamp_s, n / 25.0, 1e-9);
    ++n;
  }
  EXPECT_EQ(n, 5);
}

// ---- image folders ------------------------------------------------------------------------------------------

TEST(Datasets, ImageFolderSortsNaturallyAndStamps) {
  TempDir dir;
  const cv::Size size(20, 10);
  WriteImage(dir / "img10.png", size, 10);
  WriteImage(dir / "img2.jpg", size, 2);
  WriteImage(dir / "img1.pgm", size, 1);
  WriteText(dir / "notes.txt", "not an image");
  const auto files = ListImageFiles(dir.path().string());
  ASSERT_EQ(files.size(), 3u);
  EXPECT_EQ(fs::path(files[0]).filename(), "img1.pgm");
  EXPECT_EQ(fs::path(files[1]).filename(), "img2.jpg");
  EXPECT_EQ(fs::path(files[2]).filename(), "img10.png");

  DatasetOptions o;
  o.fps = 20;
  Dataset ds = OpenDataset(dir.path().string(), o);
  EXPECT_EQ(ds.kind, DatasetKind::kImageFolder);
  EXPECT_FALSE(ds.camera.has_value());
  EXPECT_FALSE(ds.ground_truth.has_value());
  Frame f;
  ASSERT_TRUE(ds.source->Next(&f));
  ASSERT_TRUE(ds.source->Next(&f));
  EXPECT_EQ(f.index, 1);
  EXPECT_DOUBLE_EQ(f.stamp_s, 1 / 20.0);

  // A timestamps file in the folder is used; one of the wrong length is an error naming it.
  WriteText(dir / "times.txt", "# stamps\n100.5\n100.75\n101.0\n");
  Dataset ds2 = OpenDataset(dir.path().string());
  ASSERT_TRUE(ds2.source->Next(&f));
  ASSERT_TRUE(ds2.source->Next(&f));
  EXPECT_DOUBLE_EQ(f.stamp_s, 100.75);
  WriteText(dir / "times.txt", "1\n2\n");
  ExpectThrowsWith([&] { OpenDataset(dir.path().string()); }, "times.txt", "2 timestamps");

  // A camera file in the folder, whose size must match the images.
  fs::remove(dir.path() / "times.txt");
  WriteCameraYaml(dir / "camera.yaml", PinholeCamera(30, 30, 10, 5, 20, 10));
  Dataset ds3 = OpenDataset(dir.path().string());
  ASSERT_TRUE(ds3.camera.has_value());
  EXPECT_EQ(ds3.camera->fx, 30);
  WriteCameraYaml(dir / "camera.yaml", PinholeCamera(30, 30, 10, 5, 40, 20));
  ExpectThrowsWith([&] { OpenDataset(dir.path().string()); }, "40x20", "20x10");
}

// ---- KITTI ----------------------------------------------------------------------------------------------

TEST(Datasets, KittiRealSequence) {
  const std::string dir = DataSequence("kitti_odometry_06_frames000-050");
  if (dir.empty()) GTEST_SKIP() << "KITTI 06 excerpt not found (set MCSLAM_DATA); skipping";
  EXPECT_EQ(DetectDatasetKind(dir), DatasetKind::kKitti);
  Dataset ds = OpenDataset(dir);
  EXPECT_EQ(ds.kind, DatasetKind::kKitti);
  EXPECT_EQ(ds.source->FrameCount(), 51);
  ASSERT_TRUE(ds.image_size.has_value());
  EXPECT_EQ(*ds.image_size, cv::Size(1226, 370));
  ASSERT_TRUE(ds.camera.has_value());
  // calib.txt without the "P0:" prefix: the first line is P0.
  EXPECT_DOUBLE_EQ(ds.camera->fx, 707.0912);
  EXPECT_DOUBLE_EQ(ds.camera->fy, 707.0912);
  EXPECT_DOUBLE_EQ(ds.camera->cx, 601.8873);
  EXPECT_DOUBLE_EQ(ds.camera->cy, 183.1104);
  EXPECT_EQ(ds.camera->width, 1226);
  EXPECT_EQ(ds.camera->height, 370);
  EXPECT_FALSE(ds.camera->HasDistortion());
  ASSERT_TRUE(ds.ground_truth.has_value());
  ASSERT_EQ(ds.ground_truth->size(), 51u);
  ASSERT_EQ(ds.ground_truth_frames.size(), 51u);
  EXPECT_EQ(ds.ground_truth_frames[50], 50);
  EXPECT_DOUBLE_EQ(ds.ground_truth->stamps_s[1], 0.1044989);     // times.txt line 2
  EXPECT_LT(ds.ground_truth->world_from_cam[0].t.norm(), 1e-6);  // the world is camera 0 at frame 0
  // Near the end the car is ~60 m ahead along z (SOURCE.md: end position (-0.98, -1.19, 59.84) m).
  EXPECT_NEAR(ds.ground_truth->world_from_cam[50].t.z(), 59.84, 0.01);
  Frame f;
  ASSERT_TRUE(ds.source->Next(&f));
  ASSERT_TRUE(f.ok()) << f.error;
  EXPECT_EQ(f.image.channels(), 1);
  EXPECT_DOUBLE_EQ(f.stamp_s, 0.0);
  ASSERT_TRUE(ds.source->Next(&f));
  EXPECT_DOUBLE_EQ(f.stamp_s, ds.ground_truth->stamps_s[1]);

  // A camera of another size fails before any frame is processed.
  DatasetOptions o;
  o.camera = PinholeCamera(500, 500, 320, 240, 640, 480);
  ExpectThrowsWith([&] { OpenDataset(dir, o); }, "640x480", "1226x370");
  // Same aspect ratio: the message names the scale.
  o.camera = PinholeCamera(353.5456, 353.5456, 300.94, 91.55, 613, 185);
  ExpectThrowsWith([&] { OpenDataset(dir, o); }, "613x185", "scaled by 2");
}

TEST(Datasets, KittiLayoutWithPrefixedCalibAndNoTimes) {
  TempDir dir;
  fs::create_directories(dir.path() / "image_0");
  for (int i = 0; i < 3; ++i) WriteImage(dir / fmt::format("image_0/{:06d}.png", i), cv::Size(40, 30), i);
  WriteText(dir / "calib.txt",
            "P0: 50.5 0 20.25 0 0 51.5 15.75 0 0 0 1 0\n"
            "P1: 50.5 0 20.25 -30 0 51.5 15.75 0 0 0 1 0\n"
            "Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n");
  WriteText(dir / "poses.txt",
            "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 1\n1 0 0 0 0 1 0 0 0 0 1 2\n1 0 0 0 0 1 0 0 0 0 1 3\n");
  Dataset ds = OpenDataset(dir.path().string());
  EXPECT_EQ(ds.kind, DatasetKind::kKitti);
  ASSERT_TRUE(ds.camera.has_value());
  EXPECT_EQ(ds.camera->fx, 50.5);
  EXPECT_EQ(ds.camera->fy, 51.5);
  EXPECT_EQ(ds.camera->cx, 20.25);
  EXPECT_EQ(ds.camera->cy, 15.75);
  EXPECT_EQ(ds.camera->width, 40);
  // No times.txt: 10 Hz; 4 poses for 3 images: the first 3, with a note.
  ASSERT_TRUE(ds.ground_truth.has_value());
  ASSERT_EQ(ds.ground_truth->size(), 3u);
  EXPECT_DOUBLE_EQ(ds.ground_truth->stamps_s[2], 0.2);
  EXPECT_DOUBLE_EQ(ds.ground_truth->world_from_cam[2].t.z(), 2.0);
  EXPECT_GE(ds.notes.size(), 2u);
  // Fewer poses than images is an error naming the file.
  WriteText(dir / "poses.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n");
  ExpectThrowsWith([&] { OpenDataset(dir.path().string()); }, "poses.txt", "1 poses for 3 images");
  // A malformed calib line names the file and line.
  WriteText(dir / "calib.txt", "P0: 50.5 0 20.25\n");
  ExpectThrowsWith([&] { OpenDataset(dir.path().string()); }, "calib.txt:1", "12 numbers");
}

// ---- TUM --------------------------------------------------------------------------------------------------

TEST(Datasets, TumRealSequence) {
  const std::string dir = DataSequence("tum_rgbd_fr3_long_office_household_1hz");
  if (dir.empty()) GTEST_SKIP() << "TUM fr3 excerpt not found (set MCSLAM_DATA); skipping";
  Dataset ds = OpenDataset(dir);
  EXPECT_EQ(ds.kind, DatasetKind::kTum);
  EXPECT_EQ(ds.source->FrameCount(), 17);
  ASSERT_TRUE(ds.camera.has_value());
  EXPECT_EQ(ds.camera->fx, 535.4);
  EXPECT_EQ(ds.camera->fy, 539.2);
  EXPECT_EQ(ds.camera->cx, 320.1);
  EXPECT_EQ(ds.camera->cy, 247.6);
  EXPECT_EQ(ds.camera->width, 640);
  EXPECT_EQ(ds.camera->height, 480);
  EXPECT_FALSE(ds.camera->HasDistortion());
  // Frame 0 is 67 ms before the first motion-capture sample: 16 of 17 frames have ground truth.
  ASSERT_TRUE(ds.ground_truth.has_value());
  ASSERT_EQ(ds.ground_truth->size(), 16u);
  EXPECT_EQ(ds.ground_truth_frames.front(), 1);
  EXPECT_EQ(ds.ground_truth_frames.back(), 16);
  // The same interpolation as groundtruth_at_frames.txt (made independently when the data was prepared).
  const Trajectory ref = ReadTum((fs::path(dir) / "groundtruth_at_frames.txt").string());
  ASSERT_EQ(ref.size(), 16u);
  for (size_t i = 0; i < ref.size(); ++i) {
    EXPECT_NEAR(ds.ground_truth->stamps_s[i], ref.stamps_s[i], 1e-6);
    // The reference file is written to 4-6 decimals.
    EXPECT_LT((ds.ground_truth->world_from_cam[i].t - ref.world_from_cam[i].t).norm(), 2e-4) << i;
    EXPECT_LT(AngularDistanceDeg(ds.ground_truth->world_from_cam[i].q, ref.world_from_cam[i].q), 0.02) << i;
  }
  Frame f;
  ASSERT_TRUE(ds.source->Next(&f));
  ASSERT_TRUE(f.ok()) << f.error;
  EXPECT_EQ(f.image.channels(), 3);
  EXPECT_DOUBLE_EQ(f.stamp_s, 1341847980.722988);
}

TEST(Datasets, TumDefaultCameraFromTheFolderName) {
  TempDir root;
  const fs::path dir = root.path() / "rgbd_dataset_freiburg1_xyz";
  fs::create_directories(dir / "rgb");
  WriteImage((dir / "rgb/1.000000.png").string(), cv::Size(640, 480), 1);
  WriteImage((dir / "rgb/1.033000.png").string(), cv::Size(640, 480), 2);
  WriteText((dir / "rgb.txt").string(), "# color images\n1.000000 rgb/1.000000.png\n1.033000 rgb/1.033000.png\n");
  // Ground truth at 100 Hz around the frames, moving along x at 1 m/s.
  std::string gt = "# timestamp tx ty tz qx qy qz qw\n";
  for (int k = 0; k <= 10; ++k) gt += fmt::format("{:.4f} {:.4f} 0 0 0 0 0 1\n", 0.99 + 0.01 * k, 0.99 + 0.01 * k);
  WriteText((dir / "groundtruth.txt").string(), gt);
  Dataset ds = OpenDataset(dir.string());
  ASSERT_TRUE(ds.camera.has_value());
  EXPECT_EQ(ds.camera->fx, 517.306408);
  EXPECT_TRUE(ds.camera->HasDistortion());
  EXPECT_NE(ds.camera_origin.find("Freiburg 1"), std::string::npos) << ds.camera_origin;
  ASSERT_TRUE(ds.ground_truth.has_value());
  ASSERT_EQ(ds.ground_truth->size(), 2u);
  EXPECT_NEAR(ds.ground_truth->world_from_cam[1].t.x(), 1.033, 1e-9);  // interpolated between 1.03 and 1.04
  // The TUM camera is 640x480: frames of another size are refused.
  WriteImage((dir / "rgb/1.000000.png").string(), cv::Size(320, 240), 1);
  WriteImage((dir / "rgb/1.033000.png").string(), cv::Size(320, 240), 1);
  ExpectThrowsWith([&] { OpenDataset(dir.string()); }, "640x480", "320x240");
}

// ---- 7-Scenes -------------------------------------------------------------------------------------------

TEST(Datasets, SevenScenesRealSequence) {
  const std::string dir = DataSequence("7scenes_redkitchen_frames000-299");
  if (dir.empty()) GTEST_SKIP() << "7-Scenes excerpt not found (set MCSLAM_DATA); skipping";
  Dataset ds = OpenDataset(dir);
  EXPECT_EQ(ds.kind, DatasetKind::kSevenScenes);
  EXPECT_EQ(ds.source->FrameCount(), 300);
  ASSERT_TRUE(ds.camera.has_value());
  // camera-intrinsics.txt holds the depth camera's K; the reader says so.
  EXPECT_EQ(ds.camera->fx, 585);
  EXPECT_EQ(ds.camera->cx, 320);
  EXPECT_EQ(ds.camera->width, 640);
  bool noted = false;
  for (const auto& n : ds.notes) noted |= n.find("525") != std::string::npos;
  EXPECT_TRUE(noted);
  ASSERT_TRUE(ds.ground_truth.has_value());
  ASSERT_EQ(ds.ground_truth->size(), 300u);
  EXPECT_DOUBLE_EQ(ds.ground_truth->stamps_s[30], 1.0);  // 30 Hz
  // Frame 0's pose file, last column.
  EXPECT_NEAR(ds.ground_truth->world_from_cam[0].t.x(), -0.34045634, 1e-8);
  EXPECT_NEAR(ds.ground_truth->world_from_cam[0].t.y(), 0.016469818, 1e-8);
  EXPECT_NEAR(ds.ground_truth->world_from_cam[0].t.z(), 0.29656917, 1e-8);
  // groundtruth_tum.txt was derived from the same files (rotations re-orthonormalised there too).
  const Trajectory ref = ReadTum((fs::path(dir) / "groundtruth_tum.txt").string());
  ASSERT_EQ(ref.size(), 300u);
  for (size_t i = 0; i < ref.size(); i += 37) {
    EXPECT_LT((ds.ground_truth->world_from_cam[i].t - ref.world_from_cam[i].t).norm(), 1e-6) << i;
    EXPECT_LT(AngularDistanceDeg(ds.ground_truth->world_from_cam[i].q, ref.world_from_cam[i].q), 0.01) << i;
  }

  // The colour camera as the literature takes it, given explicitly.
  DatasetOptions o;
  o.camera = PinholeCamera(525, 525, 320, 240, 640, 480);
  Dataset ds2 = OpenDataset(dir, o);
  ASSERT_TRUE(ds2.camera.has_value());
  EXPECT_EQ(ds2.camera->fx, 525);
  EXPECT_EQ(ds2.camera_origin, "given camera");
  // Or from a camera file.
  TempDir tmp;
  WriteText(tmp / "cam.txt", "# fx fy cx cy\n525 525 320 240\n");
  o = {};
  o.camera_path = tmp / "cam.txt";
  Dataset ds3 = OpenDataset(dir, o);
  EXPECT_EQ(ds3.camera->fx, 525);
  EXPECT_EQ(ds3.camera->width, 640);
}

TEST(Datasets, SevenScenesOriginalLayoutWithAMissingPose) {
  TempDir dir;
  for (int i = 0; i < 3; ++i) WriteImage(dir / fmt::format("frame-{:06d}.color.png", i), cv::Size(64, 48), i);
  WriteText(dir / "frame-000000.pose.txt", "1 0 0 0.5\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
  WriteText(dir / "frame-000002.pose.txt", "1 0 0 1.5\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
  Dataset ds = OpenDataset(dir.path().string());
  EXPECT_EQ(ds.kind, DatasetKind::kSevenScenes);
  EXPECT_EQ(ds.source->FrameCount(), 3);
  ASSERT_TRUE(ds.camera.has_value());
  EXPECT_EQ(ds.camera->fx, 525);  // no intrinsics file: the usual colour camera
  ASSERT_TRUE(ds.ground_truth.has_value());
  ASSERT_EQ(ds.ground_truth->size(), 2u);
  EXPECT_EQ(ds.ground_truth_frames, (std::vector<int64_t>{0, 2}));
  EXPECT_DOUBLE_EQ(ds.ground_truth->world_from_cam[1].t.x(), 1.5);
  EXPECT_DOUBLE_EQ(ds.ground_truth->stamps_s[1], 2.0 / 30.0);
  // A malformed pose file names itself.
  WriteText(dir / "frame-000001.pose.txt", "1 0 0\n");
  ExpectThrowsWith([&] { OpenDataset(dir.path().string()); }, "frame-000001.pose.txt", "16 numbers");
}

// ---- EuRoC ----------------------------------------------------------------------------------------------

void MakeEuroc(const fs::path& root, const std::string& resolution = "[64, 48]") {
  const fs::path cam = root / "mav0" / "cam0";
  fs::create_directories(cam / "data");
  fs::create_directories(root / "mav0" / "state_groundtruth_estimate0");
  const int64_t t0 = 1403636579763555584;
  std::string csv = "#timestamp [ns],filename\n";
  for (int i = 0; i < 3; ++i) {
    const int64_t t = t0 + i * 50'000'000;  // 20 Hz
    csv += fmt::format("{},{}.png\n", t, t);
    WriteImage((cam / "data" / fmt::format("{}.png", t)).string(), cv::Size(64, 48), 50 * i);
  }
  WriteText((cam / "data.csv").string(), csv);
  WriteText((cam / "sensor.yaml").string(),
            "# General sensor definitions.\nsensor_type: camera\ncomment: VI-Sensor cam0 (MT9M034)\n"
            "T_BS:\n  cols: 4\n  rows: 4\n  data: [0.0, -1.0, 0.0, 0.1,\n         1.0, 0.0, 0.0, 0.2,\n"
            "         0.0, 0.0, 1.0, 0.3,\n         0.0, 0.0, 0.0, 1.0]\n"
            "rate_hz: 20\nresolution: " +
                resolution +
                "\ncamera_model: pinhole\n"
                "intrinsics: [45.8654, 45.7296, 36.7215, 24.8375] #fu, fv, cu, cv\n"
                "distortion_model: radial-tangential\n"
                "distortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]\n");
  // Body moving along x at 1 m/s, 200 Hz, from 10 ms before the first frame to after the last.
  std::string gt =
      "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
      "v_RS_R_x, v_RS_R_y, v_RS_R_z, b_w_x, b_w_y, b_w_z, b_a_x, b_a_y, b_a_z\n";
  for (int k = -2; k <= 25; ++k) {
    const int64_t t = t0 + k * 5'000'000 + 1'000'000;  // samples 1 ms after a multiple of 5 ms
    gt += fmt::format("{},{:.6f},0,0,1,0,0,0,1,0,0,0,0,0,0,0,0\n", t, (k * 5 + 1) * 1e-3);
  }
  WriteText((root / "mav0" / "state_groundtruth_estimate0" / "data.csv").string(), gt);
}

TEST(Datasets, EurocLayout) {
  TempDir dir;
  MakeEuroc(dir.path());
  EXPECT_EQ(DetectDatasetKind(dir.path().string()), DatasetKind::kEuroc);
  Dataset ds = OpenDataset(dir.path().string());
  EXPECT_EQ(ds.kind, DatasetKind::kEuroc);
  EXPECT_EQ(ds.source->FrameCount(), 3);
  ASSERT_TRUE(ds.camera.has_value());
  EXPECT_EQ(ds.camera->fx, 45.8654);
  EXPECT_EQ(ds.camera->cy, 24.8375);
  EXPECT_EQ(ds.camera->width, 64);
  EXPECT_EQ(ds.camera->height, 48);
  EXPECT_EQ(ds.camera->dist.k1, -0.28340811);
  EXPECT_EQ(ds.camera->dist.p2, 1.76187114e-05);
  EXPECT_EQ(ds.camera->dist.k3, 0.0);
  Frame f;
  ASSERT_TRUE(ds.source->Next(&f));
  EXPECT_TRUE(f.ok()) << f.error;
  EXPECT_DOUBLE_EQ(f.stamp_s, 1403636579.763555584);
  ASSERT_TRUE(ds.ground_truth.has_value());
  ASSERT_EQ(ds.ground_truth->size(), 3u);
  // Frame i at body x = 0.05 i (interpolated between samples 1 ms apart from it); camera = body * T_BS.
  for (int i = 0; i < 3; ++i) {
    const Pose& p = ds.ground_truth->world_from_cam[static_cast<size_t>(i)];
    // Stamps near 1.4e9 s resolve ~0.24 us as doubles: at 1 m/s that is ~2.4e-7 m of interpolation error.
    EXPECT_NEAR(p.t.x(), 0.05 * i + 0.1, 1e-6);
    EXPECT_NEAR(p.t.y(), 0.2, 1e-9);
    EXPECT_NEAR(p.t.z(), 0.3, 1e-9);
    EXPECT_NEAR((p.R() * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(), 0.0, 1e-9);
    EXPECT_DOUBLE_EQ(ds.ground_truth->stamps_s[static_cast<size_t>(i)], 1403636579.763555584 + 0.05 * i);
  }
  // Also opened from mav0 itself.
  Dataset ds2 = OpenDataset((dir.path() / "mav0").string());
  EXPECT_EQ(ds2.kind, DatasetKind::kEuroc);
  EXPECT_EQ(ds2.source->FrameCount(), 3);
}

// A EuRoC-layout sequence of a fisheye camera (TUM-VI's, Kalibr's `distortion_model: equidistant`): k1-k4 of the
// Kannala-Brandt model; four coefficients only.
TEST(Datasets, EurocLayoutWithAnEquidistantFisheye) {
  TempDir dir;
  MakeEuroc(dir.path());
  const fs::path yaml = dir.path() / "mav0" / "cam0" / "sensor.yaml";
  std::string text = mcslam::testing::ReadText(yaml.string());
  const std::string radtan = "distortion_model: radial-tangential\n"
                             "distortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]\n";
  ASSERT_NE(text.find(radtan), std::string::npos);
  text.replace(text.find(radtan), radtan.size(),
               "distortion_model: equidistant\ndistortion_coefficients: [0.0034, 0.0007, -0.002, 0.0002]\n");
  WriteText(yaml.string(), text);
  Dataset ds = OpenDataset(dir.path().string());
  ASSERT_TRUE(ds.camera.has_value());
  EXPECT_EQ(ds.camera->dist.model, LensModel::kEquidistant);
  EXPECT_EQ(ds.camera->dist.k1, 0.0034);
  EXPECT_EQ(ds.camera->dist.k3, -0.002);
  EXPECT_EQ(ds.camera->dist.k4, 0.0002);
  EXPECT_EQ(ds.camera->dist.p1, 0.0);
  const std::string four = "[0.0034, 0.0007, -0.002, 0.0002]";
  text.replace(text.find(four), four.size(), "[0.0034, 0.0007, -0.002, 0.0002, 0.1]");
  WriteText(yaml.string(), text);
  EXPECT_THROW(OpenDataset(dir.path().string()), std::exception);
}

TEST(Datasets, EurocWrongResolutionIsCaught) {
  TempDir dir;
  MakeEuroc(dir.path(), "[752, 480]");
  ExpectThrowsWith([&] { OpenDataset(dir.path().string()); }, "752x480", "64x48");
  DatasetOptions o;
  o.check_image_size = false;  // the caller may take it on itself
  EXPECT_NO_THROW(OpenDataset(dir.path().string(), o));
}

// A resolution that is no image size is refused naming the file and the key, before it becomes an int (the fuzzer
// found 2.4e22 cast: undefined behaviour).
TEST(Datasets, EurocResolutionThatIsNoImageSizeIsAClearError) {
  for (const char* resolution : {"[2.4e22, 48]", "[64, -48]", "[64.5, 48]", "[0, 48]"}) {
    TempDir dir;
    MakeEuroc(dir.path(), resolution);
    ExpectThrowsWith([&] { OpenDataset(dir.path().string()); }, "sensor.yaml", "resolution");
  }
}

// ---- synthetic --------------------------------------------------------------------------------------------

TEST(Datasets, SyntheticFolderWithAndWithoutImages) {
  TempDir dir;
  Trajectory gt;
  for (int i = 0; i < 4; ++i) {
    gt.stamps_s.push_back(i / 30.0);
    gt.world_from_cam.push_back(Pose(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1 * i, 0, 0)));
  }
  WriteTum(dir / "groundtruth.txt", gt);
  WriteCameraYaml(dir / "camera.yaml", PinholeCamera(100, 100, 32, 24, 64, 48), 30);
  Dataset ds = OpenDataset(dir.path().string());
  EXPECT_EQ(ds.kind, DatasetKind::kSynthetic);
  EXPECT_EQ(ds.source->FrameCount(), 0);
  EXPECT_FALSE(ds.ground_truth.has_value());
  ASSERT_TRUE(ds.camera.has_value());
  EXPECT_EQ(ds.camera->fx, 100);
  EXPECT_FALSE(ds.notes.empty());

  fs::create_directories(dir.path() / "images");
  for (int i = 0; i < 4; ++i) WriteImage(dir / fmt::format("images/{:06d}.png", i), cv::Size(64, 48), i);
  Dataset ds2 = OpenDataset(dir.path().string());
  EXPECT_EQ(ds2.source->FrameCount(), 4);
  ASSERT_TRUE(ds2.ground_truth.has_value());
  ASSERT_EQ(ds2.ground_truth->size(), 4u);
  EXPECT_DOUBLE_EQ(ds2.ground_truth->world_from_cam[3].t.x(), 0.3);
  Frame f;
  ASSERT_TRUE(ds2.source->Next(&f));
  ASSERT_TRUE(ds2.source->Next(&f));
  EXPECT_DOUBLE_EQ(f.stamp_s, gt.stamps_s[1]);
}

// ---- helpers ------------------------------------------------------------------------------------------------

TEST(Datasets, SampleTrajectoryAtInterpolatesNearSamplesOnly) {
  Trajectory s;
  s.stamps_s = {0.00, 0.01, 0.02, 0.50, 0.51};
  for (double t : s.stamps_s)
    s.world_from_cam.push_back(Pose(QuaternionFromRotationVector(Eigen::Vector3d(0, 0, t)), Eigen::Vector3d(t, 0, 0)));
  std::vector<int64_t> used;
  const Trajectory out = SampleTrajectoryAt(s, {-0.1, 0.005, 0.01, 0.03, 0.25, 0.49, 0.6}, 0.02, &used);
  // -0.1: too early; 0.005: halfway; 0.01: exact; 0.03: 10 ms after the last of a run (nearest); 0.25: far
  // from all; 0.49: 10 ms before a run, across a gap (nearest, no interpolation over it); 0.6: too late.
  ASSERT_EQ(used, (std::vector<int64_t>{1, 2, 3, 5}));
  EXPECT_NEAR(out.world_from_cam[0].t.x(), 0.005, 1e-12);
  EXPECT_NEAR(RotationVectorFromQuaternion(out.world_from_cam[0].q).z(), 0.005, 1e-12);
  EXPECT_DOUBLE_EQ(out.world_from_cam[1].t.x(), 0.01);
  EXPECT_DOUBLE_EQ(out.world_from_cam[2].t.x(), 0.02);
  EXPECT_DOUBLE_EQ(out.world_from_cam[3].t.x(), 0.50);
  EXPECT_DOUBLE_EQ(out.stamps_s[3], 0.49);
}

TEST(Datasets, CameraTextFiles) {
  TempDir dir;
  WriteText(dir / "c9.txt", "# fx fy cx cy k1 k2 p1 p2 k3\n500 501 320 240 0.1 -0.2 0.001 0.002 0.05\n");
  const PinholeCamera c = ReadCameraText(dir / "c9.txt", 640, 480);
  EXPECT_EQ(c.fy, 501);
  EXPECT_EQ(c.dist.k3, 0.05);
  EXPECT_EQ(c.width, 640);
  WriteText(dir / "c5.txt", "500 501 320 240 0.1\n");
  ExpectThrowsWith([&] { ReadCameraText(dir / "c5.txt", 640, 480); }, "c5.txt:1", "found 5");
  WriteText(dir / "cneg.txt", "-500 501 320 240\n");
  ExpectThrowsWith([&] { ReadCameraText(dir / "cneg.txt", 640, 480); }, "cneg.txt:1");
  WriteText(dir / "k.txt", "585 0 320\n0 585 240\n0 0 1\n");
  EXPECT_EQ(ReadIntrinsicsMatrix(dir / "k.txt", 640, 480).fx, 585);
  WriteText(dir / "kskew.txt", "585 2 320\n0 585 240\n0 0 1\n");
  ExpectThrowsWith([&] { ReadIntrinsicsMatrix(dir / "kskew.txt", 640, 480); }, "kskew.txt", "skew");
  EXPECT_EQ(TumColorCamera(3).fx, 535.4);
  EXPECT_THROW(TumColorCamera(4), std::invalid_argument);
}

}  // namespace
}  // namespace mcslam::io
