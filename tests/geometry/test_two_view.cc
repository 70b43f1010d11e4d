// With -march=native on AVX-512 machines, GCC 12 reports -Wmaybe-uninitialized false positives inside its own
// _mm512_extractf64x4_pd as Eigen's dynamic-size products instantiate it (here: the Cramer-Rao bound). They
// must be silenced before Eigen is included, so for this whole file.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "geometry/two_view.h"
#include "two_view_scene.h"

namespace mcslam::geometry {
namespace {

using testing::Corrupt;
using testing::CustomTwoViewScene;
using testing::NoiseOptions;
using testing::PaperTwoViewScene;
using testing::RotationErrorDeg;
using testing::TranslationDirectionErrorDeg;
using testing::TwoViewScene;

constexpr EssentialMethod kMethods[] = {EssentialMethod::kEightPoint, EssentialMethod::kFivePointOpenCV};

TwoViewOptions Options(EssentialMethod method) {
  TwoViewOptions o;
  o.method = method;
  return o;
}

TEST(EstimateTwoView, ExactDataGivesTheTruePoseAndStructure) {
  for (const EssentialMethod method : kMethods) {
    for (const uint64_t seed : {1, 2, 3}) {
      const TwoViewScene scene = PaperTwoViewScene(seed, 0, 12);
      const TwoViewResult r = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, Options(method));
      ASSERT_TRUE(r.ok) << ToString(method) << " seed " << seed << ": " << r.failure;
      EXPECT_EQ(r.status, TwoViewStatus::kOk);
      // Exact data: rounding and the LM's step tolerance only (~1e-10 deg); 1e-6 deg is a wide margin that
      // still catches any systematic error.
      EXPECT_LT(RotationErrorDeg(r.cam2_from_cam1, scene.cam2_from_cam1), 1e-6) << ToString(method);
      EXPECT_LT(TranslationDirectionErrorDeg(r.cam2_from_cam1, scene.cam2_from_cam1), 1e-6) << ToString(method);
      EXPECT_NEAR(r.cam2_from_cam1.t.norm(), 1.0, 1e-12);
      const int n = static_cast<int>(scene.uv_norm1.size());
      EXPECT_EQ(r.num_inliers, n);
      EXPECT_EQ(r.num_triangulated, n);  // the paper scene at 12 frames: every point has > 1 deg parallax
      // The structure is the truth divided by the baseline (|t| = 1); exact up to the pose's ~1e-10.
      const double b = scene.baseline_m();
      for (int i = 0; i < n; ++i) {
        ASSERT_TRUE(r.triangulated[i]);
        EXPECT_LT((r.points_in_cam1[i] * b - scene.points_in_cam1[i]).norm(), 1e-6 * scene.points_in_cam1[i].norm());
      }
      EXPECT_GT(r.median_parallax_deg, 1.0);
      EXPECT_LT(r.cheirality_ratio, 0.05);  // only points near an epipole could fit a wrong decomposition
    }
  }
}

// Tally of pose errors over seeds.
struct Accuracy {
  std::vector<double> rot, dir;
  int failures = 0;
  void Add(double r, double d) {
    rot.push_back(r);
    dir.push_back(d);
  }
  static double Mean(const std::vector<double>& v) {
    double s = 0;
    for (const double x : v) s += x;
    return v.empty() ? 0.0 : s / static_cast<double>(v.size());
  }
  static double Max(const std::vector<double>& v) { return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()); }
  static double Median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  }
  void Print(const char* label) const {
    std::printf("[ accuracy ] %-34s ok %2zu/%zu  rotation mean %.3f median %.3f max %.3f deg | direction mean %.3f median "
                "%.3f max %.3f deg\n",
                label, rot.size(), rot.size() + failures, Mean(rot), Median(rot), Max(rot), Mean(dir), Median(dir),
                Max(dir));
  }
};

