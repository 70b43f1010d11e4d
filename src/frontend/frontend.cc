#include "frontend/frontend.h"
#include "core/median.h"

#include <fmt/format.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>

#include "frontend/kalman.h"
#include "frontend/patch_align.h"
#include "frontend/sift_describer.h"

namespace mcslam::frontend {
namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// Velocity uncertainty of a new track: small when its neighbours tell how the image moves there.
constexpr double kVelocitySigmaFromNeighboursPx = 3.0;
constexpr double kVelocitySigmaUnknownPx = 10.0;

std::string TypeName(int type) {
  const int depth = CV_MAT_DEPTH(type), channels = CV_MAT_CN(type);
  static constexpr const char* kDepths[] = {"8U", "8S", "16U", "16S", "32S", "32F", "64F", "16F"};
  return fmt::format("CV_{}C{}", depth >= 0 && depth < 8 ? kDepths[depth] : "?", channels);
}

// 8-bit gray copy of the caller's frame (always a fresh buffer: the description task may still read the
// previous one, and the caller may reuse its own).
cv::Mat ToGray8(const cv::Mat& image, int64_t index) {
  if (image.empty()) throw std::invalid_argument(fmt::format("frame {}: empty image", index));
  cv::Mat img8;
  if (image.depth() == CV_8U) {
    img8 = image;
  } else if (image.depth() == CV_16U) {
    image.convertTo(img8, CV_8U, 1.0 / 256.0);
  } else {
    throw std::invalid_argument(
        fmt::format("frame {}: unsupported pixel type {} (expected 8- or 16-bit gray, BGR or BGRA)", index,
                    TypeName(image.type())));
  }
  cv::Mat gray;
  switch (img8.channels()) {
    case 1:
      gray = img8.clone();
      break;
    case 3:
      cv::cvtColor(img8, gray, cv::COLOR_BGR2GRAY);
      break;
    case 4:
      cv::cvtColor(img8, gray, cv::COLOR_BGRA2GRAY);
      break;
    default:
      throw std::invalid_argument(fmt::format("frame {}: unsupported pixel type {} (expected 1, 3 or 4 channels)",
                                              index, TypeName(image.type())));
  }
  return gray;
}

Eigen::Vector2d ToEigen(const cv::Point2f& p) { return {p.x, p.y}; }

struct Track {
  int64_t id = 0;
  cv::Point2f uv;
  ConstantVelocityKalman kf;
  int age = 0;
  bool remapped = false;
  std::optional<Descriptor> descriptor;
  int described_at_age = 0;  // the track's age when `descriptor` was taken
  // The patch the track was born with and the affine warp from patch offsets to image offsets found at the
  // last alignment (linear part only; the translation follows the track).
  AffinePatch anchor;
  cv::Matx22f anchor_linear = cv::Matx22f::eye();
};

enum class AnchorOutcome : uint8_t { kNotAligned, kKept, kReanchor, kMismatch };

// Aligns a track's birth patch with `gray` from `uv` (where LK put it). On success writes the aligned centre
// and the warp's linear part.
AnchorOutcome AlignWithAnchor(const cv::Mat& gray, const AffinePatch& anchor, const cv::Point2f& uv,
                              const FrontendOptions& o, cv::Point2f* aligned, cv::Matx22f* linear) {
  const AffinePatch::Result r = anchor.Align(gray, uv, *linear, 50, 0.001f);
  // Too near the edge to align: the track keeps its LK position this frame.
  if (!r.inside) return AnchorOutcome::kNotAligned;
  // A mirrored warp (negative determinant) is no view of the same surface.
  if (r.left_image || !(r.correlation >= o.anchor_min_correlation) || !(cv::norm(r.centre - uv) <= o.anchor_max_shift_px) ||
      !(cv::determinant(r.linear) > 0))
    return AnchorOutcome::kMismatch;
  *aligned = r.centre;
  *linear = r.linear;
  // Singular values of the linear part: how much the patch grew, shrank or was sheared since birth.
  cv::Vec2f w;
  cv::Matx22f u, vt;
  cv::SVD::compute(r.linear, w, u, vt);
  const double smax = std::max(w[0], w[1]), smin = std::min(w[0], w[1]);
  const double k = o.anchor_max_scale_change;
  return (smax > k || smin < 1.0 / k || smax > k * smin) ? AnchorOutcome::kReanchor : AnchorOutcome::kKept;
}

// The patch a track is monitored with from here on; empty (unmonitored) when it does not fit in the image or
// holds no more than an edge.
AffinePatch MonitorPatch(const cv::Mat& gray, const cv::Point2f& uv, const FrontendOptions& o) {
  AffinePatch patch(gray, uv, o.anchor_patch_px);
  if (!patch.empty() && patch.texture_ratio() < o.anchor_min_texture_ratio) return {};
  return patch;
}

struct Candidate {
  cv::Point2f uv;
  float response = 0;
  int cell = 0;
};

}  // namespace

float DescriptorDistance(const Descriptor& a, const Descriptor& b) {
  float s = 0;
  for (int i = 0; i < kDescriptorLength; ++i) {
    const float d = a[i] - b[i];
    s += d * d;
  }
  return std::sqrt(s);
}

