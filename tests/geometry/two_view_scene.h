#pragma once
// Two-view test data: two frames of the paper's synthetic scene (sim/paper_scenario.h: the points of a box
// about 1 m wide at about 3 m, f = 500 px, 320x240) or an arbitrary point set seen by two given cameras,
// with pixel noise and a fixed fraction of wrong matches added here (so that exactly that fraction of the
// correspondences is wrong, which the simulator's per-observation outliers would not give).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <numeric>
#include <vector>

#include <Eigen/Core>
#include <Eigen/LU>

#include "core/camera.h"
#include "core/pose.h"
#include "core/random.h"
#include "geometry/essential.h"
#include "sim/paper_scenario.h"

namespace mcslam::geometry::testing {

struct TwoViewScene {
  PinholeCamera camera = sim::PaperCamera();
  Pose cam2_from_cam1;                         // true relative pose, |t| = the true baseline (m)
  std::vector<Eigen::Vector3d> points_in_cam1;  // true points, one per correspondence
  std::vector<Eigen::Vector2d> uv_norm1, uv_norm2;
  std::vector<uint8_t> is_outlier;              // per correspondence: uv_norm2 is a wrong match
  double baseline_m() const { return cam2_from_cam1.t.norm(); }
};

struct NoiseOptions {
  double noise_px = 0.0;          // Gaussian, per coordinate, in both views
  double outlier_fraction = 0.0;  // exactly round(fraction * n) correspondences get a wrong uv_norm2
  uint64_t seed = 1;
};

// Adds noise and outliers to exact correspondences (in place). Outliers: a uniform pixel in the image at least
// 10 px from the true one, as the simulator does.
inline void Corrupt(const NoiseOptions& options, TwoViewScene* scene) {
  const PinholeCamera& cam = scene->camera;
  const int n = static_cast<int>(scene->uv_norm1.size());
  CounterRng noise(options.seed, 101), pick(options.seed, 102), pixel(options.seed, 103);
  scene->is_outlier.assign(n, 0);
  for (int i = 0; i < n; ++i) {
    for (auto* uv : {&scene->uv_norm1[i], &scene->uv_norm2[i]}) {
      // One draw a statement, last coordinate first, here and below: the order in which GCC evaluated the
      // Eigen::Vector2d(Normal(), Normal()) this was (argument order is unspecified in C++; clang goes left to
      // right), so that both compilers make the same scenes and the bounds measured on them hold for both.
      const double nv = noise.Normal(), nu = noise.Normal();
      const Eigen::Vector2d px = cam.NormalizedToPixel(*uv) + options.noise_px * Eigen::Vector2d(nu, nv);
      *uv = cam.PixelToNormalized(px);
    }
  }
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  for (int i = n - 1; i > 0; --i) std::swap(order[i], order[pick.Below(static_cast<uint32_t>(i + 1))]);  // Fisher-Yates
  const int num_outliers = static_cast<int>(std::lround(options.outlier_fraction * n));
  for (int k = 0; k < num_outliers; ++k) {
    const int i = order[k];
    const Eigen::Vector2d truth = cam.NormalizedToPixel(scene->uv_norm2[i]);
    Eigen::Vector2d px;
    do {
      const double v = pixel.Uniform(0, cam.height - 1), u = pixel.Uniform(0, cam.width - 1);
      px = Eigen::Vector2d(u, v);
    } while ((px - truth).norm() < 10.0);
    scene->uv_norm2[i] = cam.PixelToNormalized(px);
    scene->is_outlier[i] = 1;
  }
}

// Frames frame1 and frame2 of the paper scenario with `scenario_seed` (which sets the points and the path):
// the points visible in both, with their exact projections.
inline TwoViewScene PaperTwoViewScene(uint64_t scenario_seed, int frame1, int frame2) {
  sim::PaperScenarioOptions opt;
  opt.frames = std::max(frame1, frame2) + 1;
  opt.seed = scenario_seed;
  const sim::SyntheticSequence seq = sim::MakePaperScenario(opt);
  TwoViewScene scene;
  scene.camera = seq.camera;
  const Pose& cam1_from_world = seq.cam_from_world[frame1];
  const Pose& cam2_from_world = seq.cam_from_world[frame2];
  scene.cam2_from_cam1 = cam2_from_world * cam1_from_world.Inverse();
  std::map<int64_t, Eigen::Vector2d> seen1;
  for (const auto& o : seq.frames[frame1].observations) seen1[o.feature_id] = o.uv_true_px;
  for (const auto& o : seq.frames[frame2].observations) {
    const auto it = seen1.find(o.feature_id);
    if (it == seen1.end()) continue;
    scene.points_in_cam1.push_back(cam1_from_world * seq.points_in_world[o.feature_id]);
    scene.uv_norm1.push_back(scene.camera.PixelToNormalized(it->second));
    scene.uv_norm2.push_back(scene.camera.PixelToNormalized(o.uv_true_px));
  }
  scene.is_outlier.assign(scene.uv_norm1.size(), 0);
  return scene;
}

// Any point set (in camera 1) seen by two cameras: the points in front of both and inside both images.
inline TwoViewScene CustomTwoViewScene(const std::vector<Eigen::Vector3d>& points_in_cam1, const Pose& cam2_from_cam1) {
  TwoViewScene scene;
  scene.cam2_from_cam1 = cam2_from_cam1;
  for (const auto& p1 : points_in_cam1) {
    Eigen::Vector2d px1, px2;
    if (!scene.camera.Project(p1, &px1) || !scene.camera.Project(cam2_from_cam1 * p1, &px2)) continue;
    if (!scene.camera.InImage(px1) || !scene.camera.InImage(px2)) continue;
    scene.points_in_cam1.push_back(p1);
    scene.uv_norm1.push_back(scene.camera.PixelToNormalized(px1));
    scene.uv_norm2.push_back(scene.camera.PixelToNormalized(px2));
  }
  scene.is_outlier.assign(scene.uv_norm1.size(), 0);
  return scene;
}

// n points uniform on the plane z = depth (camera 1) over the image, seeded.
inline std::vector<Eigen::Vector3d> PlanePoints(int n, double depth, uint64_t seed) {
  CounterRng rng(seed, 201);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < n; ++i) {
    const double x = rng.Uniform(-0.3, 0.3) * depth, y = rng.Uniform(-0.22, 0.22) * depth;
    pts.emplace_back(x, y, depth);
  }
  return pts;
}

