#include "geometry/rotation_only.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <fmt/format.h>

#include "core/median.h"

namespace mcslam::geometry {
namespace {

// Inlier flags and their count for a rotation; the sum of squared inlier angles in `sq_sum`.
int ScoreRotation(const Eigen::Matrix3d& r, std::span<const Eigen::Vector3d> ref,
                  std::span<const Eigen::Vector3d> cam, double threshold_rad, std::vector<uint8_t>* inlier,
                  double* sq_sum) {
  int n = 0;
  *sq_sum = 0;
  inlier->assign(ref.size(), 0);
  for (size_t k = 0; k < ref.size(); ++k) {
    const double a = AngleBetween(r * ref[k], cam[k]);
    if (a < threshold_rad) {
      (*inlier)[k] = 1;
      *sq_sum += a * a;
      ++n;
    }
  }
  return n;
}

}  // namespace

Eigen::Matrix3d RotationFromBearings(std::span<const Eigen::Vector3d> ref, std::span<const Eigen::Vector3d> cam) {
  Eigen::Matrix3d h = Eigen::Matrix3d::Zero();  // sum ref_k cam_k^T
  for (size_t k = 0; k < ref.size() && k < cam.size(); ++k) h += ref[k] * cam[k].transpose();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;  // a rotation, not a reflection
  return svd.matrixV() * d * svd.matrixU().transpose();
}

Eigen::Matrix3d RobustRotationFromBearings(std::span<const Eigen::Vector3d> ref, std::span<const Eigen::Vector3d> cam) {
  // Each refit takes the better half under the last rotation: the first, fitted to every pair, may be tilted by
  // the wrong ones, and its better half hold some of them still.
  constexpr int kRefits = 3;
  const size_t n = std::min(ref.size(), cam.size());
  Eigen::Matrix3d r = RotationFromBearings(ref.first(n), cam.first(n));
  std::vector<double> a(n);
  for (int refit = 0; refit < kRefits; ++refit) {
    for (size_t k = 0; k < n; ++k) a[k] = AngleBetween(r * ref[k], cam[k]);
    const double cut = UpperMedian(a);
    std::vector<Eigen::Vector3d> ref_in, cam_in;
    for (size_t k = 0; k < n; ++k)
      if (a[k] <= cut) ref_in.push_back(ref[k]), cam_in.push_back(cam[k]);
    if (ref_in.size() < 3) break;
    r = RotationFromBearings(ref_in, cam_in);
  }
  return r;
}

double NonRotationalMotionRad(std::span<const Eigen::Vector3d> ref, std::span<const Eigen::Vector3d> cam) {
  const size_t n = std::min(ref.size(), cam.size());
  if (n < 3) return 0.0;
  const Eigen::Matrix3d r = RobustRotationFromBearings(ref, cam);
  std::vector<double> a(n);
  for (size_t k = 0; k < n; ++k) a[k] = AngleBetween(r * ref[k], cam[k]);
  return UpperMedian(std::move(a));
}

RotationOnlyResult EstimateRotationOnly(std::span<const Eigen::Vector3d> ref, std::span<const Eigen::Vector3d> cam,
                                        const RotationOnlyOptions& options) {
  RotationOnlyResult out;
  const int n = static_cast<int>(std::min(ref.size(), cam.size()));
  const int need = std::max(options.min_inliers, 2);
  if (n < need) {
    out.failure = fmt::format("{} bearings, {} needed", n, need);
    return out;
  }
  const double threshold_rad = options.threshold_px / options.focal_px;
  std::mt19937_64 rng(options.seed);
  std::uniform_int_distribution<int> pick(0, n - 1);
  int best = -1;
  double best_sq = 0;
  Eigen::Matrix3d best_r = Eigen::Matrix3d::Identity();
  std::vector<uint8_t> flags;
  int iterations = options.iterations;
  for (int it = 0; it < iterations; ++it) {
    const int i = pick(rng), j = pick(rng);
    // Two bearings less than a few thresholds apart fix the rotation about their common direction poorly.
    if (i == j || AngleBetween(ref[i], ref[j]) < 4 * threshold_rad) continue;
    const Eigen::Vector3d r2[2] = {ref[i], ref[j]}, c2[2] = {cam[i], cam[j]};
    const Eigen::Matrix3d r = RotationFromBearings(r2, c2);
    double sq = 0;
    const int count = ScoreRotation(r, ref.first(n), cam.first(n), threshold_rad, &flags, &sq);
    if (count > best || (count == best && sq < best_sq)) {
      best = count;
      best_sq = sq;
      best_r = r;
      // Enough draws for 99.9 % confidence of one all-inlier pair at the inlier ratio seen so far.
      const double w = static_cast<double>(count) / n;
      if (w > 0.05) {
        const double needed = std::log(1e-3) / std::log(std::max(1e-12, 1.0 - w * w));
        iterations = std::min(options.iterations, std::max(it + 1, static_cast<int>(std::ceil(needed))));
      }
    }
  }
  if (best < need) {
    out.failure = fmt::format("{} of {} bearings agree on a rotation, {} needed", std::max(best, 0), n, need);
    return out;
  }
  // Least squares on the inliers, then the inliers of that, until they stop changing (3 rounds at most).
  Eigen::Matrix3d r = best_r;
  double sq = 0;
  int count = ScoreRotation(r, ref.first(n), cam.first(n), threshold_rad, &flags, &sq);
  for (int round = 0; round < 3; ++round) {
    std::vector<Eigen::Vector3d> a, b;
    for (int k = 0; k < n; ++k)
      if (flags[k]) a.push_back(ref[k]), b.push_back(cam[k]);
    const Eigen::Matrix3d refit = RotationFromBearings(a, b);
    std::vector<uint8_t> refit_flags;
    double refit_sq = 0;
    const int refit_count = ScoreRotation(refit, ref.first(n), cam.first(n), threshold_rad, &refit_flags, &refit_sq);
    if (refit_count < count || (refit_count == count && refit_sq >= sq)) break;
    r = refit, flags = std::move(refit_flags), count = refit_count, sq = refit_sq;
  }
  out.ok = true;  // count >= best >= need: a refit is kept only when it keeps at least as many
  out.cam_from_ref = r;
  out.inlier = std::move(flags);
  out.inliers = count;
  out.rms_px = std::sqrt(sq / count) * options.focal_px;
  return out;
}

}  // namespace mcslam::geometry