// The done criterion of issue #4: 20 % wrong matches and 1 px noise at f = 500 (320x240): relative rotation to
// < 0.5 deg and translation direction to < 1 deg, for several seeds, with both methods.
//
// Not on the paper's box: with its ~200 points on 2-3 faces filling half of a 35 deg field of view, the
// Cramer-Rao bound at 1 px is 1.3-2 deg in rotation and 2-30 deg in direction (PaperSceneIsBelowTheCriterion
// below), so no estimator can meet the criterion there. Here: a room-like scene, 4000 points at 1-5 m filling
// the view (~3000 seen by both cameras), 30 cm of hand-held motion; bound ~0.02-0.2 deg / 0.1-0.5 deg.
TEST(EstimateTwoView, DoneCriterionTwentyPercentOutliersOnePixelNoise) {
  constexpr int kSeeds = 10;
  std::vector<TwoViewScene> scenes;
  double bound_rot = 0, bound_dir = 0;
  for (uint64_t seed = 1; seed <= kSeeds; ++seed) {
    scenes.push_back(testing::DeepTwoViewScene(seed, 4000, 0.3));
    const testing::CramerRao bound = testing::CramerRaoBound(scenes.back(), 1.0);
    bound_rot = std::max(bound_rot, bound.rotation_deg);
    bound_dir = std::max(bound_dir, bound.direction_deg);
    Corrupt({.noise_px = 1.0, .outlier_fraction = 0.2, .seed = seed}, &scenes.back());
  }
  std::printf("[ accuracy ] deep scene, %d seeds, ~3000 points: Cramer-Rao bound (RMS) at most %.3f deg rotation, %.3f "
              "deg direction\n",
              kSeeds, bound_rot, bound_dir);
  for (const EssentialMethod method : kMethods) {
    for (const bool refine : {false, true}) {
      Accuracy acc;
      for (uint64_t seed = 1; seed <= kSeeds; ++seed) {
        const TwoViewScene& scene = scenes[seed - 1];
        TwoViewOptions o = Options(method);
        o.refine = refine;
        o.ransac_threshold_px = 2.0;  // 2 sigma of the 1-dof Sampson residual under 1 px noise: keeps ~95 %
        o.seed = seed;
        const TwoViewResult r = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
        if (!r.ok) {
          ++acc.failures;
          if (refine) ADD_FAILURE() << ToString(method) << " seed " << seed << ": " << r.failure;
          continue;
        }
        const double rot = RotationErrorDeg(r.cam2_from_cam1, scene.cam2_from_cam1);
        const double dir = TranslationDirectionErrorDeg(r.cam2_from_cam1, scene.cam2_from_cam1);
        acc.Add(rot, dir);
        if (!refine) continue;  // the linear estimates are reported, not held to the criterion (see the table)
        EXPECT_LT(rot, 0.5) << ToString(method) << " seed " << seed;
        EXPECT_LT(dir, 1.0) << ToString(method) << " seed " << seed;
        // Wrong matches are (nearly all) rejected: one lands within 2 px of its epipolar line only by chance
        // (a 4 px band across a ~300 px image: ~1-2 %).
        int outliers_in = 0, outliers = 0;
        for (size_t i = 0; i < scene.is_outlier.size(); ++i) {
          outliers += scene.is_outlier[i];
          outliers_in += scene.is_outlier[i] && r.inliers[i];
        }
        EXPECT_LE(outliers_in, outliers / 20) << ToString(method) << " seed " << seed;
      }
      const std::string label = std::string("deep scene, ") + ToString(method) + (refine ? " + LM" : ", linear only");
      acc.Print(label.c_str());
    }
  }
}

