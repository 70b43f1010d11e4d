// With -march=native on AVX-512 machines, GCC 12 reports -Wmaybe-uninitialized and -Warray-bounds false
// positives inside Eigen's vectorised kernels as Eigen::umeyama instantiates them (3xN products, and a
// runtime-sized head() of a 4x4 whose packet path is never taken). They must be silenced before Eigen is
// included, so for this whole file.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Warray-bounds"
#endif
#include "eval/trajectory_eval.h"
#include "core/median.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <tuple>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <fmt/format.h>

namespace mcslam::eval {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// RMS distance of the points from their centroid, and the centroid.
double Spread(const Eigen::Matrix3Xd& pts, Eigen::Vector3d* centroid) {
  *centroid = pts.rowwise().mean();
  return std::sqrt((pts.colwise() - *centroid).squaredNorm() / static_cast<double>(pts.cols()));
}

// RMS extents of the centred points along their principal directions, largest first.
Eigen::Vector3d PrincipalSpreads(const Eigen::Matrix3Xd& pts, const Eigen::Vector3d& centroid) {
  const Eigen::Matrix3d scatter = (pts.colwise() - centroid) * (pts.colwise() - centroid).transpose();
  const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3d>(scatter).singularValues();  // descending
  return (sv / static_cast<double>(pts.cols())).cwiseMax(0.0).cwiseSqrt();
}

// Points exactly on a line, up to rounding: a lateral extent of 1e-6 of the length is far below any real
// trajectory's wiggle and far above rounding noise.
bool OnALine(const Eigen::Vector3d& spreads) { return spreads[1] <= 1e-6 * spreads[0]; }

// The rotation R that best maps the estimated orientations onto the true ones, R R_est ~ R_gt (chordal L2
// mean of R_gt R_est^T, projected onto SO(3)).
Eigen::Matrix3d OrientationAlignment(const std::vector<Eigen::Quaterniond>& gt, const std::vector<Eigen::Quaterniond>& est) {
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < gt.size(); ++i) sum += gt[i].toRotationMatrix() * est[i].toRotationMatrix().transpose();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

std::string TimeRange(const io::Trajectory& t) {
  const auto [lo, hi] = std::minmax_element(t.stamps_s.begin(), t.stamps_s.end());
  return fmt::format("[{:.6f}, {:.6f}] s", *lo, *hi);
}

}  // namespace

Alignment ParseAlignment(const std::string& name) {
  const std::string n = Lower(name);
  if (n == "sim3") return Alignment::kSim3;
  if (n == "se3") return Alignment::kSE3;
  if (n == "none") return Alignment::kNone;
  throw std::invalid_argument(fmt::format("unknown alignment '{}' (expected sim3, se3 or none)", name));
}

std::string ToString(Alignment a) {
  switch (a) {
    case Alignment::kSim3: return "sim3";
    case Alignment::kSE3: return "se3";
    case Alignment::kNone: return "none";
  }
  return "unknown";
}

void AssociationOptions::Check() const {
  if (!std::isfinite(max_dt_s) || max_dt_s < 0)
    throw std::invalid_argument(fmt::format("association: max_dt_s must be a non-negative number, got {}", max_dt_s));
}

void EvalOptions::Check() const {
  association.Check();
  if (rpe_delta < 1) throw std::invalid_argument(fmt::format("eval: rpe_delta must be at least 1, got {}", rpe_delta));
}

