// Rotation about the camera centre from bearings (geometry/rotation_only.h): Wahba's problem in a RANSAC.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include <Eigen/Geometry>

#include "core/pose.h"
#include "geometry/rotation_only.h"

namespace mcslam::geometry {
namespace {

constexpr double kFocalPx = 500.0;

struct Bearings {
  std::vector<Eigen::Vector3d> ref, cam;
  std::vector<bool> outlier;
  Eigen::Matrix3d cam_from_ref;
};

// Points 2-6 m in front of a reference camera inside a 60 degree cone, seen again by a camera turned by
// `turn_deg` about a random axis and moved by `move` (in the reference frame); pixel noise of `noise_px`
// (per coordinate, at kFocalPx) on the second view, and a fraction of the second bearings replaced by random
// ones.
Bearings MakeBearings(uint64_t seed, int n, double turn_deg, double noise_px, double outliers,
                      const Eigen::Vector3d& move = Eigen::Vector3d::Zero()) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1), depth(2, 6), unit(0, 1);
  std::normal_distribution<double> g(0, 1);
  Bearings b;
  // One draw a statement, last coordinate first, here and below: the order in which GCC evaluated the
  // Eigen::Vector3d(g(rng), g(rng), g(rng)) these were (unspecified in C++; clang goes left to right), so
  // that both compilers make the same bearings.
  const double az = g(rng), ay = g(rng), ax = g(rng);
  const Eigen::Vector3d axis = Eigen::Vector3d(ax, ay, az).normalized();
  b.cam_from_ref = Eigen::AngleAxisd(DegToRad(turn_deg), axis).toRotationMatrix();
  for (int k = 0; k < n; ++k) {
    const double d = depth(rng), ry = 0.58 * u(rng), rx = 0.58 * u(rng);
    const Eigen::Vector3d x = Eigen::Vector3d(rx, ry, 1.0).normalized() * d;
    b.ref.push_back(x.normalized());
    Eigen::Vector3d seen = b.cam_from_ref * (x - move);
    seen /= seen.z();
    seen.x() += noise_px / kFocalPx * g(rng);
    seen.y() += noise_px / kFocalPx * g(rng);
    const bool wrong = unit(rng) < outliers;
    b.outlier.push_back(wrong);
    if (wrong) {
      const double wz = 1.0 + unit(rng), wy = u(rng), wx = u(rng);
      b.cam.push_back(Eigen::Vector3d(wx, wy, wz).normalized());
    } else {
      b.cam.push_back(seen.normalized());
    }
  }
  return b;
}

double RotationErrorDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return RadToDeg(Eigen::AngleAxisd(a * b.transpose()).angle());
}

TEST(RotationFromBearings, ExactBearingsGiveTheRotationToRoundingError) {
  const Bearings b = MakeBearings(1, 50, 25.0, 0.0, 0.0);
  // Double precision on unit vectors: 1e-9 degrees leaves orders of magnitude for the SVD's rounding.
  EXPECT_LT(RotationErrorDeg(RotationFromBearings(b.ref, b.cam), b.cam_from_ref), 1e-9);
  // Two bearings that are not parallel fix it too (the minimal sample of the RANSAC).
  const std::vector<Eigen::Vector3d> r2(b.ref.begin(), b.ref.begin() + 2), c2(b.cam.begin(), b.cam.begin() + 2);
  EXPECT_LT(RotationErrorDeg(RotationFromBearings(r2, c2), b.cam_from_ref), 1e-9);
  // A rotation, never a reflection.
  EXPECT_NEAR(RotationFromBearings(r2, c2).determinant(), 1.0, 1e-12);
}

double MedianAngleDeg(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b) {
  std::vector<double> d;
  for (size_t k = 0; k < a.size(); ++k) d.push_back(RadToDeg(AngleBetween(a[k], b[k])));
  std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2), d.end());
  return d[d.size() / 2];
}