std::optional<DescriptorMatch> MatchDescriptor(const Descriptor& query, std::span<const Descriptor* const> candidates,
                                               const FrontendOptions& options) {
  float best = std::numeric_limits<float>::infinity(), second = best;
  size_t best_index = 0;
  for (size_t i = 0; i < candidates.size(); ++i) {
    if (!candidates[i]) continue;
    const float dist = DescriptorDistance(query, *candidates[i]);
    if (dist < best) {
      second = best;
      best = dist;
      best_index = i;
    } else if (dist < second) {
      second = dist;
    }
  }
  if (!(best <= options.remap_max_distance && best < options.remap_ratio * second)) return std::nullopt;
  return DescriptorMatch{best_index, best};
}

void FrontendOptions::Check() const {
  auto fail = [](const std::string& what) { throw std::invalid_argument("FrontendOptions." + what); };
  if (max_features < 1) fail(fmt::format("max_features must be >= 1 (got {})", max_features));
  if (cell_size_px < 4) fail(fmt::format("cell_size_px must be >= 4 (got {})", cell_size_px));
  if (max_new_per_cell < 1) fail(fmt::format("max_new_per_cell must be >= 1 (got {})", max_new_per_cell));
  if (!(quality_level > 0 && quality_level < 1))
    fail(fmt::format("quality_level must be in (0, 1) (got {})", quality_level));
  if (!(min_distance_px >= 0) || !std::isfinite(min_distance_px))
    fail(fmt::format("min_distance_px must be >= 0 (got {})", min_distance_px));
  if (block_size < 2 || block_size > 31) fail(fmt::format("block_size must be in [2, 31] (got {})", block_size));
  if (border_px < 0) fail(fmt::format("border_px must be >= 0 (got {})", border_px));
  if (pyramid_levels < 1 || pyramid_levels > 8)
    fail(fmt::format("pyramid_levels must be in [1, 8] (got {})", pyramid_levels));
  if (window_px < 5 || window_px % 2 == 0) fail(fmt::format("window_px must be odd and >= 5 (got {})", window_px));
  if (max_iterations < 1) fail(fmt::format("max_iterations must be >= 1 (got {})", max_iterations));
  if (!(epsilon_px > 0) || !std::isfinite(epsilon_px))
    fail(fmt::format("epsilon_px must be positive (got {})", epsilon_px));
  if (!(min_eigen_threshold >= 0) || !std::isfinite(min_eigen_threshold))
    fail(fmt::format("min_eigen_threshold must be >= 0 (got {})", min_eigen_threshold));
  if (!(max_forward_backward_px > 0))
    fail(fmt::format("max_forward_backward_px must be positive (got {})", max_forward_backward_px));
  if (std::isnan(max_patch_error)) fail("max_patch_error must be a number (<= 0 turns the check off)");
  if (retry_pyramid_levels < 0 || retry_pyramid_levels > 8)
    fail(fmt::format("retry_pyramid_levels must be in [0, 8] (got {})", retry_pyramid_levels));
  if (anchor_every < 0) fail(fmt::format("anchor_every must be >= 0 (got {})", anchor_every));
  if (!(anchor_auto_reanchor_fraction >= 0 && anchor_auto_reanchor_fraction <= 1))
    fail(fmt::format("anchor_auto_reanchor_fraction must be in [0, 1] (got {})", anchor_auto_reanchor_fraction));
  if (anchor_patch_px < 7 || anchor_patch_px % 2 == 0)
    fail(fmt::format("anchor_patch_px must be odd and >= 7 (got {})", anchor_patch_px));
  if (!(anchor_min_correlation > -1 && anchor_min_correlation < 1))
    fail(fmt::format("anchor_min_correlation must be in (-1, 1) (got {})", anchor_min_correlation));
  if (!(anchor_max_shift_px > 0) || !std::isfinite(anchor_max_shift_px))
    fail(fmt::format("anchor_max_shift_px must be positive (got {})", anchor_max_shift_px));
  if (!(anchor_max_scale_change > 1) || !std::isfinite(anchor_max_scale_change))
    fail(fmt::format("anchor_max_scale_change must be > 1 (got {})", anchor_max_scale_change));
  if (!(anchor_min_texture_ratio >= 0 && anchor_min_texture_ratio < 1))
    fail(fmt::format("anchor_min_texture_ratio must be in [0, 1) (got {})", anchor_min_texture_ratio));
  if (track_border_px < 0) fail(fmt::format("track_border_px must be >= 0 (got {})", track_border_px));
  if (!(kalman_accel_sigma_px > 0) || !std::isfinite(kalman_accel_sigma_px))
    fail(fmt::format("kalman_accel_sigma_px must be positive (got {})", kalman_accel_sigma_px));
  if (!(kalman_measurement_sigma_px > 0) || !std::isfinite(kalman_measurement_sigma_px))
    fail(fmt::format("kalman_measurement_sigma_px must be positive (got {})", kalman_measurement_sigma_px));
  if (!(init_velocity_radius_px >= 0) || !std::isfinite(init_velocity_radius_px))
    fail(fmt::format("init_velocity_radius_px must be >= 0 (got {})", init_velocity_radius_px));
  if (!(jolt_min_failed_fraction >= 0 && jolt_min_failed_fraction <= 1))
    fail(fmt::format("jolt_min_failed_fraction must be in [0, 1] (got {})", jolt_min_failed_fraction));
  if (!(jolt_min_shift_px >= 0) || !std::isfinite(jolt_min_shift_px))
    fail(fmt::format("jolt_min_shift_px must be >= 0 (got {})", jolt_min_shift_px));
  if (descriptor_refresh_frames < 0)
    fail(fmt::format("descriptor_refresh_frames must be >= 0 (got {})", descriptor_refresh_frames));
  if (!(descriptor_size_px >= 1 && descriptor_size_px <= 64))
    fail(fmt::format("descriptor_size_px must be in [1, 64] (got {})", descriptor_size_px));
  if (remap_window_px < 1) fail(fmt::format("remap_window_px must be >= 1 (got {})", remap_window_px));
  if (remap_max_candidates < 1) fail(fmt::format("remap_max_candidates must be >= 1 (got {})", remap_max_candidates));
  if (!(remap_max_distance > 0)) fail(fmt::format("remap_max_distance must be positive (got {})", remap_max_distance));
  if (!(remap_ratio > 0 && remap_ratio <= 1)) fail(fmt::format("remap_ratio must be in (0, 1] (got {})", remap_ratio));
}

