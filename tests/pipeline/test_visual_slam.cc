// The pipeline layer on the rendered paper scene: frames through a VisualSlam as an application would pass
// them, with a gap of unreadable frames and an image the front end does not take.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "compute/point_kernel.h"
#include "compute/pose_kernel.h"
#include "eval/trajectory_eval.h"
#include "pipeline/visual_slam.h"
#include "sim/paper_scenario.h"
#include "sim/scenarios.h"
#include "sim/render.h"
#include "test_util.h"

namespace mcslam::pipeline {
namespace {

constexpr double kFps = 30.0;

sim::SyntheticSequence PaperScene(int frames, uint64_t seed) {
  sim::PaperScenarioOptions so;
  so.frames = frames;
  so.seed = seed;
  return sim::MakePaperScenario(so);
}

struct Scene {
  sim::SyntheticSequence seq;
  sim::SceneRenderer renderer{sim::RenderOptions{}};
  Scene(int frames, uint64_t seed) : seq(PaperScene(frames, seed)) {}
  // A scenario of the zoo rendered as `mcslam synth --scenario NAME --seed SEED --render` renders it (with
  // `--exposure-step` and `--blur-sigma` when given).
  // edge_samples 0: the renders before outlines took a sensor's coverage (sim::RenderOptions::edge_samples), for the
  // tests that reproduce a case found on them.
  Scene(const std::string& name, uint64_t seed, double image_scale = 1.0, double exposure_step = 1.0,
        double blur_sigma_px = 0.0, int edge_samples = sim::RenderOptions{}.edge_samples)
      : seq(Scenario(name, seed, image_scale)),
        renderer(seq.scene, Textures(seed, exposure_step, blur_sigma_px, edge_samples)) {}
  static sim::SyntheticSequence Scenario(const std::string& name, uint64_t seed, double image_scale) {
    sim::ScenarioOptions so;
    so.name = name;
    so.seed = seed;
    so.image_scale = image_scale;
    return sim::MakeScenario(so);
  }
  static sim::RenderOptions Textures(uint64_t seed, double exposure_step = 1.0, double blur_sigma_px = 0.0,
                                     int edge_samples = sim::RenderOptions{}.edge_samples) {
    sim::RenderOptions ro;
    ro.seed = seed;
    ro.edge_samples = edge_samples;
    ro.exposure_step = exposure_step;
    ro.blur_sigma_px = blur_sigma_px;
    return ro;
  }
  // Each frame rendered once (a render depends on the frame's index alone): the tests that run the scene twice or
  // more, to compare options or to run in a map the first run made, render it once (under the sanitizers the
  // renderer was a fifth of VisualSlamMap.ARunInALoadedMapMovesNoneOfItsPoints' 100 s). A copy: the caller may
  // draw on it.
  cv::Mat Frame(int i) const {
    const std::lock_guard<std::mutex> lock(cache_mutex_);
    cv::Mat& frame = cache_[i];
    if (frame.empty())
      frame = renderer.Render(seq.camera, seq.cam_from_world[static_cast<size_t>(i)], static_cast<uint64_t>(i));
    return frame.clone();
  }

