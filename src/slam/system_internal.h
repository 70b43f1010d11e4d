#pragma once
// Helpers shared by the System's stage files (initializer.cc, settler.cc, frame_tracker.cc, mapper.cc, bridge.cc,
// relocaliser.cc); not part of the slam layer's interface.
#include <chrono>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/camera.h"
#include "core/pose.h"
#include "geometry/bundle_adjust.h"
#include "slam/map.h"

namespace mcslam::slam::detail {

// The noise σ of a feature (px, per coordinate) from a median reprojection residual: 1.1774 σ for Gaussian noise.
inline double NoiseFromMedianResidualPx(double median_residual_px) { return median_residual_px / 1.1774; }

// The parallax (degrees) at which two views fix a point's depth to `relative_depth_noise` of itself: a parallax
// θ fixes it to about σ / (f θ). Used for the first map and for new points alike.
inline double ParallaxForDepthNoiseDeg(double noise_px, double focal_px, double relative_depth_noise) {
  return RadToDeg(noise_px / (focal_px * relative_depth_noise));
}

// The largest difference (degrees) between a frame's orientation in a provisional map and its relocalised one
// for the provisional map to join the map (Bridge::Join): the provisional map's orientation is anchored to
// the map's at the turn and drifts little while it lasts; its scale is what the join finds.
constexpr double kJoinMaxRotationDeg = 5.0;

// The points mirrored in depth about their median depth along the reference camera's axis, each kept on its
// ray (so the reference view is unchanged): the start of the depth-reversed twin of a two-view solution or map.
std::vector<Eigen::Vector3d> MirrorInDepth(const std::vector<Eigen::Vector3d>& points_in_ref);

// m of n positions 0..n-1, evenly spread and strictly increasing, the first and (for m >= 2) the last among
// them: i (n - 1) / (m - 1) for i < m. All n when m >= n. The frames a long window is judged or refined on.
std::vector<int> EvenlySpread(int n, int m);

// The lag-1 correlation of residual sequences, pooled: sum over sequences and k >= 1 of r_k . r_(k-1), over the
// sum of |r_k|^2 over the same k. About 0 for independent noise, phi for an AR(1) sequence r_k = phi r_(k-1) + e_k,
// 1 for a constant bias; 0 when no sequence has two entries.
double PooledLag1Correlation(const std::vector<std::vector<Eigen::Vector2d>>& sequences);

// The median angle (degrees) between each b[i] and the epipolar plane of a[i] under the relative pose b_from_a
// (the plane through b's centre holding a's centre and the ray of a[i]); the angle to the turned ray itself where
// the move is nil.
double EpipolarDisagreementDeg(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b,
                               const Pose& b_from_a);

// The unit bearings (through `ideal`, the undistorted pinhole) of the tracks frames a and b share, in a's order:
// in_a[i] and in_b[i] are one track's.
void SharedBearings(const FrameRecord& a, const FrameRecord& b, const PinholeCamera& ideal,
                    std::vector<Eigen::Vector3d>* in_a, std::vector<Eigen::Vector3d>* in_b);

// The mean over `residuals_px` of min(r^2, cap_px^2) (px^2): a window's fit, each wrong match counted at most
// the cap; infinity for none.
double CappedMeanSquarePx2(const std::vector<double>& residuals_px, double cap_px);

// The noise variance of the depth-reversal tests is at least this (px^2: a residual of 0.03 px), so that two
// exact fits of clean data do not count as a clear winner and loser.
constexpr double kCostFloorPx2 = 1e-3;

inline double Ms(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace mcslam::slam::detail