// The paper's box at 1 px noise: the bound is above the criterion, i.e. the two-view problem itself is the
// limit there, not the estimator. The table documents what both methods do on it (8-point: mostly refused or
// wrong; 5-point: better but noise-limited), for whoever tunes the initialisation.
TEST(EstimateTwoView, PaperSceneIsBelowTheCriterion) {
  constexpr int kSeeds = 10;
  std::vector<TwoViewScene> scenes;
  for (uint64_t seed = 1; seed <= kSeeds; ++seed) {
    scenes.push_back(PaperTwoViewScene(seed, 0, 20));  // 20 frames: 10-50 cm of motion, 4-9 deg of rotation
    const testing::CramerRao bound = testing::CramerRaoBound(scenes.back(), 1.0);
    EXPECT_GT(bound.rotation_deg, 0.5) << "seed " << seed;  // the criterion is out of reach by theory
    Corrupt({.noise_px = 1.0, .outlier_fraction = 0.2, .seed = seed}, &scenes.back());
  }
  for (const EssentialMethod method : kMethods) {
    Accuracy acc;
    for (uint64_t seed = 1; seed <= kSeeds; ++seed) {
      const TwoViewScene& scene = scenes[seed - 1];
      TwoViewOptions o = Options(method);
      o.ransac_threshold_px = 2.0;
      o.seed = seed;
      const TwoViewResult r = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
      if (!r.ok) {
        ++acc.failures;
        EXPECT_FALSE(r.failure.empty());
        continue;
      }
      acc.Add(RotationErrorDeg(r.cam2_from_cam1, scene.cam2_from_cam1),
              TranslationDirectionErrorDeg(r.cam2_from_cam1, scene.cam2_from_cam1));
    }
    const std::string label = std::string("paper box, 1 px, ") + ToString(method) + " + LM";
    acc.Print(label.c_str());
  }
}

TEST(EstimateTwoView, ExactDataWithOutliers) {
  for (const EssentialMethod method : kMethods) {
    for (const bool refine : {false, true}) {
      for (uint64_t seed = 1; seed <= 5; ++seed) {
        TwoViewScene scene = testing::DeepTwoViewScene(seed, 1000, 0.3);
        Corrupt({.noise_px = 0.0, .outlier_fraction = 0.2, .seed = seed}, &scene);
        TwoViewOptions o = Options(method);
        o.refine = refine;
        o.seed = seed;
        const TwoViewResult r = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
        ASSERT_TRUE(r.ok) << ToString(method) << " refine " << refine << " seed " << seed << ": " << r.failure;
        const double rot = RotationErrorDeg(r.cam2_from_cam1, scene.cam2_from_cam1);
        const double dir = TranslationDirectionErrorDeg(r.cam2_from_cam1, scene.cam2_from_cam1);
        if (method == EssentialMethod::kFivePointOpenCV && !refine) {
          // OpenCV returns the model of its best minimal sample: 5 exact inliers give the exact model (up to
          // its polynomial roots, ~1e-9). 1e-5 deg: margin, and still catches any real error.
          EXPECT_LT(rot, 1e-5) << ToString(method) << " seed " << seed;
          EXPECT_LT(dir, 1e-5) << ToString(method) << " seed " << seed;
        } else {
          // The 8-point refit and the LM fit all inliers, and ~1 % of the wrong matches fall within the 1 px
          // band of their epipolar line by chance: they bias the fit a little, here by < 0.1 deg (a score that
          // takes them in is lower, so nothing in a robust fit can tell). At 1 px of noise the noise dominates
          // by far (see the done-criterion table).
          EXPECT_LT(rot, 0.1) << ToString(method) << " refine " << refine << " seed " << seed;
          EXPECT_LT(dir, 0.1) << ToString(method) << " refine " << refine << " seed " << seed;
        }
        for (size_t i = 0; i < scene.is_outlier.size(); ++i) {
          if (!scene.is_outlier[i]) {
            EXPECT_TRUE(r.inliers[i]) << "true inlier " << i << " rejected";
          }
        }
      }
    }
  }
}

