#include "geometry/bundle_adjust.h"

#include <cmath>
#include <limits>
#include <stdexcept>

#include <ceres/ceres.h>
#include <ceres/product_manifold.h>
#include <fmt/format.h>

#include "geometry/reprojection_cost.h"

namespace mcslam::geometry {

void BundleAdjustOptions::Check() const {
  if (!(focal_px > 0)) throw std::invalid_argument(fmt::format("bundle adjustment: focal_px must be > 0, got {}", focal_px));
  if (!(huber_px > 0)) throw std::invalid_argument(fmt::format("bundle adjustment: huber_px must be > 0, got {}", huber_px));
  if (max_iterations < 1)
    throw std::invalid_argument(fmt::format("bundle adjustment: max_iterations must be >= 1, got {}", max_iterations));
  if (!(function_tolerance >= 0 && function_tolerance < 1))
    throw std::invalid_argument(
        fmt::format("bundle adjustment: function_tolerance must be in [0, 1), got {}", function_tolerance));
  if (num_threads < 1) throw std::invalid_argument(fmt::format("bundle adjustment: num_threads must be >= 1, got {}", num_threads));
}

double ReprojectionErrorPx(const Pose& cam_from_world, const Eigen::Vector3d& point_in_world,
                           const Eigen::Vector2d& uv_norm, double focal_px) {
  const Eigen::Vector3d p = cam_from_world * point_in_world;
  if (!(p.z() > 1e-9)) return std::numeric_limits<double>::infinity();
  return focal_px * (p.head<2>() / p.z() - uv_norm).norm();
}

namespace {

double RmsPx(const std::vector<Pose>& cams, const std::vector<Eigen::Vector3d>& pts,
             const std::vector<BundleObservation>& obs, double focal) {
  double s = 0;
  for (const BundleObservation& o : obs) {
    const double e = ReprojectionErrorPx(cams[o.camera], pts[o.point], o.uv_norm, focal);
    if (std::isfinite(e)) s += e * e;  // behind the camera: no pixel residual exists
  }
  return obs.empty() ? 0.0 : std::sqrt(s / obs.size());
}

}  // namespace

BundleAdjustSummary BundleAdjust(std::vector<Pose>& cams, std::vector<Eigen::Vector3d>& pts,
                                 const std::vector<BundleObservation>& obs, const std::vector<bool>& fixed,
                                 const BundleAdjustOptions& options, const std::vector<bool>& fixed_points) {
  options.Check();
  if (fixed.size() != cams.size()) throw std::invalid_argument("bundle adjustment: one fixed flag per camera is needed");
  if (!fixed_points.empty() && fixed_points.size() != pts.size())
    throw std::invalid_argument("bundle adjustment: one fixed flag per point is needed (or none)");
  BundleAdjustSummary out;
  out.initial_rms_px = RmsPx(cams, pts, obs, options.focal_px);
  std::vector<std::array<double, 7>> pose(cams.size());  // qx qy qz qw tx ty tz
  for (size_t i = 0; i < cams.size(); ++i) {
    const Eigen::Quaterniond qi = cams[i].q.normalized();
    pose[i] = {qi.x(), qi.y(), qi.z(), qi.w(), cams[i].t.x(), cams[i].t.y(), cams[i].t.z()};
  }
  // One loss for every residual (it holds only its scale), owned here rather than one allocated for each; the
  // problem's structure is built right by construction, so Ceres' per-block checks are skipped.
  ceres::CauchyLoss cauchy(options.huber_px);
  ceres::HuberLoss huber(options.huber_px);
  ceres::LossFunction* loss = options.cauchy ? static_cast<ceres::LossFunction*>(&cauchy) : &huber;
  ceres::Problem::Options problem_options;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.disable_all_safety_checks = true;
  ceres::Problem problem(problem_options);
  for (const BundleObservation& o : obs) {
    if (o.camera < 0 || o.camera >= static_cast<int>(cams.size()) || o.point < 0 || o.point >= static_cast<int>(pts.size()))
      throw std::invalid_argument("bundle adjustment: observation index out of range");
    if (!std::isfinite(ReprojectionErrorPx(cams[o.camera], pts[o.point], o.uv_norm, options.focal_px))) {
      ++out.left_out_behind;
      continue;
    }
    if (fixed[static_cast<size_t>(o.camera)]) {
      problem.AddResidualBlock(new FixedCameraReprojectionCost(cams[o.camera], o.uv_norm, options.focal_px), loss,
                               pts[o.point].data());
      continue;
    }
    auto* cost = new ReprojectionCost(o.uv_norm, options.focal_px);
    problem.AddResidualBlock(cost, loss, pose[o.camera].data(), pts[o.point].data());
  }
  for (size_t i = 0; i < cams.size(); ++i)
    if (problem.HasParameterBlock(pose[i].data()))  // a free camera's (fixed ones' residuals take only the point)
      problem.SetManifold(pose[i].data(),
                          new ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>());
  for (size_t j = 0; j < fixed_points.size(); ++j)
    if (fixed_points[j] && problem.HasParameterBlock(pts[j].data())) problem.SetParameterBlockConstant(pts[j].data());
  ceres::Solver::Options so;
  switch (options.linear_solver) {
    case BundleAdjustOptions::LinearSolver::kSparseSchur: so.linear_solver_type = ceres::SPARSE_SCHUR; break;
    case BundleAdjustOptions::LinearSolver::kDenseSchur: so.linear_solver_type = ceres::DENSE_SCHUR; break;
    case BundleAdjustOptions::LinearSolver::kIterativeSchur:
      so.linear_solver_type = ceres::ITERATIVE_SCHUR;
      so.preconditioner_type = ceres::JACOBI;
      break;
  }
  so.max_num_iterations = options.max_iterations;
  so.function_tolerance = options.function_tolerance;
  so.num_threads = options.num_threads;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  for (size_t i = 0; i < cams.size(); ++i)
    cams[i] = Pose(Eigen::Quaterniond(pose[i][3], pose[i][0], pose[i][1], pose[i][2]),
                   Eigen::Vector3d(pose[i][4], pose[i][5], pose[i][6]));
  out.converged = summary.termination_type == ceres::CONVERGENCE;
  out.iterations = static_cast<int>(summary.iterations.size());
  out.final_rms_px = RmsPx(cams, pts, obs, options.focal_px);
  out.report = summary.BriefReport();
  return out;
}

}  // namespace mcslam::geometry