std::vector<MatchedPair> Associate(const io::Trajectory& gt, const io::Trajectory& est,
                                   const AssociationOptions& options) {
  options.Check();
  for (const auto* t : {&gt, &est})
    if (t->stamps_s.size() != t->world_from_cam.size())
      throw std::runtime_error(fmt::format("{} trajectory has {} stamps but {} poses", t == &gt ? "ground truth" : "estimated",
                                           t->stamps_s.size(), t->world_from_cam.size()));
  std::vector<MatchedPair> pairs;
  if (!gt.has_stamps || !est.has_stamps) {
    const size_t n = std::min(gt.size(), est.size());
    for (size_t i = 0; i < n; ++i) pairs.push_back({i, i, 0.0});
    return pairs;
  }
  for (const auto* t : {&gt, &est})
    for (double s : t->stamps_s)
      if (!std::isfinite(s))
        throw std::runtime_error(fmt::format("{} trajectory has a non-finite stamp", t == &gt ? "ground truth" : "estimated"));

  // Ground-truth indices by stamp, for a binary search of the window around each estimate stamp.
  std::vector<size_t> gt_order(gt.size());
  std::iota(gt_order.begin(), gt_order.end(), size_t{0});
  std::stable_sort(gt_order.begin(), gt_order.end(),
                   [&](size_t a, size_t b) { return gt.stamps_s[a] < gt.stamps_s[b]; });

  struct Candidate {
    double abs_dt;
    size_t est, gt;
  };
  std::vector<Candidate> candidates;
  for (size_t i = 0; i < est.size(); ++i) {
    const double t = est.stamps_s[i];
    auto it = std::lower_bound(gt_order.begin(), gt_order.end(), t - options.max_dt_s,
                               [&](size_t j, double value) { return gt.stamps_s[j] < value; });
    for (; it != gt_order.end() && gt.stamps_s[*it] <= t + options.max_dt_s; ++it) {
      const double abs_dt = std::abs(t - gt.stamps_s[*it]);
      if (abs_dt <= options.max_dt_s) candidates.push_back({abs_dt, i, *it});
    }
  }
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
    return std::tie(a.abs_dt, a.est, a.gt) < std::tie(b.abs_dt, b.est, b.gt);
  });
  std::vector<bool> gt_used(gt.size(), false), est_used(est.size(), false);
  for (const Candidate& c : candidates) {
    if (gt_used[c.gt] || est_used[c.est]) continue;
    gt_used[c.gt] = est_used[c.est] = true;
    pairs.push_back({c.gt, c.est, est.stamps_s[c.est] - gt.stamps_s[c.gt]});
  }
  std::sort(pairs.begin(), pairs.end(), [&](const MatchedPair& a, const MatchedPair& b) {
    return std::tie(est.stamps_s[a.est_index], a.est_index) < std::tie(est.stamps_s[b.est_index], b.est_index);
  });
  return pairs;
}

Pose Similarity3::Apply(const Pose& est_world_from_cam) const {
  return Pose(Eigen::Quaterniond(rotation) * est_world_from_cam.q, (*this) * est_world_from_cam.t);
}