// ---- Impl -----------------------------------------------------------------------------------------------

struct Frontend::Impl {
  explicit Impl(const FrontendOptions& o)
      : options(o), describer(o.descriptor_size_px), task_describer(o.descriptor_size_px) {}

  FrontendOptions options;
  SiftDescriber describer;       // used on the caller's thread (remapping, synchronous description)
  SiftDescriber task_describer;  // used by the description task only
  std::vector<Track> tracks;
  int64_t next_id = 0;
  cv::Size size;  // of the frames since the last Reset; empty before the first
  std::vector<cv::Mat> prev_pyramid;

  // Description of the tracks born in the last frame (indices into `tracks`, which does not change until
  // the task is joined).
  tbb::task_group task_group;
  bool pending = false;
  std::vector<size_t> pending_tracks;
  std::vector<Descriptor> pending_descriptors;
  std::vector<char> pending_ok;
  double pending_ms = 0;

  // Scratch kept between frames to avoid reallocating.
  cv::Mat eig, eig_dilated, blocked, hann;

  double JoinDescription() {
    if (!pending) return 0.0;
    const auto t0 = Clock::now();
    task_group.wait();
    for (size_t k = 0; k < pending_tracks.size(); ++k)
      if (pending_ok[k]) {
        Track& t = tracks[pending_tracks[k]];
        t.descriptor = pending_descriptors[k];
        t.described_at_age = t.age;
      }
    pending = false;
    pending_tracks.clear();
    return MsSince(t0);
  }

  // Describes tracks[indices] from `gray`, now or on the task.
  void StartDescription(const cv::Mat& gray, std::vector<size_t> indices, FrameStats* stats) {
    if (indices.empty()) return;
    std::vector<cv::Point2f> points;
    points.reserve(indices.size());
    for (size_t i : indices) points.push_back(tracks[i].uv);
    pending_tracks = std::move(indices);
    pending_descriptors.assign(points.size(), Descriptor{});
    pending_ok.assign(points.size(), 0);
    pending = true;
    auto work = [this, gray, points = std::move(points)](const SiftDescriber& d) {
      const auto t0 = Clock::now();
      // A track without a descriptor simply cannot be remapped; nothing else changes.
      d.DescribeAll(gray, points, &pending_descriptors, &pending_ok);
      pending_ms = MsSince(t0);
    };
    if (options.describe_async) {
      task_group.run([work, this] { work(task_describer); });
    } else {
      work(describer);
      JoinDescription();
      stats->describe_ms = pending_ms;
    }
  }

  // Median velocity of the tracks near `uv` (carried tracks only), with how sure it is.
  std::pair<Eigen::Vector2d, double> InitialVelocity(const cv::Point2f& uv, size_t n_carried) const {
    const double r2 = options.init_velocity_radius_px * options.init_velocity_radius_px;
    std::vector<double> vu, vv;
    if (r2 > 0) {
      for (size_t i = 0; i < n_carried; ++i) {
        const cv::Point2f d = tracks[i].uv - uv;
        if (tracks[i].age > 0 && d.x * d.x + d.y * d.y <= r2) {
          vu.push_back(tracks[i].kf.velocity_px().x());
          vv.push_back(tracks[i].kf.velocity_px().y());
        }
      }
    }
    if (vu.empty()) return {Eigen::Vector2d::Zero(), kVelocitySigmaUnknownPx};
    return {Eigen::Vector2d(UpperMedian(vu), UpperMedian(vv)), kVelocitySigmaFromNeighboursPx};
  }

  void TrackFeatures(const cv::Mat& gray, const std::vector<cv::Mat>& pyramid, FrameResult* result);
  void DetectAndRemap(const cv::Mat& gray, std::span<const RemapRequest> remap, FrameResult* result);
};