// n points in a box of depths [near, far] filling the view of camera 1, seeded.
inline std::vector<Eigen::Vector3d> VolumePoints(int n, double near, double far, uint64_t seed) {
  CounterRng rng(seed, 202);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < n; ++i) {
    const double z = rng.Uniform(near, far);
    const double y = rng.Uniform(-0.22, 0.22) * z, x = rng.Uniform(-0.3, 0.3) * z;  // y first: GCC's order
    pts.emplace_back(x, y, z);
  }
  return pts;
}

// A room-like scene: `num_points` points at depths 1-5 m filling the view of camera 1, and a hand-held motion
// of `baseline_m` in a seeded random direction (mostly horizontal) with a 4 deg rotation about a random axis.
inline TwoViewScene DeepTwoViewScene(uint64_t seed, int num_points, double baseline_m) {
  CounterRng rng(seed, 203);
  // Last coordinate first: GCC's order for the Eigen::Vector3d(Normal(), Normal(), Normal()) these were.
  const double wz = rng.Normal(), wy = rng.Normal(), wx = rng.Normal();
  Eigen::Vector3d w(wx, wy, wz);
  w *= DegToRad(4.0) / w.norm();
  const double tz = rng.Normal(), ty = 0.3 * rng.Normal(), tx = rng.Normal();
  Eigen::Vector3d t(tx, ty, tz);
  t *= baseline_m / t.norm();
  return CustomTwoViewScene(VolumePoints(num_points, 1.0, 5.0, seed), Pose(QuaternionFromRotationVector(w), t));
}

// Cramer-Rao bound of the relative pose for Gaussian pixel noise of `noise_px` per coordinate: the inverse
// Fisher information of the Sampson residuals at the true pose (first-order the reprojection error with the
// points eliminated), as RMS errors in degrees of the rotation (3 dof) and of the translation direction
// (2 dof). No unbiased estimator does better on average.
struct CramerRao {
  double rotation_deg = 0, direction_deg = 0;
};
inline CramerRao CramerRaoBound(const TwoViewScene& scene, double noise_px) {
  const Pose truth(scene.cam2_from_cam1.q, scene.cam2_from_cam1.t.normalized());
  Eigen::Matrix<double, 5, 5> fisher = Eigen::Matrix<double, 5, 5>::Zero();
  for (size_t i = 0; i < scene.uv_norm1.size(); ++i) {
    Eigen::Matrix<double, 1, 5> j;
    geometry::SampsonResidual(truth, scene.uv_norm1[i], scene.uv_norm2[i], scene.camera.fx, &j);
    fisher += j.transpose() * j;
  }
  const Eigen::Matrix<double, 5, 5> cov = fisher.inverse() * (noise_px * noise_px);
  return {RadToDeg(std::sqrt(cov.topLeftCorner<3, 3>().trace())), RadToDeg(std::sqrt(cov.bottomRightCorner<2, 2>().trace()))};
}

// Errors of an estimated relative pose against the truth (the estimate's |t| is 1, the truth's the baseline).
inline double RotationErrorDeg(const Pose& estimate, const Pose& truth) { return AngularDistanceDeg(estimate.q, truth.q); }
inline double TranslationDirectionErrorDeg(const Pose& estimate, const Pose& truth) {
  const Eigen::Vector3d a = estimate.t.normalized(), b = truth.t.normalized();
  return RadToDeg(std::atan2(a.cross(b).norm(), a.dot(b)));
}

}  // namespace mcslam::geometry::testing