AlignmentResult AlignPositions(const std::vector<Eigen::Vector3d>& est_positions,
                               const std::vector<Eigen::Vector3d>& gt_positions, Alignment alignment) {
  if (est_positions.size() != gt_positions.size())
    throw std::runtime_error(fmt::format("alignment: {} estimated positions but {} ground-truth positions",
                                         est_positions.size(), gt_positions.size()));
  const size_t n = est_positions.size();
  const size_t min_points = alignment == Alignment::kNone ? 1 : 3;
  if (n < min_points)
    throw std::runtime_error(fmt::format("alignment: {} matched poses; {} alignment needs at least {}", n,
                                         ToString(alignment), min_points));
  Eigen::Matrix3Xd est(3, n), gt(3, n);
  for (size_t i = 0; i < n; ++i) {
    if (!est_positions[i].allFinite() || !gt_positions[i].allFinite())
      throw std::runtime_error(fmt::format("alignment: position {} is not finite", i));
    est.col(static_cast<Eigen::Index>(i)) = est_positions[i];
    gt.col(static_cast<Eigen::Index>(i)) = gt_positions[i];
  }
  AlignmentResult result;
  if (alignment == Alignment::kNone) return result;

  Eigen::Vector3d est_centroid, gt_centroid;
  const double est_spread = Spread(est, &est_centroid), gt_spread = Spread(gt, &gt_centroid);
  // All positions equal (up to rounding of the centroid, ~1e-16 relative): rotation and scale are undefined.
  for (auto [spread, centroid, what] : {std::tuple{est_spread, est_centroid, "estimated"},
                                        std::tuple{gt_spread, gt_centroid, "ground-truth"}})
    if (!(spread > 1e-12 * (1.0 + centroid.norm())))
      throw std::runtime_error(fmt::format(
          "alignment: the {} camera positions are all the same (spread {:.3g} m), so no {} alignment exists", what,
          spread, ToString(alignment)));

  const Eigen::Matrix4d T = Eigen::umeyama(est, gt, alignment == Alignment::kSim3);
  const Eigen::Matrix3d sR = T.topLeftCorner<3, 3>();
  // det(s R) = s^3; for SE(3) umeyama returns R itself and the scale is exactly 1.
  const double scale = alignment == Alignment::kSim3 ? std::cbrt(sR.determinant()) : 1.0;
  if (!std::isfinite(scale) || !(scale > 0) || !T.allFinite())
    throw std::runtime_error(fmt::format("alignment: degenerate {} alignment (scale {})", ToString(alignment), scale));
  result.gt_world_from_est_world.scale = scale;
  result.gt_world_from_est_world.rotation = alignment == Alignment::kSim3 ? Eigen::Matrix3d(sR / scale) : sR;
  result.gt_world_from_est_world.translation = T.topRightCorner<3, 1>();
  const Eigen::Vector3d est_spreads = PrincipalSpreads(est, est_centroid), gt_spreads = PrincipalSpreads(gt, gt_centroid);
  result.lateral_spread_m = std::min(gt_spreads[1], scale * est_spreads[1]);
  const Eigen::Matrix3Xd residual = gt - ((sR * est).colwise() + T.topRightCorner<3, 1>().eval());
  result.residual_rmse_m = std::sqrt(residual.squaredNorm() / static_cast<double>(n));
  // A quarter: the lateral shape is then at most 4x its error, and the alignment's turn about the main
  // direction is uncertain by up to atan(1/4) = 14 degrees, more than the rotation errors it would be used for.
  constexpr double kMaxResidualOverLateral = 0.25;
  result.rotation_ambiguous = OnALine(est_spreads) || OnALine(gt_spreads) ||
                              result.residual_rmse_m >= kMaxResidualOverLateral * result.lateral_spread_m;
  return result;
}

ErrorStats ComputeStats(std::vector<double> errors) {
  ErrorStats s;
  s.count = errors.size();
  if (errors.empty()) {
    s.rmse = s.mean = s.median = s.max = kNaN;
    return s;
  }
  double sum = 0, sum_sq = 0;
  for (double e : errors) {
    sum += e;
    sum_sq += e * e;
  }
  const double n = static_cast<double>(errors.size());
  s.mean = sum / n;
  s.rmse = std::sqrt(sum_sq / n);
  s.max = *std::max_element(errors.begin(), errors.end());
  s.median = Median(std::move(errors));
  return s;
}

