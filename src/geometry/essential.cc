// With -march=native on AVX-512 machines, GCC 12 reports -Wmaybe-uninitialized false positives inside its own
// _mm512_extractf64x4_pd (_mm256_undefined_pd) as Eigen's dynamic-size products instantiate it. They must be
// silenced before Eigen is included, so for this whole file.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#include "geometry/essential.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <fmt/format.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace mcslam::geometry {
namespace {

// Second-smallest singular value of the 8-point design matrix, relative to the largest, below which the
// solution space of A e = 0 counts as more than one-dimensional. Exactly degenerate data gives ~1e-16 here;
// real, well-posed data gives 1e-3 and more, so the exact value is uncritical.
constexpr double kRankTolerance = 1e-8;

// Hartley's normalising transform (H&Z §4.4.4): centroid to the origin, mean distance to it sqrt(2).
// Returns false when all points coincide (no scale to normalise by).
bool NormalisingTransform(std::span<const Eigen::Vector2d> uv, std::span<const int> indices, int n,
                          Eigen::Matrix3d* transform) {
  auto at = [&](int k) -> const Eigen::Vector2d& { return indices.empty() ? uv[k] : uv[indices[k]]; };
  Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
  for (int k = 0; k < n; ++k) centroid += at(k);
  centroid /= n;
  double mean_distance = 0;
  for (int k = 0; k < n; ++k) mean_distance += (at(k) - centroid).norm();
  mean_distance /= n;
  if (!(mean_distance > 1e-12)) return false;
  const double s = std::sqrt(2.0) / mean_distance;
  *transform << s, 0, -s * centroid.x(), 0, s, -s * centroid.y(), 0, 0, 1;
  return true;
}

}  // namespace

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Eigen::Matrix3d EssentialFromPose(const Pose& cam2_from_cam1) { return Skew(cam2_from_cam1.t) * cam2_from_cam1.R(); }

std::optional<Eigen::Matrix3d> EssentialEightPoint(std::span<const Eigen::Vector2d> uv_norm1,
                                                   std::span<const Eigen::Vector2d> uv_norm2,
                                                   std::span<const int> indices) {
  if (uv_norm1.size() != uv_norm2.size()) return std::nullopt;
  const int n = static_cast<int>(indices.empty() ? uv_norm1.size() : indices.size());
  if (n < 8) return std::nullopt;
  for (int k = 0; k < n; ++k) {
    const int i = indices.empty() ? k : indices[k];
    if (i < 0 || i >= static_cast<int>(uv_norm1.size())) return std::nullopt;
    if (!uv_norm1[i].allFinite() || !uv_norm2[i].allFinite()) return std::nullopt;
  }
  Eigen::Matrix3d t1, t2;
  if (!NormalisingTransform(uv_norm1, indices, n, &t1) || !NormalisingTransform(uv_norm2, indices, n, &t2))
    return std::nullopt;

  // One row per correspondence: x2^T E x1 = 0 written as a . e = 0, e = E in row-major order.
  auto row = [&](int k) {
    const int i = indices.empty() ? k : indices[k];
    const Eigen::Vector3d p1 = t1 * uv_norm1[i].homogeneous();
    const Eigen::Vector3d p2 = t2 * uv_norm2[i].homogeneous();
    Eigen::Matrix<double, 9, 1> r;
    r << p2.x() * p1.x(), p2.x() * p1.y(), p2.x(), p2.y() * p1.x(), p2.y() * p1.y(), p2.y(), p1.x(), p1.y(), 1.0;
    return r;
  };
  Eigen::Matrix<double, 9, 1> e;
  if (n == 8) {
    // The minimal sample (RANSAC calls this for every one): the null vector of the 8 x 9 A is the last column of
    // Q in A^T = Q R, orthogonal to A's 8 rows. Column pivoting makes R rank-revealing: |R77| / |R00| stands for
    // the second-smallest singular value of the 9 relative to the largest (within small factors, which the
    // tolerance's margin covers). A few times cheaper than the Jacobi SVD of A, which iterates to convergence.
    Eigen::Matrix<double, 9, 8> a_t;
    for (int k = 0; k < 8; ++k) a_t.col(k) = row(k);
    const Eigen::ColPivHouseholderQR<Eigen::Matrix<double, 9, 8>> qr(a_t);
    const double r00 = std::abs(qr.matrixQR()(0, 0)), r77 = std::abs(qr.matrixQR()(7, 7));
    if (!(r00 > 0) || r77 < kRankTolerance * r00) return std::nullopt;
    e = qr.householderQ() * Eigen::Matrix<double, 9, 1>::Unit(8);
  } else {
    // Least squares over n > 8: the right singular vector of the smallest singular value. A's QR (A = Q R, Q
    // orthonormal) gives a 9 x 9 R with A's singular values and right singular vectors, and its fixed-size SVD is
    // cheaper than the n x 9 one; QR keeps A's conditioning, which the normal equations A^T A would square.
    Eigen::Matrix<double, Eigen::Dynamic, 9> a(n, 9);
    for (int k = 0; k < n; ++k) a.row(k) = row(k).transpose();
    const Eigen::HouseholderQR<Eigen::Matrix<double, Eigen::Dynamic, 9>> qr(a);
    const Eigen::Matrix<double, 9, 9> r = qr.matrixQR().topRows<9>().triangularView<Eigen::Upper>();
    const Eigen::JacobiSVD<Eigen::Matrix<double, 9, 9>> svd(r, Eigen::ComputeFullV);
    const auto& sv = svd.singularValues();  // decreasing; the second-smallest is sv[7]
    if (!(sv[0] > 0) || sv[7] < kRankTolerance * sv[0]) return std::nullopt;
    e = svd.matrixV().col(8);
  }
  Eigen::Matrix3d e_normalised;
  e_normalised << e[0], e[1], e[2], e[3], e[4], e[5], e[6], e[7], e[8];
  // p2^T En p1 = x2^T (T2^T En T1) x1.
  const Eigen::Matrix3d e_raw = t2.transpose() * e_normalised * t1;

  // Nearest essential matrix in Frobenius norm: equal the two largest singular values, zero the third
  // (H&Z Result 9.17 / §11.3); scaled to (1, 1, 0).
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd_e(e_raw, Eigen::ComputeFullU | Eigen::ComputeFullV);
  if (!(svd_e.singularValues()[0] > 0)) return std::nullopt;
  const Eigen::Matrix3d essential =
      svd_e.matrixU() * Eigen::Vector3d(1, 1, 0).asDiagonal() * svd_e.matrixV().transpose();
  if (!essential.allFinite()) return std::nullopt;
  return essential;
}

