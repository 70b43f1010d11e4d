#include "geometry/self_calibration.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include <ceres/ceres.h>
#include <ceres/product_manifold.h>
#include <fmt/format.h>

#include "geometry/reprojection_cost.h"

namespace mcslam::geometry {

void IntrinsicsOptions::Check() const {
  if (!(loss_px > 0)) throw std::invalid_argument(fmt::format("self-calibration: loss_px must be > 0, got {}", loss_px));
  if (max_iterations < 1)
    throw std::invalid_argument(fmt::format("self-calibration: max_iterations must be >= 1, got {}", max_iterations));
  if (num_threads < 1)
    throw std::invalid_argument(fmt::format("self-calibration: num_threads must be >= 1, got {}", num_threads));
}

namespace {

struct Solved {
  double cost = 0;
  std::array<double, 2> intr{1.0, 0.0};
  std::vector<double> residuals;
  std::string report;
};

Solved Solve(const PinholeCamera& camera, const std::vector<Pose>& cams, const std::vector<Eigen::Vector3d>& pts,
             const std::vector<PixelObservation>& obs, const std::vector<bool>& fixed, bool free_intrinsics,
             const IntrinsicsOptions& options) {
  std::vector<std::array<double, 7>> pose(cams.size());
  for (size_t i = 0; i < cams.size(); ++i) {
    const Eigen::Quaterniond q = cams[i].q.normalized();
    pose[i] = {q.x(), q.y(), q.z(), q.w(), cams[i].t.x(), cams[i].t.y(), cams[i].t.z()};
  }
  std::vector<Eigen::Vector3d> X = pts;
  Solved out;
  ceres::CauchyLoss loss(options.loss_px);
  ceres::Problem::Options po;
  po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  std::vector<ceres::ResidualBlockId> ids;
  for (const PixelObservation& o : obs) {
    auto* cost = new CalibratedReprojectionCost(camera, o.uv_px);
    ids.push_back(problem.AddResidualBlock(cost, &loss, pose[o.camera].data(), X[o.point].data(), out.intr.data()));
  }
  for (size_t i = 0; i < cams.size(); ++i) {
    if (!problem.HasParameterBlock(pose[i].data())) continue;
    problem.SetManifold(pose[i].data(),
                        new ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>());
    if (fixed[i]) problem.SetParameterBlockConstant(pose[i].data());
  }
  if (!free_intrinsics) problem.SetParameterBlockConstant(out.intr.data());
  else if (!options.free_focal) problem.SetManifold(out.intr.data(), new ceres::SubsetManifold(2, {0}));
  ceres::Solver::Options so;
  // Tens of cameras that all see the same few hundred points: conjugate gradients on the Schur complement
  // without forming it (as BundleAdjustOptions::LinearSolver::kIterativeSchur; 7-Scenes' six fits of 40 frames
  // 0.46 s faster, k1, its sigma and the halves' the same to the printed digit).
  so.linear_solver_type = ceres::ITERATIVE_SCHUR;
  so.preconditioner_type = ceres::JACOBI;
  so.max_num_iterations = options.max_iterations;
  so.num_threads = options.num_threads;
  so.logging_type = ceres::SILENT;
  // Started near its optimum (a settled window), the change a k1 makes is a small fraction of the cost: Ceres'
  // default tolerance (1e-6 of it) can stop before the first step.
  so.function_tolerance = 1e-10;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  out.cost = summary.final_cost;
  out.report = summary.BriefReport();
  ceres::Problem::EvaluateOptions eo;
  eo.residual_blocks = ids;
  eo.apply_loss_function = false;
  problem.Evaluate(eo, nullptr, &out.residuals, nullptr, nullptr);
  return out;
}

double InlierRms(const std::vector<double>& r, double limit) {
  double s = 0;
  int n = 0;
  for (size_t i = 0; i + 1 < r.size(); i += 2) {
    const double e2 = r[i] * r[i] + r[i + 1] * r[i + 1];
    if (e2 < limit * limit) s += e2, ++n;
  }
  return n ? std::sqrt(s / n) : 0.0;
}

}  // namespace

IntrinsicsFit RefineIntrinsics(const PinholeCamera& camera, const std::vector<Pose>& cams,
                               const std::vector<Eigen::Vector3d>& pts, const std::vector<PixelObservation>& obs,
                               const std::vector<bool>& fixed, const IntrinsicsOptions& options) {
  options.Check();
  camera.Check();
  if (fixed.size() != cams.size()) throw std::invalid_argument("self-calibration: one fixed flag per camera is needed");
  for (const PixelObservation& o : obs)
    if (o.camera < 0 || o.camera >= static_cast<int>(cams.size()) || o.point < 0 || o.point >= static_cast<int>(pts.size()))
      throw std::invalid_argument("self-calibration: observation index out of range");
  // Observations behind their camera have no pixel residual: left out of both adjustments.
  std::vector<PixelObservation> front;
  front.reserve(obs.size());
  for (const PixelObservation& o : obs)
    if ((cams[o.camera] * pts[o.point]).z() > 1e-9) front.push_back(o);
  IntrinsicsFit fit;
  fit.camera = camera;
  if (front.empty()) {  // nothing measures the camera: it stays as given
    fit.report = "no observation in front of its camera";
    return fit;
  }
  const Solved a = Solve(camera, cams, pts, front, fixed, false, options);
  const Solved b = Solve(camera, cams, pts, front, fixed, true, options);
  fit.focal_scale = b.intr[0];
  fit.delta_k1 = b.intr[1];
  fit.camera.fx *= b.intr[0];
  fit.camera.fy *= b.intr[0];
  fit.camera.dist.k1 += b.intr[1];
  fit.cost_fixed = a.cost;
  fit.cost_free = b.cost;
  fit.rms_fixed_px = InlierRms(a.residuals, 3 * options.loss_px);
  fit.rms_free_px = InlierRms(b.residuals, 3 * options.loss_px);
  fit.observations = static_cast<int>(front.size());
  fit.report = b.report;
  // The likelihood ratio of the two fits: twice their cost difference over the residuals' variance (a
  // coordinate's: half the free fit's mean squared 2D inlier residual) is chi-square with one degree of freedom
  // a free intrinsic under the hypothesis that the given camera is right. Its square root, for k1 alone, is
  // |delta_k1| / sigma: the standard deviation it implies.
  const double var = 0.5 * fit.rms_free_px * fit.rms_free_px;
  fit.chi2 = var > 0 ? std::max(0.0, 2.0 * (a.cost - b.cost) / var) : 0.0;
  if (!options.free_focal && fit.chi2 > 0) fit.sigma_k1 = std::abs(fit.delta_k1) / std::sqrt(fit.chi2);
  return fit;
}

}  // namespace mcslam::geometry