namespace {

// How well the best similarity maps the positions `from` onto `to`, as residual sums of squares: with a proper
// rotation (Sim(3)), with a reflection, and the spread of `to` about its mean (what no fit at all leaves).
struct SimilarityFits {
  double rss_proper = 0, rss_reflected = 0, spread = 0;
  // A mirror image: the reflection fits with at most half the rms residual of the best Sim(3). A depth-reversed
  // map fits its reflection to within its noise and no Sim(3); a trajectory that is only wrong (its scale
  // drifting, a jump) fits neither, and the sign of its least-squares linear map, which an earlier test read,
  // is then left to chance (rendered sparse scenario, seeds 4 and 10 at 2cc5903: 4x scale drift, a negative
  // determinant, orientations 15 deg off). Points along a line or in a plane fit a reflection across it as
  // well as a rotation: never mirrored for that.
  bool Reflected() const { return rss_reflected < 0.25 * rss_proper; }
  // The Sim(3) explains the positions (rms residual at most half their spread): its rotation means something.
  bool ProperFits() const { return rss_proper <= 0.25 * spread; }
};

SimilarityFits FitSimilarities(const std::vector<Eigen::Vector3d>& from, const std::vector<Eigen::Vector3d>& to) {
  SimilarityFits fits;
  const size_t n = from.size();
  if (n < 4 || to.size() != n) return fits;
  Eigen::Vector3d mf = Eigen::Vector3d::Zero(), mt = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < n; ++i) mf += from[i], mt += to[i];
  mf /= static_cast<double>(n), mt /= static_cast<double>(n);
  double var_from = 0;
  Eigen::Matrix3d cross = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d f = from[i] - mf, t = to[i] - mt;
    var_from += f.squaredNorm(), fits.spread += t.squaredNorm(), cross += t * f.transpose();
  }
  fits.rss_proper = fits.rss_reflected = fits.spread;
  if (!(var_from > 0)) return fits;
  // Umeyama: the orthogonal Q maximising trace(Q^T cross) is U V^T; its trace is d1 + d2 + d3 if det(U V^T) > 0,
  // else the best proper rotation flips the least singular direction (d1 + d2 - d3) and the reflection keeps it.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(cross, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d d = svd.singularValues();
  const double sign = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  const double trace_proper = d[0] + d[1] + sign * d[2], trace_reflected = d[0] + d[1] - sign * d[2];
  // Residual sum of squares with the best scale c = trace / var_from: spread - trace^2 / var_from.
  fits.rss_proper = std::max(0.0, fits.spread - trace_proper * trace_proper / var_from);
  fits.rss_reflected = std::max(0.0, fits.spread - trace_reflected * trace_reflected / var_from);
  return fits;
}

}  // namespace