 private:
  mutable std::mutex cache_mutex_;
  mutable std::map<int, cv::Mat> cache_;
};

VisualSlam Make(const Scene& scene) {
  return VisualSlam(scene.seq.camera, VisualSlamOptions{}, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
}

// The latest report of every frame (the System revises reports of earlier frames, e.g. at initialisation).
using Reports = std::map<int64_t, slam::FrameReport>;
void Keep(const VisualSlamStep& step, Reports* reports) {
  for (const slam::FrameReport& r : step.reports) (*reports)[r.index] = r;
}

// Every frame of the scene through a VisualSlam with these options, and its Finish.
Reports RunWhole(const Scene& scene, const VisualSlamOptions& options) {
  VisualSlam vs(scene.seq.camera, options, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
  Reports reports;
  const int frames = static_cast<int>(scene.seq.cam_from_world.size());
  for (int i = 0; i < frames; ++i) Keep(vs.Process(scene.Frame(i), i, i / kFps), &reports);
  for (const slam::FrameReport& r : vs.Finish()) reports[r.index] = r;
  return reports;
}

// Position error of each posed frame after a Sim(3) alignment of all of them onto the truth.
std::map<int64_t, double> ErrorsAfterAlignment(const Scene& scene, const Reports& reports) {
  io::Trajectory gt, est;
  for (size_t i = 0; i < scene.seq.cam_from_world.size(); ++i) {
    gt.stamps_s.push_back(static_cast<double>(i) / kFps);
    gt.world_from_cam.push_back(scene.seq.cam_from_world[i].Inverse());
  }
  std::vector<int64_t> index;
  for (const auto& [i, r] : reports)
    if (r.has_pose) {
      est.stamps_s.push_back(static_cast<double>(i) / kFps);
      est.world_from_cam.push_back(r.cam_from_world.Inverse());
      index.push_back(i);
    }
  const eval::TrajectoryErrors errors = eval::EvaluateTrajectory(gt, est, {});
  std::map<int64_t, double> out;
  for (const eval::FrameError& e : errors.frames) out[index[e.est_index]] = (e.gt_position - e.est_position_aligned).norm();
  return out;
}

TEST(VisualSlam, AFrameAfterAGapOfUnreadableFramesIsRelocalisedAndTracked) {
  // Frames 100-119 (two thirds of a second) cannot be read: the camera moves on meanwhile, so the frame after
  // the gap is placed by relocalisation (descriptor matches to the map, PnP) before its Monte Carlo step.
  // Four paths (seeds), ~4 s each. Measured over seeds 1-8: relocalised from 32-75 PnP inliers; the relocalised
  // frame 0.1-3.0 cm from the truth after a Sim(3) alignment of the run, the frames after it 0.4-5.5 cm at
  // worst (before the gap: 0.8-1.9 cm). A wrong relocalisation puts the frame tens of centimetres off (the
  // scene is 3 m away), so the bounds below, about twice the worst measured, still tell the two apart.
  constexpr int kFrames = 140, kGapBegin = 100, kGapEnd = 120;
  for (uint64_t seed : {1, 2, 3, 4}) {
    SCOPED_TRACE(::testing::Message() << "seed " << seed);
    const Scene scene(kFrames, seed);
    VisualSlam vs = Make(scene);
    Reports reports;
    int relocalised_before_gap = 0;
    VisualSlamStep after_gap;
    for (int i = 0; i < kFrames; ++i) {
      if (i >= kGapBegin && i < kGapEnd) {
        vs.SkipFrame();
        continue;
      }
      VisualSlamStep step = vs.Process(scene.Frame(i), i, i / kFps);
      Keep(step, &reports);
      if (i < kGapBegin) relocalised_before_gap += step.reloc_tried;
      if (i == kGapEnd) after_gap = std::move(step);
    }
    const std::map<int64_t, double> errors = ErrorsAfterAlignment(scene, reports);
    double worst_before = 0, worst_after = 0;
    for (const auto& [i, e] : errors) {
      double& worst = i < kGapBegin ? worst_before : worst_after;
      worst = std::max(worst, e);
    }
    std::printf("seed %llu: relocalised from %d of %d matches; worst position error %.4f m before the gap, %.4f m "
                "after, %.4f m on the relocalised frame (%zu posed frames)\n",
                static_cast<unsigned long long>(seed), after_gap.reloc_inliers, after_gap.reloc_matches, worst_before,
                worst_after, errors.count(kGapEnd) ? errors.at(kGapEnd) : -1.0, errors.size());
    // Nothing is lost before the gap on this scene, so relocalisation is never tried there.
    EXPECT_EQ(relocalised_before_gap, 0);
    ASSERT_TRUE(after_gap.reloc_tried);
    // The features that survived the gap and those matched by descriptor: half the fewest measured.
    EXPECT_GE(after_gap.reloc_inliers, 16) << after_gap.reloc_matches << " matches";
    ASSERT_NE(after_gap.current(), nullptr);
    EXPECT_EQ(after_gap.current()->status, slam::FrameStatus::kTracked) << after_gap.current()->note;
    int tracked_after = 0;
    for (int i = kGapEnd; i < kFrames; ++i)
      tracked_after += reports.count(i) && reports.at(i).status == slam::FrameStatus::kTracked;
    EXPECT_GE(tracked_after, kFrames - kGapEnd - 1);
    ASSERT_TRUE(errors.count(kGapEnd));
    EXPECT_LT(errors.at(kGapEnd), 0.06);
    EXPECT_LT(worst_after, 0.11);
  }
}

// MappingOptions::starving_min_track_frames. Under the fast scenario's motion most tracks live three or four
// frames; a map whose keyframes have fewer than 30 pose inliers (starving) takes new points from tracks seen in
// two posed frames instead of three, or it keeps too few of what is in view to survive a jolt. Measured here
// (seeds 1-10, ~5 s each): no frame lost on any seed; with three views seed 2 loses 14 (frames 18-31, after a
// 7 deg jolt left 7 map points in view). `mcslam run` (its local adjustment on its own thread) lost 0-2 frames
// on seeds 1-10. The bound: three lost frames a seed, the most the CLI lost plus one; the three-view run's 14
// sits far beyond it. Seeds 1-3 and 6 (6 the one the CLI lost most on). Rendered as these were measured, outlines
// from the 2x2 grid of rays (edge_samples 0): with outlines at a sensor's coverage seed 2 loses 9 frames with two
// views and 11 with three (docs/scenarios.md, "Outlines").
constexpr uint64_t kFastSeeds[] = {1, 2, 3, 6};
constexpr int kMaxLost = 3;
TEST(VisualSlam, AStarvingMapTakesNewPointsFromTwoViewsSoFastMotionDoesNotLoseIt) {
  auto lost_after_init = [](const Scene& scene, int min_views) {
    VisualSlamOptions options;
    // Upright relocalisation only: what is measured is how long the map stays lost, not how it is found again.
    // Through descriptors turned about the camera's axis too, seed 2's three-view run is found again sooner
    // (7 frames lost instead of 14; its two-view run loses none either way).
    options.relocalise_turned = false;
    // And the frames lost stay lost: not placed afterwards once the map is found again (the count is of frames the
    // map could not pose when they came; SystemOptions::pose_lost_frames_when_found).
    options.system.pose_lost_frames_when_found = false;
    options.system.mapping.starving_min_track_frames = min_views;
    const Reports reports = RunWhole(scene, options);
    int lost = 0;
    for (const auto& [i, r] : reports) lost += r.status == slam::FrameStatus::kLost;
    return lost;
  };
  for (uint64_t seed : kFastSeeds) {
    SCOPED_TRACE(::testing::Message() << "seed " << seed);
    const Scene scene("fast", seed, 1.0, 1.0, 0.0, 0);
    const int lost = lost_after_init(scene, 2);
    std::printf("[ fast     ] seed %llu: %d frames lost (two views when starving)\n",
                static_cast<unsigned long long>(seed), lost);
    EXPECT_LE(lost, kMaxLost);
    if (seed == 2) {
      const int lost3 = lost_after_init(scene, 3);
      std::printf("[ fast     ] seed 2: %d frames lost (three views)\n", lost3);
      EXPECT_GE(lost3, 10);
    }
  }
}

// InitOptions::min_count_floor. The rendered sparse scenario (a box and floor with smooth textures and a few blobs:
// 21-35 corners a frame) offers fewer features than the initialisation asks for on a textured scene; the counts
// are lowered to 60 % of what a frame tracks, down to the floor. The frames of its first 30 % (the robustness
// matrix's bound for the start) are run with the floor at 20 and at its default.
// Measured (2 cores, AVX-512, 2026-11-28): initialised at frames 44, 17, 14, 22, 30 on seeds 2-6 with the floor at
// 12, seed 1 not within the 90 frames; at 20 only seed 2 (frame 57). Over seeds 1-30 through `mcslam run`: 27
// initialised at 12 (17 within the 90 frames), 19 at 20 (7), none mirrored. Bounds: never mirrored; at least two
// more seeds started than at 20 (five against one measured).
TEST(VisualSlam, ALowTextureSceneInitialisesFromTheFewCornersItHas) {
  constexpr int kFrames = 90;  // 30 % of the scenario's 300
  struct Outcome {
    int init_frame = -1;
    bool mirrored = false;
  };
  auto run = [](const Scene& scene, uint64_t seed, int floor) {
    VisualSlamOptions options;
    options.system.init.min_count_floor = floor;
    options.system.seed = options.system.tracker.seed = seed;  // as `mcslam run --seed` sets both
    VisualSlam vs(scene.seq.camera, options, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
    Reports reports;
    Outcome o;
    for (int i = 0; i < kFrames; ++i) {
      const VisualSlamStep step = vs.Process(scene.Frame(i), i, i / kFps);
      for (const slam::FrameReport& r : step.reports)
        if (r.initialisation && o.init_frame < 0) o.init_frame = i;
      Keep(step, &reports);
    }
    for (const slam::FrameReport& r : vs.Finish()) reports[r.index] = r;
    io::Trajectory gt, est;
    for (const auto& [i, r] : reports)
      if (r.has_pose) {
        gt.stamps_s.push_back(static_cast<double>(i) / kFps);
        gt.world_from_cam.push_back(scene.seq.cam_from_world[static_cast<size_t>(i)].Inverse());
        est.stamps_s.push_back(static_cast<double>(i) / kFps);
        est.world_from_cam.push_back(r.cam_from_world.Inverse());
      }
    if (est.stamps_s.size() >= 3) o.mirrored = eval::EvaluateTrajectory(gt, est, {}).mirrored;
    return o;
  };
  int started_low = 0, started_high = 0;
  for (uint64_t seed = 1; seed <= 6; ++seed) {
    SCOPED_TRACE(::testing::Message() << "seed " << seed);
    const Scene scene("sparse", seed);
    const Outcome low = run(scene, seed, slam::InitOptions{}.min_count_floor), high = run(scene, seed, 20);
    std::printf("[ sparse   ] seed %llu: initialised at frame %d with the floor at %d, %d at 20%s\n",
                static_cast<unsigned long long>(seed), low.init_frame, slam::InitOptions{}.min_count_floor,
                high.init_frame, low.mirrored || high.mirrored ? " (mirrored)" : "");
    EXPECT_FALSE(low.mirrored);
    started_low += low.init_frame >= 0;
    started_high += high.init_frame >= 0;
  }
  EXPECT_GE(started_low, started_high + 2);
}

// FrontendOptions::min_cells. The fast scenario rendered at half the paper's resolution (160x120, f = 250
// px): a fixed grid of 40 px cells is 4 x 3 cells there, two new corners each at most in a frame, too few to
// follow a camera that moves 15x the paper's speed. The grid shrinks with the image instead (20 px cells).
// Measured (2 cores, 2026-11-28): seed 1 tracked 150 of 150 frames with the grid that shrinks, 12 with the fixed
// one (seeds 2 and 3: 150 against 9, 149 against 38; the half-resolution matrix of docs/robustness_low_res.md).
// Bounds: 95 % of the frames (the matrix's success rule) against fewer than half. Rendered as measured, outlines
// from the 2x2 grid of rays (edge_samples 0): with outlines at a sensor's coverage the grid that shrinks tracks 116.
TEST(VisualSlam, ALowResolutionImageGetsAGridItsSizeCanHold) {
  const Scene scene("fast", 1, 0.5, 1.0, 0.0, 0);
  ASSERT_EQ(scene.seq.camera.height, 120);
  auto tracked = [&](int min_cells) {
    VisualSlamOptions options;
    options.frontend.min_cells = min_cells;
    options.system.seed = options.system.tracker.seed = 1;
    const Reports reports = RunWhole(scene, options);
    int n = 0;
    for (const auto& [i, r] : reports) n += r.status == slam::FrameStatus::kTracked;
    return n;
  };
  const int shrinking = tracked(frontend::FrontendOptions{}.min_cells), fixed = tracked(1);
  std::printf("[ low res  ] fast seed 1 at 160x120: %d of 150 frames tracked with the grid that shrinks, %d with "
              "40 px cells\n", shrinking, fixed);
  EXPECT_GE(shrinking, 143);
  EXPECT_LT(fixed, 75);
}

// VisualSlamOptions::describe_map_points_only (docs/tuning.md). The rendered forward scenario (a car: tracks are
// born fast and leave the view fast, and few become map points), seed 1: describing only the map points' tracks, from
// the frames they were born in, computes a fraction of the SIFT descriptors and tracks as well. Measured (2 cores,
// AVX2, 2026-12-08): the forward runs of seeds 1-10 were the same to the bit with and without it (`scripts/
// robustness.sh`); the bound leaves 10 % for a CPU whose rounding sends one remap another way.
TEST(VisualSlam, DescribingOnlyTheMapPointsTracksDescribesFewerAndTracksAsWell) {
  const Scene scene("forward", 1);
  struct Outcome {
    long described = 0;  // SIFT descriptions computed
    int tracked = 0;
    double ate_m = 0;
  };
  auto run = [&](bool only) {
    VisualSlamOptions options;
    options.describe_map_points_only = only;
    VisualSlam vs(scene.seq.camera, options, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
    Reports reports;
    Outcome o;
    const int frames = static_cast<int>(scene.seq.cam_from_world.size());
    for (int i = 0; i < frames; ++i) {
      const VisualSlamStep step = vs.Process(scene.Frame(i), i, i / kFps);
      const frontend::FrameStats& st = step.frontend.stats;
      o.described += (only ? 0 : st.detected - st.described_for_remap) + st.refreshed + st.described_listed;
      Keep(step, &reports);
    }
    for (const slam::FrameReport& r : vs.Finish()) reports[r.index] = r;
    double sum_sq = 0;
    const std::map<int64_t, double> errors = ErrorsAfterAlignment(scene, reports);
    for (const auto& [i, e] : errors) sum_sq += e * e;
    o.tracked = static_cast<int>(errors.size());
    o.ate_m = errors.empty() ? 1e9 : std::sqrt(sum_sq / static_cast<double>(errors.size()));
    std::printf("[ describe ] %s: %ld descriptions, %d frames posed, ATE %.4f m\n",
                only ? "map points' tracks only" : "every track at its birth", o.described, o.tracked, o.ate_m);
    return o;
  };
  const Outcome every = run(false), only = run(true);
  EXPECT_LT(only.described, every.described / 2);
  EXPECT_EQ(only.tracked, every.tracked);
  EXPECT_LE(only.ate_m, 1.1 * every.ate_m);
}

// SystemOptions::rotation_only_over_weak_pose. The rendered rotation scenario, seed 5: after the provisional map
// joined the map (frame 188) the camera pans on without moving (frames 180-203), seeing 10-15 of the map's points
// at one edge of the image. The pose step still finds a pose from them, but six degrees of freedom fitted to so
// few points trade part of the turn for a move, and new points triangulated from that phantom baseline pull the
// frames after it off when the camera moves again. The turn about the last centre, which the tracks agree on, is
// taken instead.
// Measured (through VisualSlam, 2 cores, 2026-11-28): seed 5, taken as turns, 11 of frames 180-203 posed as a turn,
// the worst position error from frame 180 on 5.8 cm and the ATE 1.19 cm; kept, none, 10.4 cm and 2.17 cm. Over
// seeds 1-9 of the scene the ATE taken as turns is 0.55-0.91 of the kept one's, on every seed, and 0.12-0.67 % of
// the path. A run can derail here either way: before remapping also matched a point's first look, seed 5's kept
// run ended 1.8 m off (ATE 58 cm against 0.75 cm taken as turns), and seed 2's run taken as turns 69 cm (ATE 26
// cm). The bounds: more frames posed as a turn; the ATE under the kept one's; at most half a percent of the 3.3 m
// path (seed 5: 0.36 %).
TEST(VisualSlam, AWeakPoseInAPureTurnIsTakenAsTheTurn) {
  const Scene scene("rotation", 5);
  struct Outcome {
    int turns = 0;  // of frames 180-203, posed as a turn
    double worst_m = 0, ate_m = 0;
  };
  auto run = [&](bool over_weak_pose) {
    VisualSlamOptions options;
    options.system.rotation_only_over_weak_pose = over_weak_pose;
    const Reports reports = RunWhole(scene, options);
    Outcome o;
    for (const auto& [i, r] : reports) o.turns += r.rotation_only && i >= 180 && i <= 203;
    double sum_sq = 0;
    const std::map<int64_t, double> errors = ErrorsAfterAlignment(scene, reports);
    for (const auto& [i, e] : errors) o.worst_m = std::max(o.worst_m, i >= 180 ? e : 0.0), sum_sq += e * e;
    o.ate_m = errors.empty() ? 1e9 : std::sqrt(sum_sq / static_cast<double>(errors.size()));
    std::printf("[ turn     ] weak poses %s: %d of frames 180-203 posed as a turn; worst position error from frame "
                "180 on %.4f m; ATE %.4f m over %zu frames\n",
                over_weak_pose ? "taken as turns" : "kept", o.turns, o.worst_m, o.ate_m, errors.size());
    return o;
  };
  const Outcome on = run(true), off = run(false);
  EXPECT_GT(on.turns, off.turns);
  EXPECT_LT(on.ate_m, off.ate_m);
  EXPECT_LT(on.ate_m, 0.005 * 3.29);  // the scenario's path, 3.29 m (robustness matrix)
}

// The point adjustment's outliers are a few points at a time; more than half of a keyframe's map points at once
// are a window whose poses disagree (PointAdjuster::AdjustPoints). The rendered rotation scenario with exposure steps
// and blur (`mcslam synth --scenario rotation --seed 2 --render --exposure-step 1.3 --blur-sigma 2`): after its
// provisional map joined the map, the frames the local adjustment had stepped over were ~7 px off the points it
// moved, and 49 of the 79 points of frame 210 were removed at once; the run then drifted on 13-20 inliers (ATE
// 15.0 cm through `mcslam run`; 10.5 cm with the points kept). Measured here: the points kept on 1 frame, no
// keyframe losing more than 17, all 270 frames posed, ATE 2.8 cm; without keeping them, 51 points left at once
// and 54 frames went without a pose (ATE 3.5 cm over the 216 posed). Bound: at least 265 frames posed, which is
// what the guard changes. The ATE is printed, not asserted: it does not tell the guard's run from the run without
// it (3.5 cm over fewer frames), and the path after the join is chaotic: with the pose step's translation prior,
// it measured 2.7 cm under g++ (AVX-512, the guard never acting) and 15.3 cm in clang's sanitized build (the guard
// acting on 7 frames, all 270 posed). (How many frames the guard acts on is printed, not asserted either: another
// CPU's last bits may lead the run where no window disagrees.)
TEST(VisualSlam, AKeyframeDoesNotLoseMostOfItsPointsAtOnce) {
  const Scene scene("rotation", 2, 1.0, 1.3, 2.0);
  const Reports reports = RunWhole(scene, VisualSlamOptions{});
  int kept = 0, worst_removed = 0;
  for (const auto& [i, r] : reports) {
    kept += r.note.find("would have left the map at once") != std::string::npos;
    worst_removed = std::max(worst_removed, r.removed);
  }
  double sum_sq = 0;
  const std::map<int64_t, double> errors = ErrorsAfterAlignment(scene, reports);
  for (const auto& [i, e] : errors) sum_sq += e * e;
  const double ate = errors.empty() ? 1e9 : std::sqrt(sum_sq / static_cast<double>(errors.size()));
  std::printf("[ kept     ] points kept on %d frames; at most %d removed at once; ATE %.4f m over %zu frames\n", kept,
              worst_removed, ate, errors.size());
  EXPECT_GE(errors.size(), 265u);
}

TEST(VisualSlam, AnImageTheFrontEndDoesNotTakeSkipsThatFrameOnly) {
  constexpr int kFrames = 90, kBad = 70;
  const Scene scene(kFrames, 1);
  VisualSlam vs = Make(scene);
  Reports reports;
  for (int i = 0; i < kBad; ++i) Keep(vs.Process(scene.Frame(i), i, i / kFps), &reports);
  ASSERT_TRUE(vs.system().initialised());
  const size_t points_before = vs.system().map().points().size();
  const cv::Mat doubles(scene.seq.camera.height, scene.seq.camera.width, CV_64FC1, cv::Scalar(0.5));
  try {
    vs.Process(doubles, kBad, kBad / kFps);
    FAIL() << "a 64-bit float image was taken";
  } catch (const UnusableFrame& e) {
    EXPECT_NE(std::string(e.what()).find("pixel type"), std::string::npos) << e.what();
  }
  EXPECT_EQ(vs.system().map().points().size(), points_before);  // the back end never saw it
  // The next frame comes after a gap: relocalised, then tracked on.
  const VisualSlamStep next = vs.Process(scene.Frame(kBad + 1), kBad + 1, (kBad + 1) / kFps);
  EXPECT_TRUE(next.reloc_tried);
  ASSERT_NE(next.current(), nullptr);
  EXPECT_EQ(next.current()->status, slam::FrameStatus::kTracked) << next.current()->note;
}

// Remapping's back-off (VisualSlamOptions::remap_tries_every_frame): the camera stops after 60 frames and a
// grey card covers the middle of the view for 40 frames, then goes. The map points behind it are lost, in view
// and not to be found: each is looked for in every frame for its first tries, then (the late tries failing)
// in one frame of remap_retry_every; when the card goes, corners appear where they should be and they are
// looked for at once (a new track would take the corner for good otherwise). The same run without the back-off
// (remap_backoff_below 0) is the control.
struct RemapCounts {
  int first_tried = 0;    // requests tried in the frame after the card came (the lost points in view)
  int late_tried = 0;     // requests tried in the card's last 12 frames
  int back_remapped = 0;  // points re-attached in the 8 frames after it went
};
RemapCounts RunWithCard(uint64_t seed, bool back_off,
                        int min_inliers = VisualSlamOptions{}.remap_backoff_min_inliers) {
  constexpr int kMoving = 60, kCardEnd = 100, kEnd = 108;
  const Scene scene(kMoving, seed);
  VisualSlamOptions o;
  if (!back_off) o.remap_backoff_below = 0;
  o.remap_backoff_min_inliers = min_inliers;
  VisualSlam vs(scene.seq.camera, o, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
  const cv::Mat still = scene.Frame(kMoving - 1);
  cv::Mat card = still.clone();
  cv::rectangle(card, cv::Rect(still.cols / 3, still.rows / 3, still.cols / 3, still.rows / 3), cv::Scalar::all(128),
                cv::FILLED);
  RemapCounts c;
  for (int i = 0; i < kEnd; ++i) {
    const cv::Mat& image = i < kMoving ? scene.Frame(i) : i < kCardEnd ? card : still;
    const VisualSlamStep step = vs.Process(i < kMoving ? image.clone() : image, i, i / kFps);
    const frontend::FrameStats& st = step.frontend.stats;
    const int tried = st.remap_requests - st.remap_refused_id - st.remap_outside - st.remap_deferred;
    if (i == kMoving + 1) c.first_tried = tried;
    if (i >= kCardEnd - 12 && i < kCardEnd) c.late_tried += tried;
    if (i >= kCardEnd) c.back_remapped += st.remapped;
    if (i == kMoving - 1) {
      EXPECT_TRUE(vs.system().initialised());
    }
  }
  return c;
}

// The back-off's gate on the map's health (remap_backoff_min_inliers) is open here (0): the card leaves the
// pose fewer than 60 inliers on half the seeds, where the default keeps looking in every frame (the last check).
// Measured over seeds 1-8 (~9 s a seed for both runs): the card hides 12-31 lost points in view (tried in the
// frame after it came, without the back-off); in its last 12 frames the back-off tries 0.10-0.14 of the
// control's requests (one frame in 8 is 0.125); after it goes the back-off re-attaches 0.94-1.0 times the
// control's points (9-16), and without the look at new corners it re-attached 0.56-0.73 times (seeds 1, 2, a
// 25-frame card: the new tracks took the corners). Bounds: 0.25 (about twice the worst measured) and 0.8
// (between the two behaviours).
TEST(VisualSlam, RemappingBacksOffFromPointsItCannotFindAndTakesThemBackWhenTheyReappear) {
  for (uint64_t seed : {1, 2, 4}) {
    SCOPED_TRACE(::testing::Message() << "seed " << seed);
    const RemapCounts with = RunWithCard(seed, true, 0), without = RunWithCard(seed, false);
    std::printf("seed %llu: tried first %d / %d, in the card's last 12 frames %d / %d, re-attached after %d / %d "
                "(back-off / none)\n",
                static_cast<unsigned long long>(seed), with.first_tried, without.first_tried, with.late_tried,
                without.late_tried, with.back_remapped, without.back_remapped);
    EXPECT_GE(without.first_tried, 8);  // the card hides points to look for (measured 12 at least)
    EXPECT_GE(without.late_tried, 12 * without.first_tried / 2);  // the control tries them in every frame
    EXPECT_LE(with.late_tried, 0.25 * without.late_tried);
    EXPECT_GE(with.back_remapped, 0.8 * without.back_remapped);
    EXPECT_GE(without.back_remapped, 5);  // the points come back when the card goes (measured 9 at least)
    if (seed == 1) {  // a thin map (no pose has that many inliers) never backs off: the control's run exactly
      const RemapCounts thin = RunWithCard(seed, true, std::numeric_limits<int>::max());
      EXPECT_EQ(thin.first_tried, without.first_tried);
      EXPECT_EQ(thin.late_tried, without.late_tried);
      EXPECT_EQ(thin.back_remapped, without.back_remapped);
    }
  }
}

// VisualSlamOptions::pipelined: each Push starts its frame's front end and runs the back end of the frame before,
// whose step it returns; Flush brings back the frame in flight (before a gap of unreadable frames and at the end).
// Every frame gets one step, in order; the same seed gives the same poses; and the frames are tracked as well as
// sequentially: the front end looks for lost points where the frame before the last placed them, which changes the
// runs in their last digits and, through them, their seed-to-seed noise. Measured over the rendered paper scenario
// (`mcslam run --pipelined`, seeds 1-5, 300 frames): ATE 0.06-0.20 % of the path, sequentially 0.05-0.34 %; here
// (120 frames, a 10-frame gap from frame 80) seeds 1-2: every frame tracked in both loops, the worst position error
// 13.6 and 6.9 mm pipelined, 12.7 and 8.6 mm sequentially. Bounds: every frame after the gap tracked, the worst error
// under 11 cm as the gap test above has it (a wrong relocalisation is tens of centimetres off).
TEST(VisualSlam, ThePipelinedLoopGivesEveryFrameItsStepInOrderAndTracksThemAll) {
  constexpr int kFrames = 120, kGapBegin = 80, kGapEnd = 90;
  for (uint64_t seed : {1, 2}) {
    SCOPED_TRACE(::testing::Message() << "seed " << seed);
    const Scene scene(kFrames, seed);
    VisualSlamOptions options;
    options.pipelined = true;
    std::vector<Reports> runs;
    for (int run = 0; run < 2; ++run) {
      VisualSlam vs(scene.seq.camera, options, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
      Reports reports;
      std::vector<int64_t> order;
      bool relocalised_after_gap = false;
      auto take = [&](const std::optional<VisualSlamStep>& step) {
        if (!step) return;
        order.push_back(step->frontend.index);
        if (step->frontend.index == kGapEnd) relocalised_after_gap = step->reloc_tried;
        Keep(*step, &reports);
      };
      for (int i = 0; i < kFrames; ++i) {
        if (i >= kGapBegin && i < kGapEnd) {
          if (i == kGapBegin) {
            EXPECT_THROW(vs.SkipFrame(), std::logic_error);  // the frame before the gap is in flight
            take(vs.Flush());
          }
          vs.SkipFrame();
          continue;
        }
        const std::optional<VisualSlamStep> step = vs.Push(scene.Frame(i), i, i / kFps);
        EXPECT_EQ(step.has_value(), i > 0 && i != kGapEnd) << "frame " << i;  // nothing in flight then
        take(step);
      }
      EXPECT_THROW(vs.Finish(), std::logic_error);
      take(vs.Flush());
      EXPECT_FALSE(vs.Flush().has_value());
      for (const slam::FrameReport& r : vs.Finish()) reports[r.index] = r;
      std::vector<int64_t> expected;
      for (int i = 0; i < kFrames; ++i)
        if (i < kGapBegin || i >= kGapEnd) expected.push_back(i);
      EXPECT_EQ(order, expected);
      EXPECT_TRUE(relocalised_after_gap);
      int tracked_after = 0;
      for (int i = kGapEnd; i < kFrames; ++i)
        tracked_after += reports.count(i) && reports.at(i).status == slam::FrameStatus::kTracked;
      EXPECT_EQ(tracked_after, kFrames - kGapEnd);
      double worst = 0;
      for (const auto& [i, e] : ErrorsAfterAlignment(scene, reports)) worst = std::max(worst, e);
      std::printf("seed %llu run %d: worst position error %.4f m\n", static_cast<unsigned long long>(seed), run, worst);
      EXPECT_LT(worst, 0.11);
      runs.push_back(std::move(reports));
    }
    // The same seed, the same poses, to the last bit: the two stages share nothing while they overlap.
    ASSERT_EQ(runs[0].size(), runs[1].size());
    for (const auto& [i, r] : runs[0]) {
      ASSERT_TRUE(runs[1].count(i)) << i;
      EXPECT_EQ(r.cam_from_world.t, runs[1].at(i).cam_from_world.t) << "frame " << i;
    }
  }
}

// ---- maps saved and loaded ---------------------------------------------------------------------------------

// MappingOptions::local_ba_async, as `mcslam run` has it: a keyframe's local bundle adjustment is solved while the
// next frame's front end runs; that frame's step starts with the keyframe's revised report, and Finish hands
// over the last one. The last frame's report then holds the pose the System ends with.
TEST(VisualSlam, ALocalAdjustmentSolvedBesideTheNextFrameComesBackWithIt) {
  constexpr int kFrames = 130;
  const Scene scene(kFrames, 1);
  VisualSlamOptions options;
  options.system.mapping.local_ba_async = true;
  VisualSlam vs(scene.seq.camera, options, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
  Reports reports;
  int revised = 0;
  for (int i = 0; i < kFrames; ++i) {
    const VisualSlamStep step = vs.Process(scene.Frame(i), i, i / kFps);
    for (size_t k = 0; k < step.reports.size(); ++k) {
      if (!step.reports[k].local_ba) continue;
      EXPECT_EQ(k, 0u) << "frame " << i;
      EXPECT_EQ(step.reports[k].index, i - 1);
      ++revised;
    }
    Keep(step, &reports);
  }
  // The last frame's, when it had one (measured: it has).
  const std::vector<slam::FrameReport> last = vs.Finish();
  ASSERT_LE(last.size(), 1u);
  // Measured: 35 in all. The first map settles until frame ~95 here (no local adjustment meanwhile), then every
  // frame is an adjusted keyframe; the bound leaves the settling 14 frames more on another CPU.
  EXPECT_GE(revised + static_cast<int>(last.size()), 20);
  EXPECT_TRUE(vs.Finish().empty());
  const slam::Map& map = vs.system().map();
  for (const slam::FrameReport& r : last) {
    EXPECT_EQ(r.index, kFrames - 1);
    EXPECT_TRUE(r.local_ba);
    const auto frame = std::find_if(map.frames.begin(), map.frames.end(),
                                    [](const slam::FrameRecord& f) { return f.index == kFrames - 1; });
    ASSERT_NE(frame, map.frames.end());
    EXPECT_EQ(r.cam_from_world.t, frame->cam_from_world.t);
    EXPECT_EQ(r.cam_from_world.q.coeffs(), frame->cam_from_world.q.coeffs());
  }
  for (int i = 0; i < kFrames; ++i) EXPECT_TRUE(reports.count(i)) << i;
}

TEST(VisualSlamMap, AMapLoadedAndSavedAgainIsTheSameFile) {
  constexpr int kFrames = 60;
  const Scene scene(kFrames, 2);
  VisualSlam first = Make(scene);
  for (int i = 0; i < kFrames; ++i) first.Process(scene.Frame(i), i, i / kFps);
  ASSERT_TRUE(first.system().initialised());
  io::MapFile map = first.ExportMap();
  map.options = {{"note", "as the caller fills it"}};
  ASSERT_GT(map.points.size(), 50u);
  const slam::Map& m = first.system().map();
  ASSERT_EQ(map.keyframes.size(), static_cast<size_t>(std::count_if(m.keyframes.begin(), m.keyframes.end(), [&](int k) {
              return m.frames[static_cast<size_t>(k)].has_pose;
            })));
  ASSERT_GE(map.keyframes.size(), static_cast<size_t>(kFrames / 2));
  // Each point with a look: the live tracks' descriptors and those kept since a track ended.
  const auto described = std::count_if(map.points.begin(), map.points.end(), [](const io::MapFilePoint& p) {
    return p.descriptor.has_value() && p.first_descriptor.has_value();
  });
  EXPECT_EQ(static_cast<size_t>(described), map.points.size());
  const std::vector<uint8_t> bytes = io::SerialiseMapFile(map);

  VisualSlam second = Make(scene);
  second.LoadMap(io::ParseMapFile(bytes, "first.map"));
  EXPECT_TRUE(second.system().initialised());
  io::MapFile again = second.ExportMap();
  again.options = map.options;
  EXPECT_EQ(io::SerialiseMapFile(again), bytes);
  // New tracks are numbered above every id of the map, so that none is taken for a map point.
  int64_t max_id = 0;
  for (const io::MapFilePoint& p : map.points) max_id = std::max(max_id, p.id);
  for (const io::MapFileKeyframe& k : map.keyframes)
    for (int64_t id : k.feature_ids) max_id = std::max(max_id, id);
  EXPECT_GT(second.frontend().NextFeatureId(), max_id);

  // A map whose run self-calibrated its lens' k1 (InitOptions::self_calibrate) is loaded with the camera as
  // given, and the run goes on with the map's k1 (its features are undistorted with it); any other difference is
  // refused.
  io::MapFile calibrated = map;
  calibrated.camera.dist.k1 = -0.03;
  VisualSlam third = Make(scene);
  third.LoadMap(calibrated);
  EXPECT_EQ(third.system().camera().dist.k1, -0.03);
  EXPECT_EQ(third.ExportMap().camera.dist.k1, -0.03);
  calibrated.camera.dist.k2 = 0.01;
  VisualSlam fourth = Make(scene);
  try {
    fourth.LoadMap(calibrated);
    ADD_FAILURE() << "a map of another lens was loaded";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("k2"), std::string::npos) << e.what();
  }
}

// A run in a loaded map localises in that map's frame: none of its points is moved, by the local bundle adjustment
// (which holds them fixed), by the Monte Carlo point adjustment (which skips them) or by the bundle adjustment that
// --structure ba runs in its place (which holds them fixed too); one that left the map and was
// triangulated again from this run's views is this run's (System::Loaded false). Before the point adjustment
// skipped them, it re-sampled loaded points whose residual in this run was over its candidate threshold: on 7-Scenes
// a tenth of them moved by up to 9 map units and the second run drifted 10 % in scale out of the map
// (docs/tuning.md).
TEST(VisualSlamMap, ARunInALoadedMapMovesNoneOfItsPoints) {
  constexpr int kFrames = 120;
  const Scene scene(kFrames, 3);
  VisualSlam first = Make(scene);
  for (int i = 0; i < kFrames; ++i) first.Process(scene.Frame(i), i, i / kFps);
  first.Finish();
  ASSERT_TRUE(first.system().initialised());
  const io::MapFile map = first.ExportMap();
  std::map<int64_t, Eigen::Vector3d> where;
  for (const io::MapFilePoint& p : map.points) where[p.id] = p.position_in_world;

  // The default structure step, and the bundle adjustment that takes its place (--structure ba, §8's baseline).
  for (const slam::StructureMethod method : {slam::StructureMethod::kMonteCarlo, slam::StructureMethod::kBundleAdjustment}) {
    SCOPED_TRACE(method == slam::StructureMethod::kMonteCarlo ? "Monte Carlo structure" : "bundle adjustment structure");
    VisualSlamOptions options;
    options.system.structure_method = method;
    VisualSlam second(scene.seq.camera, options, compute::MakeCpuPoseKernel(), compute::MakeCpuPointKernel());
    second.LoadMap(map);
    Reports reports;
    for (int i = 0; i < kFrames; ++i) Keep(second.Process(scene.Frame(i), i, i / kFps), &reports);
    for (const slam::FrameReport& r : second.Finish()) reports[r.index] = r;
    int tracked = 0, adjusted = 0;
    for (const auto& [i, r] : reports) tracked += r.status == slam::FrameStatus::kTracked, adjusted += r.adjusted;
    EXPECT_EQ(tracked, kFrames);
    EXPECT_GT(adjusted, 0);  // the adjustments ran
    int held = 0;
    for (const slam::MapPoint& p : second.system().map().points()) {
      if (!second.system().Loaded(p.id)) {
        EXPECT_FALSE(where.count(p.id) && p.state != slam::PointState::kRemoved && p.position_in_world == where.at(p.id))
            << "point " << p.id << " is the loaded map's, where it put it, but not held";
        continue;
      }
      ASSERT_TRUE(where.count(p.id)) << "point " << p.id << " is this run's, not the loaded map's";
      EXPECT_EQ(p.position_in_world, where.at(p.id)) << "loaded point " << p.id << " moved";
      held += p.state != slam::PointState::kRemoved;
    }
    // Most of the map stays in it: a run that dropped its loaded points would hold nothing.
    EXPECT_GE(held, static_cast<int>(map.points.size()) / 2) << "of " << map.points.size();
  }
}

TEST(VisualSlamMap, AMapIsRefusedWhereItCannotBeUsed) {
  const Scene scene(10, 1);
  VisualSlam vs = Make(scene);
  for (int i = 0; i < 3; ++i) vs.Process(scene.Frame(i), i, i / kFps);
  io::MapFile map = vs.ExportMap();  // not initialised: no point
  VisualSlam empty = Make(scene);
  try {
    empty.LoadMap(map);
    FAIL() << "a map without points was loaded";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("none with a descriptor"), std::string::npos) << e.what();
  }
  map.camera.fx += 5;
  VisualSlam other = Make(scene);
  try {
    other.LoadMap(map);
    FAIL() << "a map of another camera was loaded";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("another camera"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("fx"), std::string::npos) << e.what();
  }
  // After frames, even a good map (the one of the test above) is refused, and nothing changes.
  const Scene longer(40, 1);
  VisualSlam mapped = Make(longer);
  for (int i = 0; i < 40; ++i) mapped.Process(longer.Frame(i), i, i / kFps);
  ASSERT_TRUE(mapped.system().initialised());
  const io::MapFile good = mapped.ExportMap();
  EXPECT_THROW(vs.LoadMap(good), std::logic_error);
  EXPECT_FALSE(vs.system().initialised());
}

TEST(VisualSlamOptions, CheckNamesTheField) {
  VisualSlamOptions o;
  EXPECT_NO_THROW(o.Check());
  o.max_remap_requests = -1;
  EXPECT_THROW(o.Check(), std::invalid_argument);
  testing::ExpectThrowsWith([&] { o.Check(); }, "max_remap_requests");
  o = {};
  o.remap_retry_every = 0;
  EXPECT_THROW(o.Check(), std::invalid_argument);
  testing::ExpectThrowsWith([&] { o.Check(); }, "remap_retry_every");
  o = {};
  o.remap_tries_every_frame = -1;
  EXPECT_THROW(o.Check(), std::invalid_argument);
  o = {};
  o.relocalisation_max_distance = 0;
  EXPECT_THROW(o.Check(), std::invalid_argument);
  o = {};
  o.system.tracker.hypotheses = 0;  // the System's own checks run too
  EXPECT_THROW(o.Check(), std::invalid_argument);
}

}  // namespace
}  // namespace mcslam::pipeline
