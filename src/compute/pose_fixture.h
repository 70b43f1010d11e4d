#pragma once
// Synthetic scoring problems for benchmarks and backend-equivalence tests. PoseFixture: `count` points on a
// 1 m object about 3 m in front of an identity camera (the paper's set-up), features at their exact
// projections. PointFixture (below): points seen by keyframes on an arc. KeyframeWindowFixture: the point
// adjustments of successive keyframes, their windows overlapping as in a run.
#include <cmath>
#include <cstdint>
#include <vector>

#include "compute/point_kernel.h"
#include "compute/pose_kernel.h"
#include "core/random.h"

namespace mcslam::compute {

struct PoseFixture {
  std::vector<float> x, y, z, u, v;
  PoseSampling sampling;
  PoseScoringParams params;

  explicit PoseFixture(int count, uint64_t seed = 3, float focal_px = 500.0f) {
    CounterRng rng(seed, 0);
    for (int i = 0; i < count; ++i) {
      const float X = static_cast<float>(rng.Uniform(-0.5, 0.5)), Y = static_cast<float>(rng.Uniform(-0.4, 0.4));
      const float Z = 3.0f + static_cast<float>(rng.Uniform(-0.3, 0.3));
      x.push_back(X), y.push_back(Y), z.push_back(Z);
      u.push_back(focal_px * X / Z), v.push_back(focal_px * Y / Z);
    }
    params.fx = params.fy = focal_px;
    for (float& s : sampling.sigma_q) s = 0.0087f;  // ~1 degree per axis
    for (float& s : sampling.sigma_t) s = 0.01f;    // 1 cm
  }
  PoseScoringPoints View() const {
    return {x.data(), y.data(), z.data(), u.data(), v.data(), static_cast<int>(x.size())};
  }

  // The shape of a tracking frame instead: the features seen by a camera that moved from the prior (the
  // identity) by `move_m` along (1, -0.5, 0.8)/|.| and a turn of `turn_deg` about (0.3, 1, 0.2)/|.|, with
  // Gaussian noise of `noise_px` and a fraction `outliers` of features uniform within +-50 px of the truth;
  // a 25 px cap. The best hypothesis is then one of the sampled ones, not the centre, and backends that
  // agree pick hypotheses of the same score (the exact fixture's winner, the centre, scores only rounding).
  void MoveCamera(float move_m = 0.01f, float turn_deg = 0.5f, float noise_px = 1.0f, float outliers = 0.1f,
                  uint64_t seed = 17) {
    const float n_t = std::sqrt(1.0f + 0.25f + 0.64f), n_r = std::sqrt(0.09f + 1.0f + 0.04f);
    const float half = 0.5f * turn_deg * 3.14159265f / 180.0f;
    const float q[4] = {std::cos(half), std::sin(half) * 0.3f / n_r, std::sin(half) * 1.0f / n_r,
                        std::sin(half) * 0.2f / n_r};
    const float t[3] = {move_m * 1.0f / n_t, move_m * -0.5f / n_t, move_m * 0.8f / n_t};
    const ScaledPose p = MakeScaledPose(q, t, params.fx, params.fy);
    CounterRng rng(seed, 1);
    for (size_t i = 0; i < x.size(); ++i) {
      const float X[3] = {x[i], y[i], z[i]};
      const float xc = p.t[0] + p.r[0] * X[0] + p.r[1] * X[1] + p.r[2] * X[2];
      const float yc = p.t[1] + p.r[3] * X[0] + p.r[4] * X[1] + p.r[5] * X[2];
      const float zc = p.t[2] + p.r[6] * X[0] + p.r[7] * X[1] + p.r[8] * X[2];
      u[i] = xc / zc, v[i] = yc / zc;
      if (rng.Uniform(0.0, 1.0) < outliers) {
        u[i] += static_cast<float>(rng.Uniform(-50.0, 50.0)), v[i] += static_cast<float>(rng.Uniform(-50.0, 50.0));
      } else {
        u[i] += noise_px * static_cast<float>(rng.Normal()), v[i] += noise_px * static_cast<float>(rng.Normal());
      }
    }
    params.max_distance_px = 25.0f;
  }
};

// The exact observation of world point X by a camera with pre-scaled pose p (undistorted px minus the
// principal point).
inline void ObserveBy(const ScaledPose& p, const float X[3], float* u, float* v) {
  const float x = p.t[0] + p.r[0] * X[0] + p.r[1] * X[1] + p.r[2] * X[2];
  const float y = p.t[1] + p.r[3] * X[0] + p.r[4] * X[1] + p.r[5] * X[2];
  const float z = p.t[2] + p.r[6] * X[0] + p.r[7] * X[1] + p.r[8] * X[2];
  *u = x / z, *v = y / z;
}

// Keyframes for point-kernel tests and benchmarks: `count` cameras 3 m from the origin, looking at it from an
// arc (rotations about y, 0.03 rad apart and centred on 0: five cameras span -0.06 .. 0.06 rad), with
// f = 500 px and a 50 px cap.
struct ArcCameras {
  std::vector<ScaledPose> poses;
  PoseScoringParams params;

