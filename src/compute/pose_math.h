#pragma once
// Per-hypothesis math of the Monte Carlo pose estimator, shared by the CPU backend (g++, vectorised
// across hypotheses) and the CUDA backend (nvcc, one thread per hypothesis). Plain floats and C++17 only:
// nothing here may depend on Eigen or on the host.
#include <cmath>

#include "core/host_device.h"

namespace mcslam::compute {

// Centre of the sampling and the standard deviations of Eq. 2. Quaternion order (w, x, y, z);
// the pose maps world to camera (cam_from_world).
struct PoseSampling {
  float q[4] = {1, 0, 0, 0};
  float t[3] = {0, 0, 0};
  float sigma_q[4] = {0, 0, 0, 0};  // std of omega, added to the quaternion before normalising
  float sigma_t[3] = {0, 0, 0};     // std of tau, added to the translation
};

// Camera and robust-cost constants of the score (Algorithm 1).
struct PoseScoringParams {
  float fx = 1, fy = 1;             // focal lengths, px
  float max_distance_px = 1e4f;     // a point contributes at most this (also the cost of a point behind the camera)
  float min_depth = 1e-3f;          // a point nearer than this (in camera z) counts as behind the camera
};

// Elementary operations of the scalar instantiation (CUDA threads, and the CPU's reference path). The CPU
// backend instantiates the same templates below with a SIMD vector type and its own Math (one hypothesis
// per lane), so both backends run one source of the per-hypothesis math.
struct ScalarMath {
  // Rsqrt: in the per-point distance (may be an approximation; the CPU's has |rel err| < 2^-14).
  // RsqrtAccurate: once per hypothesis, to normalise the quaternion (full float precision).
  MCSLAM_HOST_DEVICE static MCSLAM_INLINE float Rsqrt(float x) {
#if defined(__CUDA_ARCH__)
    return rsqrtf(x);
#else
    return 1.0f / sqrtf(x);
#endif
  }
  MCSLAM_HOST_DEVICE static MCSLAM_INLINE float RsqrtAccurate(float x) { return Rsqrt(x); }
  MCSLAM_HOST_DEVICE static MCSLAM_INLINE float Min(float a, float b) { return a < b ? a : b; }
  // x > than ? a : b
  MCSLAM_HOST_DEVICE static MCSLAM_INLINE float SelectGreater(float x, float than, float a, float b) {
    return x > than ? a : b;
  }
};

// A hypothesis as the scoring loop wants it: rotation rows pre-multiplied by fx, fy (row 2 plain), so
// that X' = fx*X, Y' = fy*Y and Z come from 9 fused multiply-adds.
template <typename F>
struct ScaledPoseT {
  F r[9];
  F t[3];
};
using ScaledPose = ScaledPoseT<float>;

// Eq. 2: q = normalize(q_c + omega), t = t_c + tau, from 7 standard normals n[0..6] scaled by the sigmas.
template <typename M, typename F>
MCSLAM_HOST_DEVICE MCSLAM_INLINE void PerturbPoseT(const PoseSampling& s, F n0, F n1, F n2, F n3, F n4, F n5, F n6,
                                                   F q[4], F t[3]) {
  const F qw = s.q[0] + s.sigma_q[0] * n0;
  const F qx = s.q[1] + s.sigma_q[1] * n1;
  const F qy = s.q[2] + s.sigma_q[2] * n2;
  const F qz = s.q[3] + s.sigma_q[3] * n3;
  const F inv = M::RsqrtAccurate(qw * qw + qx * qx + qy * qy + qz * qz);
  q[0] = qw * inv;
  q[1] = qx * inv;
  q[2] = qy * inv;
  q[3] = qz * inv;
  t[0] = s.t[0] + s.sigma_t[0] * n4;
  t[1] = s.t[1] + s.sigma_t[1] * n5;
  t[2] = s.t[2] + s.sigma_t[2] * n6;
}

// Rotation matrix (row-major) of a unit quaternion (w, x, y, z).
template <typename F>
MCSLAM_HOST_DEVICE MCSLAM_INLINE void QuaternionToRotationT(const F q[4], F r[9]) {
  const F w = q[0], x = q[1], y = q[2], z = q[3];
  const F xx = x * x, yy = y * y, zz = z * z, xy = x * y, xz = x * z, yz = y * z, wx = w * x, wy = w * y, wz = w * z;
  r[0] = 1.0f - 2.0f * (yy + zz);
  r[1] = 2.0f * (xy - wz);
  r[2] = 2.0f * (xz + wy);
  r[3] = 2.0f * (xy + wz);
  r[4] = 1.0f - 2.0f * (xx + zz);
  r[5] = 2.0f * (yz - wx);
  r[6] = 2.0f * (xz - wy);
  r[7] = 2.0f * (yz + wx);
  r[8] = 1.0f - 2.0f * (xx + yy);
}

template <typename F>
MCSLAM_HOST_DEVICE MCSLAM_INLINE ScaledPoseT<F> MakeScaledPoseT(const F q[4], const F t[3], float fx, float fy) {
  ScaledPoseT<F> p;
  QuaternionToRotationT(q, p.r);
  p.r[0] *= fx;
  p.r[1] *= fx;
  p.r[2] *= fx;
  p.r[3] *= fy;
  p.r[4] *= fy;
  p.r[5] *= fy;
  p.t[0] = t[0] * fx;
  p.t[1] = t[1] * fy;
  p.t[2] = t[2];
  return p;
}

// Eq. 1 and the distance of Algorithm 1: |Π(R z + t) − y| in pixels, capped at max_distance_px; a point
// behind the camera costs the cap. (u, v) is the observed feature, undistorted, minus the principal point.
// Division-free form: |(X'/Z − u, Y'/Z − v)| = e² / sqrt(e² Z²) with e = (X' − u Z, Y' − v Z), one
// reciprocal square root instead of a division and a square root.
// Either the pose (P, pose kernel: one hypothesis per lane) or the point (X, point kernel: one sample per
// lane) may be the SIMD type; F is the result type (the vector type when either is).
template <typename M, typename F, typename P, typename X>
MCSLAM_HOST_DEVICE MCSLAM_INLINE F ReprojectionDistanceT(const ScaledPoseT<P>& p, X x, X y, X z, float u, float v,
                                                         const PoseScoringParams& k, F cap) {
  // Written t + r0 x + r1 y + r2 z so that each row contracts to three fused multiply-adds.
  const F Xc = p.t[0] + p.r[0] * x + p.r[1] * y + p.r[2] * z;
  const F Yc = p.t[1] + p.r[3] * x + p.r[4] * y + p.r[5] * z;
  const F Zc = p.t[2] + p.r[6] * x + p.r[7] * y + p.r[8] * z;
  const F ex = Xc - u * Zc;
  const F ey = Yc - v * Zc;
  const F e2 = ex * ex + ey * ey;
  const F d = e2 * M::Rsqrt(e2 * (Zc * Zc) + 1e-30f);
  return M::SelectGreater(Zc, k.min_depth, M::Min(d, cap), cap);
}

// Eq. 7 (point hypotheses, Algorithm 2): a sample around the point, z = z_c + sigma * n.
template <typename F>
MCSLAM_HOST_DEVICE MCSLAM_INLINE void PerturbPointT(const float c[3], const float sigma[3], F n0, F n1, F n2, F z[3]) {
  z[0] = c[0] + sigma[0] * n0;
  z[1] = c[1] + sigma[1] * n1;
  z[2] = c[2] + sigma[2] * n2;
}

// Scalar entry points (CUDA kernels, host reference).
MCSLAM_HOST_DEVICE MCSLAM_INLINE void PerturbPose(const PoseSampling& s, float n0, float n1, float n2, float n3,
                                                  float n4, float n5, float n6, float q[4], float t[3]) {
  PerturbPoseT<ScalarMath, float>(s, n0, n1, n2, n3, n4, n5, n6, q, t);
}
MCSLAM_HOST_DEVICE MCSLAM_INLINE ScaledPose MakeScaledPose(const float q[4], const float t[3], float fx, float fy) {
  return MakeScaledPoseT<float>(q, t, fx, fy);
}
MCSLAM_HOST_DEVICE MCSLAM_INLINE float ReprojectionDistance(const ScaledPose& p, float x, float y, float z, float u,
                                                            float v, const PoseScoringParams& k) {
  return ReprojectionDistanceT<ScalarMath, float, float, float>(p, x, y, z, u, v, k, k.max_distance_px);
}

}  // namespace mcslam::compute
