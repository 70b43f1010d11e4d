#include "apps/options_json.h"

#include <stdexcept>
#include <string>

#include <fmt/format.h>

// Each options struct listed field by field, once: the same list writes and reads it. Enumerations by name.
namespace mcslam::geometry {
NLOHMANN_JSON_SERIALIZE_ENUM(EssentialMethod, {{EssentialMethod::kEightPoint, "8point"},
                                               {EssentialMethod::kFivePointOpenCV, "5point"}})
}  // namespace mcslam::geometry

namespace mcslam::slam {
NLOHMANN_JSON_SERIALIZE_ENUM(RandomMode, {{RandomMode::kTable, "table"}, {RandomMode::kFresh, "fresh"}})
NLOHMANN_JSON_SERIALIZE_ENUM(PoseTrackerOptions::Pivot, {{PoseTrackerOptions::Pivot::kCentroid, "centroid"},
                                                         {PoseTrackerOptions::Pivot::kOrigin, "origin"}})
NLOHMANN_JSON_SERIALIZE_ENUM(PoseMethod, {{PoseMethod::kMonteCarlo, "mc"}, {PoseMethod::kPnp, "pnp"}})
NLOHMANN_JSON_SERIALIZE_ENUM(StructureMethod, {{StructureMethod::kMonteCarlo, "mc"},
                                               {StructureMethod::kBundleAdjustment, "ba"}})

NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(PoseTrackerOptions, hypotheses, seed, random, sigma_rot_deg,
                                                sigma_rot_motion_scale, sigma_trans_floor_m, sigma_trans_scale,
                                                translation_prior_steps,
                                                inlier_threshold_px, max_distance_px, min_points, min_inliers,
                                                min_inlier_ratio, keyframe_min_inlier_ratio, pivot, rounds, round_shrink,
                                                retry_rot_scale, retry_max_residual_ratio,
                                                retry_max_residual_fraction, retry_min_typical_fraction)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(InitOptions, min_median_motion_deg, min_nonrotational_motion_px, min_common_features, min_inliers,
                                                min_points, min_shared_fraction, min_count_floor, min_window_frames,
                                                min_median_parallax_deg, max_relative_depth_noise, ambiguity_chi2,
                                                method, ransac_threshold_px, refine_window, refine_huber_px,
                                                settle_parallax_deg, settle_step, settle_max_frames,
                                                pose_frames_before_reference, self_calibrate, calibration_min_z,
                                                calibration_min_shift_px, calibration_min_half_share,
                                                calibration_min_half_z)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(MappingOptions, min_track_frames, min_parallax_deg,
                                                max_relative_depth_noise, max_noise_parallax_deg, starving_inliers,
                                                starving_min_track_frames,
                                                starving_parallax_deg, max_reprojection_px, retriangulate_after_frames,
                                                history_frames, adjust, adjust_threshold_px, candidate_threshold_px,
                                                samples, window, sigma_scale, sigma_floor_rel_depth, max_distance_px,
                                                local_ba_keyframes, local_ba_loss_sigmas, local_ba_min_loss_px,
                                                local_ba_min_step_of_depth, local_ba_function_tolerance, local_ba_async, merge_revisited_points)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(PoseSmootherOptions, alpha, predict_frames)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(KnownMapOptions, tracker, smoother)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(SystemOptions, pose_method, structure_method, ba_iterations,
                                                ba_fixed_keyframes, tracker, init, mapping, smoother,
                                                sigma_trans_floor_rel_depth, seed, relocalise_min_inliers,
                                                rotation_only, rotation_only_min_tracks, rotation_only_min_ratio,
                                                rotation_only_over_weak_pose, rotation_only_keep_turn_over_a_jump,
                                                bridge, bridge_join_waits_over_a_jump,
                                                bridge_wait_placed_by_map_tracks, restart_min_lost_frames,
                                                pose_lost_frames_when_found)
}  // namespace mcslam::slam

