#include "frontend/frontend_impl.h"
#include "frontend/image_noise.h"

#include <algorithm>
#include <cmath>

namespace mcslam::frontend {

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

DetectionGrid GridFor(const FrontendOptions& o, int width, int height) {
  DetectionGrid g;
  const double area_px = static_cast<double>(width) * static_cast<double>(height);
  const double cell = std::floor(std::sqrt(area_px / std::max(o.min_cells, 1)));
  g.cell_px = static_cast<int>(std::clamp(cell, 4.0, static_cast<double>(o.cell_size_px)));
  g.min_distance_px = o.min_distance_px * g.cell_px / o.cell_size_px;
  return g;
}

void FrontendOptions::Check() const {
  auto fail = [](const std::string& what) { throw std::invalid_argument("FrontendOptions." + what); };
  if (max_features < 1) fail(fmt::format("max_features must be >= 1 (got {})", max_features));
  if (cell_size_px < 4) fail(fmt::format("cell_size_px must be >= 4 (got {})", cell_size_px));
  if (min_cells < 1) fail(fmt::format("min_cells must be >= 1 (got {})", min_cells));
  if (max_new_per_cell < 1) fail(fmt::format("max_new_per_cell must be >= 1 (got {})", max_new_per_cell));
  if (!(quality_level > 0 && quality_level < 1))
    fail(fmt::format("quality_level must be in (0, 1) (got {})", quality_level));
  if (!(corner_noise_margin >= 0 && std::isfinite(corner_noise_margin)))
    fail(fmt::format("corner_noise_margin must be >= 0 (got {})", corner_noise_margin));
  if (!(corner_noise_fraction > 0 && corner_noise_fraction < 1))
    fail(fmt::format("corner_noise_fraction must be in (0, 1) (got {})", corner_noise_fraction));
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
  if (!(exposure_min_change >= 0) || !std::isfinite(exposure_min_change))
    fail(fmt::format("exposure_min_change must be >= 0 (0: never compensated; got {})", exposure_min_change));
  if (!(anchor_blur_ratio >= 0 && anchor_blur_ratio <= 1))
    fail(fmt::format("anchor_blur_ratio must be in [0, 1] (0: no frame counts as blurred; got {})", anchor_blur_ratio));
  if (!(anchor_max_scale_change > 1) || !std::isfinite(anchor_max_scale_change))
    fail(fmt::format("anchor_max_scale_change must be > 1 (got {})", anchor_max_scale_change));
  if (!(anchor_min_texture_ratio >= 0 && anchor_min_texture_ratio < 1))
    fail(fmt::format("anchor_min_texture_ratio must be in [0, 1) (got {})", anchor_min_texture_ratio));
  if (anchor_max_iterations < 1) fail(fmt::format("anchor_max_iterations must be >= 1 (got {})", anchor_max_iterations));
  if (!(anchor_epsilon_px > 0) || !std::isfinite(anchor_epsilon_px))
    fail(fmt::format("anchor_epsilon_px must be > 0 (got {})", anchor_epsilon_px));
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

void CheckImage(const cv::Mat& image, int64_t index) {
  if (image.empty()) throw std::invalid_argument(fmt::format("frame {}: empty image", index));
  if (image.depth() != CV_8U && image.depth() != CV_16U)
    throw std::invalid_argument(
        fmt::format("frame {}: unsupported pixel type {} (expected 8- or 16-bit gray, BGR or BGRA)", index,
                    TypeName(image.type())));
  if (image.channels() != 1 && image.channels() != 3 && image.channels() != 4)
    throw std::invalid_argument(fmt::format("frame {}: unsupported pixel type {} (expected 1, 3 or 4 channels)",
                                            index, TypeName(image.type())));
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
  // The camera's noise, measured on every frame (a camera's gain follows the light): the detection's threshold and
  // the birth-patch alignment's correlation threshold follow it.
  st.noise_grey = ImageNoiseSigma(gray);
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

std::optional<Descriptor> Frontend::DescriptorIfDone(int64_t feature_id) const {
  for (const Track& t : impl_->tracks)
    if (t.id == feature_id) return t.descriptor;
  return std::nullopt;
}

std::vector<std::optional<Descriptor>> Frontend::DescribeTurned(std::span<const int64_t> ids,
                                                                std::span<const float> angles_deg) {
  Impl& m = *impl_;
  if (m.prev_pyramid.empty()) return {};
  std::vector<cv::Point2f> points;
  std::vector<size_t> live;  // index into ids of each point
  for (size_t i = 0; i < ids.size(); ++i)
    for (const Track& t : m.tracks)
      if (t.id == ids[i]) {
        points.push_back(t.uv);
        live.push_back(i);
        break;
      }
  std::vector<Descriptor> d;
  std::vector<char> ok;
  m.describer.DescribeTurned(m.prev_pyramid[0], points, angles_deg, &d, &ok);
  std::vector<std::optional<Descriptor>> out(angles_deg.size() * ids.size());
  for (size_t a = 0; a < angles_deg.size(); ++a)
    for (size_t k = 0; k < live.size(); ++k)
      if (ok[a * points.size() + k]) out[a * ids.size() + live[k]] = d[a * points.size() + k];
  return out;
}

void Frontend::DescribeOnly(const std::function<bool(int64_t)>& wanted) {
  Impl& m = *impl_;
  m.describe_only = true;
  m.listed.clear();
  for (const Track& t : m.tracks)
    if (wanted(t.id)) m.listed.insert(t.id);
}

void Frontend::DescribeEveryTrack() {
  impl_->describe_only = false;
  impl_->listed.clear();
}

int Frontend::DescribeMissing(std::span<const int64_t> ids) {
  Impl& m = *impl_;
  m.JoinDescription();
  if (m.prev_pyramid.empty() || ids.empty()) return 0;
  const std::unordered_set<int64_t> want(ids.begin(), ids.end());
  std::vector<size_t> which;
  std::vector<Look> looks;
  for (size_t i = 0; i < m.tracks.size(); ++i)
    if (!m.tracks[i].descriptor && want.count(m.tracks[i].id)) {
      which.push_back(i);
      looks.push_back(m.LookOf(m.tracks[i], m.prev_pyramid[0], m.tracks[i].uv));
    }
  if (which.empty()) return 0;
  std::vector<Descriptor> d;
  std::vector<char> ok;
  DescribeLooks(m.describer, looks, &d, &ok);
  int n = 0;
  for (size_t k = 0; k < which.size(); ++k)
    if (ok[k]) {
      m.SetDescriptor(&m.tracks[which[k]], d[k], looks[k].from_birth);
      ++n;
    }
  return n;
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
  impl_->blurred_run = 0;
  impl_->listed.clear();
}

size_t Frontend::NumTracks() const { return impl_->tracks.size(); }
int64_t Frontend::NextFeatureId() const { return impl_->next_id; }
void Frontend::ReserveIdsBelow(int64_t next) { impl_->next_id = std::max(impl_->next_id, next); }
const FrontendOptions& Frontend::options() const { return impl_->options; }

}  // namespace mcslam::frontend
