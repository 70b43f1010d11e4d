#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include <ceres/autodiff_cost_function.h>
#include <ceres/rotation.h>

#include "core/random.h"
#include "geometry/bundle_adjust.h"
#include "geometry/reprojection_cost.h"
#include "geometry/pnp.h"

namespace mcslam::geometry {
namespace {

// Random draws in one statement each, last coordinate first: the order in which GCC evaluated the
// Eigen::Vector3d(Normal(), Normal(), Normal()) these replace (argument order is unspecified in C++; clang
// goes left to right), so that the data are the same with either compiler.
Eigen::Vector3d NormalVector(CounterRng& rng, double sigma) {
  const double z = sigma * rng.Normal(), y = sigma * rng.Normal(), x = sigma * rng.Normal();
  return Eigen::Vector3d(x, y, z);
}

Eigen::Vector3d CloudPoint(CounterRng& rng) {
  const double z = 3 + rng.Uniform(-0.3, 0.3), y = rng.Uniform(-0.4, 0.4), x = rng.Uniform(-0.5, 0.5);
  return Eigen::Vector3d(x, y, z);
}

// Eight cameras on a 40 cm arc looking at a 1 m cloud 3 m away, exact observations.
struct Scene {
  std::vector<Pose> cams;
  std::vector<Eigen::Vector3d> pts;
  std::vector<BundleObservation> obs;
  Scene() {
    CounterRng rng(1, 0);
    for (int i = 0; i < 150; ++i) pts.push_back(CloudPoint(rng));
    for (int c = 0; c < 8; ++c) {
      const Eigen::Vector3d centre(0.05 * c, 0.01 * c, 0.0);
      const Eigen::Quaterniond world_from_cam_q = QuaternionFromRotationVector(Eigen::Vector3d(0, -0.01 * c, 0));
      cams.push_back(Pose(world_from_cam_q, centre).Inverse());
    }
    for (int c = 0; c < 8; ++c)
      for (int i = 0; i < 150; ++i) {
        const Eigen::Vector3d p = cams[c] * pts[i];
        obs.push_back({c, i, p.head<2>() / p.z()});
      }
  }
};

// Up to 100 iterations, the first two cameras held: they fix the gauge, scale included.
BundleAdjustSummary AdjustWithTheFirstTwoFixed(std::vector<Pose>& cams, std::vector<Eigen::Vector3d>& pts,
                                               const std::vector<BundleObservation>& obs,
                                               double function_tolerance = BundleAdjustOptions().function_tolerance) {
  std::vector<bool> fixed(cams.size(), false);
  fixed[0] = fixed[1] = true;
  BundleAdjustOptions o;
  o.max_iterations = 100;
  o.function_tolerance = function_tolerance;
  return BundleAdjust(cams, pts, obs, fixed, o);
}

// The scene's cameras but the first two moved by ~1 cm and ~0.3 deg, its points by ~2 cm (seeded).
void PerturbedStart(const Scene& truth, std::vector<Pose>* cams, std::vector<Eigen::Vector3d>* pts) {
  *cams = truth.cams;
  *pts = truth.pts;
  CounterRng rng(2, 0);
  for (size_t c = 2; c < cams->size(); ++c) {
    const Eigen::Vector3d dt = NormalVector(rng, 0.01);  // translation before rotation: GCC's order, as above
    const Eigen::Vector3d dw = NormalVector(rng, 0.005);
    (*cams)[c] = Pose((*cams)[c].q * QuaternionFromRotationVector(dw), (*cams)[c].t + dt);
  }
  for (auto& p : *pts) p += NormalVector(rng, 0.02);
}

TEST(BundleAdjust, RecoversPerturbedPosesAndPoints) {
  const Scene truth;
  std::vector<Pose> cams;
  std::vector<Eigen::Vector3d> pts;
  PerturbedStart(truth, &cams, &pts);
  const BundleAdjustSummary s = AdjustWithTheFirstTwoFixed(cams, pts, truth.obs);
  EXPECT_GT(s.initial_rms_px, 1.0);
  EXPECT_LT(s.final_rms_px, 1e-4);  // exact data: converges to zero residual (float-free double solve)
  for (size_t c = 0; c < cams.size(); ++c) {
    EXPECT_LT((cams[c].t - truth.cams[c].t).norm(), 1e-4) << c;
    EXPECT_LT(AngularDistanceDeg(cams[c].q, truth.cams[c].q), 1e-3) << c;
  }
}

// BundleAdjustOptions::function_tolerance: the same perturbed start with noisy observations (0.5 px), stopped when
// an iteration lowers the cost by less than 0.1 % of it, ends in fewer iterations than at Ceres' 1e-6 and within
// 1 % of that solution's residual (the noise sets both; the last iterations of the tighter test move the cost
// by less than the looser one's stop); out of [0, 1) it is refused by name.
TEST(BundleAdjust, ALooserFunctionToleranceStopsSoonerAtAboutTheSameResidual) {
  const Scene truth;
  std::vector<BundleObservation> noisy = truth.obs;
  CounterRng noise(3, 0);
  for (BundleObservation& o : noisy) {
    const double dy = noise.Normal(), dx = noise.Normal();
    o.uv_norm += Eigen::Vector2d(dx, dy) * (0.5 / 500.0);  // 0.5 px at the default focal length of 500 px
  }
  auto adjust = [&](double tolerance) {
    std::vector<Pose> cams;
    std::vector<Eigen::Vector3d> pts;
    PerturbedStart(truth, &cams, &pts);
    return AdjustWithTheFirstTwoFixed(cams, pts, noisy, tolerance);
  };
  const BundleAdjustSummary tight = adjust(1e-6), loose = adjust(1e-3);
  std::printf("[ tolerance ] 1e-6: %d iterations, %.5f px; 1e-3: %d iterations, %.5f px\n", tight.iterations,
              tight.final_rms_px, loose.iterations, loose.final_rms_px);
  EXPECT_TRUE(tight.converged);
  EXPECT_TRUE(loose.converged);
  EXPECT_LT(loose.iterations, tight.iterations);
  EXPECT_LT(loose.final_rms_px, 1.01 * tight.final_rms_px);
  BundleAdjustOptions bad;
  for (const double t : {-1e-3, 1.0, std::nan("")}) {
    bad.function_tolerance = t;
    try {
      bad.Check();
      ADD_FAILURE() << t;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("function_tolerance"), std::string::npos) << e.what();
    }
  }
}

// BundleAdjustOptions::linear_solver: the sparse, dense and iterative (not formed) Schur complements solve the
// same Levenberg-Marquardt problem, so from the same perturbed start with noisy observations (0.5 px) all three
// end at the same minimum: the residual within 1e-6 of the dense one's, every camera within 1e-5 m and 1e-4 deg
// of it (the perturbation is 1 cm and 0.3 deg; measured: sparse 3e-15 m, iterative 4.5e-7 m and 8e-6 deg, 12
// iterations against 9, so the bounds leave 20x and 12x). Exact observations: the iterative solver also converges
// to a zero residual.
TEST(BundleAdjust, TheThreeLinearSolversReachTheSameMinimum) {
  using Solver = BundleAdjustOptions::LinearSolver;
  const Scene truth;
  std::vector<BundleObservation> noisy = truth.obs;
  CounterRng noise(4, 0);
  for (BundleObservation& o : noisy) {
    const double dy = noise.Normal(), dx = noise.Normal();
    o.uv_norm += Eigen::Vector2d(dx, dy) * (0.5 / 500.0);
  }
  auto adjust = [&](Solver solver, const std::vector<BundleObservation>& obs, std::vector<Pose>* cams) {
    std::vector<Eigen::Vector3d> pts;
    PerturbedStart(truth, cams, &pts);
    std::vector<bool> fixed(cams->size(), false);
    fixed[0] = fixed[1] = true;
    BundleAdjustOptions o;
    o.max_iterations = 100;
    o.function_tolerance = 1e-12;
    o.linear_solver = solver;
    return BundleAdjust(*cams, pts, obs, fixed, o);
  };
  std::vector<Pose> dense_cams;
  const BundleAdjustSummary dense = adjust(Solver::kDenseSchur, noisy, &dense_cams);
  for (const Solver solver : {Solver::kSparseSchur, Solver::kIterativeSchur}) {
    std::vector<Pose> cams;
    const BundleAdjustSummary s = adjust(solver, noisy, &cams);
    double dt = 0, dq = 0;
    for (size_t c = 0; c < cams.size(); ++c)
      dt = std::max(dt, (cams[c].t - dense_cams[c].t).norm()), dq = std::max(dq, AngularDistanceDeg(cams[c].q, dense_cams[c].q));
    std::printf("[ solver %d ] %d iterations, %.8f px (dense: %d, %.8f px); cameras within %.2e m, %.2e deg\n",
                static_cast<int>(solver), s.iterations, s.final_rms_px, dense.iterations, dense.final_rms_px, dt, dq);
    EXPECT_NEAR(s.final_rms_px, dense.final_rms_px, 1e-6 * dense.final_rms_px) << static_cast<int>(solver);
    EXPECT_LT(dt, 1e-5) << static_cast<int>(solver);
    EXPECT_LT(dq, 1e-4) << static_cast<int>(solver);
  }
  std::vector<Pose> cams;
  const BundleAdjustSummary exact = adjust(Solver::kIterativeSchur, truth.obs, &cams);
  EXPECT_LT(exact.final_rms_px, 1e-4);
  for (size_t c = 0; c < cams.size(); ++c) EXPECT_LT((cams[c].t - truth.cams[c].t).norm(), 1e-4) << c;
}

// The written-out residual and Jacobians (geometry/reprojection_cost.h) against Ceres' automatic differentiation of
// the residual they replaced (UnitQuaternionRotatePoint, then the pinhole projection), at 200 random unit
// quaternions, translations and points in front of the camera: the same residuals and the same Jacobians to 1e-9 of
// their largest entry (both evaluate the same polynomials in double precision; measured: a few 1e-16). The
// fixed-camera cost against the same reference with the pose held; each block's Jacobian alone when the other is
// held (no pointer for it) the same as with both. A point behind the camera: no residual.
// The larger of worst and d, a NaN d taken as the larger (std::max would drop it).
double Worse(double worst, double d) { return d <= worst ? worst : d; }

struct AutoDiffReference {
  double u, v, f;
  template <typename T>
  bool operator()(const T* pose, const T* X, T* r) const {
    const T q_wxyz[4] = {pose[3], pose[0], pose[1], pose[2]};
    T p[3];
    ceres::UnitQuaternionRotatePoint(q_wxyz, X, p);
    p[0] += pose[4], p[1] += pose[5], p[2] += pose[6];
    if (!(p[2] > T(1e-9))) return false;
    r[0] = T(f) * (p[0] / p[2] - T(u));
    r[1] = T(f) * (p[1] / p[2] - T(v));
    return true;
  }
};

TEST(BundleAdjust, TheWrittenOutJacobiansAreTheAutomaticOnes) {
  CounterRng rng(11, 0);
  double worst = 0, worst_fixed = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Quaterniond q = QuaternionFromRotationVector(NormalVector(rng, 1.0));
    const Eigen::Vector3d t = NormalVector(rng, 0.5);
    const Eigen::Vector3d in_cam = Eigen::Vector3d(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(0.5, 5));
    const Eigen::Vector3d X = q.conjugate() * (in_cam - t);
    const Eigen::Vector2d uv(rng.Uniform(-0.5, 0.5), rng.Uniform(-0.5, 0.5));
    const double f = rng.Uniform(300, 1500);
    const double pose[7] = {q.x(), q.y(), q.z(), q.w(), t.x(), t.y(), t.z()};
    const double* params[2] = {pose, X.data()};
    double r_ref[2], J0_ref[14], J1_ref[6], r[2], J0[14], J1[6], r_fixed[2], J_fixed[6];
    double* jac_ref[2] = {J0_ref, J1_ref};
    double* jac[2] = {J0, J1};
    ceres::AutoDiffCostFunction<AutoDiffReference, 2, 7, 3> reference(new AutoDiffReference{uv.x(), uv.y(), f});
    ASSERT_TRUE(reference.Evaluate(params, r_ref, jac_ref));
    ASSERT_TRUE(ReprojectionCost(uv, f).Evaluate(params, r, jac));
    const FixedCameraReprojectionCost fixed(Pose(q, t), uv, f);
    const double* point_only[1] = {X.data()};
    double* jac_fixed[1] = {J_fixed};
    ASSERT_TRUE(fixed.Evaluate(point_only, r_fixed, jac_fixed));
    double scale = 0;
    for (double v : J0_ref) scale = std::max(scale, std::abs(v));
    for (double v : J1_ref) scale = std::max(scale, std::abs(v));
    for (int i = 0; i < 2; ++i) {
      worst = Worse(worst, std::abs(r[i] - r_ref[i]) / scale);
      worst_fixed = Worse(worst_fixed, std::abs(r_fixed[i] - r_ref[i]) / scale);
    }
    for (int i = 0; i < 14; ++i) worst = Worse(worst, std::abs(J0[i] - J0_ref[i]) / scale);
    for (int i = 0; i < 6; ++i) {
      worst = Worse(worst, std::abs(J1[i] - J1_ref[i]) / scale);
      worst_fixed = Worse(worst_fixed, std::abs(J_fixed[i] - J1_ref[i]) / scale);
    }
    // One block held (Ceres passes no Jacobian for a constant block): the other's is the same.
    double J0_only[14], J1_only[6];
    double* pose_only[2] = {J0_only, nullptr};
    double* point_only_jac[2] = {nullptr, J1_only};
    ASSERT_TRUE(ReprojectionCost(uv, f).Evaluate(params, r, pose_only));
    ASSERT_TRUE(ReprojectionCost(uv, f).Evaluate(params, r, point_only_jac));
    for (int i = 0; i < 14; ++i) EXPECT_EQ(J0_only[i], J0[i]);
    for (int i = 0; i < 6; ++i) EXPECT_EQ(J1_only[i], J1[i]);
    // Residuals alone (no Jacobian asked for) are the same values.
    double r_only[2];
    ASSERT_TRUE(ReprojectionCost(uv, f).Evaluate(params, r_only, nullptr));
    EXPECT_EQ(r_only[0], r[0]);
    EXPECT_EQ(r_only[1], r[1]);
  }
  std::printf("[ jacobians ] largest difference from the automatic ones: %.2e (free camera), %.2e (fixed), of the "
              "largest entry\n", worst, worst_fixed);
  EXPECT_LT(worst, 1e-9);
  EXPECT_LT(worst_fixed, 1e-9);
  const double pose[7] = {0, 0, 0, 1, 0, 0, 0};
  const double behind[3] = {0.1, 0.2, -1.0};
  const double* params[2] = {pose, behind};
  double r[2];
  EXPECT_FALSE(ReprojectionCost(Eigen::Vector2d(0, 0), 500).Evaluate(params, r, nullptr));
  const double* point_only[1] = {behind};
  EXPECT_FALSE(FixedCameraReprojectionCost(Pose(), Eigen::Vector2d(0, 0), 500).Evaluate(point_only, r, nullptr));
}