TEST(RobustRotationFromBearings, WrongTracksDoNotTiltTheTurn) {
  // A 12 degree turn (a fast hand-held frame), 0.5 px of noise, 30 % wrong tracks: the plain least-squares fit is
  // tilted by the wrong ones, the refits to the better half are not. Measured over seeds 1-20: 0.006-0.062 degrees
  // off; the plain fit 1.97-11.9. Bounds: every seed under 0.25 (4x the worst measured, 8x under the plain fit's
  // best), and the plain fit over 1 on every seed (else the wrong tracks would test nothing).
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    const Bearings b = MakeBearings(seed, 60, 12.0, 0.5, 0.3);
    const double robust = RotationErrorDeg(RobustRotationFromBearings(b.ref, b.cam), b.cam_from_ref);
    const double plain = RotationErrorDeg(RotationFromBearings(b.ref, b.cam), b.cam_from_ref);
    EXPECT_LT(robust, 0.25) << "seed " << seed;
    EXPECT_GT(plain, 1.0) << "seed " << seed;
  }
}

TEST(NonRotationalMotion, ATurnLeavesOnlyTheNoise) {
  // A 20 degree turn about the camera's centre, 1 px of noise per coordinate on the second view, 20 % wrong
  // tracks. A right track's residual is about Rayleigh-distributed (median 1.18 sigma, less off the axis, where a
  // pixel is a smaller angle); the wrong fifth moves the median of all up, and the refits keep them out of the
  // rotation. Measured over seeds 1-20: 0.96-1.27 px (one refit instead of three: seed 9 at 1.93, its rotation
  // still tilted by wrong tracks). Bounds: 0.8-1.6 px, which a tilted rotation (a pixel more) or a residual of
  // zero would leave.
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    const Bearings b = MakeBearings(seed, 100, 20.0, 1.0, 0.2);
    const double px = NonRotationalMotionRad(b.ref, b.cam) * kFocalPx;
    EXPECT_GT(px, 0.8) << "seed " << seed;
    EXPECT_LT(px, 1.6) << "seed " << seed;
  }
}

TEST(NonRotationalMotion, ACameraCirclingWhatItLooksAtShowsItsParallax) {
  // A camera that moves 30 cm sideways while turning to keep a point 4 m ahead in the centre of the view (an orbit
  // of 4.3 degrees about it) in front of points 2-6 m away, 1 px of noise: the median feature moves little
  // (measured over seeds 1-10: 0.97-1.22 degrees, under the 2.3 that starts the initialisation), but no rotation
  // explains what moves: the depths' spread about 4 m times the parallax, 7.1-9.8 px at f = 500 px (noise alone
  // leaves about 1.1, above). Bounds: the motion under 2 degrees, the non-rotational part over 5 px.
  const Eigen::Vector3d move(0.3, 0.0, 0.0), fixated(0.0, 0.0, 4.0);
  const Eigen::Vector3d from = fixated - move;  // where the point lies from the moved camera, in the reference's axes
  const Eigen::Matrix3d turn = Eigen::Quaterniond::FromTwoVectors(from, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  for (uint64_t seed = 1; seed <= 10; ++seed) {
    Bearings b = MakeBearings(seed, 100, 0.0, 0.0, 0.0);
    std::mt19937_64 rng(seed + 100);
    std::normal_distribution<double> g(0, 1.0 / kFocalPx);
    std::uniform_real_distribution<double> depth(2, 6);
    for (size_t k = 0; k < b.ref.size(); ++k) {
      const Eigen::Vector3d x = b.ref[k] / b.ref[k].z() * depth(rng);
      b.ref[k] = x.normalized();
      Eigen::Vector3d seen = turn * (x - move);
      seen /= seen.z();
      const double ny = g(rng), nx = g(rng);
      seen.x() += nx, seen.y() += ny;
      b.cam[k] = seen.normalized();
    }
    EXPECT_LT(MedianAngleDeg(b.ref, b.cam), 2.0) << "seed " << seed;
    EXPECT_GT(NonRotationalMotionRad(b.ref, b.cam) * kFocalPx, 5.0) << "seed " << seed;
  }
}

TEST(NonRotationalMotion, TooFewBearingsGiveZero) {
  const Bearings b = MakeBearings(2, 2, 5.0, 1.0, 0.0);
  EXPECT_EQ(NonRotationalMotionRad(b.ref, b.cam), 0.0);
}

TEST(EstimateRotationOnly, RecoversTheTurnThroughNoiseAndWrongTracks) {
  // 100 bearings, 1 px noise, 30 % wrong. The error is the noise's: the turn about the optical axis is the
  // least fixed, by bearings ~0.3 rad off the axis, about sigma / (f 0.3 sqrt(70)) = 0.045 deg. Measured over
  // seeds 1-20: 0.006-0.090 deg (median 0.036). Bound: 0.2 deg, twice the worst (a RANSAC that kept a wrong track
  // would be off by degrees), and every wrong track out.
  double worst = 0;
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    const Bearings b = MakeBearings(seed, 100, 20.0, 1.0, 0.3);
    RotationOnlyOptions o;
    o.focal_px = kFocalPx;
    o.threshold_px = 3.0 * std::sqrt(2.0);
    o.seed = seed;
    const RotationOnlyResult r = EstimateRotationOnly(b.ref, b.cam, o);
    ASSERT_TRUE(r.ok) << "seed " << seed << ": " << r.failure;
    const double err = RotationErrorDeg(r.cam_from_ref, b.cam_from_ref);
    worst = std::max(worst, err);
    EXPECT_LT(err, 0.2) << "seed " << seed;
    int wrong_in = 0, right_out = 0;
    for (size_t k = 0; k < b.ref.size(); ++k) {
      wrong_in += b.outlier[k] && r.inlier[k];
      right_out += !b.outlier[k] && !r.inlier[k];
    }
    // A random bearing falls within 4.2 px of its predicted one by chance about never in a 60 deg cone
    // (~1e-4 of the cone per track); a good one misses it beyond 3 sigma (~1 %).
    EXPECT_EQ(wrong_in, 0) << "seed " << seed;
    EXPECT_LE(right_out, 3) << "seed " << seed;
    // The inliers' residual is the noise's (measured 1.06-1.30 px: sqrt(2) sigma, cut at the threshold), not zero.
    EXPECT_GT(r.rms_px, 0.5) << "seed " << seed;
    EXPECT_LT(r.rms_px, 2.5) << "seed " << seed;
  }
  std::printf("[ rotation ] 20 seeds, 1 px noise, 30 %% wrong tracks: worst rotation error %.4f deg\n", worst);
}