TEST(EstimateTwoView, RansacIsDeterministicPerSeed) {
  TwoViewScene scene = testing::DeepTwoViewScene(3, 1000, 0.3);
  Corrupt({.noise_px = 1.0, .outlier_fraction = 0.2, .seed = 3}, &scene);
  TwoViewOptions o;
  o.ransac_threshold_px = 2.0;
  o.seed = 42;
  const TwoViewResult a = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
  const TwoViewResult b = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
  ASSERT_TRUE(a.ok) << a.failure;
  EXPECT_EQ(a.essential, b.essential);  // bit-identical
  EXPECT_EQ(a.cam2_from_cam1.q.coeffs(), b.cam2_from_cam1.q.coeffs());
  EXPECT_EQ(a.cam2_from_cam1.t, b.cam2_from_cam1.t);
  EXPECT_EQ(a.inliers, b.inliers);
  EXPECT_EQ(a.ransac_iterations, b.ransac_iterations);
  // Another seed draws other samples; it may end at the same optimum after the local optimisation.
  o.seed = 43;
  const TwoViewResult c = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
  ASSERT_TRUE(c.ok) << c.failure;
  EXPECT_LT(RotationErrorDeg(c.cam2_from_cam1, scene.cam2_from_cam1), 0.5);
}

TEST(EstimateTwoView, AdaptiveIterationsFollowTheInlierRatio) {
  TwoViewOptions o;
  o.ransac_threshold_px = 2.0;
  // Exact data: the first non-degenerate sample has all inliers, so one sample is enough.
  const TwoViewScene exact = testing::DeepTwoViewScene(1, 1000, 0.3);
  EXPECT_EQ(EstimateTwoView(exact.uv_norm1, exact.uv_norm2, o).ransac_iterations, 1);
  // 20 % outliers and 1 px noise (~5 % of the true inliers beyond 2 px): w ~ 0.76 once the local optimisation
  // found the model, log(0.001) / log(1 - 0.76^8) = 59; at least the 38 of w = 0.8; far below the cap.
  TwoViewScene noisy = testing::DeepTwoViewScene(1, 1000, 0.3);
  Corrupt({.noise_px = 1.0, .outlier_fraction = 0.2, .seed = 1}, &noisy);
  const int iterations = EstimateTwoView(noisy.uv_norm1, noisy.uv_norm2, o).ransac_iterations;
  EXPECT_GE(iterations, 38);
  EXPECT_LT(iterations, 500);
  // 60 % outliers: log(0.001) / log(1 - 0.4^8) ~ 10000 samples needed; the cap of 100 holds.
  TwoViewScene bad = testing::DeepTwoViewScene(1, 1000, 0.3);
  Corrupt({.noise_px = 0.0, .outlier_fraction = 0.6, .seed = 1}, &bad);
  o.max_iterations = 100;
  EXPECT_EQ(EstimateTwoView(bad.uv_norm1, bad.uv_norm2, o).ransac_iterations, 100);
}

TEST(EstimateTwoView, RefinementIsNeverWorseAndBetterOnNoisyDataInTheMean) {
  constexpr int kSeeds = 20;
  double linear_sum = 0, refined_sum = 0;
  int compared = 0;
  for (uint64_t seed = 1; seed <= kSeeds; ++seed) {
    TwoViewScene scene = testing::DeepTwoViewScene(seed, 1000, 0.3);
    Corrupt({.noise_px = 1.0, .outlier_fraction = 0.2, .seed = seed}, &scene);
    TwoViewOptions o;
    o.ransac_threshold_px = 2.0;
    o.seed = seed;
    o.refine = false;
    const TwoViewResult linear = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
    o.refine = true;
    const TwoViewResult refined = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
    ASSERT_TRUE(refined.ok) << "seed " << seed << ": " << refined.failure;
    if (!linear.ok) continue;  // the linear-only estimate may be refused (wrong basin); nothing to compare then
    ++compared;
    // LM from the linear estimate on its inliers never raises the cost it minimises (squared Sampson distances).
    std::vector<int> idx;
    for (size_t i = 0; i < linear.inliers.size(); ++i)
      if (linear.inliers[i]) idx.push_back(static_cast<int>(i));
    RefineSummary summary;
    RefineRelativePose(linear.cam2_from_cam1, scene.uv_norm1, scene.uv_norm2, idx, RefineOptions{}, &summary);
    EXPECT_LE(summary.final_cost, summary.initial_cost) << "seed " << seed;
    linear_sum += RotationErrorDeg(linear.cam2_from_cam1, scene.cam2_from_cam1) +
                  TranslationDirectionErrorDeg(linear.cam2_from_cam1, scene.cam2_from_cam1);
    refined_sum += RotationErrorDeg(refined.cam2_from_cam1, scene.cam2_from_cam1) +
                   TranslationDirectionErrorDeg(refined.cam2_from_cam1, scene.cam2_from_cam1);
  }
  std::printf("[ refine   ] deep scene, 1000 points, %d of %d seeds with a linear estimate: mean (rotation + "
              "direction) error linear %.3f deg, with LM %.3f deg\n",
              compared, kSeeds, linear_sum / compared, refined_sum / compared);
  EXPECT_GE(compared, kSeeds / 2);
  EXPECT_LT(refined_sum, linear_sum);
}