TrajectoryErrors EvaluateTrajectory(const io::Trajectory& gt, const io::Trajectory& est, const EvalOptions& options) {
  options.Check();
  if (gt.empty()) throw std::runtime_error("eval: the ground-truth trajectory has no poses");
  if (est.empty()) throw std::runtime_error("eval: the estimated trajectory has no poses");

  const std::vector<MatchedPair> pairs = Associate(gt, est, options.association);
  if (pairs.empty())
    throw std::runtime_error(fmt::format(
        "eval: no estimated pose has a ground-truth pose within max_dt={} s (ground truth stamps {}, estimate "
        "stamps {}); are both in seconds and on the same clock?",
        options.association.max_dt_s, TimeRange(gt), TimeRange(est)));
  if (options.alignment != Alignment::kNone && pairs.size() < 3)
    throw std::runtime_error(fmt::format("eval: only {} poses matched between estimate and ground truth; {} alignment "
                                         "needs at least 3",
                                         pairs.size(), ToString(options.alignment)));

  TrajectoryErrors out;
  out.alignment = options.alignment;
  out.gt_size = gt.size();
  out.est_size = est.size();
  out.rpe_delta = options.rpe_delta;

  std::vector<Eigen::Vector3d> est_positions, gt_positions;
  for (const MatchedPair& p : pairs) {
    const Pose& g = gt.world_from_cam[p.gt_index];
    const Pose& e = est.world_from_cam[p.est_index];
    if (!g.AllFinite() || g.q.norm() == 0)
      throw std::runtime_error(fmt::format("eval: ground-truth pose {} (stamp {}) is not finite", p.gt_index,
                                           gt.stamps_s[p.gt_index]));
    if (!e.AllFinite() || e.q.norm() == 0)
      throw std::runtime_error(fmt::format("eval: estimated pose {} (stamp {}) is not finite", p.est_index,
                                           est.stamps_s[p.est_index]));
    est_positions.push_back(e.t);
    gt_positions.push_back(g.t);
  }
  out.alignment_result = AlignPositions(est_positions, gt_positions, options.alignment);
  const Similarity3& gt_from_est = out.alignment_result.gt_world_from_est_world;

  std::vector<Pose> aligned;  // est world_from_cam moved into the ground-truth world
  std::vector<double> trans_errors, rot_errors;
  std::vector<Eigen::Quaterniond> gt_q, est_q;
  for (const MatchedPair& p : pairs) {
    const Pose& g = gt.world_from_cam[p.gt_index];
    const Pose a = gt_from_est.Apply(est.world_from_cam[p.est_index]);
    FrameError f;
    f.stamp_s = est.stamps_s[p.est_index];
    f.gt_index = p.gt_index;
    f.est_index = p.est_index;
    f.gt_position = g.t;
    f.est_position_aligned = a.t;
    f.trans_err_m = (a.t - g.t).norm();
    f.rot_err_deg = AngularDistanceDeg(g.q, a.q);
    trans_errors.push_back(f.trans_err_m);
    rot_errors.push_back(f.rot_err_deg);
    gt_q.push_back(g.q.normalized());
    est_q.push_back(est.world_from_cam[p.est_index].q.normalized());
    out.frames.push_back(f);
    aligned.push_back(a);
  }
  out.ate_m = ComputeStats(trans_errors);
  out.rot_deg = ComputeStats(rot_errors);
  const Eigen::Quaterniond orient(OrientationAlignment(gt_q, est_q));
  std::vector<double> rot_orient;
  for (size_t i = 0; i < gt_q.size(); ++i) rot_orient.push_back(AngularDistanceDeg(gt_q[i], orient * est_q[i]));
  out.rot_orient_deg = ComputeStats(rot_orient);
  for (size_t k = 1; k < gt_positions.size(); ++k) out.gt_path_length_m += (gt_positions[k] - gt_positions[k - 1]).norm();
  // Mirrored: the positions fit a reflection far better than any Sim(3), or they fit a Sim(3) (a mirror image
  // across the plane of a flat path is one) and the orientations are still more than 90 degrees off after it.
  const SimilarityFits fits = FitSimilarities(est_positions, gt_positions);
  out.mirrored = fits.Reflected() || (fits.ProperFits() && out.rot_deg.median > 90.0);

  // RPE: error of the estimated motion between matched poses k and k + delta, (gt_k^-1 gt_j)^-1 (est_k^-1 est_j).
  std::vector<double> rpe_trans, rpe_rot;
  const size_t delta = static_cast<size_t>(options.rpe_delta);
  for (size_t k = 0; k + delta < pairs.size(); ++k) {
    const Pose& gk = gt.world_from_cam[pairs[k].gt_index];
    const Pose& gj = gt.world_from_cam[pairs[k + delta].gt_index];
    const Pose gt_motion = gk.Inverse() * gj;
    const Pose est_motion = aligned[k].Inverse() * aligned[k + delta];
    const Pose error = gt_motion.Inverse() * est_motion;
    rpe_trans.push_back(error.t.norm());
    rpe_rot.push_back(AngularDistanceDeg(Eigen::Quaterniond::Identity(), error.q));
  }
  out.rpe_trans_m = ComputeStats(rpe_trans);
  out.rpe_rot_deg = ComputeStats(rpe_rot);
  return out;
}

