#include "apps/run_report.h"

#include <algorithm>
#include <cmath>

#include <fstream>
#include <stdexcept>

#include <fmt/format.h>

#include "apps/image_run.h"
#include "apps/options.h"
#include "apps/options_json.h"
#include "core/median.h"
#include "io/ply.h"

namespace mcslam::apps {

nlohmann::json StageJson(const Stage& s) {
  nlohmann::json j;
  j["count"] = s.ms.size();
  if (s.ms.empty()) {
    j["median_ms"] = nullptr, j["mean_ms"] = nullptr;
    return j;
  }
  double sum = 0;
  for (double x : s.ms) sum += x;
  j["median_ms"] = UpperMedian(s.ms);
  j["mean_ms"] = sum / static_cast<double>(s.ms.size());
  j["p90_ms"] = Quantile(s.ms, 0.9);
  j["p99_ms"] = Quantile(s.ms, 0.99);
  j["max_ms"] = *std::max_element(s.ms.begin(), s.ms.end());
  return j;
}

std::string StageTable(const std::vector<std::pair<std::string, Stage>>& stages, int64_t frames, double wall_s) {
  std::string out = fmt::format("{:<24} {:>7} {:>9} {:>9} {:>9} {:>9}  (ms)\n", "stage", "frames", "median", "p90",
                                "p99", "max");
  const Stage* frontend = nullptr;
  const Stage* pose = nullptr;
  const Stage* frame = nullptr;
  for (const auto& [name, s] : stages) {
    if (name == "frontend_total") frontend = &s;
    if (name == "track") pose = &s;
    if (name == "frame_total") frame = &s;
    if (s.ms.empty()) {
      out += fmt::format("{:<24} {:>7}\n", name, 0);
      continue;
    }
    out += fmt::format("{:<24} {:>7} {:>9.3f} {:>9.3f} {:>9.3f} {:>9.3f}\n", name, s.ms.size(), UpperMedian(s.ms),
                       Quantile(s.ms, 0.9), Quantile(s.ms, 0.99), *std::max_element(s.ms.begin(), s.ms.end()));
  }
  out += fmt::format("throughput {:.2f} frames/s ({} frames in {:.3f} s)", frames / std::max(wall_s, 1e-9), frames,
                     wall_s);
  if (frame && !frame->ms.empty())
    out += fmt::format("; latency median {:.3f} ms, p99 {:.3f} ms", UpperMedian(frame->ms), Quantile(frame->ms, 0.99));
  if (frontend && pose && !frontend->ms.empty() && !pose->ms.empty())
    out += fmt::format("; front end / pose step {:.2f}", UpperMedian(frontend->ms) / UpperMedian(pose->ms));
  return out + "\n";
}

nlohmann::json SelfCalibrationJson(const slam::SelfCalibration& c) {
  if (!c.tried) return nullptr;
  return {{"accepted", c.accepted},         {"frame", c.frame},     {"k1_given", c.k1_given},
          {"k1_measured", c.k1_measured},   {"sigma_k1", c.sigma_k1}, {"z", c.z},
          {"corner_shift_px", c.corner_shift_px}, {"k1_halves", {c.k1_half[0], c.k1_half[1]}},
          {"sigma_k1_halves", {c.sigma_k1_half[0], c.sigma_k1_half[1]}}, {"min_half_share", c.min_half_share},
          {"max_half_share", c.max_half_share}, {"min_half_z", c.min_half_z},
          {"frames", c.frames}, {"points", c.points},
          {"observations", c.observations}, {"note", c.note}};
}

ExitError NotInitialisedError(const slam::InitOptions& init, const std::vector<slam::FrameReport>& reports,
                              int64_t frames, const std::string& out_dir) {
  const std::string motion_rule = fmt::format(
      "the features must move by a median of {:.2f} deg, or {:.1f} px that no turn of the camera explains, with a "
      "median parallax of {:.1f} deg",
      init.min_median_motion_deg, init.min_nonrotational_motion_px, init.min_median_parallax_deg);
  const slam::NotInitialisedSummary why = slam::WhyNotInitialised(reports, motion_rule);
  const std::string head = why.too_little_motion  ? "the sequence never moved enough to initialise"
                           : why.too_few_features ? "the first map was never made: too few features to track"
                                                  : "the first map was never made";
  return ExitError(kExitNotInitialised,
                   fmt::format("{} ({} frames; outputs written to {}): {}", head, frames, out_dir,
                               why.text.empty() ? motion_rule : why.text));
}

ReportCounts CountReports(const std::vector<slam::FrameReport>& reports) {
  ReportCounts c;
  for (const slam::FrameReport& r : reports) {
    c.tracked += r.status == slam::FrameStatus::kTracked;
    c.lost += r.status == slam::FrameStatus::kLost;
    c.not_initialised += r.status == slam::FrameStatus::kWaitingForInit;
    c.keyframes += r.keyframe;
    c.rotation_only += r.rotation_only;
    c.provisional += r.provisional;
    c.guessed_scale += r.guessed_scale();
    if (r.status == slam::FrameStatus::kWaitingForInit && r.init_wait != slam::InitWait::kNone)
      ++c.waiting_for_init[static_cast<size_t>(r.init_wait)];
  }
  return c;
}

void PutCounts(const ReportCounts& c, nlohmann::json* j) {
  (*j)["tracked"] = c.tracked;
  (*j)["lost"] = c.lost;
  (*j)["not_initialised"] = c.not_initialised;
  (*j)["keyframes"] = c.keyframes;
  (*j)["rotation_only"] = c.rotation_only;  // of the tracked: posed by their turn about the last centre
  (*j)["provisional"] = c.provisional;      // of the tracked: posed in a provisional map (a bridge over the unmapped)
  (*j)["guessed_scale"] = c.guessed_scale;  // of those: its provisional map never joined the map, its scale a guess
  // The frames waiting for a map, by what held each back (frames.csv's note says it per frame).
  nlohmann::json waiting = nlohmann::json::object();
  for (int k = 1; k < slam::kInitWaitReasons; ++k)
    waiting[slam::InitWaitName(static_cast<slam::InitWait>(k))] = c.waiting_for_init[static_cast<size_t>(k)];
  (*j)["waiting_for_init"] = waiting;
}

nlohmann::json StatsJson(const eval::ErrorStats& s) {
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  return {{"count", s.count}, {"rmse", num(s.rmse)}, {"mean", num(s.mean)}, {"median", num(s.median)}, {"max", num(s.max)}};
}

namespace {

// frames.csv's columns: the back end's, the front end's (empty on a run from observations), the note.
constexpr const char* kBackEndColumns =
    "index,stamp,status,keyframe,init,scored,inliers,map_points,new_points,adjusted,removed,reproj_mean_px,"
    "reproj_median_px,track_ms,map_ms,adjust_ms,init_ms,trans_err_m,rot_err_deg,score,sigma_tx,sigma_ty,sigma_tz,"
    "guessed_scale";
constexpr const char* kFrontEndColumns =
    "features,fe_tracked,fe_detected,"
    "fe_lost,fe_lost_status,fe_lost_forward_backward,fe_lost_patch_error,fe_lost_outside,fe_lost_anchor,fe_anchored,"
    "fe_reanchored,fe_anchor_shift_px,fe_retried,fe_recovered,"
    "fe_remap_requests,fe_remapped,fe_remap_refused_id,fe_remap_outside,fe_remap_no_candidate,fe_remap_no_match,"
    "fe_remap_over_budget,fe_remap_deferred,fe_refreshed,fe_jolt_recovered,fe_sharpness,fe_blurred,fe_exposure_gain,fe_noise_grey,"
    "decode_ms,backend_ms,fe_convert_ms,"
    "fe_pyramid_ms,fe_track_ms,fe_anchor_ms,fe_detect_ms,fe_remap_ms,fe_describe_ms,fe_describe_wait_ms,fe_total_ms,frame_ms";

// The cells of a frame the reader could not decode, column by column (so that they follow the column lists):
// its index and stamp, status "skipped", the decoding's and the whole frame's time; the counts 0; what was never
// measured (the other times, residuals, errors, scores, the pose's sigmas) empty.
std::string SkippedCells(const FrameRow& row) {
  const std::string columns = std::string(kBackEndColumns) + ',' + kFrontEndColumns;
  std::string out;
  size_t begin = 0;
  while (begin <= columns.size()) {
    const size_t end = std::min(columns.find(',', begin), columns.size());
    const std::string name = columns.substr(begin, end - begin);
    auto ends_with = [&](const std::string& suffix) {
      return name.size() >= suffix.size() && name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0;
    };
    if (!out.empty()) out += ',';
    if (name == "index")
      out += std::to_string(row.index);
    else if (name == "stamp")
      out += fmt::format("{:.9f}", row.stamp_s);
    else if (name == "status")
      out += "skipped";
    else if (name == "decode_ms")
      out += fmt::format("{:.3f}", row.decode_ms);
    else if (name == "frame_ms")
      out += fmt::format("{:.3f}", row.frame_ms);
    else if (!(ends_with("_ms") || name.starts_with("reproj_") || name.starts_with("sigma_") || name == "score" ||
               name == "trans_err_m" || name == "rot_err_deg" || name == "fe_sharpness" || name == "fe_exposure_gain" ||
               name == "fe_noise_grey"))
      out += '0';
    begin = end + 1;
  }
  return out;
}

std::string Clean(std::string s) {
  for (char& c : s)
    if (c == ',' || c == '\n' || c == '\r') c = ';';
  return s;
}

std::string BackEndCells(const slam::FrameReport& r, const std::map<int64_t, const eval::FrameError*>& error_of_index) {
  std::string te, re;
  if (auto e = error_of_index.find(r.index); r.has_pose && e != error_of_index.end())
    te = fmt::format("{:.6g}", e->second->trans_err_m), re = fmt::format("{:.6g}", e->second->rot_err_deg);
  return fmt::format("{},{:.9f},{},{},{},{},{},{},{},{},{},{:.4f},{:.4f},{:.3f},{:.3f},{:.3f},{:.3f},{},{},{:.6g},{:.6g},{:.6g},{:.6g},{}",
                     r.index, r.stamp_s, slam::ToString(r.status), int(r.keyframe), int(r.initialisation), r.scored,
                     r.inliers, r.map_points, r.new_points, r.adjusted, r.removed, r.reproj_mean_px,
                     r.reproj_median_px, r.track_ms, r.map_ms, r.adjust_ms, r.init_ms, te, re, r.score, r.sigma_t.x(),
                     r.sigma_t.y(), r.sigma_t.z(), int(r.guessed_scale()));
}

std::string FrontEndCells(const FrameRow& row) {
  const frontend::FrameStats& s = row.fe;
  return fmt::format(
      "{},{},{},{},{},{},{},{},{},{},{},{:.4f},{},{},{},{},{},{},{},{},{},{},{},{},{:.3f},{},{:.3f},{:.3f},{:.3f},{:.3f},"
      "{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f}",
      row.features, s.tracked, s.detected, row.lost_tracks, s.lost_status, s.lost_forward_backward, s.lost_patch_error,
      s.lost_outside, s.lost_anchor, s.anchored, s.reanchored, s.mean_anchor_shift_px, s.retried, s.recovered,
      s.remap_requests, s.remapped, s.remap_refused_id, s.remap_outside, s.remap_no_candidate, s.remap_no_match,
      s.remap_over_budget, s.remap_deferred, s.refreshed, s.jolt_recovered, s.anchor_sharpness, int(s.blurred),
      s.exposure_gain, s.noise_grey, row.decode_ms, row.backend_ms, s.convert_ms,
      s.pyramid_ms, s.track_ms, s.anchor_ms, s.detect_ms, s.remap_ms, s.describe_ms, s.describe_wait_ms, s.total_ms, row.frame_ms);
}

}  // namespace

namespace {

std::ofstream OpenFramesCsv(const std::string& path) {
  std::ofstream f(path);
  if (!f) throw std::runtime_error(fmt::format("cannot write '{}'", path));
  f << kBackEndColumns << ',' << kFrontEndColumns << ",note\n";
  return f;
}

void CloseFramesCsv(std::ofstream& f, const std::string& path) {
  f.close();
  if (!f) throw std::runtime_error(fmt::format("error while writing '{}'", path));
}

}  // namespace

void WriteFramesCsv(const std::string& path, const std::vector<slam::FrameReport>& reports,
                    const std::map<int64_t, size_t>& report_of_index,
                    const std::map<int64_t, const eval::FrameError*>& error_of_index, const std::vector<FrameRow>& rows) {
  std::ofstream f = OpenFramesCsv(path);
  for (const FrameRow& row : rows) {
    if (row.skipped) {
      // The counts 0, the times empty but the decoding's and the frame's; the note says why (the reader's
      // message names the file; otherwise the name is added).
      const std::string why = row.error.find(row.name) != std::string::npos ? row.error : row.name + ": " + row.error;
      f << SkippedCells(row) << ',' << Clean(why) << '\n';
      continue;
    }
    auto it = report_of_index.find(row.index);
    if (it == report_of_index.end()) continue;  // interrupted between the front end and the back end
    const slam::FrameReport& r = reports[it->second];
    f << BackEndCells(r, error_of_index) << ',' << FrontEndCells(row) << ',' << Clean(r.note) << '\n';
  }
  CloseFramesCsv(f, path);
}

void WriteFramesCsv(const std::string& path, const std::vector<slam::FrameReport>& reports,
                    const std::optional<eval::TrajectoryErrors>& errors) {
  // The trajectory the errors are of is the posed reports in order: its pose k is the k-th posed report's frame.
  std::map<int64_t, const eval::FrameError*> error_of_index;
  if (errors) {
    std::vector<int64_t> posed;
    for (const slam::FrameReport& r : reports)
      if (r.has_pose) posed.push_back(r.index);
    for (const eval::FrameError& e : errors->frames) error_of_index[posed[e.est_index]] = &e;
  }
  std::ofstream f = OpenFramesCsv(path);
  const std::string no_front_end(static_cast<size_t>(std::count(kFrontEndColumns, kFrontEndColumns + std::char_traits<char>::length(kFrontEndColumns), ',')), ',');
  for (const slam::FrameReport& r : reports)
    f << BackEndCells(r, error_of_index) << ',' << no_front_end << ',' << Clean(r.note) << '\n';
  CloseFramesCsv(f, path);
}

void ImageRun::WriteReport() {
  // Counts and per-stage times.
  sum.frames = frames_processed;
  sum.interrupted = interrupted;
  sum.initialised = vslam->system().made_a_map();
  sum.localised = vslam->system().localised();
  Stage decode, fe_convert, fe_pyramid, fe_track, fe_anchor, fe_detect, fe_remap, fe_describe, fe_wait, fe_total, be_track, be_map,
      be_adjust, be_adjust_points, be_local_ba, be_local_ba_wait, be_init, be_total, frame_total, reloc;
  int64_t remap_requests = 0, remapped = 0, remap_outside = 0, remap_no_candidate = 0, remap_no_match = 0,
          remap_over_budget = 0, remap_refused = 0, remap_deferred = 0, refreshed = 0, described_for_remap = 0,
          described_listed = 0, detected = 0;
  double features_sum = 0;
  nlohmann::json skipped_frames = nlohmann::json::array();
  for (const FrameRow& row : rows) {
    decode.Add(row.decode_ms);
    frame_total.Add(row.frame_ms);
    if (row.skipped) {
      ++sum.skipped;
      skipped_frames.push_back({{"index", row.index}, {"name", row.name}, {"error", row.error}});
      continue;
    }
    fe_convert.Add(row.fe.convert_ms), fe_pyramid.Add(row.fe.pyramid_ms), fe_track.Add(row.fe.track_ms);
    fe_anchor.Add(row.fe.anchor_ms);
    fe_detect.Add(row.fe.detect_ms), fe_remap.Add(row.fe.remap_ms), fe_describe.Add(row.fe.describe_ms);
    fe_wait.Add(row.fe.describe_wait_ms), fe_total.Add(row.fe.total_ms);
    remap_requests += row.fe.remap_requests, remapped += row.fe.remapped;
    remap_outside += row.fe.remap_outside, remap_no_candidate += row.fe.remap_no_candidate;
    remap_no_match += row.fe.remap_no_match, remap_over_budget += row.fe.remap_over_budget;
    remap_refused += row.fe.remap_refused_id, remap_deferred += row.fe.remap_deferred;
    refreshed += row.fe.refreshed, described_for_remap += row.fe.described_for_remap;
    described_listed += row.fe.described_listed, detected += row.fe.detected;
    be_total.Add(row.backend_ms);
    // The System reports the time of its failed initialisation attempts on 'waiting' reports, which the
    // initialisation then replaces; the wall time of Process before the map exists is that time, all of it.
    if (row.before_init) be_init.Add(row.backend_ms);
    features_sum += row.features;
  }
  const ReportCounts counts = CountReports(reports);
  sum.tracked = counts.tracked;
  sum.lost = counts.lost;
  sum.not_initialised = counts.not_initialised;
  sum.keyframes = counts.keyframes;
  for (const slam::FrameReport& r : reports) {
    be_track.Add(r.track_ms), be_map.Add(r.map_ms), be_adjust.Add(r.adjust_ms);
    if (r.local_ba) be_local_ba.Add(r.local_ba_ms), be_local_ba_wait.Add(r.local_ba_wait_ms);
    be_adjust_points.Add(r.adjust_points_ms);
  }
  sum.fps = frames_processed / std::max(times.wall_s, 1e-9);
  if (errors) sum.ate_rmse_m = errors->ate_m.rmse;

  nlohmann::json j;
  j["input"] = input;
  j["dataset"] = io::ToString(data.kind);
  j["source"] = data.source->Description();
  j["camera"] = {{"fx", camera.fx}, {"fy", camera.fy}, {"cx", camera.cx}, {"cy", camera.cy},
                 {"width", camera.width}, {"height", camera.height}, {"distorted", camera.HasDistortion()},
                 {"lens_model", ToString(camera.dist.model)},
                 {"origin", data.camera_origin},
                 // The frames as they came, and how many times they were halved to the size above (--max-megapixels).
                 {"input_width", input_camera.width}, {"input_height", input_camera.height},
                 {"halvings", halvings}};
  j["notes"] = notes;
  j["options"] = {{"backend", backend},
                  {"pose", sys_opts.pose_method == slam::PoseMethod::kPnp ? "pnp" : "mc"},
                  {"structure", sys_opts.structure_method == slam::StructureMethod::kBundleAdjustment ? "ba" : "mc"},
                  {"ba_iterations", sys_opts.ba_iterations},
                  {"hypotheses", sys_opts.tracker.hypotheses},
                  {"rounds", sys_opts.tracker.rounds},
                  {"seed", sys_opts.seed},
                  {"samples_per_point", sys_opts.mapping.samples},
                  {"init_min_median_motion_deg", sys_opts.init.min_median_motion_deg},
                  {"init_min_nonrotational_motion_px", sys_opts.init.min_nonrotational_motion_px},
                  {"init_min_median_parallax_deg", sys_opts.init.min_median_parallax_deg},
                  {"sigma_rot_deg", sys_opts.tracker.sigma_rot_deg},
                  {"new_point_min_parallax_deg", sys_opts.mapping.min_parallax_deg},
                  {"max_features", fe_opts.max_features},
                  {"describe_async", fe_opts.describe_async},
                  {"start", options.start},
                  {"end", options.end}};
  j["options"]["system"] = ToJson(sys_opts);  // every option: what the run did, from its report alone
  j["options"]["frontend"] = ToJson(fe_opts);
  // The run's own flags (what the input, its camera and ground truth were, and what was written): with the two
  // above, the command that reproduces the run.
  j["options"]["image"] = {{"dataset", options.dataset},       {"camera", options.camera_path},
                           {"gt", options.gt_path},            {"format", options.format},
                           {"fps", options.fps},               {"gt_scale", options.gt_scale},
                           {"relocalise", options.relocalise}, {"relocalise_turned", options.relocalise_turned},
                           {"pipelined", options.pipelined},   {"max_megapixels", options.max_megapixels},
                           {"describe_map_points_only", options.describe_map_points_only},
                           {"overlay", options.overlay_path},
                           {"plot", options.plot_path},        {"viewer", options.viewer}};
  if (!options.load_map_path.empty() || !options.save_map_path.empty()) {
    j["map_files"] = nlohmann::json::object();
    if (!options.load_map_path.empty()) j["map_files"]["loaded"] = options.load_map_path;
    if (map_saved) j["map_files"]["saved"] = options.save_map_path;
  }
  j["frames"] = frames_processed;
  j["frames_read"] = frames_read;
  j["skipped"] = sum.skipped;
  j["skipped_frames"] = skipped_frames;
  PutCounts(counts, &j);
  j["map_points"] = sum.map_points;
  j["initialised"] = sum.initialised;
  j["initialisation"] = init_frame ? nlohmann::json{{"frame", *init_frame}, {"note", init_note}} : nlohmann::json(nullptr);
  j["initialisation_rejections"] = init_rejections;
  j["depth_reversals"] = depth_reversals;
  j["map_restarts"] = map_restarts;
  int64_t merged_tracks = 0;
  for (const FrameRow& row : rows) merged_tracks += row.merged_tracks;
  j["revisits_merged"] = merged_tracks;  // new tracks that went on as an older map point (Mapper::RevisitedPoint)
  j["self_calibration"] = SelfCalibrationJson(vslam->system().self_calibration());
  j["interrupted"] = interrupted;
  AddRunTimes(times, &j);
  j["fps"] = sum.fps;
  j["frontend"] = {{"mean_features", frames_processed > 0 ? features_sum / frames_processed : 0.0},
                   {"remap_requests", remap_requests},
                   {"remapped", remapped},
                   {"remap_refused_id", remap_refused},
                   {"remap_outside", remap_outside},
                   {"remap_no_candidate", remap_no_candidate},
                   {"remap_no_match", remap_no_match},
                   {"remap_over_budget", remap_over_budget},
                   {"remap_deferred", remap_deferred},
                   {"descriptors_refreshed", refreshed},
                   {"new_tracks_described_for_remap", described_for_remap},
                   {"tracks_born", detected},
                   {"described_as_map_points", described_listed}};
  {
    // tried: frames after a lost or skipped one; pose_found: PnP found a pose; tracked: ... and the frame's
    // pose step succeeded from it.
    int64_t tried = 0, pose_found = 0, reloc_tracked = 0, turned = 0;
    for (const FrameRow& row : rows) {
      if (!row.reloc_tried) continue;
      ++tried;
      reloc.Add(row.reloc_ms);
      if (row.reloc_inliers == 0) continue;
      ++pose_found;
      turned += row.reloc_turned;
      if (auto it = report_of_index.find(row.index);
          it != report_of_index.end() && reports[it->second].status == slam::FrameStatus::kTracked)
        ++reloc_tracked;
    }
    j["relocalisation"] = {{"enabled", options.relocalise},
                           {"turned", options.relocalise_turned},
                           {"tried", tried},
                           {"pose_found", pose_found},
                           {"pose_found_turned", turned},
                           {"tracked", reloc_tracked},
                           {"ms", StageJson(reloc)}};
  }
  // Front end stages and back end stages, over the frames where each did some work (map and adjust run on
  // keyframes only, local_ba on those whose window was adjusted, init before the map exists: the whole of
  // System::Process then, the successful call too). local_ba_wait: what the next frame waited for a local
  // adjustment solved beside it (MappingOptions::local_ba_async).
  stages = {{"decode", decode},
            {"frontend_total", fe_total},
            {"frontend_convert", fe_convert},
            {"frontend_pyramid", fe_pyramid},
            {"frontend_track", fe_track},
            {"frontend_anchor", fe_anchor},
            {"frontend_detect", fe_detect},
            {"frontend_remap", fe_remap},
            {"frontend_describe", fe_describe},
            {"frontend_describe_wait", fe_wait},
            {"relocalise", reloc},
            {"init", be_init},
            {"track", be_track},
            {"map", be_map},
            {"adjust", be_adjust},
            {"adjust_points", be_adjust_points},
            {"local_ba", be_local_ba},
            {"local_ba_wait", be_local_ba_wait},
            {"backend_total", be_total},
            {"frame_total", frame_total}};
  j["stages_ms"] = nlohmann::json::object();
  for (const auto& [name, stage] : stages) j["stages_ms"][name] = StageJson(stage);
  if (errors) {
    j["ground_truth"] = {{"source", gt_origin},
                         {"poses", gt->size()},
                         {"matched", errors->matched()},
                         {"alignment", "sim3"},
                         {"scale", errors->alignment_result.gt_world_from_est_world.scale},
                         // Positions that do not fix the rotation about the path's main direction (eval.h): rot_deg
                         // then measures the alignment; rot_orient_deg does not depend on it.
                         {"rotation_ambiguous", errors->alignment_result.rotation_ambiguous},
                         {"lateral_spread_m", errors->alignment_result.lateral_spread_m},
                         {"path_length_m", errors->gt_path_length_m},
                         {"mirrored", errors->mirrored},
                         {"ate_m", StatsJson(errors->ate_m)},
                         {"rot_deg", StatsJson(errors->rot_deg)},
                         {"rot_orient_deg", StatsJson(errors->rot_orient_deg)},
                         {"rpe_delta", errors->rpe_delta},
                         {"rpe_trans_m", StatsJson(errors->rpe_trans_m)},
                         {"rpe_rot_deg", StatsJson(errors->rpe_rot_deg)}};
  } else if (gt) {
    j["ground_truth"] = {{"source", gt_origin}, {"poses", gt->size()}, {"error", eval_failure}};
  } else {
    j["ground_truth"] = nullptr;
  }
  j["error"] = failure.empty() ? nlohmann::json(nullptr) : nlohmann::json(failure);
  WriteReportJson((out / "report.json").string(), j);
}

void ImageRun::WritePlot() {
  if (!options.plot_path.empty()) {
    std::vector<Eigen::Vector3d> ref, est;
    std::vector<std::string> caption{fmt::format("{} ({} frames, {} tracked)", data.path, frames_processed, sum.tracked)};
    if (errors) {
      for (const eval::FrameError& e : errors->frames) ref.push_back(e.gt_position), est.push_back(e.est_position_aligned);
      caption.push_back(fmt::format("ATE (Sim3) RMSE {:.4g} m, mean {:.4g} m; rotation mean {:.3g} deg; scale {:.4g}",
                                    errors->ate_m.rmse, errors->ate_m.mean, errors->rot_deg.mean,
                                    errors->alignment_result.gt_world_from_est_world.scale));
    } else {
      for (const Pose& p : traj.world_from_cam) est.push_back(p.t);
      caption.push_back(gt ? "not aligned: " + eval_failure : "no ground truth: the estimate in its own frame");
    }
    WriteTopView(options.plot_path, ref, est, caption);
  }
}

}  // namespace mcslam::apps
