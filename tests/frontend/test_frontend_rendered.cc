// The front end on the rendered paper scene, where every feature's truth is known: the scene point a track
// starts on (ray-cast from its first pixel with the exact pose) projects, with the exact pose of each later
// frame, where the track should be. The distance is the tracker's own error, free of any 3D estimate.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <optional>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "core/median.h"
#include "frontend/frontend.h"
#include "sim/paper_scenario.h"
#include "sim/render.h"

namespace mcslam::frontend {
namespace {

struct DriftFigures {
  // Error of the live tracks against the truth, by age (frames since the track was born or re-attached):
  // tracks born inside one surface, and those born where the surface changes (the box's outline, an edge
  // between faces: a corner there is no point of the scene and slides along the outline as the view turns).
  std::map<int, std::vector<double>> by_age, by_age_outline;
  int tracks = 0, outline_tracks = 0;
};

DriftFigures MeasureDrift(int frames, const FrontendOptions& options) {
  sim::PaperScenarioOptions so;
  so.frames = frames;
  const sim::SyntheticSequence seq = sim::MakePaperScenario(so);
  const sim::SceneRenderer renderer(sim::RenderOptions{});
  Frontend fe(options);
  struct Truth {
    std::optional<Eigen::Vector3d> point;
    bool outline = false;
  };
  std::map<int64_t, Truth> truth;  // per track, from its first pixel
  DriftFigures fig;
  for (int i = 0; i < frames; ++i) {
    const cv::Mat img = renderer.Render(seq.camera, seq.cam_from_world[static_cast<size_t>(i)], static_cast<uint64_t>(i));
    const FrameResult r = fe.Process(img, i, i / 30.0);
    for (const TrackedFeature& f : r.features) {
      auto it = truth.find(f.feature_id);
      const Pose& pose = seq.cam_from_world[static_cast<size_t>(i)];
      if (it == truth.end()) {
        Truth t;
        const auto hit = renderer.SurfacePoint(seq.camera, pose, f.uv_px);
        if (hit) t.point = hit->point;
        // Outline: some pixel within 10 px (the LK window's half side) sees another surface or the background.
        for (int dy = -10; dy <= 10 && hit; dy += 2)
          for (int dx = -10; dx <= 10; dx += 2) {
            const auto h = renderer.SurfacePoint(seq.camera, pose, f.uv_px + Eigen::Vector2d(dx, dy));
            if (!h || h->surface != hit->surface) t.outline = true;
          }
        fig.outline_tracks += t.outline;
        truth[f.feature_id] = t;
        ++fig.tracks;
        continue;
      }
      if (!it->second.point) continue;
      Eigen::Vector2d uv;
      if (!seq.camera.ProjectWorld(pose, *it->second.point, &uv)) continue;
      auto& bins = it->second.outline ? fig.by_age_outline : fig.by_age;
      bins[f.age_frames].push_back((uv - f.uv_px).norm());
    }
  }
  return fig;
}

// The errors in `by_age` at ages [lo, hi), sorted.
std::vector<double> Errors(const std::map<int, std::vector<double>>& by_age, int lo, int hi) {
  std::vector<double> e;
  for (auto it = by_age.lower_bound(lo); it != by_age.end() && it->first < hi; ++it)
    e.insert(e.end(), it->second.begin(), it->second.end());
  std::sort(e.begin(), e.end());
  return e;
}

void Print(const char* label, const DriftFigures& fig) {
  std::printf("%s: %d tracks, %d born on an outline\n", label, fig.tracks, fig.outline_tracks);
  const int bins[][2] = {{1, 5}, {5, 20}, {20, 50}, {50, 100}, {100, 200}};
  for (const auto* m : {&fig.by_age, &fig.by_age_outline}) {
    std::printf("  %s\n", m == &fig.by_age ? "born inside a surface" : "born on an outline");
    for (const auto& b : bins) {
      const std::vector<double> e = Errors(*m, b[0], b[1]);
      if (e.empty()) continue;
      std::printf("    age %3d-%3d: n=%5zu median %.3f px  p90 %.3f px  max %.2f px\n", b[0], b[1], e.size(), UpperMedian(e),
                  e[e.size() * 9 / 10], e.back());
    }
  }
}

// Frame-to-frame LK slides: the paper scene's tracks are pixels off their scene point after a hundred frames.
// Aligned with their birth patch (the default), they stay within a tenth of a pixel.
TEST(FrontendRendered, AnchoredTracksStayOnTheirScenePoint) {
  FrontendOptions plain;
  plain.anchor_every = 0;
  const DriftFigures anchored = MeasureDrift(200, FrontendOptions{}), drifting = MeasureDrift(200, plain);
  Print("anchored (default)", anchored);
  Print("frame-to-frame only (anchor_every = 0)", drifting);
  const std::vector<double> a = Errors(anchored.by_age, 100, 200), d = Errors(drifting.by_age, 100, 200);
  ASSERT_GT(a.size(), 500u);  // measured ~1900 (track, frame) pairs: the anchoring keeps most tracks alive
  ASSERT_GT(d.size(), 500u);
  // Dropping the tracks that no longer match their birth patch must not leave only the easy ones: the anchored
  // run keeps most of the (track, frame) pairs the plain one has at these ages (measured 73 %).
  EXPECT_GT(static_cast<double>(a.size()), 0.5 * static_cast<double>(d.size()));
  auto within = [](const std::vector<double>& e, double px) {
    return static_cast<double>(std::lower_bound(e.begin(), e.end(), px) - e.begin()) / static_cast<double>(e.size());
  };
  std::printf("ages 100-199, within 0.5 px: anchored %.3f, frame-to-frame %.3f\n", within(a, 0.5), within(d, 0.5));
  // Measured: anchored median 0.08 px, frame-to-frame 1.67 px; the bounds sit between the two with a margin of
  // 2x or more on each side. Some anchored tracks still slide (occluded points whose patch keeps matching at a
  // correlation above 0.9): the share within 0.5 px is checked, not the tail.
  EXPECT_LT(UpperMedian(a), 0.2);
  EXPECT_GT(UpperMedian(d), 0.6);
  // Measured: 83 % of the anchored (track, frame) pairs within 0.5 px of the truth, 10 % of the others.
  EXPECT_GT(within(a, 0.5), 0.6);
  EXPECT_LT(within(d, 0.5), 0.3);
  // Right after birth the two agree (the anchoring cannot make young tracks worse): ages 1-5 median below
  // 0.15 px for both (measured 0.05-0.08 px).
  EXPECT_LT(UpperMedian(Errors(anchored.by_age, 1, 5)), 0.15);
  EXPECT_LT(UpperMedian(Errors(drifting.by_age, 1, 5)), 0.15);
}

// The paper scene's first frames, then frames changed by `change` (a camera's photometry: exposure, blur) from
// frame `from` on; the results of the frames from `from` on.
template <typename Change>
std::vector<FrameResult> RunWithChange(const FrontendOptions& options, int from, int frames, Change change) {
  sim::PaperScenarioOptions so;
  so.frames = frames;
  const sim::SyntheticSequence seq = sim::MakePaperScenario(so);
  const sim::SceneRenderer renderer(sim::RenderOptions{});
  Frontend fe(options);
  std::vector<FrameResult> out;
  for (int i = 0; i < frames; ++i) {
    cv::Mat img = renderer.Render(seq.camera, seq.cam_from_world[static_cast<size_t>(i)], static_cast<uint64_t>(i));
    if (i >= from) change(i, img);
    FrameResult r = fe.Process(img, i, i / 30.0);
    if (i >= from) out.push_back(std::move(r));
  }
  return out;
}

// One exposure step by `factor` at frame 30 of the paper scene, with and without its compensation: the step
// frame's tracks before it, those lost either way, and the gain each measured.
struct ExposureStep {
  int before = 0, lost_with = 0, lost_without = 0;
  float gain_with = 1, gain_without = 1;
};
ExposureStep RunExposureStep(double factor) {
  const auto scaled = [factor](int, cv::Mat& img) { img.convertTo(img, -1, factor); };
  FrontendOptions off;
  off.exposure_min_change = 0;
  const std::vector<FrameResult> with = RunWithChange(FrontendOptions{}, 30, 31, scaled);
  const std::vector<FrameResult> without = RunWithChange(off, 30, 31, scaled);
  ExposureStep e;
  e.lost_with = static_cast<int>(with[0].lost.size());
  e.lost_without = static_cast<int>(without[0].lost.size());
  e.before = with[0].stats.tracked + e.lost_with;
  e.gain_with = with[0].stats.exposure_gain;
  e.gain_without = without[0].stats.exposure_gain;
  std::printf("exposure %.1fx: %d tracks before; lost %d with compensation (gain %.3f), %d without\n", factor,
              e.before, e.lost_with, e.gain_with, e.lost_without);
  return e;
}

// An auto exposure that jumps (0.6x here) scales every intensity: Lucas-Kanade matches intensities as they are and
// loses tracks, unless the previous frame is first brought to the new exposure (FrontendOptions::
// exposure_min_change). Measured on this scene: with it 3 of 76 tracks lost and the gain measured 0.608; without it
// 48 lost. Bounds: at most 10 % lost with it, at least 25 % without; the gain within 0.02 (the 8-bit rounding of
// the darker frame and the texture clipped at black move the windows' mean ratio by ~1 %).
TEST(FrontendRendered, AnExposureStepKeepsTheTracks) {
  const ExposureStep e = RunExposureStep(0.6);
  ASSERT_GT(e.before, 40);
  EXPECT_NEAR(e.gain_with, 0.6, 0.02);
  EXPECT_LE(e.lost_with, 0.10 * e.before);
  EXPECT_GE(e.lost_without, 0.25 * e.before);
  EXPECT_EQ(e.gain_without, 1.0f);
}

// A step down so large that Lucas-Kanade follows almost no track before the compensation (0.4x here; the rendered
// planar scenario's 1/1.69 step from a clipped exposure lost 93 of 94): the gain cannot be measured on the tracks
// that followed, so it is measured where the tracks were predicted to be. Measured on this scene: gain 0.400, 3 of
// 76 lost with it, 71 without (the 5 that followed are too few to measure it: 8 needed). Bounds as above: at most
// 10 % lost with it, the gain within 0.02; and the step must lose at least 90 % of the tracks without compensation
// (else the windows of the followed tracks would measure it and this would test nothing new).
TEST(FrontendRendered, AnExposureStepThatLosesEveryTrackIsMeasuredAtThePredictions) {
  const ExposureStep e = RunExposureStep(0.4);
  ASSERT_GT(e.before, 40);
  ASSERT_GE(e.lost_without, 0.90 * e.before);
  EXPECT_NEAR(e.gain_with, 0.4, 0.02);
  EXPECT_LE(e.lost_with, 0.10 * e.before);
}

// The same measurement must not take a jolt for a change of light: a frame whose tracks all fail because the view
// jumped (the image shifted by 20-60 px, the light unchanged) compares other texture in the windows at the
// predictions and measures a gain that is not there, which must then be refused because it does not follow the
// tracks. Measured on this scene: no gain taken for any of the four jolts; with that check off, the 30 px jolt took
// a gain of 0.913. Exact: a gain is taken or it is not.
TEST(FrontendRendered, AJoltIsNotTakenForAnExposureStep) {
  for (const int jolt : {20, 30, 40, 60}) {
    const auto shifted = [jolt](int, cv::Mat& img) {
      const cv::Mat m = (cv::Mat_<double>(2, 3) << 1, 0, jolt, 0, 1, jolt / 2);
      cv::warpAffine(img, img, m, img.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
    };
    const std::vector<FrameResult> r = RunWithChange(FrontendOptions{}, 30, 31, shifted);
    std::printf("jolt %d px: tracked %d, lost %zu, gain %.3f\n", jolt, r[0].stats.tracked, r[0].lost.size(),
                r[0].stats.exposure_gain);
    EXPECT_EQ(r[0].stats.exposure_gain, 1.0f) << jolt;
  }
}

// Two blurred frames (Gaussian, sigma 2 px: a shake) between sharp ones. The blurred frames must keep their tracks
// where LK puts them, take no new patch and no new corner, so that the sharp frame after them still aligns with
// the sharp birth patches (FrontendOptions::anchor_blur_ratio). Measured on this scene: sharpness ratios 0.40 in
// both blurred frames, 0.90 in the sharp one after; with the check off, 46 tracks took blurred patches in the first
// blurred frame and the sharp frame after measured 1.99 against them. Bounds: blurred below 0.6; the sharp frame
// after within [0.8, 1.2] with the check (sharp frames measure 0.86-1.0), above 1.3 without; no track lost to its
// patch in the blurred frames.
TEST(FrontendRendered, ABlurredFrameKeepsItsTracksAndTheirBirthPatches) {
  const auto shake = [](int i, cv::Mat& img) {
    if (i < 32) cv::GaussianBlur(img, img, cv::Size(), 2.0);
  };
  FrontendOptions off;
  off.anchor_blur_ratio = 0;
  const std::vector<FrameResult> with = RunWithChange(FrontendOptions{}, 30, 33, shake);
  const std::vector<FrameResult> without = RunWithChange(off, 30, 33, shake);
  for (size_t k = 0; k < with.size(); ++k)
    std::printf("frame %zu: sharpness %.3f (off: %.3f), blurred %d, re-anchored %d (off: %d), new corners %d, lost to "
                "the patch %d\n",
                30 + k, with[k].stats.anchor_sharpness, without[k].stats.anchor_sharpness, with[k].stats.blurred,
                with[k].stats.reanchored, without[k].stats.reanchored, with[k].stats.detected,
                with[k].stats.lost_anchor);
  for (size_t k = 0; k < 2; ++k) {
    const FrameStats& st = with[k].stats;
    EXPECT_TRUE(st.blurred) << k;
    EXPECT_LT(st.anchor_sharpness, 0.6f) << k;
    EXPECT_EQ(st.reanchored, 0) << k;
    EXPECT_EQ(st.detected, 0) << k;
    EXPECT_EQ(st.lost_anchor, 0) << k;
  }
  EXPECT_GT(without[0].stats.reanchored, 5);
  EXPECT_FALSE(with[2].stats.blurred);
  EXPECT_GT(with[2].stats.anchor_sharpness, 0.8f);
  EXPECT_LT(with[2].stats.anchor_sharpness, 1.2f);
  EXPECT_GT(without[2].stats.anchor_sharpness, 1.3f);
}

// A dark, noisy camera (the paper scene at a quarter of its contrast with Gaussian noise of 2 grey levels added):
// even the tracks that follow their point correlate ~0.85 with their birth patches, so at the fixed 0.9 most of
// them mismatched, the frame's many mismatches made them take new patches (38 a frame on average over the run),
// and the tracks slid as frame-to-frame tracking does (ATE 0.27 -> 3.7 cm on seed 2). The threshold is lowered by
// the correlation the measured noise leaves a patch (frontend_impl.h, AlignWithAnchor). Measured here: noise
// measured 1.99 grey levels (the added 2 and the renderer's own quarter); 2.5 tracks a frame take new patches over
// frames 30-59 (7.4 before the detection's noise floor kept the noise from passing as new corners). Bounds: the noise within 1.6-2.6; at most 15 new patches a frame (38 with the fixed threshold).
TEST(FrontendRendered, ANoisyDarkCameraKeepsItsBirthPatches) {
  cv::RNG rng(7);
  const auto dark = [&](int, cv::Mat& img) {
    cv::Mat f, noise(img.size(), CV_32F);
    img.convertTo(f, CV_32F, 0.25);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, 2.0);
    f += noise;
    f.convertTo(img, CV_8U);
  };
  const std::vector<FrameResult> r = RunWithChange(FrontendOptions{}, 0, 60, dark);
  double reanchored = 0, noise = 0;
  for (size_t k = 30; k < r.size(); ++k) reanchored += r[k].stats.reanchored, noise += r[k].stats.noise_grey;
  reanchored /= 30, noise /= 30;
  std::printf("dark and noisy: noise measured %.2f grey levels, %.1f new patches a frame\n", noise, reanchored);
  EXPECT_GT(noise, 1.6);
  EXPECT_LT(noise, 2.6);
  EXPECT_LE(reanchored, 15.0);
}

// A noisy camera (the paper scene with Gaussian noise of 6 grey levels added): with a threshold relative to the
// frame's strongest corner only, the noise itself passes as corners in the empty cells, which the next frame's
// forward-backward check drops again (the whole run's ATE 0.32 -> 2.2 cm). The threshold's noise floor
// (FrontendOptions::corner_noise_margin) keeps the detections near the clean frames'. Measured over frames 1-59:
// clean 56 new corners; noisy 95 with the floor (1.7x), 832 without it (15x). Bounds: with the floor at most 2.5x
// the clean count, without it at least 5x (the test fails if the floor does nothing); the noise measured 6.42
// against the 6.1 expected, within 0.8 (the estimate moves in steps of 0.25 grey levels).
TEST(FrontendRendered, ANoisyCamerasNoiseIsNotTakenForCorners) {
  cv::RNG rng(11);
  const auto noisy = [&](int, cv::Mat& img) {
    cv::Mat f, noise(img.size(), CV_32F);
    img.convertTo(f, CV_32F);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, 6.0);
    f += noise;
    f.convertTo(img, CV_8U);
  };
  const auto none = [](int, cv::Mat&) {};
  FrontendOptions off;
  off.corner_noise_margin = 0;
  auto detected = [](const std::vector<FrameResult>& r) {
    int n = 0;
    for (size_t k = 1; k < r.size(); ++k) n += r[k].stats.detected;
    return n;
  };
  const std::vector<FrameResult> clean = RunWithChange(FrontendOptions{}, 0, 60, none);
  const std::vector<FrameResult> with = RunWithChange(FrontendOptions{}, 0, 60, noisy);
  const std::vector<FrameResult> without = RunWithChange(off, 0, 60, noisy);
  const int c = detected(clean), w = detected(with), wo = detected(without);
  std::printf("new corners over frames 1-59: clean %d, noisy %d with the noise floor, %d without; noise measured %.2f\n",
              c, w, wo, with[30].stats.noise_grey);
  ASSERT_GT(c, 20);
  EXPECT_LE(w, 2.5 * c);
  EXPECT_GE(wo, 5 * c);
  EXPECT_NEAR(with[30].stats.noise_grey, 6.1, 0.8);  // the added 6 and the renderer's own 1.2 in quadrature
}

}  // namespace
}  // namespace mcslam::frontend
