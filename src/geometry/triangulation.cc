// With -march=native on AVX-512 machines, GCC 12 reports -Wmaybe-uninitialized false positives inside its own
// _mm512_extractf64x4_pd (_mm256_undefined_pd) as Eigen's dynamic-size products instantiate it. They must be
// silenced before Eigen is included, so for this whole file.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#include "geometry/triangulation.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/SVD>
#include <fmt/format.h>

namespace mcslam::geometry {

void TriangulationOptions::Check() const {
  if (!(std::isfinite(max_reprojection_px) && max_reprojection_px > 0))
    throw std::invalid_argument(
        fmt::format("TriangulationOptions.max_reprojection_px must be > 0 and finite, got {}", max_reprojection_px));
  if (!(std::isfinite(focal_px) && focal_px > 0))
    throw std::invalid_argument(fmt::format("TriangulationOptions.focal_px must be > 0 and finite, got {}", focal_px));
  if (!(min_parallax_deg >= 0 && min_parallax_deg < 180))
    throw std::invalid_argument(
        fmt::format("TriangulationOptions.min_parallax_deg must be in [0, 180), got {}", min_parallax_deg));
  if (!(std::isfinite(min_depth) && min_depth >= 0))
    throw std::invalid_argument(fmt::format("TriangulationOptions.min_depth must be >= 0 and finite, got {}", min_depth));
}

const char* ToString(TriangulationStatus status) {
  switch (status) {
    case TriangulationStatus::kOk: return "ok";
    case TriangulationStatus::kBadInput: return "bad input";
    case TriangulationStatus::kAtInfinity: return "at infinity";
    case TriangulationStatus::kBehindCamera: return "behind camera";
    case TriangulationStatus::kLargeReprojection: return "large reprojection error";
    case TriangulationStatus::kSmallParallax: return "small parallax";
  }
  return "?";
}

Eigen::Vector4d TriangulateHomogeneous(std::span<const Pose> cam_from_world, std::span<const Eigen::Vector2d> uv_norm) {
  const int n = static_cast<int>(cam_from_world.size());
  if (n < 2 || uv_norm.size() != cam_from_world.size()) return Eigen::Vector4d::Zero();
  Eigen::Matrix<double, Eigen::Dynamic, 4> a(2 * n, 4);
  for (int i = 0; i < n; ++i) {
    const Eigen::Matrix<double, 3, 4> p = cam_from_world[i].Matrix3x4();
    a.row(2 * i) = uv_norm[i].x() * p.row(2) - p.row(0);
    a.row(2 * i + 1) = uv_norm[i].y() * p.row(2) - p.row(1);
  }
  if (n == 2) {
    // Square system: a fixed-size SVD is faster and this path runs for every correspondence of an initialisation.
    const Eigen::Matrix4d a4 = a;
    const Eigen::JacobiSVD<Eigen::Matrix4d> svd(a4, Eigen::ComputeFullV);
    return svd.matrixV().col(3);
  }
  const Eigen::JacobiSVD<Eigen::Matrix<double, Eigen::Dynamic, 4>> svd(a, Eigen::ComputeFullV);
  return svd.matrixV().col(3);
}

InFrontOfBoth TriangulateInFrontOfBoth(const Pose& cam2_from_cam1, std::span<const Eigen::Vector2d> uv_norm1,
                                       std::span<const Eigen::Vector2d> uv_norm2, std::span<const int> indices) {
  InFrontOfBoth out;
  const std::array<Pose, 2> poses = {Pose::Identity(), cam2_from_cam1};
  auto consider = [&](int i) {
    const std::array<Eigen::Vector2d, 2> obs = {uv_norm1[i], uv_norm2[i]};
    const Eigen::Vector4d x = TriangulateHomogeneous(poses, obs);
    if (!x.allFinite() || !(std::abs(x.w()) > 1e-12 * x.head<3>().norm())) return;  // at infinity: no sign
    const Eigen::Vector3d p1 = x.head<3>() / x.w();
    if (p1.z() > 0 && (cam2_from_cam1 * p1).z() > 0) out.indices.push_back(i), out.points_in_cam1.push_back(p1);
  };
  if (uv_norm1.size() != uv_norm2.size()) return out;
  if (indices.empty()) {
    for (int i = 0; i < static_cast<int>(uv_norm1.size()); ++i) consider(i);
  } else {
    for (const int i : indices) consider(i);
  }
  return out;
}

double ParallaxDeg(std::span<const Pose> cam_from_world, const Eigen::Vector3d& point_in_world) {
  double best = 0;
  const int n = static_cast<int>(cam_from_world.size());
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d ray_i = point_in_world - cam_from_world[i].OriginOfTargetInSource();
    for (int j = i + 1; j < n; ++j) {
      const Eigen::Vector3d ray_j = point_in_world - cam_from_world[j].OriginOfTargetInSource();
      best = std::max(best, AngleBetween(ray_i, ray_j));  // accurate for the small angles this check is about
    }
  }
  return RadToDeg(best);
}

