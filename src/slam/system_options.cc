// The System's options: their names on the command line and their checks (system_options.h).
#include "slam/system_options.h"

#include <cmath>

#include <stdexcept>
#include <string>

#include <fmt/format.h>

namespace mcslam::slam {

namespace {

void Fail(const std::string& what) { throw std::invalid_argument(what); }

}  // namespace

PoseMethod ParsePoseMethod(const std::string& name) {
  if (name == "mc") return PoseMethod::kMonteCarlo;
  if (name == "pnp") return PoseMethod::kPnp;
  throw std::invalid_argument(fmt::format("pose method must be 'mc' or 'pnp', got '{}'", name));
}

StructureMethod ParseStructureMethod(const std::string& name) {
  if (name == "mc") return StructureMethod::kMonteCarlo;
  if (name == "ba") return StructureMethod::kBundleAdjustment;
  throw std::invalid_argument(fmt::format("structure method must be 'mc' or 'ba', got '{}'", name));
}

void InitOptions::Check() const {
  if (!(min_median_motion_deg > 0 && min_median_motion_deg < 90))
    Fail(fmt::format("init: min_median_motion_deg must be in (0, 90), got {}", min_median_motion_deg));
  if (!(min_nonrotational_motion_px >= 0 && std::isfinite(min_nonrotational_motion_px)))
    Fail(fmt::format("init: min_nonrotational_motion_px must be >= 0, got {}", min_nonrotational_motion_px));
  if (!(max_relative_depth_noise > 0)) Fail(fmt::format("init: max_relative_depth_noise must be > 0, got {}", max_relative_depth_noise));
  if (!(ambiguity_chi2 >= 0)) Fail(fmt::format("init: ambiguity_chi2 must be >= 0, got {}", ambiguity_chi2));
  if (min_common_features < 8) Fail(fmt::format("init: min_common_features must be >= 8, got {}", min_common_features));
  if (min_inliers < 8) Fail(fmt::format("init: min_inliers must be >= 8, got {}", min_inliers));
  if (min_points < 3) Fail(fmt::format("init: min_points must be >= 3, got {}", min_points));
  if (!(min_shared_fraction > 0 && min_shared_fraction <= 1))
    Fail(fmt::format("init: min_shared_fraction must be in (0, 1], got {}", min_shared_fraction));
  if (min_window_frames < 2) Fail(fmt::format("init: min_window_frames must be >= 2, got {}", min_window_frames));
  if (min_count_floor < 8) Fail(fmt::format("init: min_count_floor must be >= 8, got {}", min_count_floor));
  if (!(min_median_parallax_deg >= 0)) Fail(fmt::format("init: min_median_parallax_deg must be >= 0, got {}", min_median_parallax_deg));
  if (!(ransac_threshold_px > 0)) Fail(fmt::format("init: ransac_threshold_px must be > 0, got {}", ransac_threshold_px));
  if (!(settle_parallax_deg >= 0 && settle_parallax_deg < 90))
    Fail(fmt::format("init: settle_parallax_deg must be in [0, 90), got {}", settle_parallax_deg));
  if (settle_max_frames < 3) Fail(fmt::format("init: settle_max_frames must be >= 3, got {}", settle_max_frames));
  if (!(settle_step > 1)) Fail(fmt::format("init: settle_step must be > 1, got {}", settle_step));
  if (!(calibration_min_z > 0)) Fail(fmt::format("init: calibration_min_z must be > 0, got {}", calibration_min_z));
  if (!(calibration_min_shift_px >= 0))
    Fail(fmt::format("init: calibration_min_shift_px must be >= 0, got {}", calibration_min_shift_px));
  if (!(calibration_min_half_share >= 0 && calibration_min_half_share <= 1))
    Fail(fmt::format("init: calibration_min_half_share must be in [0, 1], got {}", calibration_min_half_share));
  if (!(calibration_min_half_z >= 0))
    Fail(fmt::format("init: calibration_min_half_z must be >= 0, got {}", calibration_min_half_z));
}

void MappingOptions::Check() const {
  if (history_frames < 1) Fail(fmt::format("mapping: history_frames must be >= 1, got {}", history_frames));
  if (local_ba_keyframes < 0 || local_ba_keyframes == 1 || local_ba_keyframes > 64)
    Fail(fmt::format("mapping: local_ba_keyframes must be 0 (off) or in [2, 64], got {}", local_ba_keyframes));
  if (!(local_ba_loss_sigmas > 0 && local_ba_loss_sigmas <= 100))
    Fail(fmt::format("mapping: local_ba_loss_sigmas must be in (0, 100], got {}", local_ba_loss_sigmas));
  if (!(local_ba_min_loss_px > 0 && local_ba_min_loss_px <= 100))
    Fail(fmt::format("mapping: local_ba_min_loss_px must be in (0, 100], got {}", local_ba_min_loss_px));
  if (!(local_ba_min_step_of_depth >= 0 && local_ba_min_step_of_depth <= 1))
    Fail(fmt::format("mapping: local_ba_min_step_of_depth must be in [0, 1], got {}", local_ba_min_step_of_depth));
  if (!(local_ba_function_tolerance >= 0 && local_ba_function_tolerance < 1))
    Fail(fmt::format("mapping: local_ba_function_tolerance must be in [0, 1), got {}", local_ba_function_tolerance));
  if (retriangulate_after_frames < 1)
    Fail(fmt::format("mapping: retriangulate_after_frames must be >= 1, got {}", retriangulate_after_frames));
  if (min_track_frames < 2) Fail(fmt::format("mapping: min_track_frames must be >= 2, got {}", min_track_frames));
  if (!(min_parallax_deg >= 0)) Fail(fmt::format("mapping: min_parallax_deg must be >= 0, got {}", min_parallax_deg));
  if (!(max_relative_depth_noise > 0))
    Fail(fmt::format("mapping: max_relative_depth_noise must be > 0, got {}", max_relative_depth_noise));
  if (!(max_noise_parallax_deg >= 0 && max_noise_parallax_deg < 90))
    Fail(fmt::format("mapping: max_noise_parallax_deg must be in [0, 90), got {}", max_noise_parallax_deg));
  if (starving_inliers < 0) Fail(fmt::format("mapping: starving_inliers must be >= 0, got {}", starving_inliers));
  if (starving_min_track_frames < 2)
    Fail(fmt::format("mapping: starving_min_track_frames must be >= 2, got {}", starving_min_track_frames));
  if (!(starving_parallax_deg >= 0))
    Fail(fmt::format("mapping: starving_parallax_deg must be >= 0, got {}", starving_parallax_deg));
  if (!(max_reprojection_px > 0)) Fail(fmt::format("mapping: max_reprojection_px must be > 0, got {}", max_reprojection_px));
  if (!(adjust_threshold_px > 0)) Fail(fmt::format("mapping: adjust_threshold_px must be > 0, got {}", adjust_threshold_px));
  if (!(candidate_threshold_px >= 0))
    Fail(fmt::format("mapping: candidate_threshold_px must be >= 0, got {}", candidate_threshold_px));
  if (samples < 1) Fail(fmt::format("mapping: samples must be >= 1, got {}", samples));
  if (window < 2) Fail(fmt::format("mapping: window must be >= 2 keyframes, got {}", window));
  if (!(sigma_scale >= 0)) Fail(fmt::format("mapping: sigma_scale must be >= 0, got {}", sigma_scale));
  if (!(sigma_floor_rel_depth > 0)) Fail(fmt::format("mapping: sigma_floor_rel_depth must be > 0, got {}", sigma_floor_rel_depth));
  if (!(max_distance_px > 0 && max_distance_px <= 1e6))
    Fail(fmt::format("mapping: max_distance_px must be in (0, 1e6], got {}", max_distance_px));
}

void SystemOptions::Check() const {
  if (ba_iterations < 1) Fail(fmt::format("ba_iterations must be >= 1, got {}", ba_iterations));
  if (ba_fixed_keyframes < 1) Fail(fmt::format("ba_fixed_keyframes must be >= 1, got {}", ba_fixed_keyframes));
  if (rotation_only_min_tracks < 3)
    Fail(fmt::format("rotation_only_min_tracks must be >= 3, got {}", rotation_only_min_tracks));
  if (!(rotation_only_min_ratio > 0 && rotation_only_min_ratio <= 1))
    Fail(fmt::format("rotation_only_min_ratio must be in (0, 1], got {}", rotation_only_min_ratio));
  if (restart_min_lost_frames < 0)
    Fail(fmt::format("restart_min_lost_frames must be >= 0 (0: never), got {}", restart_min_lost_frames));
  if (relocalise_min_inliers < 6)
    Fail(fmt::format("relocalise_min_inliers must be >= 6, got {}", relocalise_min_inliers));
  tracker.Check();
  init.Check();
  mapping.Check();
  smoother.Check();
  if (!(sigma_trans_floor_rel_depth > 0))
    Fail(fmt::format("sigma_trans_floor_rel_depth must be > 0, got {}", sigma_trans_floor_rel_depth));
}

}  // namespace mcslam::slam
