// The front end on real sequences from the shared data folder (skipped, visibly, when it is absent).
// Besides the checks, each test prints its figures: features per frame, survival, milliseconds per stage.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>

#include "../test_util.h"
#include "frontend/frontend.h"
#include "io/datasets.h"

namespace mcslam::frontend {
namespace {

struct Figures {
  int frames = 0;
  double mean_features = 0;
  double min_survival = 1, mean_survival = 0;  // tracked / features of the previous frame
  // tracked / (features of the previous frame - those that left the image): how often tracking itself fails.
  double min_survival_in_view = 1, mean_survival_in_view = 0;
  double convert_ms = 0, pyramid_ms = 0, track_ms = 0, detect_ms = 0, describe_ms = 0, total_ms = 0;
  int skipped = 0;
};

std::string SequenceDir(const std::string& name) {
  const std::string data = mcslam::testing::DataDir();
  if (data.empty()) return "";
  const std::string dir = (std::filesystem::path(data) / name).string();
  return std::filesystem::is_directory(dir) ? dir : "";
}

Figures RunSequence(const std::string& dir, int max_frames, const FrontendOptions& options, const std::string& label) {
  io::Dataset ds = io::OpenDataset(dir);
  Frontend fe(options);
  Figures fig;
  io::Frame frame;
  size_t prev_features = 0;
  int steps = 0;
  while (fig.frames + fig.skipped < max_frames && ds.source->Next(&frame)) {
    if (!frame.ok()) {
      ++fig.skipped;
      continue;
    }
    const FrameResult r = fe.Process(frame.image, frame.index, frame.stamp_s);
    if (fig.frames > 0 && prev_features > 0) {
      const double s = static_cast<double>(r.stats.tracked) / static_cast<double>(prev_features);
      fig.min_survival = std::min(fig.min_survival, s);
      fig.mean_survival += s;
      const double in_view = static_cast<double>(prev_features) - r.stats.lost_outside;
      const double sv = in_view > 0 ? static_cast<double>(r.stats.tracked) / in_view : 1.0;
      fig.min_survival_in_view = std::min(fig.min_survival_in_view, sv);
      fig.mean_survival_in_view += sv;
      ++steps;
    }
    prev_features = r.features.size();
    fig.mean_features += static_cast<double>(r.features.size());
    fig.convert_ms += r.stats.convert_ms;
    fig.pyramid_ms += r.stats.pyramid_ms;
    fig.track_ms += r.stats.track_ms;
    fig.detect_ms += r.stats.detect_ms;
    fig.describe_ms += r.stats.describe_ms;
    fig.total_ms += r.stats.total_ms;
    ++fig.frames;
  }
  if (fig.frames > 0) {
    const double n = fig.frames;
    fig.mean_features /= n;
    fig.convert_ms /= n;
    fig.pyramid_ms /= n;
    fig.track_ms /= n;
    fig.detect_ms /= n;
    fig.describe_ms /= n;
    fig.total_ms /= n;
  }
  if (steps > 0) {
    fig.mean_survival /= steps;
    fig.mean_survival_in_view /= steps;
  }
  std::printf(
      "[figures] %s: %d frames, %.0f features/frame, survival mean %.3f min %.3f, of those staying in view mean "
      "%.3f min %.3f; ms/frame: convert %.2f pyramid %.2f track %.2f detect %.2f describe %.2f total %.2f\n",
      label.c_str(), fig.frames, fig.mean_features, fig.mean_survival, fig.min_survival, fig.mean_survival_in_view,
      fig.min_survival_in_view, fig.convert_ms, fig.pyramid_ms, fig.track_ms, fig.detect_ms, fig.describe_ms,
      fig.total_ms);
  return fig;
}

TEST(FrontendReal, Kitti06KeepsMostFeaturesFrameToFrame) {
  const std::string dir = SequenceDir("kitti_odometry_06_frames000-050");
  if (dir.empty()) GTEST_SKIP() << "KITTI 06 excerpt not found (set MCSLAM_DATA); skipping";
  // The default options: at 10 Hz forward a tenth of the tracks no longer match their birth patch one frame
  // later, which the automatic mismatch policy measures and answers with new patches; dropped
  // (AnchorMismatch::kDrop), the survival falls to 0.38 (min) / 0.47 (mean).
  FrontendOptions options;
  const Figures fig = RunSequence(dir, 11, options, "KITTI 06 frames 0-10");
  EXPECT_EQ(fig.frames, 11);
  EXPECT_EQ(fig.skipped, 0);
  // ~1.2 m forward per frame at 10 Hz: the near scenery (roadside trees, parked cars, grass) leaves the
  // 1226x370 image within a few frames, and up to a quarter of the tracks leave it in one step. Of the tracks
  // that stay in view, 70 % must be followed every step; of all tracks, more than half, and 65 % on average.
  EXPECT_GE(fig.min_survival_in_view, 0.70);
  EXPECT_GE(fig.min_survival, 0.50);
  EXPECT_GE(fig.mean_survival, 0.65);
  EXPECT_GE(fig.mean_features, 200);
}

TEST(FrontendReal, SevenScenesHandHeld30Hz) {
  const std::string dir = SequenceDir("7scenes_redkitchen_frames000-299");
  if (dir.empty()) GTEST_SKIP() << "7-Scenes RedKitchen excerpt not found (set MCSLAM_DATA); skipping";
  const Figures fig = RunSequence(dir, 60, FrontendOptions{}, "7-Scenes RedKitchen frames 0-59");
  EXPECT_EQ(fig.frames, 60);
  // Slow hand-held motion at 30 Hz (7 mm and 0.4 degrees a frame): nearly every track survives a step.
  EXPECT_GE(fig.mean_survival, 0.85);
}

TEST(FrontendReal, TumOneHertzRunsAndReports) {
  const std::string dir = SequenceDir("tum_rgbd_fr3_long_office_household_1hz");
  if (dir.empty()) GTEST_SKIP() << "TUM fr3 1 Hz excerpt not found (set MCSLAM_DATA); skipping";
  // 1 s between frames (14-41 cm, 2-12 degrees): a frame-to-frame tracker loses most tracks here. The test
  // reports the figures and checks that the front end keeps finding features; no survival is promised.
  const Figures fig = RunSequence(dir, 17, FrontendOptions{}, "TUM fr3 long office, 1 Hz");
  EXPECT_EQ(fig.frames, 17);
  EXPECT_GE(fig.mean_features, 200);
}

}  // namespace
}  // namespace mcslam::frontend