double SignedSampsonDistance(const Eigen::Matrix3d& essential, const Eigen::Vector2d& uv_norm1,
                             const Eigen::Vector2d& uv_norm2) {
  const Eigen::Vector3d x1 = uv_norm1.homogeneous(), x2 = uv_norm2.homogeneous();
  const Eigen::Vector3d l2 = essential * x1;              // epipolar line of x1 in view 2
  const Eigen::Vector3d l1 = essential.transpose() * x2;  // epipolar line of x2 in view 1
  const double algebraic = x2.dot(l2);
  const double gradient_sq = l2.head<2>().squaredNorm() + l1.head<2>().squaredNorm();
  if (!(gradient_sq > 1e-300)) {
    if (algebraic == 0) return 0.0;
    return std::copysign(std::numeric_limits<double>::infinity(), algebraic);
  }
  return algebraic / std::sqrt(gradient_sq);
}

double SampsonDistance(const Eigen::Matrix3d& essential, const Eigen::Vector2d& uv_norm1,
                       const Eigen::Vector2d& uv_norm2) {
  return std::abs(SignedSampsonDistance(essential, uv_norm1, uv_norm2));
}

std::array<Pose, 4> DecomposeEssential(const Eigen::Matrix3d& essential) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(essential, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d u = svd.matrixU(), v = svd.matrixV();
  // Flipping the sign of U or V only flips the sign of E, which describes the same geometry; with both
  // proper rotations, U W V^T and U W^T V^T are rotations.
  if (u.determinant() < 0) u = -u;
  if (v.determinant() < 0) v = -v;
  Eigen::Matrix3d w;
  w << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  const Eigen::Matrix3d r1 = u * w * v.transpose();
  const Eigen::Matrix3d r2 = u * w.transpose() * v.transpose();
  const Eigen::Vector3d t = u.col(2);
  return {Pose::FromRotationTranslation(r1, t), Pose::FromRotationTranslation(r1, -t),
          Pose::FromRotationTranslation(r2, t), Pose::FromRotationTranslation(r2, -t)};
}