  explicit ArcCameras(int count = 5) {
    params.fx = params.fy = 500.0f;
    params.max_distance_px = 50.0f;
    for (int i = 0; i < count; ++i) {
      const float a = 0.03f * (static_cast<float>(i) - 0.5f * static_cast<float>(count - 1));
      const float q[4] = {std::cos(a / 2), 0.0f, std::sin(a / 2), 0.0f};
      const float t[3] = {0.0f, 0.0f, 3.0f};
      poses.push_back(MakeScaledPose(q, t, params.fx, params.fy));
    }
  }
  // The exact observation of a world point in camera k (undistorted px minus the principal point).
  void Observe(int k, const float X[3], float* u, float* v) const { ObserveBy(poses[k], X, u, v); }
};

// A view of a fixture's arrays (poses, cx .. sz, begin, pose_idx, ou, ov, params) as a PointAdjustProblem.
template <typename Fixture>
PointAdjustProblem PointProblemOf(const Fixture& f) {
  PointAdjustProblem pr;
  pr.poses = f.poses.data();
  pr.num_poses = static_cast<int>(f.poses.size());
  pr.cx = f.cx.data(), pr.cy = f.cy.data(), pr.cz = f.cz.data(), pr.sx = f.sx.data(), pr.sy = f.sy.data(), pr.sz = f.sz.data();
  pr.obs_begin = f.begin.data();
  pr.num_points = static_cast<int>(f.cx.size());
  pr.obs_pose = f.pose_idx.data(), pr.obs_u = f.ou.data(), pr.obs_v = f.ov.data();
  pr.params = f.params;
  return pr;
}

// A point-adjustment problem on the ArcCameras: `num_points` points within 0.3 m of the origin, each centre a
// few cm off the truth (spread 3, 3, 5 cm) and its observations up to 1.5 px off the exact projections.
// Point p is seen by the first views(p) cameras: all of them (kAll: the shape of a point adjustment over a
// keyframe window, what `mcslam bench points` times), or p % (cameras + 1) of them (kVarying: some points by
// none, for the backend-equivalence tests). Observations before first_obs belong to no point (obs_begin
// need not start at 0).
struct PointFixture : ArcCameras {
  enum class Views { kAll, kVarying };
  std::vector<float> cx, cy, cz, sx, sy, sz, ou, ov;
  std::vector<int> begin{0}, pose_idx;

  explicit PointFixture(int num_points, int cameras = 5, Views views = Views::kVarying, int first_obs = 0,
                        uint64_t seed = 11)
      : ArcCameras(cameras) {
    for (int o = 0; o < first_obs; ++o) pose_idx.push_back(0), ou.push_back(0), ov.push_back(0);
    begin[0] = first_obs;
    CounterRng rng(seed, 0);
    const auto uni = [&rng] { return static_cast<float>(rng.Uniform(-1.0, 1.0)); };
    for (int p = 0; p < num_points; ++p) {
      const float X[3] = {0.3f * uni(), 0.3f * uni(), 0.3f * uni()};
      cx.push_back(X[0] + 0.03f * uni()), cy.push_back(X[1] + 0.03f * uni()), cz.push_back(X[2] + 0.03f * uni());
      sx.push_back(0.03f), sy.push_back(0.03f), sz.push_back(0.05f);
      const int seen_by = views == Views::kAll ? cameras : p % (cameras + 1);
      for (int k = 0; k < seen_by; ++k) {
        float u, v;
        Observe(k, X, &u, &v);
        pose_idx.push_back(k), ou.push_back(u + 1.5f * uni()), ov.push_back(v + 1.5f * uni());
      }
      begin.push_back(static_cast<int>(pose_idx.size()));
    }
  }
  int observations() const { return begin.back() - begin.front(); }
  PointAdjustProblem Problem() const { return PointProblemOf(*this); }
};

// Successive keyframes' point adjustments as the System makes them. Keyframe k (3 m from the origin, turned by
// 0.01 k rad about y) sees points k * shift .. k * shift + per_keyframe - 1 (point j within 0.3 m of the
// origin): those are its features, their exact projections up to 1.5 px off, the same in every call. A call
// adjusts the points of its current keyframe (the window's first) over the window's keyframes that see them;
// the centres (a few cm off the truth) are the call's own. KeyframeWindowFixture(c, window): the window is
// keyframes c + window - 1 (current) down to c, so call c + 1's window is one keyframe on.
struct KeyframeWindowFixture {
  std::vector<ScaledPose> poses;
  std::vector<float> cx, cy, cz, sx, sy, sz, ou, ov;
  std::vector<int> begin{0}, pose_idx;
  std::vector<int> keyframe_begin{0};
  std::vector<float> keyframe_u, keyframe_v;
  PoseScoringParams params;