void Frontend::Impl::TrackFeatures(const cv::Mat& gray, const std::vector<cv::Mat>& pyramid, FrameResult* result) {
  FrameStats& st = result->stats;
  const size_t n = tracks.size();
  if (n == 0 || prev_pyramid.empty()) return;
  const FrontendOptions& o = options;
  const cv::Size win(o.window_px, o.window_px);
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, o.max_iterations, o.epsilon_px);
  const float w1 = static_cast<float>(size.width - 1), h1 = static_cast<float>(size.height - 1);
  auto clamp_to_image = [&](cv::Point2f p) {
    p.x = std::clamp(p.x, 0.0f, w1);
    p.y = std::clamp(p.y, 0.0f, h1);
    return p;
  };
  const float b = static_cast<float>(o.track_border_px);
  auto outside = [&](const cv::Point2f& p) { return !(p.x >= b && p.y >= b && p.x <= w1 - b && p.y <= h1 - b); };

  std::vector<cv::Point2f> p0(n), start(n);
  for (size_t i = 0; i < n; ++i) {
    p0[i] = tracks[i].uv;
    const Eigen::Vector2d pred = tracks[i].kf.Predict(o.kalman_accel_sigma_px);
    start[i] = clamp_to_image(
        o.use_kalman_prediction ? cv::Point2f(static_cast<float>(pred.x()), static_cast<float>(pred.y())) : p0[i]);
  }

  enum Outcome : uint8_t { kOk, kOutside, kStatus, kForwardBackward, kAnchor };
  std::vector<cv::Point2f> p1(n);
  std::vector<float> err(n, 0.0f);
  std::vector<uint8_t> outcome(n, kStatus);

  // Forward from the prediction, then back from where each track ended, started as far from its origin as
  // the forward result was from its own start (so that the round trip is not handed the answer).
  auto round_trip = [&](const std::vector<size_t>& which, int levels) {
    std::vector<cv::Point2f> a(which.size()), fwd(which.size());
    for (size_t k = 0; k < which.size(); ++k) {
      a[k] = p0[which[k]];
      fwd[k] = start[which[k]];
    }
    std::vector<uchar> status, status_back;
    std::vector<float> e, e_back;
    cv::calcOpticalFlowPyrLK(prev_pyramid, pyramid, a, fwd, status, e, win, levels - 1, criteria,
                             cv::OPTFLOW_USE_INITIAL_FLOW, o.min_eigen_threshold);
    std::vector<size_t> back_of;
    std::vector<cv::Point2f> from, back;
    for (size_t k = 0; k < which.size(); ++k) {
      const size_t i = which[k];
      p1[i] = fwd[k];
      err[i] = e[k];
      if (outside(fwd[k])) {
        outcome[i] = kOutside;
      } else if (!status[k]) {
        outcome[i] = kStatus;
      } else {
        back_of.push_back(i);
        from.push_back(fwd[k]);
        back.push_back(clamp_to_image(fwd[k] - (start[i] - p0[i])));
      }
    }
    if (from.empty()) return;
    cv::calcOpticalFlowPyrLK(pyramid, prev_pyramid, from, back, status_back, e_back, win, levels - 1, criteria,
                             cv::OPTFLOW_USE_INITIAL_FLOW, o.min_eigen_threshold);
    for (size_t k = 0; k < back_of.size(); ++k) {
      const size_t i = back_of[k];
      if (!status_back[k]) {
        outcome[i] = kStatus;
      } else if (cv::norm(back[k] - p0[i]) > o.max_forward_backward_px) {
        outcome[i] = kForwardBackward;
      } else {
        outcome[i] = kOk;
      }
    }
  };

  std::vector<size_t> all(n);
  for (size_t i = 0; i < n; ++i) all[i] = i;
  round_trip(all, o.pyramid_levels);
  // Tracks the shallow pyramid could not follow (a young track without a velocity, a jolt) get one more try
  // with a deeper pyramid; the forward-backward check still has the last word.
  if (o.retry_pyramid_levels > o.pyramid_levels) {
    std::vector<size_t> retry;
    for (size_t i = 0; i < n; ++i)
      if ((outcome[i] == kStatus || outcome[i] == kForwardBackward) && !outside(start[i])) retry.push_back(i);
    if (!retry.empty()) {
      st.retried = static_cast<int>(retry.size());
      round_trip(retry, o.retry_pyramid_levels);
      for (size_t i : retry) st.recovered += outcome[i] == kOk;
    }
    // A jolt of the camera (a sudden turn, a shake) moves the whole image away from every track's own
    // prediction, further than the deeper pyramid reaches; LK then fails, or worse settles in a local minimum
    // that the round trip confirms. The image's global shift, measured by phase correlation of a coarse
    // pyramid level (the whole image: it needs no track to have followed), gives the tracks that failed
    // twice a last try from where that shift puts them, when it is jolt_min_shift_px away from their
    // prediction. Only when a good part of the tracks failed together: a jolt loses most of them at once,
    // while a few failures are occlusions and changes of look (a car's forward motion) that no global shift
    // explains, and retrying those only gives LK another chance to settle somewhere wrong.
    std::vector<size_t> failed;
    for (size_t i = 0; i < n; ++i)
      if (outcome[i] == kStatus || outcome[i] == kForwardBackward) failed.push_back(i);
    if (o.jolt_recovery && !failed.empty() &&
        static_cast<double>(failed.size()) >= o.jolt_min_failed_fraction * static_cast<double>(n)) {
      const int level = std::min(2, static_cast<int>(std::min(pyramid.size(), prev_pyramid.size()) / 2) - 1);
      if (level >= 0) {
        cv::Mat a, c;
        prev_pyramid[static_cast<size_t>(2 * level)].convertTo(a, CV_32F);
        pyramid[static_cast<size_t>(2 * level)].convertTo(c, CV_32F);
        if (a.size() == c.size() && a.cols >= 16 && a.rows >= 16) {
          if (hann.size() != a.size()) cv::createHanningWindow(hann, a.size(), CV_32F);
          double response = 0;
          const cv::Point2d d = cv::phaseCorrelate(a, c, hann, &response) * static_cast<double>(1 << level);
          const cv::Point2f shift(static_cast<float>(d.x), static_cast<float>(d.y));
          std::vector<size_t> again;
          for (size_t i : failed) {
            const cv::Point2f from = clamp_to_image(p0[i] + shift);
            if (outside(from) || cv::norm(from - start[i]) < o.jolt_min_shift_px) continue;
            start[i] = from;
            again.push_back(i);
          }
          if (!again.empty()) {
            round_trip(again, o.retry_pyramid_levels);
            for (size_t i : again) st.jolt_recovered += outcome[i] == kOk;
          }
        }
      }
    }
  }

  // Alignment with the birth patches (each track on its own: in parallel, the result independent of the order).
  const auto t_anchor = Clock::now();
  std::vector<uint8_t> reanchor(n, 0), aligned_ok(n, 0), mismatch(n, 0);
  std::vector<float> anchor_shift(n, 0.0f);
  if (o.anchor_every > 0) {
    std::vector<size_t> due;
    for (size_t i = 0; i < n; ++i)
      if (outcome[i] == kOk && !tracks[i].anchor.empty() && (tracks[i].age + 1) % o.anchor_every == 0) due.push_back(i);
    tbb::parallel_for(size_t{0}, due.size(), [&](size_t k) {
      const size_t i = due[k];
      cv::Point2f aligned = p1[i];
      const AnchorOutcome a = AlignWithAnchor(gray, tracks[i].anchor, p1[i], o, &aligned, &tracks[i].anchor_linear);
      if (a == AnchorOutcome::kNotAligned) return;  // too near the edge: the LK position stands this frame
      if (a == AnchorOutcome::kMismatch) {
        mismatch[i] = 1;  // decided below, from the frame's count
        return;
      }
      if (a == AnchorOutcome::kReanchor) reanchor[i] = 1;
      anchor_shift[i] = static_cast<float>(cv::norm(aligned - p1[i]));
      aligned_ok[i] = 1;
      p1[i] = aligned;
    });
  }
  // A mismatched track goes, or stays where LK put it and takes a new patch there (FrontendOptions::anchor_mismatch).
  const int mismatches = static_cast<int>(std::count(mismatch.begin(), mismatch.end(), 1));
  const int aligned_count = static_cast<int>(std::count(aligned_ok.begin(), aligned_ok.end(), 1)) + mismatches;
  using AM = FrontendOptions::AnchorMismatch;
  const bool keep_mismatched =
      o.anchor_mismatch == AM::kReanchor ||
      (o.anchor_mismatch == AM::kAuto && mismatches > o.anchor_auto_reanchor_fraction * aligned_count);
  for (size_t i = 0; i < n; ++i)
    if (mismatch[i] && keep_mismatched) reanchor[i] = 1;
    else if (mismatch[i]) outcome[i] = kAnchor;
  st.anchor_ms = MsSince(t_anchor);
  double sum_shift = 0;

  std::vector<Track> kept;
  kept.reserve(n);
  double sum_pred = 0, sum_disp = 0;
  for (size_t i = 0; i < n; ++i) {
    Track& t = tracks[i];
    bool lost = true;
    if (outcome[i] == kOutside || outside(start[i])) {
      ++st.lost_outside;
    } else if (outcome[i] == kStatus) {
      ++st.lost_status;
    } else if (outcome[i] == kForwardBackward) {
      ++st.lost_forward_backward;
    } else if (outcome[i] == kAnchor) {
      ++st.lost_anchor;
    } else if (o.max_patch_error > 0 && err[i] > o.max_patch_error) {
      ++st.lost_patch_error;
    } else {
      lost = false;
    }
    if (lost) {
      result->lost.push_back({t.id, ToEigen(p0[i]), t.descriptor});
      continue;
    }
    sum_pred += cv::norm(p1[i] - start[i]);
    sum_disp += cv::norm(p1[i] - p0[i]);
    t.kf.Update(ToEigen(p1[i]), o.kalman_measurement_sigma_px);
    t.uv = p1[i];
    if (aligned_ok[i]) {
      ++st.anchored;
      sum_shift += anchor_shift[i];
    }
    if (reanchor[i]) {
      // Near the image's edge the new patch may not fit, or it may hold only an edge (empty): the track then
      // goes on unmonitored.
      t.anchor = MonitorPatch(gray, t.uv, o);
      t.anchor_linear = cv::Matx22f::eye();
      st.reanchored += !t.anchor.empty();
    }
    ++t.age;
    t.remapped = false;
    kept.push_back(std::move(t));
  }
  tracks = std::move(kept);
  if (st.anchored > 0) st.mean_anchor_shift_px = sum_shift / st.anchored;
  st.tracked = static_cast<int>(tracks.size());
  if (!tracks.empty()) {
    st.mean_prediction_error_px = sum_pred / static_cast<double>(tracks.size());
    st.mean_displacement_px = sum_disp / static_cast<double>(tracks.size());
  }
}