// The self-calibration's written-out residual and Jacobians (pose, point, and the focal scale and k1 increment)
// against Ceres' automatic differentiation of the residual they replaced, at 200 random poses, points, lenses (k1,
// k2, k3, p1, p2 all non-zero) and intrinsics blocks: to 1e-9 of the largest entry (measured: a few 1e-16); the
// intrinsics' Jacobian alone (pose and point held) the same.
struct CalibratedAutoDiffReference {
  PinholeCamera cam;
  double u, v;
  template <typename T>
  bool operator()(const T* pose, const T* X, const T* intr, T* r) const {
    const T q_wxyz[4] = {pose[3], pose[0], pose[1], pose[2]};
    T p[3];
    ceres::UnitQuaternionRotatePoint(q_wxyz, X, p);
    p[0] += pose[4], p[1] += pose[5], p[2] += pose[6];
    if (!(p[2] > T(1e-9))) return false;
    const T x = p[0] / p[2], y = p[1] / p[2];
    const T r2 = x * x + y * y;
    const Distortion& d = cam.dist;
    const T k1 = T(d.k1) + intr[1];
    const T radial = T(1) + r2 * (k1 + r2 * (T(d.k2) + r2 * T(d.k3)));
    const T xd = x * radial + T(2 * d.p1) * x * y + T(d.p2) * (r2 + T(2) * x * x);
    const T yd = y * radial + T(d.p1) * (r2 + T(2) * y * y) + T(2 * d.p2) * x * y;
    r[0] = intr[0] * T(cam.fx) * xd + T(cam.cx) - T(u);
    r[1] = intr[0] * T(cam.fy) * yd + T(cam.cy) - T(v);
    return true;
  }
};