namespace mcslam::frontend {
NLOHMANN_JSON_SERIALIZE_ENUM(FrontendOptions::AnchorMismatch, {{FrontendOptions::AnchorMismatch::kAuto, "auto"},
                                                               {FrontendOptions::AnchorMismatch::kDrop, "drop"},
                                                               {FrontendOptions::AnchorMismatch::kReanchor, "reanchor"}})
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(
    FrontendOptions, max_features, cell_size_px, max_new_per_cell, quality_level, corner_noise_margin,
    corner_noise_fraction, min_distance_px, min_cells,
    block_size, border_px, pyramid_levels, retry_pyramid_levels, window_px, jolt_recovery, jolt_min_shift_px,
    jolt_min_failed_fraction, max_iterations, epsilon_px, min_eigen_threshold, max_forward_backward_px,
    max_patch_error, exposure_min_change, track_border_px, anchor_every, anchor_patch_px, anchor_min_correlation, anchor_max_shift_px,
    anchor_mismatch, anchor_auto_reanchor_fraction, anchor_blur_ratio, anchor_max_scale_change, anchor_min_texture_ratio,
    anchor_max_iterations, anchor_epsilon_px,
    use_kalman_prediction, kalman_accel_sigma_px, kalman_measurement_sigma_px, init_velocity_radius_px,
    descriptor_size_px, describe_async, descriptor_refresh_frames, remap_window_px, remap_max_candidates,
    remap_max_distance, remap_ratio)
}  // namespace mcslam::frontend

namespace mcslam::apps {

namespace {

// Every field given must read back as given: nlohmann reads an enumeration's name that the tables above do not
// know as its first value, and a number where a bool is expected as a bool; both are refused here, naming the field.
void CheckReadBack(const nlohmann::json& given, const nlohmann::json& back, const std::string& path) {
  for (const auto& [key, value] : given.items()) {
    const std::string name = path.empty() ? key : path + "." + key;
    if (!back.contains(key)) throw std::invalid_argument(fmt::format("{}: no such option", name));
    if (value.is_object()) {
      CheckReadBack(value, back[key], name);
    } else if (back[key] != value) {
      throw std::invalid_argument(fmt::format("{} = {}: not a valid value", name, value.dump()));
    }
  }
}

template <typename T>
void Read(const nlohmann::json& j, T* options, const char* what) {
  if (!j.is_object()) throw std::invalid_argument(fmt::format("{} options: an object is expected, got {}", what, j.dump()));
  // The fields not given keep their values: what `options` holds, patched with `j` (the macros above would
  // fill a missing field with its default instead).
  nlohmann::json merged = *options;
  merged.merge_patch(j);
  T read = *options;
  try {
    from_json(merged, read);
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(fmt::format("{} options: {}", what, e.what()));
  }
  try {
    CheckReadBack(j, nlohmann::json(read), "");
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("{} options: {}", what, e.what()));
  }
  *options = read;
}

}  // namespace

nlohmann::json ToJson(const slam::SystemOptions& options) { return options; }
nlohmann::json ToJson(const frontend::FrontendOptions& options) { return options; }
nlohmann::json ToJson(const slam::KnownMapOptions& options) { return options; }
void FromJson(const nlohmann::json& j, slam::SystemOptions* options) { Read(j, options, "system"); }
void FromJson(const nlohmann::json& j, frontend::FrontendOptions* options) { Read(j, options, "front end"); }
void FromJson(const nlohmann::json& j, slam::KnownMapOptions* options) { Read(j, options, "known map"); }

nlohmann::json OverlayChanges(nlohmann::json base, const nlohmann::json& defaults, const nlohmann::json& given) {
  if (!given.is_object()) return given != defaults ? given : base;
  if (!base.is_object()) base = nlohmann::json::object();
  for (const auto& [key, value] : given.items()) {
    const nlohmann::json d = defaults.is_object() && defaults.contains(key) ? defaults[key] : nlohmann::json();
    if (value.is_object())
      base[key] = OverlayChanges(base.contains(key) ? base[key] : nlohmann::json::object(), d, value);
    else if (value != d)
      base[key] = value;
  }
  return base;
}

}  // namespace mcslam::apps