TEST(EstimateRotationOnly, ACameraThatAlsoMovesIsNoTurn) {
  // 20 cm sideways in front of points 2-6 m away: 17-50 px of parallax, far beyond a 2 px threshold; the
  // bearings cannot agree on any one rotation, whatever the seed.
  for (uint64_t seed = 1; seed <= 10; ++seed) {
    const Bearings b = MakeBearings(seed, 100, 10.0, 0.5, 0.0, Eigen::Vector3d(0.2, 0, 0));
    RotationOnlyOptions o;
    o.focal_px = kFocalPx;
    o.threshold_px = 2.0;
    o.min_inliers = 20;
    o.seed = seed;
    const RotationOnlyResult r = EstimateRotationOnly(b.ref, b.cam, o);
    // Points at about the same depth still agree with some rotation (measured over these seeds: 0-23 of 100,
    // below the 20 asked in 6 of 10); what must not happen is most agreeing, as the System asks (70 %).
    EXPECT_LT(r.inliers, 50) << "seed " << seed;
  }
}

TEST(EstimateRotationOnly, TooFewBearingsFailSayingSo) {
  const Bearings b = MakeBearings(3, 10, 5.0, 0.0, 0.0);
  RotationOnlyOptions o;
  o.min_inliers = 20;
  const RotationOnlyResult r = EstimateRotationOnly(b.ref, b.cam, o);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.failure.find("10 bearings, 20 needed"), std::string::npos) << r.failure;
}

TEST(EstimateRotationOnly, SameSeedSameResult) {
  const Bearings b = MakeBearings(5, 80, 15.0, 1.0, 0.4);
  RotationOnlyOptions o;
  o.seed = 9;
  const RotationOnlyResult a = EstimateRotationOnly(b.ref, b.cam, o), c = EstimateRotationOnly(b.ref, b.cam, o);
  ASSERT_TRUE(a.ok);
  EXPECT_EQ(a.inlier, c.inlier);
  EXPECT_EQ(a.cam_from_ref, c.cam_from_ref);  // bit for bit
}

}  // namespace
}  // namespace mcslam::geometry