TEST(EstimateTwoView, PaperScenarioWithItsOwnOutliers) {
  // The simulator's outliers are per observation (20 % in each frame), so ~36 % of the correspondences are
  // wrong here. Exact projections otherwise: the linear 8-point estimate comes back exactly. (Not so the
  // refined one, nor OpenCV's 5-point, which picks its model by the inlier count: on this box a model 1-3 deg
  // off still fits the 160 true inliers within 1 px and takes in a few wrong matches more. That is how flat
  // the problem is there; see PaperSceneIsBelowTheCriterion.)
  for (const EssentialMethod method : {EssentialMethod::kEightPoint}) {
    for (const uint64_t seed : {7, 8, 9}) {
      sim::PaperScenarioOptions so;
      so.frames = 21;
      so.outlier_fraction = 0.2;
      so.seed = seed;
      const sim::SyntheticSequence seq = sim::MakePaperScenario(so);
      std::map<int64_t, Eigen::Vector2d> first;
      for (const auto& obs : seq.frames[0].observations) first[obs.feature_id] = obs.uv_px;
      std::vector<Eigen::Vector2d> uv1, uv2;
      for (const auto& obs : seq.frames[20].observations) {
        if (!first.count(obs.feature_id)) continue;
        uv1.push_back(seq.camera.PixelToNormalized(first[obs.feature_id]));
        uv2.push_back(seq.camera.PixelToNormalized(obs.uv_px));
      }
      TwoViewOptions o = Options(method);
      o.seed = seed;
      o.refine = false;
      const TwoViewResult r = EstimateTwoView(uv1, uv2, o);
      ASSERT_TRUE(r.ok) << ToString(method) << " seed " << seed << ": " << r.failure;
      const Pose truth = seq.cam_from_world[20] * seq.cam_from_world[0].Inverse();
      // Exact inliers: rounding only (see ExactDataWithOutliers).
      EXPECT_LT(RotationErrorDeg(r.cam2_from_cam1, truth), 1e-5) << ToString(method) << " seed " << seed;
      EXPECT_LT(TranslationDirectionErrorDeg(r.cam2_from_cam1, truth), 1e-5) << ToString(method) << " seed " << seed;
    }
  }
}

// ---- degenerate input -----------------------------------------------------------------------------------

const Pose kMotion(QuaternionFromRotationVector(Eigen::Vector3d(0.01, 0.04, -0.005)), Eigen::Vector3d(-0.25, 0.03, 0.05));