Triangulation TriangulateDlt(std::span<const Pose> cam_from_world, std::span<const Eigen::Vector2d> uv_norm,
                             const TriangulationOptions& options) {
  options.Check();
  Triangulation out;
  auto fail = [&](TriangulationStatus status, std::string why) {
    out.ok = false;
    out.status = status;
    out.failure = std::move(why);
    return out;
  };
  const int n = static_cast<int>(cam_from_world.size());
  if (n < 2) return fail(TriangulationStatus::kBadInput, fmt::format("{} view(s); triangulation needs at least 2", n));
  if (uv_norm.size() != cam_from_world.size())
    return fail(TriangulationStatus::kBadInput,
                fmt::format("{} poses but {} observations", cam_from_world.size(), uv_norm.size()));
  for (int i = 0; i < n; ++i) {
    if (!cam_from_world[i].AllFinite()) return fail(TriangulationStatus::kBadInput, fmt::format("pose {} is not finite", i));
    if (!uv_norm[i].allFinite())
      return fail(TriangulationStatus::kBadInput, fmt::format("observation {} is not finite", i));
  }

  const Eigen::Vector4d x = TriangulateHomogeneous(cam_from_world, uv_norm);
  // A weight this small against the direction part means the rays meet (numerically) at infinity.
  if (!x.allFinite() || !(std::abs(x.w()) > 1e-12 * x.head<3>().norm()))
    return fail(TriangulationStatus::kAtInfinity, "the rays are parallel: the point is at infinity");
  out.point_in_world = x.head<3>() / x.w();

  // Measure everything first, so that a failed check still reports all values.
  out.min_depth = std::numeric_limits<double>::infinity();
  int shallowest = 0, worst = 0;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d p = cam_from_world[i] * out.point_in_world;
    if (p.z() < out.min_depth) {
      out.min_depth = p.z();
      shallowest = i;
    }
    // A point behind or on the camera plane has no meaningful projection; its error counts as infinite.
    const double err = p.z() > 0 ? options.focal_px * (p.head<2>() / p.z() - uv_norm[i]).norm()
                                 : std::numeric_limits<double>::infinity();
    if (err > out.max_reprojection_px || i == 0) {
      out.max_reprojection_px = err;
      worst = i;
    }
  }
  out.parallax_deg = ParallaxDeg(cam_from_world, out.point_in_world);

  if (!(out.min_depth > options.min_depth))
    return fail(TriangulationStatus::kBehindCamera,
                fmt::format("the point is behind camera {} (depth {:.3g} <= {:.3g})", shallowest, out.min_depth,
                            options.min_depth));
  if (!(out.max_reprojection_px <= options.max_reprojection_px))
    return fail(TriangulationStatus::kLargeReprojection,
                fmt::format("reprojection error {:.3g} px in view {} > {:.3g} px", out.max_reprojection_px, worst,
                            options.max_reprojection_px));
  if (!(out.parallax_deg >= options.min_parallax_deg))
    return fail(TriangulationStatus::kSmallParallax,
                fmt::format("parallax {:.3g} deg < {:.3g} deg", out.parallax_deg, options.min_parallax_deg));
  out.ok = true;
  out.status = TriangulationStatus::kOk;
  return out;
}

}  // namespace mcslam::geometry
