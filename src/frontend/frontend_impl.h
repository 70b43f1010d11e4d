#pragma once
// Internal to the front end (frontend.cc, frontend_track.cc, frontend_detect.cc): the state behind Frontend and the
// helpers its stages share. Not part of the front end's API.
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
#include "frontend/frontend.h"

namespace mcslam::frontend {
namespace detail {


using Clock = std::chrono::steady_clock;

inline double MsSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// Velocity uncertainty of a new track: small when its neighbours tell how the image moves there.
constexpr double kVelocitySigmaFromNeighboursPx = 3.0;
constexpr double kVelocitySigmaUnknownPx = 10.0;

inline std::string TypeName(int type) {
  const int depth = CV_MAT_DEPTH(type), channels = CV_MAT_CN(type);
  static constexpr const char* kDepths[] = {"8U", "8S", "16U", "16S", "32S", "32F", "64F", "16F"};
  return fmt::format("CV_{}C{}", depth >= 0 && depth < 8 ? kDepths[depth] : "?", channels);
}

// 8-bit gray copy of the caller's frame (always a fresh buffer: the description task may still read the
// previous one, and the caller may reuse its own).
inline cv::Mat ToGray8(const cv::Mat& image, int64_t index) {
  CheckImage(image, index);
  cv::Mat img8;
  if (image.depth() == CV_8U)
    img8 = image;
  else
    image.convertTo(img8, CV_8U, 1.0 / 256.0);  // 16-bit
  cv::Mat gray;
  if (img8.channels() == 1)
    gray = img8.clone();
  else
    cv::cvtColor(img8, gray, img8.channels() == 3 ? cv::COLOR_BGR2GRAY : cv::COLOR_BGRA2GRAY);
  return gray;
}

inline Eigen::Vector2d ToEigen(const cv::Point2f& p) { return {p.x, p.y}; }

struct Track {
  int64_t id = 0;
  cv::Point2f uv;
  ConstantVelocityKalman kf;
  int age = 0;
  bool remapped = false;
  std::optional<Descriptor> descriptor;
  int described_at_age = 0;  // the track's age when `descriptor` was taken
  // Under Frontend::DescribeOnly a new track is not described at its birth; the frame it was born in is kept
  // (shared by the tracks born in it) for BirthImageFrames, so that a track listed within them is described as it
  // would have been at its birth: the same look, the same refresh schedule.
  cv::Mat birth_image;
  cv::Point2f birth_uv;
  // The patch the track was born with and the affine warp from patch offsets to image offsets found at the
  // last alignment (linear part only; the translation follows the track).
  AffinePatch anchor;
  cv::Matx22f anchor_linear = cv::Matx22f::eye();
};

enum class AnchorOutcome : uint8_t { kNotAligned, kKept, kReanchor, kMismatch };

// Aligns a track's birth patch with `gray` from `uv` (where LK put it). On success writes the aligned centre
// and the warp's linear part.
inline AnchorOutcome AlignWithAnchor(const cv::Mat& gray, const AffinePatch& anchor, const cv::Point2f& uv,
                              const FrontendOptions& o, cv::Point2f* aligned, cv::Matx22f* linear,
                              float* sharpness_ratio, float noise_variance) {
  const AffinePatch::Result r =
      anchor.Align(gray, uv, *linear, o.anchor_max_iterations, static_cast<float>(o.anchor_epsilon_px));
  // Too near the edge to align: the track keeps its LK position this frame.
  if (!r.inside) return AnchorOutcome::kNotAligned;
  *sharpness_ratio = anchor.sharpness() > 0 ? r.sharpness / anchor.sharpness() : 0.0f;
  // Noise caps the correlation a patch can reach with its birth patch even where the track is right: at most
  // sqrt(1 - noise / variance) for each of the two (a dark scene, a high gain: the rendered paper scene at a
  // quarter of its contrast with twice its noise correlates ~0.85 on its followed tracks, and at 0.9 the frame's
  // many mismatches took new patches every frame, so the tracks slid). The threshold is lowered by that cap where
  // it is under 0.95; a textured patch in a normal image (cap over 0.99) keeps anchor_min_correlation.
  const float cap = std::sqrt(std::max(0.0f, 1.0f - noise_variance / std::max(anchor.variance(), 1e-6f)) *
                              std::max(0.0f, 1.0f - noise_variance / std::max(r.variance, 1e-6f)));
  const float min_correlation = static_cast<float>(o.anchor_min_correlation) * std::min(1.0f, cap / 0.95f);
  // A mirrored warp (negative determinant) is no view of the same surface.
  if (r.left_image || !(r.correlation >= min_correlation) || !(cv::norm(r.centre - uv) <= o.anchor_max_shift_px) ||
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
inline AffinePatch MonitorPatch(const cv::Mat& gray, const cv::Point2f& uv, const FrontendOptions& o) {
  AffinePatch patch(gray, uv, o.anchor_patch_px);
  if (!patch.empty() && patch.texture_ratio() < o.anchor_min_texture_ratio) return {};
  return patch;
}

// Where a track is described: an image and a point in it; from_birth when that is its birth frame and position.
struct Look {
  cv::Mat image;
  cv::Point2f uv;
  bool from_birth = false;
};

// Describes each look (SiftDescriber::DescribeAll once per distinct image, in the order the images first come).
inline void DescribeLooks(const SiftDescriber& d, const std::vector<Look>& looks, std::vector<Descriptor>* out,
                          std::vector<char>* ok) {
  out->assign(looks.size(), Descriptor{});
  ok->assign(looks.size(), 0);
  std::vector<char> done(looks.size(), 0);
  std::vector<size_t> which;
  std::vector<cv::Point2f> points;
  std::vector<Descriptor> desc;
  std::vector<char> desc_ok;
  for (size_t first = 0; first < looks.size(); ++first) {
    if (done[first]) continue;
    which.clear(), points.clear();
    for (size_t k = first; k < looks.size(); ++k)
      if (!done[k] && looks[k].image.data == looks[first].image.data) {
        which.push_back(k), points.push_back(looks[k].uv);
        done[k] = 1;
      }
    d.DescribeAll(looks[first].image, points, &desc, &desc_ok);
    for (size_t j = 0; j < which.size(); ++j) (*out)[which[j]] = desc[j], (*ok)[which[j]] = desc_ok[j];
  }
}

struct Candidate {
  cv::Point2f uv;
  float response = 0;
  int cell = 0;
};


}  // namespace detail

using namespace detail;  // the stages' own helpers, in the three files of the front end only

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
  // Frontend::DescribeOnly: only the tracks listed are described (none at birth); off: every new track at birth.
  bool describe_only = false;
  std::unordered_set<int64_t> listed;
  int blurred_run = 0;  // frames in a row whose patches were less sharp than their birth patches (TrackFeatures)

  // Description of the tracks born in the last frame (indices into `tracks`, which does not change until
  // the task is joined).
  tbb::task_group task_group;
  bool pending = false;
  std::vector<size_t> pending_tracks;
  std::vector<Descriptor> pending_descriptors;
  std::vector<char> pending_ok;
  std::vector<char> pending_from_birth;
  double pending_ms = 0;

  // Scratch kept between frames to avoid reallocating.
  cv::Mat eig, eig_dilated, blocked, hann;
  cv::Mat gray_float;  // the frame as float pixels, for the birth-patch alignment's vector gathers
  double noise_corner_unit = -1;  // NoiseCornerResponse for the options, measured at the first detection

  double JoinDescription() {
    if (!pending) return 0.0;
    const auto t0 = Clock::now();
    task_group.wait();
    for (size_t k = 0; k < pending_tracks.size(); ++k)
      if (pending_ok[k]) SetDescriptor(&tracks[pending_tracks[k]], pending_descriptors[k], pending_from_birth[k]);
    pending = false;
    pending_tracks.clear();
    return MsSince(t0);
  }

  // A track's descriptor, taken in its birth frame (from_birth: it dates from its birth, the refresh period counts
  // from there) or now.
  static void SetDescriptor(Track* t, const Descriptor& d, bool from_birth) {
    t->descriptor = d;
    t->described_at_age = from_birth ? 0 : t->age;
    t->birth_image.release();
  }

  // Frames a new track's birth frame is kept for under DescribeOnly: the refresh period (a track listed later
  // would have been described again since its birth by then, and is described where it is now instead).
  int BirthImageFrames() const { return options.descriptor_refresh_frames > 0 ? options.descriptor_refresh_frames : 30; }

  // Where tracks[i] is described: its birth frame while kept, else `current` at `uv`.
  static Look LookOf(const Track& t, const cv::Mat& current, const cv::Point2f& uv) {
    if (!t.birth_image.empty()) return {t.birth_image, t.birth_uv, true};
    return {current, uv, false};
  }

  // Describes tracks[indices] (in `gray` where they are, or in their birth frames), now or on the task.
  void StartDescription(const cv::Mat& gray, std::vector<size_t> indices, FrameStats* stats) {
    if (indices.empty()) return;
    std::vector<Look> looks;
    looks.reserve(indices.size());
    pending_from_birth.clear();
    for (size_t i : indices) {
      looks.push_back(LookOf(tracks[i], gray, tracks[i].uv));
      pending_from_birth.push_back(looks.back().from_birth);
    }
    pending_tracks = std::move(indices);
    pending_descriptors.assign(looks.size(), Descriptor{});
    pending_ok.assign(looks.size(), 0);
    pending = true;
    auto work = [this, looks = std::move(looks)](const SiftDescriber& d) {
      const auto t0 = Clock::now();
      // A track without a descriptor simply cannot be remapped; nothing else changes.
      DescribeLooks(d, looks, &pending_descriptors, &pending_ok);
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

  // Under DescribeOnly, the listed tracks among tracks[0, n) without a descriptor are described in this frame (from
  // their birth frames while kept, else where they are: LookOf).
  void AddListed(size_t n, std::vector<size_t>* to_describe, FrameStats* st) const {
    if (!describe_only) return;
    for (size_t i = 0; i < n; ++i)
      if (!tracks[i].descriptor && listed.count(tracks[i].id)) {
        to_describe->push_back(i);
        ++st->described_listed;
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


}  // namespace mcslam::frontend
