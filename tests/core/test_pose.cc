#include <gtest/gtest.h>

#include "core/pose.h"
#include "core/random.h"

namespace mcslam {
namespace {

// Draws in one statement each, last coordinate first: the order in which GCC evaluated the former
// Eigen::Vector3d(Normal(), Normal(), Normal()) (argument order is unspecified; clang goes left to right).
Eigen::Vector3d RandomVector(CounterRng& rng) {
  const double z = rng.Normal(), y = rng.Normal(), x = rng.Normal();
  return Eigen::Vector3d(x, y, z);
}

Pose RandomPose(CounterRng& rng) {
  const Eigen::Vector3d w = RandomVector(rng);
  return Pose(QuaternionFromRotationVector(w), RandomVector(rng));
}

TEST(Pose, ComposeInverseIsIdentity) {
  CounterRng rng(7, 0);
  for (int i = 0; i < 50; ++i) {
    const Pose a = RandomPose(rng);
    const Pose id = a * a.Inverse();
    EXPECT_LT(AngularDistanceRad(id.q, Eigen::Quaterniond::Identity()), 1e-12);
    EXPECT_LT(id.t.norm(), 1e-12);
  }
}

TEST(Pose, ComposeMatchesMatrixProductAndActsOnPoints) {
  CounterRng rng(8, 0);
  for (int i = 0; i < 50; ++i) {
    const Pose a = RandomPose(rng), b = RandomPose(rng);
    const Eigen::Vector3d x = RandomVector(rng);
    EXPECT_LT(((a * b).Matrix() - a.Matrix() * b.Matrix()).norm(), 1e-12);
    EXPECT_LT(((a * b) * x - a * (b * x)).norm(), 1e-12);
  }
}

TEST(Pose, MatrixRoundTrip) {
  CounterRng rng(9, 0);
  for (int i = 0; i < 50; ++i) {
    const Pose a = RandomPose(rng);
    const Pose b = Pose::FromMatrix(a.Matrix());
    EXPECT_LT(AngularDistanceRad(a.q, b.q), 1e-12);
    EXPECT_LT((a.t - b.t).norm(), 1e-12);
    const Pose c = Pose::FromMatrix(a.Matrix3x4());
    EXPECT_LT((a.Isometry().matrix() - c.Matrix()).norm(), 1e-12);
  }
}

TEST(Pose, FromSlightlyNonOrthonormalMatrixGivesNearestRotation) {
  Eigen::Matrix3d r = Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitY()).toRotationMatrix();
  r(0, 1) += 5e-4;  // the size of the error in 7-Scenes' pose files
  const Pose p = Pose::FromRotationTranslation(r, Eigen::Vector3d::Zero());
  EXPECT_NEAR(p.R().determinant(), 1.0, 1e-12);
  EXPECT_LT((p.R() * p.R().transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_NEAR(AngularDistanceDeg(p.q, Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitY()))), 0.0,
              0.05);
}

TEST(Pose, AngularDistanceIsTheRotationAngle) {
  for (double deg : {0.0, 1e-6, 0.5, 45.0, 179.0}) {
    const Eigen::Quaterniond a(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 1, 0).normalized()));
    const Eigen::Quaterniond b = a * Eigen::Quaterniond(Eigen::AngleAxisd(DegToRad(deg), Eigen::Vector3d::UnitZ()));
    EXPECT_NEAR(AngularDistanceDeg(a, b), deg, 1e-9);
    // q and -q are the same rotation
    EXPECT_NEAR(AngularDistanceDeg(a, Eigen::Quaterniond(-b.coeffs())), deg, 1e-9);
  }
}

TEST(Pose, RotationVectorRoundTrip) {
  for (const Eigen::Vector3d& w : {Eigen::Vector3d(0.1, -0.2, 0.3), Eigen::Vector3d(1e-9, 0, 0),
                                   Eigen::Vector3d(0, 3.0, 0)}) {
    EXPECT_LT((RotationVectorFromQuaternion(QuaternionFromRotationVector(w)) - w).norm(), 1e-12);
  }
}

TEST(Pose, CentreOfCameraInWorld) {
  const Pose cam_from_world(Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitX())),
                            Eigen::Vector3d(1, 2, 3));
  const Eigen::Vector3d c = cam_from_world.OriginOfTargetInSource();
  EXPECT_LT((cam_from_world * c).norm(), 1e-12);
  EXPECT_LT((cam_from_world.Inverse().t - c).norm(), 1e-12);
}

}  // namespace
}  // namespace mcslam