  explicit KeyframeWindowFixture(int call, int window = 8, int per_keyframe = 300, int shift = 20, uint64_t seed = 5)
      : KeyframeWindowFixture(Consecutive(call, window), per_keyframe, shift, 1 + static_cast<uint32_t>(call), seed) {}

  // Any window (distinct keyframe ids, the current one first; a Fibonacci window has gaps); the centres'
  // offsets from stream centre_stream.
  KeyframeWindowFixture(const std::vector<int64_t>& window_ids, int per_keyframe, int shift, uint32_t centre_stream,
                        uint64_t seed = 5) {
    params.fx = params.fy = 500.0f;
    params.max_distance_px = 50.0f;
    const auto point = [seed](int64_t j, float X[3]) {
      CounterRng rng(seed, 100000 + static_cast<uint32_t>(j));
      for (int a = 0; a < 3; ++a) X[a] = static_cast<float>(rng.Uniform(-0.3, 0.3));
    };
    for (const int64_t k : window_ids) {
      const float a = 0.01f * static_cast<float>(k);
      const float q[4] = {std::cos(a / 2), 0.0f, std::sin(a / 2), 0.0f};
      const float t[3] = {0.0f, 0.0f, 3.0f};
      const ScaledPose p = MakeScaledPose(q, t, params.fx, params.fy);
      poses.push_back(p);
      for (int64_t j = k * shift; j < k * shift + per_keyframe; ++j) {
        float X[3];
        point(j, X);
        CounterRng feature_rng(seed ^ (static_cast<uint64_t>(k) << 20), static_cast<uint32_t>(j));
        float u, v;
        ObserveBy(p, X, &u, &v);
        keyframe_u.push_back(u + static_cast<float>(feature_rng.Uniform(-1.5, 1.5)));
        keyframe_v.push_back(v + static_cast<float>(feature_rng.Uniform(-1.5, 1.5)));
      }
      keyframe_begin.push_back(static_cast<int>(keyframe_u.size()));
    }
    CounterRng centre_rng(seed, centre_stream);
    const int64_t current = window_ids.empty() ? 0 : window_ids.front();
    for (int64_t j = current * shift; j < current * shift + per_keyframe; ++j) {
      float X[3];
      point(j, X);
      cx.push_back(X[0] + static_cast<float>(centre_rng.Uniform(-0.03, 0.03)));
      cy.push_back(X[1] + static_cast<float>(centre_rng.Uniform(-0.03, 0.03)));
      cz.push_back(X[2] + static_cast<float>(centre_rng.Uniform(-0.03, 0.03)));
      sx.push_back(0.03f), sy.push_back(0.03f), sz.push_back(0.05f);
      for (size_t w = 0; w < window_ids.size(); ++w) {
        const int64_t f = j - window_ids[w] * shift;  // the point's index among keyframe w's features
        if (f < 0 || f >= per_keyframe) continue;
        const int at = keyframe_begin[w] + static_cast<int>(f);
        pose_idx.push_back(static_cast<int>(w));
        ou.push_back(keyframe_u[static_cast<size_t>(at)]);
        ov.push_back(keyframe_v[static_cast<size_t>(at)]);
      }
      begin.push_back(static_cast<int>(pose_idx.size()));
    }
  }
  int observations() const { return begin.back() - begin.front(); }
  PointAdjustProblem Problem() const { return PointProblemOf(*this); }

 private:
  static std::vector<int64_t> Consecutive(int first, int count) {
    std::vector<int64_t> ids;
    for (int w = count - 1; w >= 0; --w) ids.push_back(first + w);
    return ids;
  }
};

}  // namespace mcslam::compute