TEST(EstimateTwoView, PlanarSceneFails) {
  for (const EssentialMethod method : kMethods) {
    for (const double noise : {0.0, 1.0}) {
      TwoViewScene scene = CustomTwoViewScene(testing::PlanePoints(200, 3.0, 5), kMotion);
      ASSERT_GE(scene.uv_norm1.size(), 100u);
      Corrupt({.noise_px = noise, .outlier_fraction = 0.2, .seed = 5}, &scene);
      TwoViewOptions o = Options(method);
      o.ransac_threshold_px = noise > 0 ? 2.0 : 1.0;
      const TwoViewResult r = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
      EXPECT_FALSE(r.ok) << ToString(method) << " noise " << noise;
      EXPECT_EQ(r.status, TwoViewStatus::kPlanarOrRotation) << ToString(method) << " noise " << noise << ": " << r.failure;
      EXPECT_GT(r.homography_inlier_ratio, 0.9);
      // Without the homography test: a plane admits two exact essential matrices (the two physical
      // decompositions of its homography; for the 8-point, a 3-parameter family of which these two are the
      // essential ones), and the data cannot tell them apart. Which one comes out depends on the samples; the
      // twin has its translation along the plane normal (~75-100 deg off here) and puts the plane far away, so
      // the parallax check usually refuses it. Reported, not asserted: the homography test is the guard.
      o.max_homography_inlier_ratio = 2.0;
      const TwoViewResult r2 = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
      std::printf("[ planar   ] %s noise %.0f px, homography test off: %s; pose error %.2f deg rotation, %.1f deg "
                  "direction\n",
                  ToString(method), noise, r2.ok ? "ok" : r2.failure.c_str(),
                  RotationErrorDeg(r2.cam2_from_cam1, scene.cam2_from_cam1),
                  TranslationDirectionErrorDeg(r2.cam2_from_cam1, scene.cam2_from_cam1));
    }
  }
}

// The planar path (issue #16): where EstimateTwoView refuses a plane, the homography's decomposition gives the
// motion. Its two physical solutions both survive two views (the plane's two-fold ambiguity: the window of
// frames decides in the System); the true one must be among them. Exact data: within 1e-4 deg (measured 1e-5).
// 1 px of noise and 20 % wrong matches, seeds 1-10 (the plane 3 m away, a 0.26 m baseline, 5 deg of
// parallax): measured 1.8 deg rotation and 17 deg direction RMS, worst 2.5 and 30 deg: two views of a plane
// leave the direction loose (the System's window adjustment refines it). Bounds: twice the worst rotation,
// 1.5 times the worst direction, which still tells the true motion from its twin (75-100 deg off here).
TEST(EstimateTwoViewPlanar, OneSolutionIsTheTrueMotion) {
  double sum_rot = 0, sum_dir = 0, max_rot = 0, max_dir = 0;
  int noisy_runs = 0;
  for (const double noise : {0.0, 1.0}) {
    for (uint64_t seed = 1; seed <= (noise > 0 ? 10u : 1u); ++seed) {
      TwoViewScene scene = CustomTwoViewScene(testing::PlanePoints(200, 3.0, seed + 4), kMotion);
      Corrupt({.noise_px = noise, .outlier_fraction = 0.2, .seed = seed + 4}, &scene);
      TwoViewOptions o = Options(EssentialMethod::kEightPoint);
      o.ransac_threshold_px = noise > 0 ? 2.0 : 1.0;
      const std::vector<TwoViewResult> sols = EstimateTwoViewPlanar(scene.uv_norm1, scene.uv_norm2, o);
      ASSERT_FALSE(sols.empty()) << "noise " << noise << " seed " << seed;
      EXPECT_LE(sols.size(), 2u);  // two of the four decompositions put the plane behind a camera
      double best_rot = 1e9, best_dir = 1e9;
      for (const TwoViewResult& r : sols) {
        EXPECT_TRUE(r.ok);
        EXPECT_GE(r.num_triangulated, 100);
        const double rot = RotationErrorDeg(r.cam2_from_cam1, scene.cam2_from_cam1);
        const double dir = TranslationDirectionErrorDeg(r.cam2_from_cam1, scene.cam2_from_cam1);
        if (rot + dir < best_rot + best_dir) best_rot = rot, best_dir = dir;
      }
      if (noise == 0) {
        EXPECT_LT(best_rot, 1e-4);
        EXPECT_LT(best_dir, 1e-4);
        continue;
      }
      sum_rot += best_rot * best_rot, sum_dir += best_dir * best_dir, ++noisy_runs;
      max_rot = std::max(max_rot, best_rot), max_dir = std::max(max_dir, best_dir);
      EXPECT_LT(best_rot, 5.0) << "seed " << seed;
      EXPECT_LT(best_dir, 45.0) << "seed " << seed;
    }
  }
  std::printf("[ planar   ] 1 px, 20 %% outliers, 10 seeds: rotation RMS %.3f max %.3f deg, direction RMS %.2f max %.2f deg\n",
              std::sqrt(sum_rot / noisy_runs), max_rot, std::sqrt(sum_dir / noisy_runs), max_dir);
}