ScaleDrift EvaluateScaleDrift(const TrajectoryErrors& errors, int segments) {
  const size_t n = errors.matched();
  if (segments < 1) throw std::invalid_argument(fmt::format("segments must be at least 1 (got {})", segments));
  if (n < 3 * static_cast<size_t>(segments))
    throw std::invalid_argument(fmt::format("{} segments need at least {} matched poses, 3 each (got {})", segments,
                                            3 * static_cast<int64_t>(segments), n));
  // The positions as aligned for the whole run: a segment's alignment of those onto the ground truth has
  // the scale relative to the whole run's.
  const double whole = errors.alignment_result.gt_world_from_est_world.scale;
  ScaleDrift out;
  double lo = std::numeric_limits<double>::infinity(), hi = 0;
  for (int k = 0; k < segments; ++k) {
    const size_t first = n * static_cast<size_t>(k) / static_cast<size_t>(segments);
    const size_t end = n * static_cast<size_t>(k + 1) / static_cast<size_t>(segments);
    std::vector<Eigen::Vector3d> est, gt;
    for (size_t i = first; i < end; ++i) {
      est.push_back(errors.frames[i].est_position_aligned);
      gt.push_back(errors.frames[i].gt_position);
    }
    SegmentErrors seg;
    seg.first = first;
    seg.count = end - first;
    seg.first_stamp_s = errors.frames[first].stamp_s;
    seg.last_stamp_s = errors.frames[end - 1].stamp_s;
    Similarity3 a;
    try {
      a = AlignPositions(est, gt, Alignment::kSim3).gt_world_from_est_world;
    } catch (const std::runtime_error&) {
      // A segment whose positions are all the same (a camera standing still) has no scale: NaN, and it
      // takes no part in the drift.
      seg.scale = seg.scale_vs_whole = kNaN;
      seg.ate_m = ComputeStats({});
      out.segments.push_back(seg);
      continue;
    }
    seg.scale_vs_whole = a.scale;
    seg.scale = whole * a.scale;
    std::vector<double> e;
    for (size_t i = 0; i < est.size(); ++i) e.push_back((a * est[i] - gt[i]).norm());
    seg.ate_m = ComputeStats(std::move(e));
    lo = std::min(lo, seg.scale);
    hi = std::max(hi, seg.scale);
    out.segments.push_back(seg);
  }
  out.max_over_min_scale = hi > 0 ? hi / lo : kNaN;
  return out;
}

void WriteFrameErrorsCsv(const std::string& path, const TrajectoryErrors& errors) {
  std::ofstream out(path, std::ios::out | std::ios::trunc);
  if (!out) throw std::runtime_error(fmt::format("{}: cannot open file for writing", path));
  out << "stamp,gt_x,gt_y,gt_z,est_x,est_y,est_z,trans_err_m,rot_err_deg\n";
  for (const FrameError& f : errors.frames) {
    out << fmt::format("{:.9f},{:.12g},{:.12g},{:.12g},{:.12g},{:.12g},{:.12g},{:.12g},{:.12g}\n", f.stamp_s,
                       f.gt_position.x(), f.gt_position.y(), f.gt_position.z(), f.est_position_aligned.x(),
                       f.est_position_aligned.y(), f.est_position_aligned.z(), f.trans_err_m, f.rot_err_deg);
  }
  out.flush();
  if (!out) throw std::runtime_error(fmt::format("{}: write failed", path));
}

std::string FormatSummary(const TrajectoryErrors& e) {
  return fmt::format(
      "matched={} align={} scale={:.6g} ate_rmse={:.6g} ate_mean={:.6g} ate_median={:.6g} ate_max={:.6g} "
      "rot_mean_deg={:.6g} rot_median_deg={:.6g} rot_max_deg={:.6g} rot_orient_mean_deg={:.6g} "
      "rot_orient_median_deg={:.6g} rpe_delta={} rpe_trans_rmse={:.6g} rpe_trans_mean={:.6g} rpe_rot_mean_deg={:.6g} "
      "mirrored={}",
      e.matched(), ToString(e.alignment), e.alignment_result.gt_world_from_est_world.scale, e.ate_m.rmse, e.ate_m.mean,
      e.ate_m.median, e.ate_m.max, e.rot_deg.mean, e.rot_deg.median, e.rot_deg.max, e.rot_orient_deg.mean,
      e.rot_orient_deg.median, e.rpe_delta, e.rpe_trans_m.rmse,
      e.rpe_trans_m.mean, e.rpe_rot_deg.mean, e.mirrored ? 1 : 0);
}

}  // namespace mcslam::eval
