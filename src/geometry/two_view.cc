#include "geometry/two_view.h"

#include "core/median.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/random.h"

namespace mcslam::geometry {
namespace {

// Random stream of the RANSAC samples (streams separate independent uses of one seed).
constexpr uint32_t kStreamRansac = 0x45535331u;  // "ESS1"
constexpr int kEightPointSample = 8;
constexpr int kFivePointSample = 5;
// The runner-up decomposition may have at most this fraction of the best one's points in front of both
// cameras. With a correct E the wrong three get almost none (points near the epipoles or at infinity only).
constexpr double kMaxCheiralityRatio = 0.7;
// Homography threshold over the Sampson threshold. The Sampson distance is a 1-dof residual (variance s^2
// for pixel noise s per coordinate); the homography's transfer error in view 2 is 2-dof with variance 2 s^2
// per coordinate (noise of both views). Equal chi-square confidence (95 %: 3.84 for 1 dof, 5.99 for 2)
// gives sqrt(2 * 5.99 / 3.84) = 1.77, so that on a truly planar scene both tests keep the same inliers.
constexpr double kHomographyThresholdFactor = 1.77;
// Refit rounds of the best RANSAC model on its inliers (it stops as soon as a refit does not lower the score).
constexpr int kMaxRefits = 5;

// MSAC score (Torr & Zisserman, "MLESAC", CVIU 2000): the sum over all correspondences of the squared Sampson
// distance truncated at the threshold. Unlike the plain inlier count it also rewards how well the inliers
// fit, which matters here: in the flat cost valleys of narrow-field two-view geometry, a model a degree off
// can pick up one stray outlier more than the right one and would win on the count alone.
struct Score {
  int inliers = 0;
  double cost = std::numeric_limits<double>::infinity();  // normalised units squared
  bool BetterThan(const Score& o) const { return cost < o.cost; }
};

Score ScoreModel(const Eigen::Matrix3d& essential, std::span<const Eigen::Vector2d> uv1,
                 std::span<const Eigen::Vector2d> uv2, double threshold, std::vector<uint8_t>* mask = nullptr) {
  Score s{0, 0.0};
  const double threshold_sq = threshold * threshold;
  if (mask) mask->assign(uv1.size(), 0);
  for (size_t i = 0; i < uv1.size(); ++i) {
    const double d = SampsonDistance(essential, uv1[i], uv2[i]);
    if (d * d < threshold_sq) {
      ++s.inliers;
      s.cost += d * d;
      if (mask) (*mask)[i] = 1;
    } else {
      s.cost += threshold_sq;
    }
  }
  return s;
}

std::vector<int> Indices(const std::vector<uint8_t>& mask) {
  std::vector<int> idx;
  for (size_t i = 0; i < mask.size(); ++i)
    if (mask[i]) idx.push_back(static_cast<int>(i));
  return idx;
}

// Samples needed so that, with probability `confidence`, one of them is all inliers (H&Z (4.18)).
int AdaptiveIterations(double inlier_ratio, int sample_size, double confidence, int cap) {
  const double p_good = std::pow(inlier_ratio, sample_size);
  if (p_good >= 1.0) return 1;
  if (!(p_good > 0.0)) return cap;
  const double n = std::log(1.0 - confidence) / std::log1p(-p_good);
  if (!(n < cap)) return cap;
  return std::max(1, static_cast<int>(std::ceil(n)));
}

// Local optimisation of a model (LO-RANSAC: Chum, Matas & Kittler, "Locally optimized RANSAC", DAGM 2003,
// with a non-linear inner step). Two stages:
//  1. LM on ALL correspondences with a Cauchy loss of scale = the threshold. A hard inlier set chosen by a
//     rough model supports that model (the true inliers it misfits are left out), so LM on it stays where it
//     started; the soft weights still hear those points (a 4 px residual keeps weight 0.2 at a 2 px scale)
//     while far outliers fade (10 px: 0.04).
//  2. Plain least squares on the inliers at the threshold, re-classified until they no longer change.
// Returns the best model met (by Score at `threshold`), never worse than the start.
constexpr int kLoRobustIterations = 30;   // stage 1 cap (it converged in 10-40 on the tests' scenes; stage 2 polishes)
constexpr int kLoPolishRounds = 3;        // stage 2: the inlier set settles in 1-2 rounds
constexpr int kLoPolishIterations = 15;

struct Model {
  Pose pose;
  Eigen::Matrix3d essential = Eigen::Matrix3d::Zero();
  Score score;
};

Model LocallyOptimise(const Model& start, std::span<const Eigen::Vector2d> uv1, std::span<const Eigen::Vector2d> uv2,
                      double threshold, double focal_px) {
  Model best = start;
  auto consider = [&](const Pose& pose) {
    const Eigen::Matrix3d e = EssentialFromPose(pose);
    const Score s = ScoreModel(e, uv1, uv2, threshold);
    if (s.BetterThan(best.score)) best = Model{pose, e, s};
  };
  RefineOptions robust;
  robust.scale = focal_px;
  robust.max_iterations = kLoRobustIterations;
  robust.cauchy_scale = threshold * focal_px;
  Pose pose = RefineRelativePose(start.pose, uv1, uv2, {}, robust);
  consider(pose);

  RefineOptions polish;
  polish.scale = focal_px;
  polish.max_iterations = kLoPolishIterations;
  std::vector<uint8_t> mask, previous;
  for (int round = 0; round < kLoPolishRounds; ++round) {
    ScoreModel(EssentialFromPose(pose), uv1, uv2, threshold, &mask);
    const std::vector<int> idx = Indices(mask);
    if (static_cast<int>(idx.size()) < kEightPointSample || mask == previous) break;  // nothing (new) to fit
    previous = mask;
    pose = RefineRelativePose(pose, uv1, uv2, idx, polish);
    consider(pose);
  }
  return best;
}

struct RansacResult {
  std::optional<Eigen::Matrix3d> essential;
  int iterations = 0;
};

RansacResult RansacEightPoint(std::span<const Eigen::Vector2d> uv1, std::span<const Eigen::Vector2d> uv2,
                              double threshold, const TwoViewOptions& options) {
  RansacResult out;
  const int n = static_cast<int>(uv1.size());
  CounterRng rng(options.seed, kStreamRansac);
  std::array<int, kEightPointSample> sample{};
  Score best;      // of the best model so far (locally optimised or not)
  Score best_raw;  // of the best minimal-sample model so far
  int needed = options.max_iterations;
  auto accept = [&](const Eigen::Matrix3d& e, const Score& s) {
    best = s;
    out.essential = e;
    needed = std::min(options.max_iterations,
                      AdaptiveIterations(static_cast<double>(s.inliers) / n, kEightPointSample, options.confidence,
                                         options.max_iterations));
  };
  while (out.iterations < needed) {
    ++out.iterations;
    for (int k = 0; k < kEightPointSample; ++k) {
      bool repeated = true;
      while (repeated) {  // distinct indices; n >= 8 so this ends
        sample[k] = static_cast<int>(rng.Below(static_cast<uint32_t>(n)));
        repeated = std::find(sample.begin(), sample.begin() + k, sample[k]) != sample.begin() + k;
      }
    }
    const std::optional<Eigen::Matrix3d> e = EssentialEightPoint(uv1, uv2, sample);
    if (!e) continue;  // degenerate sample: it still counts, so that all-degenerate data ends at the cap
    const Score s = ScoreModel(*e, uv1, uv2, threshold);
    if (s.BetterThan(best)) accept(*e, s);
    // Local optimisation whenever a sample beats the best sample so far (Chum et al.'s rule). Comparing with
    // the best optimised model instead would almost never fire here: 8-point models from 8 noisy points are
    // several px off, so a raw model rarely beats an optimised one even when it lies in a better basin.
    if (!s.BetterThan(best_raw)) continue;
    best_raw = s;
    if (options.refine) {
      // Any of the four decompositions will do: all give E up to sign, and the Sampson cost ignores the sign.
      const Model lo = LocallyOptimise(Model{DecomposeEssential(*e)[0], *e, s}, uv1, uv2, threshold, options.focal_px);
      if (lo.score.BetterThan(best)) accept(lo.essential, lo.score);
    }
  }
  if (!out.essential) return out;

  // The minimal-sample model fits 8 points exactly and the rest only roughly: re-fit on all its inliers
  // (least squares), as long as that lowers the score.
  std::vector<uint8_t> mask;
  ScoreModel(*out.essential, uv1, uv2, threshold, &mask);
  for (int round = 0; round < kMaxRefits; ++round) {
    const std::vector<int> idx = Indices(mask);
    const std::optional<Eigen::Matrix3d> e = EssentialEightPoint(uv1, uv2, idx);
    if (!e) break;
    std::vector<uint8_t> new_mask;
    const Score s = ScoreModel(*e, uv1, uv2, threshold, &new_mask);
    if (!s.BetterThan(best)) break;
    const bool same_set = new_mask == mask;
    best = s;
    out.essential = *e;
    mask.swap(new_mask);
    if (same_set) break;  // the next refit would see the same inliers and give the same model
  }
  return out;
}

std::vector<cv::Point2d> ToCv(std::span<const Eigen::Vector2d> uv) {
  std::vector<cv::Point2d> out;
  out.reserve(uv.size());
  for (const auto& p : uv) out.emplace_back(p.x(), p.y());
  return out;
}

Eigen::Matrix3d ToEigen3(const cv::Mat& m) {
  Eigen::Matrix3d out;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out(r, c) = m.at<double>(r, c);
  return out;
}

// OpenCV's five-point RANSAC and its cheirality test. On success, *essential and *cam2_from_cam1 are set.
bool FivePointOpenCV(std::span<const Eigen::Vector2d> uv1, std::span<const Eigen::Vector2d> uv2, double threshold,
                     const TwoViewOptions& options, Eigen::Matrix3d* essential, Pose* cam2_from_cam1,
                     std::string* why) {
  try {
    const std::vector<cv::Point2d> p1 = ToCv(uv1), p2 = ToCv(uv2);
    const cv::Mat identity = cv::Mat::eye(3, 3, CV_64F);  // the points are already normalised
    cv::Mat e_stack = cv::findEssentialMat(p1, p2, identity, cv::RANSAC, options.confidence, threshold,
                                           options.max_iterations, cv::noArray());
    if (e_stack.empty() || e_stack.rows % 3 != 0 || e_stack.cols != 3) {
      *why = "cv::findEssentialMat found no essential matrix";
      return false;
    }
    e_stack.convertTo(e_stack, CV_64F);
    // With exactly 5 points OpenCV returns every solution of the minimal problem, stacked: keep the best.
    Score best;
    for (int k = 0; k < e_stack.rows / 3; ++k) {
      const Eigen::Matrix3d e = ToEigen3(e_stack.rowRange(3 * k, 3 * k + 3));
      if (!e.allFinite()) continue;
      const Score s = ScoreModel(e, uv1, uv2, threshold);
      if (s.BetterThan(best)) {
        best = s;
        *essential = e;
      }
    }
    if (!std::isfinite(best.cost)) {
      *why = "cv::findEssentialMat returned no finite essential matrix";
      return false;
    }
    std::vector<uint8_t> mask_vec;
    ScoreModel(*essential, uv1, uv2, threshold, &mask_vec);
    cv::Mat mask(static_cast<int>(mask_vec.size()), 1, CV_8U, mask_vec.data());
    cv::Mat rotation, translation;
    const cv::Mat e_cv = (cv::Mat_<double>(3, 3) << (*essential)(0, 0), (*essential)(0, 1), (*essential)(0, 2),
                          (*essential)(1, 0), (*essential)(1, 1), (*essential)(1, 2), (*essential)(2, 0),
                          (*essential)(2, 1), (*essential)(2, 2));
    // distanceThresh: OpenCV drops points farther than this many baselines as "at infinity" (default 50).
    // At a 3 cm baseline a point 3 m away is 100 baselines away and valid, so effectively no limit here.
    constexpr double kFarBaselines = 1e6;
    const int in_front = cv::recoverPose(e_cv, p1, p2, identity, rotation, translation, kFarBaselines, mask);
    if (in_front <= 0) {
      *why = "cv::recoverPose found no decomposition with points in front of both cameras";
      return false;
    }
    *cam2_from_cam1 = Pose::FromRotationTranslation(
        ToEigen3(rotation), Eigen::Vector3d(translation.at<double>(0), translation.at<double>(1),
                                            translation.at<double>(2))
                                .normalized());
    return true;
  } catch (const cv::Exception& e) {
    *why = "OpenCV five-point failed: " + e.err;
    return false;
  }
}

// Correspondences (among `idx`) whose two-view triangulation lies in front of both cameras.
int CountInFront(const Pose& cam2_from_cam1, std::span<const Eigen::Vector2d> uv1, std::span<const Eigen::Vector2d> uv2,
                 const std::vector<int>& idx) {
  if (idx.empty()) return 0;  // (an empty list means every correspondence to TriangulateInFrontOfBoth)
  return static_cast<int>(TriangulateInFrontOfBoth(cam2_from_cam1, uv1, uv2, idx).indices.size());
}

// Step 5 of EstimateTwoView and of the planar path: linear triangulation of the inliers at res->cam2_from_cam1,
// with the parallax and count checks. On a failure fills res->status and res->failure and returns false.
bool TriangulateInliers(std::span<const Eigen::Vector2d> uv_norm1, std::span<const Eigen::Vector2d> uv_norm2,
                        const std::vector<int>& inlier_idx, const TwoViewOptions& options, TwoViewResult* res) {
  TriangulationOptions tri;
  tri.focal_px = options.focal_px;
  tri.max_reprojection_px = options.max_reprojection_px;
  tri.min_parallax_deg = options.min_parallax_deg;
  const std::array<Pose, 2> poses = {Pose::Identity(), res->cam2_from_cam1};
  std::vector<double> parallaxes;
  parallaxes.reserve(inlier_idx.size());
  for (const int i : inlier_idx) {
    const std::array<Eigen::Vector2d, 2> obs = {uv_norm1[i], uv_norm2[i]};
    const Triangulation t = TriangulateDlt(poses, obs, tri);
    if (t.status == TriangulationStatus::kOk || t.status == TriangulationStatus::kLargeReprojection ||
        t.status == TriangulationStatus::kSmallParallax)
      parallaxes.push_back(t.parallax_deg);
    if (t.ok) {
      res->triangulated[i] = 1;
      res->points_in_cam1[i] = t.point_in_world;
      ++res->num_triangulated;
    }
  }
  res->median_parallax_deg = Median(parallaxes);
  auto fail = [&](TwoViewStatus status, std::string why) {
    res->ok = false;
    res->status = status;
    res->failure = std::move(why);
    return false;
  };
  if (!parallaxes.empty() && res->median_parallax_deg < options.min_parallax_deg)
    return fail(TwoViewStatus::kSmallParallax,
                fmt::format("median parallax {:.3g} deg < {:.3g} deg: the baseline is too short for the scene depth",
                            res->median_parallax_deg, options.min_parallax_deg));
  if (res->num_triangulated < options.min_triangulated)
    return fail(TwoViewStatus::kTooFewTriangulated,
                fmt::format("only {} of {} inliers triangulate with positive depth, reprojection <= {} px and "
                            "parallax >= {} deg (need {})",
                            res->num_triangulated, res->num_inliers, options.max_reprojection_px,
                            options.min_parallax_deg, options.min_triangulated));
  return true;
}

// cv::findHomography (RANSAC, then its LM refinement) on the correspondences `idx`, in normalised coordinates;
// nullopt when none could be fitted. `mask` (per correspondence of the whole input, when given): within
// kHomographyThresholdFactor * threshold of the refined homography's transfer.
std::optional<Eigen::Matrix3d> FitHomography(std::span<const Eigen::Vector2d> uv1, std::span<const Eigen::Vector2d> uv2,
                                             const std::vector<int>& idx, double threshold, double confidence,
                                             std::vector<uint8_t>* mask, int* count) {
  *count = 0;
  if (idx.size() < 4) return std::nullopt;
  std::vector<cv::Point2d> p1, p2;
  for (const int i : idx) {
    p1.emplace_back(uv1[i].x(), uv1[i].y());
    p2.emplace_back(uv2[i].x(), uv2[i].y());
  }
  const double h_threshold = kHomographyThresholdFactor * threshold;
  cv::Mat h;
  try {
    constexpr int kHomographyIterations = 2000;  // cheap next to the E RANSAC; enough at >= 50 % H-inliers
    h = cv::findHomography(p1, p2, cv::RANSAC, h_threshold, cv::noArray(), kHomographyIterations, confidence);
  } catch (const cv::Exception&) {
    return std::nullopt;
  }
  if (h.empty()) return std::nullopt;
  // OpenCV's mask is that of its best minimal sample, before its final refinement; count the inliers of the
  // refined homography instead, which fits a truly planar scene to the noise level.
  const Eigen::Matrix3d hm = ToEigen3(h);
  if (mask) mask->assign(uv1.size(), 0);
  for (size_t k = 0; k < p1.size(); ++k) {
    const Eigen::Vector3d x2 = hm * Eigen::Vector3d(p1[k].x, p1[k].y, 1.0);
    if (std::abs(x2.z()) > 1e-12 && (x2.head<2>() / x2.z() - Eigen::Vector2d(p2[k].x, p2[k].y)).norm() < h_threshold) {
      ++*count;
      if (mask) (*mask)[idx[k]] = 1;
    }
  }
  return hm;
}

// Fraction of the correspondences in `idx` that one homography (FitHomography) maps within
// kHomographyThresholdFactor * threshold of their match in view 2; 0 when none could be fitted (nothing then
// suggests degeneracy).
double HomographyInlierRatio(std::span<const Eigen::Vector2d> uv1, std::span<const Eigen::Vector2d> uv2,
                             const std::vector<int>& idx, double threshold, double confidence) {
  int count = 0;
  if (!FitHomography(uv1, uv2, idx, threshold, confidence, nullptr, &count)) return 0.0;
  return static_cast<double>(count) / static_cast<double>(idx.size());
}

}  // namespace

const char* ToString(EssentialMethod method) {
  switch (method) {
    case EssentialMethod::kEightPoint: return "8point";
    case EssentialMethod::kFivePointOpenCV: return "5point";
  }
  return "?";
}

EssentialMethod ParseEssentialMethod(const std::string& name) {
  if (name == "8point") return EssentialMethod::kEightPoint;
  if (name == "5point") return EssentialMethod::kFivePointOpenCV;
  throw std::invalid_argument(fmt::format("unknown essential-matrix method '{}' (expected 8point or 5point)", name));
}

const char* ToString(TwoViewStatus status) {
  switch (status) {
    case TwoViewStatus::kOk: return "ok";
    case TwoViewStatus::kBadInput: return "bad input";
    case TwoViewStatus::kTooFewCorrespondences: return "too few correspondences";
    case TwoViewStatus::kNoModel: return "no model";
    case TwoViewStatus::kTooFewInliers: return "too few inliers";
    case TwoViewStatus::kPlanarOrRotation: return "planar scene or pure rotation";
    case TwoViewStatus::kAmbiguousCheirality: return "ambiguous cheirality";
    case TwoViewStatus::kTooFewTriangulated: return "too few triangulated points";
    case TwoViewStatus::kSmallParallax: return "small parallax";
  }
  return "?";
}

void TwoViewOptions::Check() const {
  auto bad = [](const std::string& what) { throw std::invalid_argument("TwoViewOptions." + what); };
  if (method != EssentialMethod::kEightPoint && method != EssentialMethod::kFivePointOpenCV)
    bad(fmt::format("method is not a known EssentialMethod ({})", static_cast<int>(method)));
  if (!(std::isfinite(ransac_threshold_px) && ransac_threshold_px > 0))
    bad(fmt::format("ransac_threshold_px must be > 0 and finite, got {}", ransac_threshold_px));
  if (!(std::isfinite(focal_px) && focal_px > 0)) bad(fmt::format("focal_px must be > 0 and finite, got {}", focal_px));
  if (!(confidence > 0 && confidence < 1)) bad(fmt::format("confidence must be in (0, 1), got {}", confidence));
  if (max_iterations < 1) bad(fmt::format("max_iterations must be >= 1, got {}", max_iterations));
  if (!(min_parallax_deg >= 0 && min_parallax_deg < 180))
    bad(fmt::format("min_parallax_deg must be in [0, 180), got {}", min_parallax_deg));
  if (!(std::isfinite(max_reprojection_px) && max_reprojection_px > 0))
    bad(fmt::format("max_reprojection_px must be > 0 and finite, got {}", max_reprojection_px));
  if (min_inliers < kEightPointSample) bad(fmt::format("min_inliers must be >= 8, got {}", min_inliers));
  if (min_triangulated < 1) bad(fmt::format("min_triangulated must be >= 1, got {}", min_triangulated));
  if (!(max_homography_inlier_ratio > 0))
    bad(fmt::format("max_homography_inlier_ratio must be > 0 (above 1 disables the test), got {}",
                    max_homography_inlier_ratio));
}

TwoViewResult EstimateTwoView(std::span<const Eigen::Vector2d> uv_norm1, std::span<const Eigen::Vector2d> uv_norm2,
                              const TwoViewOptions& options) {
  options.Check();
  TwoViewResult res;
  auto fail = [&](TwoViewStatus status, std::string why) {
    res.ok = false;
    res.status = status;
    res.failure = std::move(why);
    return res;
  };
  if (uv_norm1.size() != uv_norm2.size())
    return fail(TwoViewStatus::kBadInput,
                fmt::format("uv_norm1 has {} points but uv_norm2 has {}", uv_norm1.size(), uv_norm2.size()));
  const int n = static_cast<int>(uv_norm1.size());
  for (int i = 0; i < n; ++i) {
    if (!uv_norm1[i].allFinite()) return fail(TwoViewStatus::kBadInput, fmt::format("uv_norm1[{}] is not finite", i));
    if (!uv_norm2[i].allFinite()) return fail(TwoViewStatus::kBadInput, fmt::format("uv_norm2[{}] is not finite", i));
  }
  res.inliers.assign(n, 0);
  res.triangulated.assign(n, 0);
  res.points_in_cam1.assign(n, Eigen::Vector3d::Zero());
  const bool eight = options.method == EssentialMethod::kEightPoint;
  const int min_sample = eight ? kEightPointSample : kFivePointSample;
  if (n < min_sample)
    return fail(TwoViewStatus::kTooFewCorrespondences,
                fmt::format("{} correspondences; the {} method needs at least {}", n, ToString(options.method),
                            min_sample));
  const double threshold = options.ransac_threshold_px / options.focal_px;

  // 1. Essential matrix and a first pose (any decomposition for the 8-point; OpenCV's cheirality choice for
  //    the 5-point). The pose is only the start of the refinement: step 4 decides among the decompositions.
  Eigen::Matrix3d essential;
  Pose pose;
  if (eight) {
    const RansacResult ransac = RansacEightPoint(uv_norm1, uv_norm2, threshold, options);
    res.ransac_iterations = ransac.iterations;
    if (!ransac.essential)
      return fail(TwoViewStatus::kNoModel,
                  fmt::format("all {} RANSAC samples were degenerate (no motion, pure rotation, planar scene or "
                              "repeated points)",
                              ransac.iterations));
    essential = *ransac.essential;
    pose = DecomposeEssential(essential)[0];
  } else {
    std::string why;
    if (!FivePointOpenCV(uv_norm1, uv_norm2, threshold, options, &essential, &pose, &why))
      return fail(TwoViewStatus::kNoModel, why);
  }
  res.essential = essential;
  res.cam2_from_cam1 = pose;
  res.num_inliers = ScoreModel(essential, uv_norm1, uv_norm2, threshold, &res.inliers).inliers;
  if (res.num_inliers < options.min_inliers)
    return fail(TwoViewStatus::kTooFewInliers,
                fmt::format("only {} of {} correspondences fit one essential matrix within {} px (need {})",
                            res.num_inliers, n, options.ransac_threshold_px, options.min_inliers));

  // 2. Refinement: LM on the inliers, re-classified until stable (the local optimisation above). The Sampson
  //    cost does not depend on which decomposition of E the pose is, so this may run before cheirality.
  if (options.refine) {
    const Score start = ScoreModel(essential, uv_norm1, uv_norm2, threshold);
    pose = LocallyOptimise(Model{pose, essential, start}, uv_norm1, uv_norm2, threshold, options.focal_px).pose;
    essential = EssentialFromPose(pose);
    res.essential = essential;
    res.cam2_from_cam1 = pose;
    res.num_inliers = ScoreModel(essential, uv_norm1, uv_norm2, threshold, &res.inliers).inliers;
    if (res.num_inliers < options.min_inliers)
      return fail(TwoViewStatus::kTooFewInliers,
                  fmt::format("only {} of {} correspondences fit the refined essential matrix within {} px (need {})",
                              res.num_inliers, n, options.ransac_threshold_px, options.min_inliers));
  }
  const std::vector<int> inlier_idx = Indices(res.inliers);

  // 3. Degeneracy: does one homography explain the inliers as well?
  if (options.max_homography_inlier_ratio <= 1.0) {
    res.homography_inlier_ratio = HomographyInlierRatio(uv_norm1, uv_norm2, inlier_idx, threshold, options.confidence);
    if (res.homography_inlier_ratio >= options.max_homography_inlier_ratio)
      return fail(TwoViewStatus::kPlanarOrRotation,
                  fmt::format("a homography explains {:.0f} % of the {} epipolar inliers (limit {:.0f} %): the scene "
                              "is planar or the camera only rotated, so the relative pose is not determined",
                              100.0 * res.homography_inlier_ratio, res.num_inliers,
                              100.0 * options.max_homography_inlier_ratio));
  }

  // 4. Cheirality: the decomposition of E that puts the inliers in front of both cameras.
  const std::array<Pose, 4> candidates = DecomposeEssential(essential);
  std::array<int, 4> in_front{};
  for (int k = 0; k < 4; ++k) in_front[k] = CountInFront(candidates[k], uv_norm1, uv_norm2, inlier_idx);
  std::array<int, 4> order = {0, 1, 2, 3};
  std::sort(order.begin(), order.end(), [&](int a, int b) { return in_front[a] > in_front[b]; });
  const int best = in_front[order[0]], runner_up = in_front[order[1]];
  res.cheirality_ratio = best > 0 ? static_cast<double>(runner_up) / best : 1.0;
  pose = candidates[order[0]];
  res.cam2_from_cam1 = pose;
  res.essential = EssentialFromPose(pose);  // consistent in sign and scale with the returned pose
  if (best == 0 || res.cheirality_ratio > kMaxCheiralityRatio)
    return fail(TwoViewStatus::kAmbiguousCheirality,
                fmt::format("no decomposition of E puts the points clearly in front of both cameras (best {}, "
                            "runner-up {} of {} inliers)",
                            best, runner_up, res.num_inliers));

  // 5. Structure.
  if (!TriangulateInliers(uv_norm1, uv_norm2, inlier_idx, options, &res)) return res;
  res.ok = true;
  res.status = TwoViewStatus::kOk;
  res.failure.clear();
  return res;
}

std::vector<TwoViewResult> EstimateTwoViewPlanar(std::span<const Eigen::Vector2d> uv_norm1,
                                                 std::span<const Eigen::Vector2d> uv_norm2,
                                                 const TwoViewOptions& options) {
  options.Check();
  std::vector<TwoViewResult> out;
  const int n = static_cast<int>(uv_norm1.size());
  if (uv_norm2.size() != uv_norm1.size() || n < 4) return out;
  for (int i = 0; i < n; ++i)
    if (!uv_norm1[i].allFinite() || !uv_norm2[i].allFinite()) return out;
  std::vector<int> all(n);
  for (int i = 0; i < n; ++i) all[i] = i;
  const double threshold = options.ransac_threshold_px / options.focal_px;
  std::vector<uint8_t> mask;
  int count = 0;
  const std::optional<Eigen::Matrix3d> h = FitHomography(uv_norm1, uv_norm2, all, threshold, options.confidence, &mask, &count);
  if (!h || count < options.min_inliers) return out;
  const std::vector<int> inlier_idx = Indices(mask);
  // Faugeras' decomposition (as OpenCV implements it, Malis & Vargas 2007) with K = I: up to four (R, t/d, n).
  std::vector<cv::Mat> rotations, translations, normals;
  cv::Mat h_cv(3, 3, CV_64F);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) h_cv.at<double>(r, c) = (*h)(r, c);
  try {
    cv::decomposeHomographyMat(h_cv, cv::Mat::eye(3, 3, CV_64F), rotations, translations, normals);
  } catch (const cv::Exception&) {
    return out;
  }
  for (size_t k = 0; k < rotations.size(); ++k) {
    const Eigen::Vector3d t(translations[k].at<double>(0), translations[k].at<double>(1), translations[k].at<double>(2));
    // No translation: a pure rotation, which says nothing of the structure.
    if (!(t.norm() > 1e-9) || !t.allFinite()) continue;
    TwoViewResult res;
    res.inliers = mask;
    res.num_inliers = count;
    res.triangulated.assign(n, 0);
    res.points_in_cam1.assign(n, Eigen::Vector3d::Zero());
    res.homography_inlier_ratio = 1.0;
    res.cam2_from_cam1 = Pose::FromRotationTranslation(ToEigen3(rotations[k]), t.normalized());
    res.essential = EssentialFromPose(res.cam2_from_cam1);
    // The plane's side: most inliers triangulated in front of both cameras (two of the four solutions fail).
    if (CountInFront(res.cam2_from_cam1, uv_norm1, uv_norm2, inlier_idx) < count / 2) continue;
    if (!TriangulateInliers(uv_norm1, uv_norm2, inlier_idx, options, &res)) continue;
    res.ok = true;
    res.status = TwoViewStatus::kOk;
    out.push_back(std::move(res));
  }
  return out;
}

}  // namespace mcslam::geometry
