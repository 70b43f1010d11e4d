// Helpers shared by the System's stage files (system_internal.h).
#include "slam/system_internal.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/median.h"

namespace mcslam::slam {

std::vector<Eigen::Vector3d> detail::MirrorInDepth(const std::vector<Eigen::Vector3d>& points_in_ref) {
  std::vector<double> z;
  for (const Eigen::Vector3d& X : points_in_ref) z.push_back(X.z());
  const double z0 = UpperMedian(z);
  std::vector<Eigen::Vector3d> out;
  out.reserve(points_in_ref.size());
  for (const Eigen::Vector3d& X : points_in_ref) {
    const double zm = std::max(2.0 * z0 - X.z(), 0.1 * z0);
    out.push_back(X * (zm / X.z()));
  }
  return out;
}

std::vector<int> detail::EvenlySpread(int n, int m) {
  m = std::min(n, m);
  std::vector<int> out;
  for (int i = 0; i < m; ++i) out.push_back(static_cast<int>(static_cast<int64_t>(i) * (n - 1) / std::max(m - 1, 1)));
  return out;
}

double detail::PooledLag1Correlation(const std::vector<std::vector<Eigen::Vector2d>>& sequences) {
  double lagged = 0, squared = 0;
  for (const std::vector<Eigen::Vector2d>& r : sequences)
    for (size_t k = 1; k < r.size(); ++k) lagged += r[k].dot(r[k - 1]), squared += r[k].squaredNorm();
  return squared > 0 ? lagged / squared : 0.0;
}

double detail::CappedMeanSquarePx2(const std::vector<double>& residuals_px, double cap_px) {
  if (residuals_px.empty()) return std::numeric_limits<double>::infinity();
  const double cap_sq = cap_px * cap_px;
  double sum = 0;
  for (double r : residuals_px) sum += std::min(r * r, cap_sq);
  return sum / static_cast<double>(residuals_px.size());
}

void detail::SharedBearings(const FrameRecord& a, const FrameRecord& b, const PinholeCamera& ideal,
                            std::vector<Eigen::Vector3d>* in_a, std::vector<Eigen::Vector3d>* in_b) {
  in_a->clear(), in_b->clear();
  for (const FeatureUndistorted& f : a.features)
    if (const FeatureUndistorted* g = b.Find(f.id)) {
      in_a->push_back(ideal.PixelToNormalized(f.uv_px).homogeneous().normalized());
      in_b->push_back(ideal.PixelToNormalized(g->uv_px).homogeneous().normalized());
    }
}

double detail::EpipolarDisagreementDeg(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b,
                                       const Pose& b_from_a) {
  std::vector<double> off;
  for (size_t i = 0; i < a.size() && i < b.size(); ++i) {
    const Eigen::Vector3d ra = b_from_a.R() * a[i];
    const Eigen::Vector3d n = b_from_a.t.cross(ra);  // the epipolar plane's normal; nil where the move is
    const double n_norm = n.norm();
    off.push_back(n_norm > 0 && n_norm > 1e-12 * b_from_a.t.norm()
                      ? std::asin(std::min(1.0, std::abs(b[i].dot(n / n_norm))))
                      : AngleBetween(ra, b[i]));
  }
  return off.empty() ? 0.0 : UpperMedian(off) * 180.0 / M_PI;
}

}  // namespace mcslam::slam