void Frontend::Impl::DetectAndRemap(const cv::Mat& gray, std::span<const RemapRequest> remap, FrameResult* result) {
  FrameStats& st = result->stats;
  const FrontendOptions& o = options;
  const auto t_detect = Clock::now();
  const int W = gray.cols, H = gray.rows;
  const int cells_x = (W + o.cell_size_px - 1) / o.cell_size_px, cells_y = (H + o.cell_size_px - 1) / o.cell_size_px;
  auto cell_of = [&](const cv::Point2f& p) {
    const int cx = std::clamp(static_cast<int>(p.x) / o.cell_size_px, 0, cells_x - 1);
    const int cy = std::clamp(static_cast<int>(p.y) / o.cell_size_px, 0, cells_y - 1);
    return cy * cells_x + cx;
  };
  std::vector<int> occupancy(static_cast<size_t>(cells_x * cells_y), 0);
  for (const Track& t : tracks) ++occupancy[static_cast<size_t>(cell_of(t.uv))];

  // Which requests can be tried at all (decided before any corner work, so that nothing is done for none).
  std::unordered_set<int64_t> live_ids;
  for (const Track& t : tracks) live_ids.insert(t.id);
  std::unordered_set<int64_t> seen_ids;
  std::vector<const RemapRequest*> requests;
  st.remap_requests = static_cast<int>(remap.size());
  const double rb = o.border_px;
  for (const RemapRequest& r : remap) {
    if (r.feature_id < 0 || r.feature_id >= next_id || live_ids.count(r.feature_id) ||
        !seen_ids.insert(r.feature_id).second) {
      ++st.remap_refused_id;
    } else if (!r.uv_px.allFinite() || r.uv_px.x() < rb || r.uv_px.y() < rb || r.uv_px.x() > W - 1 - rb ||
               r.uv_px.y() > H - 1 - rb) {
      ++st.remap_outside;
    } else {
      requests.push_back(&r);
    }
  }

  const int budget = o.max_features - static_cast<int>(tracks.size());
  bool any_empty_cell = false;
  for (int c : occupancy) any_empty_cell |= c == 0;
  if ((budget <= 0 || !any_empty_cell) && requests.empty()) {
    st.detect_ms = MsSince(t_detect);
    return;
  }

  // Shi-Tomasi response and its local maxima, strongest first, away from the border and from every track.
  cv::cornerMinEigenVal(gray, eig, o.block_size, 3);
  double max_response = 0;
  cv::minMaxLoc(eig, nullptr, &max_response);
  std::vector<Candidate> candidates;
  if (max_response > 0) {
    cv::dilate(eig, eig_dilated, cv::Mat());
    blocked.create(gray.size(), CV_8U);
    blocked.setTo(0);
    const int radius = static_cast<int>(std::ceil(o.min_distance_px)) - 1;
    if (radius >= 0)
      for (const Track& t : tracks)
        cv::circle(blocked, cv::Point(cvRound(t.uv.x), cvRound(t.uv.y)), radius, 255, cv::FILLED);
    const float threshold = static_cast<float>(o.quality_level * max_response);
    // Only cells that can take a new corner or that a remap window touches are searched.
    std::vector<char> search(occupancy.size(), 0);
    if (budget > 0)
      for (size_t c = 0; c < occupancy.size(); ++c) search[c] = occupancy[c] == 0;
    for (const RemapRequest* r : requests) {
      const int hw = o.remap_window_px;
      const int x0 = std::max(0, static_cast<int>(r->uv_px.x()) - hw) / o.cell_size_px;
      const int x1 = std::min(W - 1, static_cast<int>(r->uv_px.x()) + hw) / o.cell_size_px;
      const int y0 = std::max(0, static_cast<int>(r->uv_px.y()) - hw) / o.cell_size_px;
      const int y1 = std::min(H - 1, static_cast<int>(r->uv_px.y()) + hw) / o.cell_size_px;
      for (int cy = y0; cy <= y1; ++cy)
        for (int cx = x0; cx <= x1; ++cx) search[static_cast<size_t>(cy * cells_x + cx)] = 1;
    }
    for (int cy = 0; cy < cells_y; ++cy) {
      for (int cx = 0; cx < cells_x; ++cx) {
        if (!search[static_cast<size_t>(cy * cells_x + cx)]) continue;
        const int xb = std::max(o.border_px, cx * o.cell_size_px),
                  xe = std::min(W - o.border_px, (cx + 1) * o.cell_size_px);
        const int yb = std::max(o.border_px, cy * o.cell_size_px),
                  ye = std::min(H - o.border_px, (cy + 1) * o.cell_size_px);
        for (int y = yb; y < ye; ++y) {
          const float* e = eig.ptr<float>(y);
          const float* d = eig_dilated.ptr<float>(y);
          const uchar* m = blocked.ptr<uchar>(y);
          for (int x = xb; x < xe; ++x) {
            if (e[x] > threshold && e[x] == d[x] && !m[x])
              candidates.push_back(
                  {cv::Point2f(static_cast<float>(x), static_cast<float>(y)), e[x], cy * cells_x + cx});
          }
        }
      }
    }
    // Ties broken by position so that the result never depends on the sort's whims.
    std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
      if (a.response != b.response) return a.response > b.response;
      if (a.uv.y != b.uv.y) return a.uv.y < b.uv.y;
      return a.uv.x < b.uv.x;
    });
  }

  // New corners: only in cells without a track, a few per cell, min_distance apart, within the budget.
  std::vector<size_t> fresh;
  {
    std::vector<int> per_cell(occupancy.size(), 0);
    const double min_d2 = o.min_distance_px * o.min_distance_px;
    std::vector<std::vector<size_t>> accepted_in_cell(occupancy.size());
    for (size_t k = 0; k < candidates.size() && static_cast<int>(fresh.size()) < budget; ++k) {
      const Candidate& c = candidates[k];
      if (occupancy[static_cast<size_t>(c.cell)] > 0 || per_cell[static_cast<size_t>(c.cell)] >= o.max_new_per_cell)
        continue;
      // min_distance against the corners already taken here and in the neighbouring cells.
      bool close = false;
      const int cx = c.cell % cells_x, cy = c.cell / cells_x;
      const int reach = static_cast<int>(std::ceil(o.min_distance_px / o.cell_size_px));
      for (int yy = std::max(0, cy - reach); yy <= std::min(cells_y - 1, cy + reach) && !close; ++yy)
        for (int xx = std::max(0, cx - reach); xx <= std::min(cells_x - 1, cx + reach) && !close; ++xx)
          for (size_t j : accepted_in_cell[static_cast<size_t>(yy * cells_x + xx)]) {
            const cv::Point2f d = candidates[j].uv - c.uv;
            if (d.x * d.x + d.y * d.y < min_d2) {
              close = true;
              break;
            }
          }
      if (close) continue;
      fresh.push_back(k);
      ++per_cell[static_cast<size_t>(c.cell)];
      accepted_in_cell[static_cast<size_t>(c.cell)].push_back(k);
    }
  }
  st.detect_ms = MsSince(t_detect);

  // Remapping (§6.4): the strongest new corners in the window around each projection, matched by SIFT.
  const auto t_remap = Clock::now();
  std::vector<std::pair<const RemapRequest*, size_t>> attached;  // request, candidate
  if (!requests.empty()) {
    std::vector<std::vector<size_t>> window_candidates(requests.size());
    std::unordered_map<size_t, std::optional<Descriptor>> descriptors;
    const float hw = static_cast<float>(o.remap_window_px);
    for (size_t r = 0; r < requests.size(); ++r) {
      const float u = static_cast<float>(requests[r]->uv_px.x()), v = static_cast<float>(requests[r]->uv_px.y());
      // `candidates` is sorted by response: the first found are the strongest.
      for (size_t k = 0;
           k < candidates.size() && static_cast<int>(window_candidates[r].size()) < o.remap_max_candidates; ++k) {
        const cv::Point2f& p = candidates[k].uv;
        if (std::abs(p.x - u) <= hw && std::abs(p.y - v) <= hw) {
          window_candidates[r].push_back(k);
          descriptors.emplace(k, std::nullopt);
        }
      }
    }
    {  // every candidate of some window described at once (a candidate without a descriptor cannot match)
      std::vector<cv::Point2f> at;
      at.reserve(descriptors.size());
      for (const auto& [k, d] : descriptors) at.push_back(candidates[k].uv);
      std::vector<Descriptor> desc;
      std::vector<char> ok;
      describer.DescribeAll(gray, at, &desc, &ok);
      size_t n = 0;
      for (auto& [k, d] : descriptors) {
        if (ok[n]) d = desc[n];
        ++n;
      }
    }
    struct Match {
      float distance;
      size_t request;
      size_t candidate;
    };
    std::vector<Match> matches;
    std::vector<const Descriptor*> looks;
    for (size_t r = 0; r < requests.size(); ++r) {
      if (window_candidates[r].empty()) {
        ++st.remap_no_candidate;
        continue;
      }
      looks.clear();
      for (size_t k : window_candidates[r]) {
        const std::optional<Descriptor>& d = descriptors.at(k);
        looks.push_back(d ? &*d : nullptr);
      }
      if (const auto m = MatchDescriptor(requests[r]->descriptor, looks, o)) {
        matches.push_back({m->distance, r, window_candidates[r][m->index]});
      } else {
        ++st.remap_no_match;
      }
    }
    // One corner for one map point: the closest descriptors win.
    std::sort(matches.begin(), matches.end(), [](const Match& a, const Match& b) {
      return a.distance != b.distance ? a.distance < b.distance : a.request < b.request;
    });
    std::unordered_set<size_t> taken;
    for (const Match& m : matches) {
      if (!taken.insert(m.candidate).second) {
        ++st.remap_no_match;
        continue;
      }
      attached.emplace_back(requests[m.request], m.candidate);
    }
  }

  // New tracks (re-attached ones first), within the budget; new corners too near a re-attached one go.
  const size_t n_carried = tracks.size();
  std::vector<size_t> to_describe;
  for (const auto& [req, k] : attached) {
    if (static_cast<int>(tracks.size()) >= o.max_features) {
      ++st.remap_over_budget;
      continue;
    }
    Track t;
    t.id = req->feature_id;
    t.uv = candidates[k].uv;
    const auto [vel, sigma] = InitialVelocity(t.uv, n_carried);
    t.kf = ConstantVelocityKalman(ToEigen(t.uv), vel, o.kalman_measurement_sigma_px, sigma);
    t.remapped = true;
    t.descriptor = req->descriptor;  // the map point keeps the look it was mapped with
    if (o.anchor_every > 0) t.anchor = MonitorPatch(gray, t.uv, o);
    tracks.push_back(std::move(t));
    result->remapped_ids.push_back(req->feature_id);
  }
  st.remapped = static_cast<int>(result->remapped_ids.size());
  const double min_d2 = o.min_distance_px * o.min_distance_px;
  for (size_t k : fresh) {
    if (static_cast<int>(tracks.size()) >= o.max_features) break;
    bool near_attached = false;
    for (const auto& [req, ka] : attached) {
      const cv::Point2f d = candidates[ka].uv - candidates[k].uv;
      near_attached |= d.x * d.x + d.y * d.y < min_d2;
    }
    if (near_attached) continue;
    Track t;
    t.id = next_id++;
    t.uv = candidates[k].uv;
    const auto [vel, sigma] = InitialVelocity(t.uv, n_carried);
    t.kf = ConstantVelocityKalman(ToEigen(t.uv), vel, o.kalman_measurement_sigma_px, sigma);
    if (o.anchor_every > 0) t.anchor = MonitorPatch(gray, t.uv, o);
    to_describe.push_back(tracks.size());
    tracks.push_back(std::move(t));
    ++st.detected;
  }
  st.remap_ms = requests.empty() ? 0.0 : MsSince(t_remap);

  // Tracks whose descriptor is descriptor_refresh_frames old are described again where they are now, when the
  // whole descriptor window is inside the image: a map point that is lost and comes back (remapping,
  // relocalisation) is then matched with how it looked when it was last seen, not at its birth.
  if (o.descriptor_refresh_frames > 0) {
    const float margin = static_cast<float>(std::ceil(2.5 * 1.5 * o.descriptor_size_px));
    for (size_t i = 0; i < n_carried; ++i) {
      const Track& t = tracks[i];
      if (!t.descriptor || t.age - t.described_at_age < o.descriptor_refresh_frames) continue;
      if (t.uv.x < margin || t.uv.y < margin || t.uv.x > static_cast<float>(W - 1) - margin ||
          t.uv.y > static_cast<float>(H - 1) - margin)
        continue;
      to_describe.push_back(i);
      ++st.refreshed;
    }
  }
  StartDescription(gray, std::move(to_describe), &st);
}