TEST(SelfCalibration, TheWrittenOutJacobiansAreTheAutomaticOnes) {
  CounterRng rng(12, 0);
  double worst = 0;
  for (int trial = 0; trial < 200; ++trial) {
    PinholeCamera cam;
    cam.fx = rng.Uniform(300, 1500), cam.fy = cam.fx * rng.Uniform(0.98, 1.02);
    cam.cx = rng.Uniform(150, 700), cam.cy = rng.Uniform(100, 500);
    cam.dist.k1 = rng.Uniform(-0.3, 0.3), cam.dist.k2 = rng.Uniform(-0.1, 0.1), cam.dist.k3 = rng.Uniform(-0.05, 0.05);
    cam.dist.p1 = rng.Uniform(-0.01, 0.01), cam.dist.p2 = rng.Uniform(-0.01, 0.01);
    const Eigen::Quaterniond q = QuaternionFromRotationVector(NormalVector(rng, 1.0));
    const Eigen::Vector3d t = NormalVector(rng, 0.5);
    const Eigen::Vector3d in_cam = Eigen::Vector3d(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(1, 5));
    const Eigen::Vector3d X = q.conjugate() * (in_cam - t);
    const Eigen::Vector2d uv(rng.Uniform(0, 640), rng.Uniform(0, 480));
    const double pose[7] = {q.x(), q.y(), q.z(), q.w(), t.x(), t.y(), t.z()};
    const double intr[2] = {rng.Uniform(0.9, 1.1), rng.Uniform(-0.05, 0.05)};
    const double* params[3] = {pose, X.data(), intr};
    double r_ref[2], J_ref[3][14], r[2], J[3][14];
    double* jac_ref[3] = {J_ref[0], J_ref[1], J_ref[2]};
    double* jac[3] = {J[0], J[1], J[2]};
    ceres::AutoDiffCostFunction<CalibratedAutoDiffReference, 2, 7, 3, 2> reference(
        new CalibratedAutoDiffReference{cam, uv.x(), uv.y()});
    ASSERT_TRUE(reference.Evaluate(params, r_ref, jac_ref));
    ASSERT_TRUE(CalibratedReprojectionCost(cam, uv).Evaluate(params, r, jac));
    const int sizes[3] = {14, 6, 4};
    double scale = 0;
    for (int b = 0; b < 3; ++b)
      for (int i = 0; i < sizes[b]; ++i) scale = std::max(scale, std::abs(J_ref[b][i]));
    for (int i = 0; i < 2; ++i) worst = Worse(worst, std::abs(r[i] - r_ref[i]) / scale);
    for (int b = 0; b < 3; ++b)
      for (int i = 0; i < sizes[b]; ++i) worst = Worse(worst, std::abs(J[b][i] - J_ref[b][i]) / scale);
    // The pose and point held (the self-calibration holds its first frames): the intrinsics' Jacobian alone, the same.
    double J2_only[4];
    double* intr_only[3] = {nullptr, nullptr, J2_only};
    ASSERT_TRUE(CalibratedReprojectionCost(cam, uv).Evaluate(params, r, intr_only));
    for (int i = 0; i < 4; ++i) EXPECT_EQ(J2_only[i], J[2][i]);
  }
  std::printf("[ jacobians ] largest difference from the automatic ones: %.2e of the largest entry\n", worst);
  EXPECT_LT(worst, 1e-9);
}