Eigen::Matrix<double, 3, 2> TangentBasis(const Eigen::Vector3d& t) {
  // Cross with the axis least aligned with t, so that the first basis vector is never ill-defined.
  const Eigen::Vector3d axis = std::abs(t.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d b1 = t.cross(axis).normalized();
  const Eigen::Vector3d b2 = t.normalized().cross(b1);
  Eigen::Matrix<double, 3, 2> basis;
  basis << b1, b2;
  return basis;
}

Pose ApplyRelativePoseUpdate(const Pose& cam2_from_cam1, const Eigen::Matrix<double, 5, 1>& delta) {
  const Eigen::Quaterniond q = QuaternionFromRotationVector(delta.head<3>()) * cam2_from_cam1.q;
  const Eigen::Vector3d t = (cam2_from_cam1.t + TangentBasis(cam2_from_cam1.t) * delta.tail<2>()).normalized();
  return Pose(q, t);
}

double SampsonResidual(const Pose& cam2_from_cam1, const Eigen::Vector2d& uv_norm1, const Eigen::Vector2d& uv_norm2,
                       double scale, Eigen::Matrix<double, 1, 5>* jacobian) {
  const Eigen::Matrix3d r = cam2_from_cam1.R();
  const Eigen::Vector3d& t = cam2_from_cam1.t;
  const Eigen::Matrix3d tx = Skew(t);
  const Eigen::Matrix3d e = tx * r;
  const Eigen::Vector3d x1 = uv_norm1.homogeneous(), x2 = uv_norm2.homogeneous();
  const Eigen::Vector3d l2 = e * x1, l1 = e.transpose() * x2;
  const double a = x2.dot(l2);
  const double g = l2.head<2>().squaredNorm() + l1.head<2>().squaredNorm();
  if (!(g > 1e-300)) {
    // Both points at their epipoles: the constraint has no gradient and says nothing about the pose.
    if (jacobian) jacobian->setZero();
    return 0.0;
  }
  const double inv_sqrt_g = 1.0 / std::sqrt(g);
  const double residual = scale * a * inv_sqrt_g;
  if (jacobian) {
    // r = s a / sqrt(g): dr = s (da / sqrt(g) - a dg / (2 g^1.5)), with, for a change dE of E,
    // da = x2^T dE x1 and dg = 2 (l2_xy . (dE x1)_xy + l1_xy . (dE^T x2)_xy).
    // dE for the rotation update exp([w]x) R: [t]x [e_j]x R; for the direction update t + B b: [B_k]x R.
    const Eigen::Matrix<double, 3, 2> basis = TangentBasis(t);
    for (int j = 0; j < 5; ++j) {
      const Eigen::Matrix3d de =
          j < 3 ? Eigen::Matrix3d(tx * Skew(Eigen::Vector3d::Unit(j)) * r) : Eigen::Matrix3d(Skew(basis.col(j - 3)) * r);
      const Eigen::Vector3d de_x1 = de * x1, de_t_x2 = de.transpose() * x2;
      const double da = x2.dot(de_x1);
      const double dg = 2.0 * (l2.head<2>().dot(de_x1.head<2>()) + l1.head<2>().dot(de_t_x2.head<2>()));
      (*jacobian)(j) = scale * (da * inv_sqrt_g - 0.5 * a * dg * inv_sqrt_g * inv_sqrt_g * inv_sqrt_g);
    }
  }
  return residual;
}

void RefineOptions::Check() const {
  if (max_iterations < 1)
    throw std::invalid_argument(fmt::format("RefineOptions.max_iterations must be >= 1, got {}", max_iterations));
  if (!(std::isfinite(scale) && scale > 0))
    throw std::invalid_argument(fmt::format("RefineOptions.scale must be > 0 and finite, got {}", scale));
  if (!(gradient_tolerance >= 0))
    throw std::invalid_argument(fmt::format("RefineOptions.gradient_tolerance must be >= 0, got {}", gradient_tolerance));
  if (!(step_tolerance >= 0))
    throw std::invalid_argument(fmt::format("RefineOptions.step_tolerance must be >= 0, got {}", step_tolerance));
  if (!(std::isfinite(cauchy_scale) && cauchy_scale >= 0))
    throw std::invalid_argument(fmt::format("RefineOptions.cauchy_scale must be >= 0 and finite, got {}", cauchy_scale));
}

namespace {

// Loss of one residual and its IRLS weight: plain squares (c = 0) or Cauchy, rho(r) = c^2 log(1 + r^2/c^2),
// whose minimiser satisfies the weighted normal equations with w = rho'(r^2) = 1 / (1 + r^2/c^2).
struct Loss {
  double c_sq = 0;
  double Value(double r_sq) const { return c_sq > 0 ? c_sq * std::log1p(r_sq / c_sq) : r_sq; }
  double Weight(double r_sq) const { return c_sq > 0 ? 1.0 / (1.0 + r_sq / c_sq) : 1.0; }
};

// Normal equations of the (reweighted) Sampson problem at a pose: sum w J^T J, sum w J^T r and the cost.
struct NormalEquations {
  Eigen::Matrix<double, 5, 5> jtj = Eigen::Matrix<double, 5, 5>::Zero();
  Eigen::Matrix<double, 5, 1> jtr = Eigen::Matrix<double, 5, 1>::Zero();
  double cost = 0;
};

template <typename ForEach>
NormalEquations Linearise(const Pose& pose, std::span<const Eigen::Vector2d> uv1, std::span<const Eigen::Vector2d> uv2,
                          double scale, const Loss& loss, ForEach for_each) {
  NormalEquations ne;
  Eigen::Matrix<double, 1, 5> j;
  for_each([&](int i) {
    const double r = SampsonResidual(pose, uv1[i], uv2[i], scale, &j);
    const double w = loss.Weight(r * r);
    ne.jtj.noalias() += w * j.transpose() * j;
    ne.jtr += (w * r) * j.transpose();
    ne.cost += loss.Value(r * r);
  });
  return ne;
}

template <typename ForEach>
double Cost(const Pose& pose, std::span<const Eigen::Vector2d> uv1, std::span<const Eigen::Vector2d> uv2, double scale,
            const Loss& loss, ForEach for_each) {
  double cost = 0;
  for_each([&](int i) {
    const double r = SampsonResidual(pose, uv1[i], uv2[i], scale);
    cost += loss.Value(r * r);
  });
  return cost;
}

}  // namespace

Pose RefineRelativePose(const Pose& cam2_from_cam1, std::span<const Eigen::Vector2d> uv_norm1,
                        std::span<const Eigen::Vector2d> uv_norm2, std::span<const int> indices,
                        const RefineOptions& options, RefineSummary* summary) {
  options.Check();
  RefineSummary local;
  RefineSummary& s = summary ? *summary : local;
  s = RefineSummary{};
  Pose pose(cam2_from_cam1.q, cam2_from_cam1.t.normalized());
  if (uv_norm1.size() != uv_norm2.size() || !pose.AllFinite()) return cam2_from_cam1;
  auto for_each = [&](auto&& f) {
    if (indices.empty()) {
      for (int i = 0; i < static_cast<int>(uv_norm1.size()); ++i) f(i);
    } else {
      for (const int i : indices) f(i);
    }
  };

  // Madsen, Nielsen & Tingleff (2004), their algorithm 3.16, on F = cost / 2. With the Cauchy loss the normal
  // equations are the reweighted ones (IRLS); a step is still accepted only when the robust cost drops.
  const Loss loss{options.cauchy_scale * options.cauchy_scale};
  NormalEquations ne = Linearise(pose, uv_norm1, uv_norm2, options.scale, loss, for_each);
  s.initial_cost = s.final_cost = ne.cost;
  if (!std::isfinite(ne.cost)) return cam2_from_cam1;
  constexpr double kTau = 1e-3;  // initial damping relative to the largest diagonal of J^T J (their choice)
  double mu = kTau * std::max(ne.jtj.diagonal().maxCoeff(), 1e-300);
  double nu = 2.0;
  bool found = ne.jtr.lpNorm<Eigen::Infinity>() <= options.gradient_tolerance;
  while (!found && s.iterations < options.max_iterations) {
    ++s.iterations;
    const Eigen::Matrix<double, 5, 5> damped = ne.jtj + mu * Eigen::Matrix<double, 5, 5>::Identity();
    const Eigen::Matrix<double, 5, 1> step = damped.ldlt().solve(-ne.jtr);
    if (!step.allFinite()) break;
    if (step.norm() <= options.step_tolerance) {
      found = true;
      break;
    }
    const Pose candidate = ApplyRelativePoseUpdate(pose, step);
    const double new_cost = Cost(candidate, uv_norm1, uv_norm2, options.scale, loss, for_each);
    // Gain ratio: actual decrease of F over the decrease the linear model predicts, (h^T (mu h - g)) / 2.
    const double predicted = 0.5 * step.dot(mu * step - ne.jtr);
    const double rho = predicted > 0 ? 0.5 * (ne.cost - new_cost) / predicted : -1.0;
    if (rho > 0 && new_cost < ne.cost) {
      pose = candidate;
      ne = Linearise(pose, uv_norm1, uv_norm2, options.scale, loss, for_each);
      found = ne.jtr.lpNorm<Eigen::Infinity>() <= options.gradient_tolerance;
      mu *= std::max(1.0 / 3.0, 1.0 - std::pow(2.0 * rho - 1.0, 3));
      nu = 2.0;
    } else {
      mu *= nu;
      nu *= 2.0;
      if (!(mu < 1e300)) break;  // no descent direction left at any damping
    }
  }
  s.converged = found;
  s.final_cost = ne.cost;
  return pose;
}

Eigen::Vector3d TranslationGivenRotation(const Eigen::Matrix3d& cam2_from_cam1_rotation,
                                         std::span<const Eigen::Vector2d> uv_norm1,
                                         std::span<const Eigen::Vector2d> uv_norm2, std::span<const int> indices) {
  if (uv_norm1.size() != uv_norm2.size()) return Eigen::Vector3d::Zero();
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  int n = 0;
  auto add = [&](int i) {
    const Eigen::Vector3d a = (cam2_from_cam1_rotation * uv_norm1[i].homogeneous()).cross(uv_norm2[i].homogeneous());
    sum += a * a.transpose();
    ++n;
  };
  if (indices.empty()) {
    for (int i = 0; i < static_cast<int>(uv_norm1.size()); ++i) add(i);
  } else {
    for (const int i : indices) add(i);
  }
  if (n < 2 || !sum.allFinite()) return Eigen::Vector3d::Zero();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(sum);
  return eigen.eigenvectors().col(0);  // eigenvalues ascending
}

std::vector<RelativePoseMinimum> RelativePoseMinima(const Pose& cam2_from_cam1, std::span<const Eigen::Vector2d> uv_norm1,
                                                    std::span<const Eigen::Vector2d> uv_norm2,
                                                    std::span<const int> indices, double radius_deg,
                                                    const RefineOptions& options) {
  options.Check();
  if (!(radius_deg > 0) || !std::isfinite(radius_deg))
    throw std::invalid_argument(fmt::format("RelativePoseMinima: radius_deg must be > 0, got {}", radius_deg));
  std::vector<Pose> starts{cam2_from_cam1};
  for (const double fraction : {0.5, 1.0})
    for (int x = -1; x <= 1; ++x)
      for (int y = -1; y <= 1; ++y)
        for (int z = -1; z <= 1; ++z) {
          if (x == 0 && y == 0 && z == 0) continue;
          const Eigen::Vector3d axis = Eigen::Vector3d(x, y, z).normalized();
          const Eigen::Quaterniond q =
              (Eigen::Quaterniond(Eigen::AngleAxisd(fraction * radius_deg * M_PI / 180.0, axis)) * cam2_from_cam1.q)
                  .normalized();
          const Eigen::Vector3d t = TranslationGivenRotation(q.toRotationMatrix(), uv_norm1, uv_norm2, indices);
          if (t.squaredNorm() > 0.5) starts.emplace_back(q, t);
        }
  std::vector<RelativePoseMinimum> minima;
  const double same_deg = radius_deg / 10.0;
  // The refinements are independent: run in parallel, merged in the starts' order (the same minima as in turn).
  std::vector<Pose> refined(starts.size());
  std::vector<RefineSummary> summaries(starts.size());
  // Isolated: while it waits, the calling thread takes no unrelated task (the front end's) and returns on time.
  tbb::this_task_arena::isolate([&] {
    tbb::parallel_for(size_t{0}, starts.size(), [&](size_t k) {
      refined[k] = RefineRelativePose(starts[k], uv_norm1, uv_norm2, indices, options, &summaries[k]);
    });
  });
  for (size_t k = 0; k < starts.size(); ++k) {
    const RefineSummary& summary = summaries[k];
    const Pose& pose = refined[k];
    // A refinement that ran out of iterations is still crawling along the valley: not a minimum.
    if (!summary.converged || !pose.AllFinite() || !std::isfinite(summary.final_cost)) continue;
    auto same = std::find_if(minima.begin(), minima.end(), [&](const RelativePoseMinimum& m) {
      return AngularDistanceDeg(m.cam2_from_cam1.q, pose.q) <= same_deg;
    });
    if (same == minima.end())
      minima.push_back({pose, summary.final_cost});
    else if (summary.final_cost < same->cost)
      *same = {pose, summary.final_cost};  // the same basin, reached closer to its floor
  }
  std::sort(minima.begin(), minima.end(),
            [](const RelativePoseMinimum& a, const RelativePoseMinimum& b) { return a.cost < b.cost; });
  return minima;
}

}  // namespace mcslam::geometry