// ---- Frontend -------------------------------------------------------------------------------------------

Frontend::Frontend(const FrontendOptions& options) {
  options.Check();
  impl_ = std::make_unique<Impl>(options);
}

Frontend::~Frontend() {
  if (impl_) impl_->task_group.wait();
}

FrameResult Frontend::Process(const cv::Mat& image, int64_t index, double stamp_s,
                              std::span<const RemapRequest> remap) {
  Impl& m = *impl_;
  const auto t_total = Clock::now();
  FrameResult result;
  result.index = index;
  result.stamp_s = stamp_s;
  FrameStats& st = result.stats;

  auto t0 = Clock::now();
  cv::Mat gray = ToGray8(image, index);
  if (!m.size.empty() && gray.size() != m.size)
    throw std::invalid_argument(fmt::format("frame {}: image is {}x{} but the previous frames were {}x{} (Reset first)",
                                            index, gray.cols, gray.rows, m.size.width, m.size.height));
  st.convert_ms = MsSince(t0);

  // The tracks must hold their descriptors before any of them is reported lost or used for remapping.
  if (m.pending) {
    st.describe_wait_ms = m.JoinDescription();
    st.describe_ms = m.pending_ms;  // the task's own time, written before it finished
  }

  t0 = Clock::now();
  std::vector<cv::Mat> pyramid;
  cv::buildOpticalFlowPyramid(gray, pyramid, cv::Size(m.options.window_px, m.options.window_px),
                              std::max(m.options.pyramid_levels, m.options.retry_pyramid_levels) - 1);
  st.pyramid_ms = MsSince(t0);

  t0 = Clock::now();
  m.size = gray.size();
  m.TrackFeatures(gray, pyramid, &result);
  st.track_ms = MsSince(t0) - st.anchor_ms;

  m.DetectAndRemap(gray, remap, &result);

  result.features.reserve(m.tracks.size());
  for (const Track& t : m.tracks) result.features.push_back({t.id, ToEigen(t.uv), t.age, t.remapped});
  m.prev_pyramid = std::move(pyramid);
  st.total_ms = MsSince(t_total);
  return result;
}