// A pure rotation is explained by a homography too, but has no translation to decompose: no solution (the
// initialisation waits).
TEST(EstimateTwoViewPlanar, PureRotationGivesNoSolution) {
  const Pose rotation(QuaternionFromRotationVector(Eigen::Vector3d(0.02, -0.06, 0.01)), Eigen::Vector3d::Zero());
  for (const double noise : {0.0, 1.0}) {
    TwoViewScene scene = CustomTwoViewScene(testing::VolumePoints(200, 2.0, 4.0, 3), rotation);
    Corrupt({.noise_px = noise, .outlier_fraction = 0.2, .seed = 3}, &scene);
    TwoViewOptions o = Options(EssentialMethod::kEightPoint);
    o.ransac_threshold_px = noise > 0 ? 2.0 : 1.0;
    EXPECT_TRUE(EstimateTwoViewPlanar(scene.uv_norm1, scene.uv_norm2, o).empty()) << "noise " << noise;
  }
}

TEST(EstimateTwoView, PureRotationAndNoMotionFail) {
  const Pose rotation(QuaternionFromRotationVector(Eigen::Vector3d(0.02, -0.06, 0.01)), Eigen::Vector3d::Zero());
  for (const EssentialMethod method : kMethods) {
    for (const Pose& motion : {rotation, Pose::Identity()}) {
      for (const double noise : {0.0, 1.0}) {
        TwoViewScene scene = CustomTwoViewScene(testing::VolumePoints(200, 2.0, 4.0, 3), motion);
        Corrupt({.noise_px = noise, .outlier_fraction = 0.2, .seed = 3}, &scene);
        TwoViewOptions o = Options(method);
        o.ransac_threshold_px = noise > 0 ? 2.0 : 1.0;
        const TwoViewResult r = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
        EXPECT_FALSE(r.ok) << ToString(method) << " noise " << noise;
        EXPECT_FALSE(r.failure.empty());
        // Without the homography test, the parallax / cheirality checks still refuse it.
        o.max_homography_inlier_ratio = 2.0;
        const TwoViewResult r2 = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
        EXPECT_FALSE(r2.ok) << ToString(method) << " noise " << noise << " (no homography test)";
      }
    }
  }
}

TEST(EstimateTwoView, TooFewCorrespondencesNaNAndSizeMismatchFail) {
  const TwoViewScene scene = PaperTwoViewScene(1, 0, 10);
  for (const EssentialMethod method : kMethods) {
    const int minimal = method == EssentialMethod::kEightPoint ? 8 : 5;
    const std::vector<Eigen::Vector2d> a(scene.uv_norm1.begin(), scene.uv_norm1.begin() + minimal - 1);
    const std::vector<Eigen::Vector2d> b(scene.uv_norm2.begin(), scene.uv_norm2.begin() + minimal - 1);
    TwoViewResult r = EstimateTwoView(a, b, Options(method));
    EXPECT_FALSE(r.ok);
    EXPECT_EQ(r.status, TwoViewStatus::kTooFewCorrespondences) << r.failure;
    // Enough for a model but fewer than min_inliers (15). Every 20th point, so that they are not all on one
    // face of the box (which the 8-point could not use).
    std::vector<Eigen::Vector2d> c, d;
    for (size_t i = 0; i < scene.uv_norm1.size() && c.size() < 10; i += 20) {
      c.push_back(scene.uv_norm1[i]);
      d.push_back(scene.uv_norm2[i]);
    }
    r = EstimateTwoView(c, d, Options(method));
    EXPECT_FALSE(r.ok);
    EXPECT_EQ(r.status, TwoViewStatus::kTooFewInliers) << r.failure;
    std::vector<Eigen::Vector2d> with_nan = scene.uv_norm2;
    with_nan[11].y() = std::nan("");
    r = EstimateTwoView(scene.uv_norm1, with_nan, Options(method));
    EXPECT_EQ(r.status, TwoViewStatus::kBadInput);
    EXPECT_NE(r.failure.find("uv_norm2[11]"), std::string::npos) << r.failure;
    r = EstimateTwoView(scene.uv_norm1, b, Options(method));
    EXPECT_EQ(r.status, TwoViewStatus::kBadInput) << r.failure;
    r = EstimateTwoView({}, {}, Options(method));
    EXPECT_EQ(r.status, TwoViewStatus::kTooFewCorrespondences) << r.failure;
  }
}