// One point that starts behind a camera (a wrong match triangulated from little parallax can end there):
// its observation by that camera has no residual and is left out; without that, Ceres gave up the whole
// adjustment at its first evaluation ("Residual and Jacobian evaluation failed") and nothing moved.
TEST(BundleAdjust, APointBehindACameraDoesNotStopTheAdjustment) {
  const Scene truth;
  std::vector<Pose> cams = truth.cams;
  std::vector<Eigen::Vector3d> pts = truth.pts;
  CounterRng rng(4, 0);
  for (size_t c = 2; c < cams.size(); ++c)
    cams[c] = Pose(cams[c].q, cams[c].t + NormalVector(rng, 0.01));
  pts[7] = Eigen::Vector3d(0.1, 0.0, -1.0);  // behind every camera
  const BundleAdjustSummary s = AdjustWithTheFirstTwoFixed(cams, pts, truth.obs);
  EXPECT_EQ(s.left_out_behind, 8);  // point 7 in each of the 8 cameras
  EXPECT_TRUE(s.converged) << s.report;
  for (size_t c = 0; c < cams.size(); ++c) {
    EXPECT_LT((cams[c].t - truth.cams[c].t).norm(), 1e-4) << c;  // exact data: the other 149 points fix them
  }
}

TEST(Pnp, RecoversAPoseWithOutliers) {
  const Scene sc;
  std::vector<Eigen::Vector2d> uv;
  for (const auto& o : sc.obs)
    if (o.camera == 5) uv.push_back(o.uv_norm);
  CounterRng rng(3, 0);
  for (size_t i = 0; i < uv.size(); i += 5) {
    const double dv = rng.Uniform(-0.1, 0.1), du = rng.Uniform(-0.1, 0.1);  // v first: GCC's order, as above
    uv[i] += Eigen::Vector2d(du, dv);
  }
  int inliers = 0;
  const auto pose = SolvePnp(sc.pts, uv, {}, &inliers);
  ASSERT_TRUE(pose.has_value());
  EXPECT_GE(inliers, 110);  // 120 exact of 150; a few of the 30 perturbed may still fall within 3 px
  EXPECT_LT((pose->t - sc.cams[5].t).norm(), 1e-6);
  EXPECT_LT(AngularDistanceDeg(pose->q, sc.cams[5].q), 1e-5);
}

}  // namespace
}  // namespace mcslam::geometry