void Frontend::WaitForDescriptors() { impl_->JoinDescription(); }

std::optional<Descriptor> Frontend::GetDescriptor(int64_t feature_id) {
  impl_->JoinDescription();
  for (const Track& t : impl_->tracks)
    if (t.id == feature_id) return t.descriptor;
  return std::nullopt;
}

bool Frontend::Relabel(int64_t from, int64_t to, const std::optional<Descriptor>& descriptor) {
  Impl& m = *impl_;
  m.JoinDescription();
  if (to < 0 || to >= m.next_id || from == to) return false;
  Track* track = nullptr;
  for (Track& t : m.tracks) {
    if (t.id == to) return false;
    if (t.id == from) track = &t;
  }
  if (!track) return false;
  track->id = to;
  track->remapped = true;
  if (descriptor) {
    track->descriptor = descriptor;
    track->described_at_age = track->age;
  }
  return true;
}

void Frontend::Reset() {
  impl_->JoinDescription();
  impl_->tracks.clear();
  impl_->prev_pyramid.clear();
  impl_->size = cv::Size();
}

size_t Frontend::NumTracks() const { return impl_->tracks.size(); }
int64_t Frontend::NextFeatureId() const { return impl_->next_id; }
const FrontendOptions& Frontend::options() const { return impl_->options; }

}  // namespace mcslam::frontend