TEST(EstimateTwoView, RandomMatchesFail) {
  TwoViewScene scene = PaperTwoViewScene(2, 0, 10);
  Corrupt({.noise_px = 0.0, .outlier_fraction = 1.0, .seed = 2}, &scene);
  for (const EssentialMethod method : kMethods) {
    const TwoViewResult r = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, Options(method));
    EXPECT_FALSE(r.ok) << ToString(method);
    EXPECT_FALSE(r.failure.empty());
  }
}

TEST(EstimateTwoView, ShortBaselineFails) {
  // One frame apart (1-3 cm at ~3 m: ~0.2-0.6 deg of parallax): a homography explains the images as well as
  // any essential matrix. Without that test, the parallax check refuses it.
  const TwoViewScene scene = PaperTwoViewScene(1, 0, 1);
  for (const EssentialMethod method : kMethods) {
    TwoViewOptions o = Options(method);
    const TwoViewResult r = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
    EXPECT_FALSE(r.ok) << ToString(method);
    EXPECT_EQ(r.status, TwoViewStatus::kPlanarOrRotation) << ToString(method) << ": " << r.failure;
    o.max_homography_inlier_ratio = 2.0;
    const TwoViewResult r2 = EstimateTwoView(scene.uv_norm1, scene.uv_norm2, o);
    EXPECT_FALSE(r2.ok) << ToString(method);
    EXPECT_EQ(r2.status, TwoViewStatus::kSmallParallax) << ToString(method) << ": " << r2.failure;
    EXPECT_LT(r2.median_parallax_deg, 1.0);
  }
}

TEST(TwoViewOptions, CheckNamesTheBadField) {
  auto message = [](TwoViewOptions o) {
    try {
      o.Check();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(message(TwoViewOptions{}), "");
  TwoViewOptions o;
  o.ransac_threshold_px = 0;
  EXPECT_NE(message(o).find("ransac_threshold_px"), std::string::npos);
  o = {};
  o.confidence = 1.0;
  EXPECT_NE(message(o).find("confidence"), std::string::npos);
  o = {};
  o.max_iterations = 0;
  EXPECT_NE(message(o).find("max_iterations"), std::string::npos);
  o = {};
  o.focal_px = -500;
  EXPECT_NE(message(o).find("focal_px"), std::string::npos);
  o = {};
  o.min_inliers = 7;
  EXPECT_NE(message(o).find("min_inliers"), std::string::npos);
  o = {};
  o.max_homography_inlier_ratio = 0;
  EXPECT_NE(message(o).find("max_homography_inlier_ratio"), std::string::npos);
  EXPECT_THROW(EstimateTwoView({}, {}, o), std::invalid_argument);
  EXPECT_EQ(ParseEssentialMethod("5point"), EssentialMethod::kFivePointOpenCV);
  EXPECT_THROW(ParseEssentialMethod("7point"), std::invalid_argument);
}

}  // namespace
}  // namespace mcslam::geometry
