#include "apps/image_job.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <tuple>
#include <unordered_map>
#include <unordered_set>

#include <Eigen/Eigenvalues>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <spdlog/spdlog.h>

#include "apps/options.h"
#include "apps/slam_job.h"
#include "core/median.h"
#include "eval/trajectory_eval.h"
#include "io/datasets.h"
#include "io/ply.h"
#include "io/trajectory_io.h"
#include "pipeline/visual_slam.h"

namespace mcslam::apps {

namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }


bool AllDigits(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// ---- per-frame bookkeeping -------------------------------------------------------------------------------

struct FrameRow {
  int64_t index = 0;
  double stamp_s = 0;
  std::string name;
  bool skipped = false;
  std::string error;  // why skipped
  frontend::FrameStats fe;
  int features = 0, lost_tracks = 0;
  // Relocalisation in this frame: tried (after a lost or skipped frame), matches to map points, PnP inliers
  // (0: no pose found).
  bool reloc_tried = false;
  int reloc_matches = 0, reloc_inliers = 0;
  double reloc_ms = 0;
  double decode_ms = 0, frame_ms = 0;
  double backend_ms = 0;     // System::Process, wall time
  bool before_init = false;  // the back end had no map when this frame came: its time is initialisation's
};

struct Stage {
  std::vector<double> ms;
  void Add(double v) {
    if (v > 0 && std::isfinite(v)) ms.push_back(v);
  }
};

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
  return j;
}

nlohmann::json StatsJson(const eval::ErrorStats& s) {
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  return {{"count", s.count}, {"rmse", num(s.rmse)}, {"mean", num(s.mean)}, {"median", num(s.median)}, {"max", num(s.max)}};
}

// ---- progress --------------------------------------------------------------------------------------------

// A carriage-return line on an interactive terminal, plain log lines every few seconds otherwise.
class Progress {
 public:
  explicit Progress(std::optional<int64_t> total) : total_(total), interactive_(isatty(fileno(stderr)) != 0) {}
  void Update(int64_t frames, int64_t index, int tracked, int lost, size_t map_points, double fps, bool force = false) {
    const auto now = Clock::now();
    const double since = std::chrono::duration<double>(now - last_).count();
    if (!force && since < (interactive_ ? 0.1 : 5.0)) return;
    last_ = now;
    const std::string total = total_ ? fmt::format("/{}", *total_) : "";
    const std::string line = fmt::format("frame {}{} ({} done): tracked {} lost {} map {} points, {:.1f} fps", index,
                                         total, frames, tracked, lost, map_points, fps);
    if (interactive_) {
      fmt::print(stderr, "\r{}\033[K", line);
      std::fflush(stderr);
      dirty_ = true;
    } else {
      spdlog::info("{}", line);
    }
  }
  // Before a log line: the carriage-return line is cleared so that the two do not mix.
  void Clear() {
    if (!dirty_) return;
    fmt::print(stderr, "\r\033[K");
    std::fflush(stderr);
    dirty_ = false;
  }

 private:
  std::optional<int64_t> total_;
  bool interactive_;
  bool dirty_ = false;
  Clock::time_point last_{};
};

// ---- AR overlay ------------------------------------------------------------------------------------------

// The frames with the tracked features and a cube anchored in the map, drawn with the smoothed pose.
class Overlay {
 public:
  Overlay(const std::string& path, const PinholeCamera& camera, double fps) : camera_(camera), path_(path) {
    writer_.open(path, cv::VideoWriter::fourcc('m', 'p', '4', 'v'), fps, cv::Size(camera.width, camera.height), true);
    if (!writer_.isOpened())
      throw std::runtime_error(fmt::format("--overlay {}: cannot open a video writer (mp4v, {}x{}, {:.3g} fps) there",
                                           path, camera.width, camera.height, fps));
  }
  // The cube sits at the median of the first map points; its side is 0.3 times the median distance of the
  // points from there (small against the part of the scene the camera looked at first).
  void Anchor(const std::vector<Eigen::Vector3d>& points) {
    if (points.size() < 3 || anchored_) return;
    Eigen::Vector3d centre;
    for (int a = 0; a < 3; ++a) {
      std::vector<double> c;
      for (const Eigen::Vector3d& p : points) c.push_back(p[a]);
      centre[a] = UpperMedian(std::move(c));
    }
    std::vector<double> d;
    for (const Eigen::Vector3d& p : points) d.push_back((p - centre).norm());
    const double half = 0.15 * UpperMedian(std::move(d));
    for (int i = 0; i < 8; ++i)
      corners_[i] = centre + half * Eigen::Vector3d(i & 1 ? 1 : -1, i & 2 ? 1 : -1, i & 4 ? 1 : -1);
    anchored_ = true;
  }
  void Write(const cv::Mat& image, const frontend::FrameResult& fe, const slam::Map& map,
             const slam::FrameReport* report) {
    cv::Mat canvas;
    if (image.depth() != CV_8U) {
      double lo = 0, hi = 0;
      cv::minMaxLoc(image.reshape(1), &lo, &hi);
      image.convertTo(canvas, CV_8U, hi > 0 ? 255.0 / hi : 1.0);
    } else {
      canvas = image;
    }
    if (canvas.channels() == 1)
      cv::cvtColor(canvas, canvas, cv::COLOR_GRAY2BGR);
    else if (canvas.channels() == 4)
      cv::cvtColor(canvas, canvas, cv::COLOR_BGRA2BGR);
    else
      canvas = canvas.clone();
    for (const frontend::TrackedFeature& f : fe.features) {
      const slam::MapPoint* p = map.Find(f.feature_id);
      const bool in_map = p && p->state != slam::PointState::kRemoved;
      const cv::Scalar colour = f.remapped ? cv::Scalar(255, 0, 255) : in_map ? cv::Scalar(0, 220, 0) : cv::Scalar(0, 200, 255);
      cv::circle(canvas, cv::Point2d(f.uv_px.x(), f.uv_px.y()), 3, colour, 1, cv::LINE_AA);
    }
    std::string status = report ? slam::ToString(report->status) : "?";
    if (report && report->has_pose && anchored_) DrawCube(&canvas, report->smoothed_cam_from_world);
    cv::putText(canvas, fmt::format("frame {}  {}  {} features", fe.index, status, fe.features.size()),
                cv::Point(10, 24), cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(0, 0, 0), 3, cv::LINE_AA);
    cv::putText(canvas, fmt::format("frame {}  {}  {} features", fe.index, status, fe.features.size()),
                cv::Point(10, 24), cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
    writer_.write(canvas);
    ++frames_;
  }
  int frames() const { return frames_; }

 private:
  void DrawCube(cv::Mat* canvas, const Pose& cam_from_world) const {
    static constexpr int kEdges[12][2] = {{0, 1}, {2, 3}, {4, 5}, {6, 7}, {0, 2}, {1, 3},
                                          {4, 6}, {5, 7}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
    std::array<std::optional<cv::Point2d>, 8> uv;
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector3d c = cam_from_world * corners_[i];
      Eigen::Vector2d px;
      // Corners behind (or nearly at) the camera leave their edges out rather than wrap around.
      if (c.z() > 1e-3 && camera_.Project(c, &px) && px.allFinite() && px.cwiseAbs().maxCoeff() < 1e5)
        uv[i] = cv::Point2d(px.x(), px.y());
    }
    for (int e = 0; e < 12; ++e) {
      const auto& a = uv[kEdges[e][0]];
      const auto& b = uv[kEdges[e][1]];
      if (a && b) cv::line(*canvas, *a, *b, e < 4 ? cv::Scalar(255, 80, 0) : cv::Scalar(0, 0, 255), 2, cv::LINE_AA);
    }
  }

  PinholeCamera camera_;
  std::string path_;
  cv::VideoWriter writer_;
  std::array<Eigen::Vector3d, 8> corners_{};
  bool anchored_ = false;
  int frames_ = 0;
};

// ---- top view plot ---------------------------------------------------------------------------------------

// The estimate (aligned into the ground truth's world when there is one) against the ground truth, seen
// along the least-spread direction of the reference path (from above, for a car or a hand-held survey).
void WriteTopView(const std::string& path, const std::vector<Eigen::Vector3d>& reference,
                  const std::vector<Eigen::Vector3d>& estimate, const std::vector<std::string>& caption) {
  const std::vector<Eigen::Vector3d>& basis_points = reference.size() >= 2 ? reference : estimate;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : basis_points) mean += p;
  mean /= std::max<double>(1.0, static_cast<double>(basis_points.size()));
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& p : basis_points) cov += (p - mean) * (p - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  // Eigenvalues ascending: the two largest span the view.
  const Eigen::Vector3d e1 = eig.eigenvectors().col(2), e2 = eig.eigenvectors().col(1);
  auto to2d = [&](const Eigen::Vector3d& p) { return Eigen::Vector2d((p - mean).dot(e1), (p - mean).dot(e2)); };
  Eigen::Vector2d lo(std::numeric_limits<double>::max(), std::numeric_limits<double>::max()), hi = -lo;
  for (const auto* set : {&reference, &estimate})
    for (const Eigen::Vector3d& p : *set) {
      const Eigen::Vector2d q = to2d(p);
      lo = lo.cwiseMin(q), hi = hi.cwiseMax(q);
    }
  const int W = 900, H = 900, margin = 70;
  cv::Mat canvas(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  if (!(hi.array() >= lo.array()).all()) lo = hi = Eigen::Vector2d::Zero();
  const Eigen::Vector2d span = (hi - lo).cwiseMax(1e-9);
  const double scale = std::min((W - 2.0 * margin) / span.x(), (H - 2.0 * margin - 60) / span.y());
  const Eigen::Vector2d centre = 0.5 * (lo + hi);
  auto px = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector2d q = to2d(p) - centre;
    return cv::Point2d(W / 2.0 + scale * q.x(), (H + 60) / 2.0 - scale * q.y());
  };
  auto polyline = [&](const std::vector<Eigen::Vector3d>& pts, const cv::Scalar& colour) {
    for (size_t i = 1; i < pts.size(); ++i) cv::line(canvas, px(pts[i - 1]), px(pts[i]), colour, 2, cv::LINE_AA);
    for (const Eigen::Vector3d& p : pts) cv::circle(canvas, px(p), 2, colour, cv::FILLED, cv::LINE_AA);
    if (!pts.empty()) cv::circle(canvas, px(pts.front()), 7, colour, 2, cv::LINE_AA);
  };
  polyline(reference, cv::Scalar(60, 160, 0));
  polyline(estimate, cv::Scalar(0, 0, 220));
  // Scale bar: the largest power of ten (times 1, 2 or 5) that fits in a fifth of the width.
  const double target = (W - 2.0 * margin) / 5.0 / scale;
  double bar = std::pow(10.0, std::floor(std::log10(std::max(target, 1e-9))));
  for (double m : {5.0, 2.0})
    if (bar * m <= target) {
      bar *= m;
      break;
    }
  const cv::Point2d b0(margin, H - 25.0), b1(margin + bar * scale, H - 25.0);
  cv::line(canvas, b0, b1, cv::Scalar(0, 0, 0), 2);
  cv::putText(canvas, fmt::format("{:g} m", bar), b1 + cv::Point2d(10, 5), cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  int y = 24;
  for (const std::string& line : caption) {
    cv::putText(canvas, line, cv::Point(12, y), cv::FONT_HERSHEY_SIMPLEX, 0.55, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    y += 22;
  }
  if (!reference.empty())
    cv::putText(canvas, "ground truth", cv::Point(W - 260, H - 42), cv::FONT_HERSHEY_SIMPLEX, 0.55,
                cv::Scalar(60, 160, 0), 2, cv::LINE_AA);
  cv::putText(canvas, reference.empty() ? "estimate" : "estimate (Sim(3)-aligned)", cv::Point(W - 260, H - 20),
              cv::FONT_HERSHEY_SIMPLEX, 0.55, cv::Scalar(0, 0, 220), 2, cv::LINE_AA);
  if (!cv::imwrite(path, canvas)) throw std::runtime_error(fmt::format("--plot {}: cannot write the image", path));
}

// ---- outputs ---------------------------------------------------------------------------------------------

void WriteFramesCsv(const std::string& path, const std::vector<FrameRow>& rows,
                    const std::vector<slam::FrameReport>& reports, const std::map<int64_t, size_t>& report_of_index,
                    const std::map<int64_t, const eval::FrameError*>& error_of_index) {
  std::ofstream f(path);
  if (!f) throw std::runtime_error(fmt::format("cannot write '{}'", path));
  f << "index,stamp,status,keyframe,init,scored,inliers,map_points,new_points,adjusted,removed,reproj_mean_px,"
       "reproj_median_px,track_ms,map_ms,adjust_ms,init_ms,trans_err_m,rot_err_deg,features,fe_tracked,fe_detected,"
       "fe_lost,fe_lost_status,fe_lost_forward_backward,fe_lost_patch_error,fe_lost_outside,fe_lost_anchor,fe_anchored,"
       "fe_reanchored,fe_anchor_shift_px,fe_retried,fe_recovered,"
       "fe_remap_requests,fe_remapped,fe_remap_refused_id,fe_remap_outside,fe_remap_no_candidate,fe_remap_no_match,"
       "fe_remap_over_budget,fe_refreshed,fe_jolt_recovered,decode_ms,backend_ms,fe_convert_ms,fe_pyramid_ms,fe_track_ms,fe_anchor_ms,fe_detect_ms,"
       "fe_remap_ms,fe_describe_ms,fe_describe_wait_ms,fe_total_ms,frame_ms,note\n";
  auto clean = [](std::string s) {
    for (char& c : s)
      if (c == ',' || c == '\n' || c == '\r') c = ';';
    return s;
  };
  for (const FrameRow& row : rows) {
    if (row.skipped) {
      f << fmt::format("{},{:.9f},skipped,0,0,0,0,0,0,0,0,,,,,,,,,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,{:.3f},,,,,,,,,,,{:.3f},{}\n", row.index,
                       row.stamp_s, row.decode_ms, row.frame_ms, clean(row.name + ": " + row.error));
      continue;
    }
    auto it = report_of_index.find(row.index);
    if (it == report_of_index.end()) continue;  // interrupted between the front end and the back end
    const slam::FrameReport& r = reports[it->second];
    std::string te, re;
    if (auto e = error_of_index.find(row.index); r.has_pose && e != error_of_index.end())
      te = fmt::format("{:.6g}", e->second->trans_err_m), re = fmt::format("{:.6g}", e->second->rot_err_deg);
    const frontend::FrameStats& s = row.fe;
    f << fmt::format(
        "{},{:.9f},{},{},{},{},{},{},{},{},{},{:.4f},{:.4f},{:.3f},{:.3f},{:.3f},{:.3f},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.4f},{},{},{},{},{},{},{},{},{},{},{},{:.3f},{:.3f},"
        "{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{:.3f},{}\n",
        r.index, r.stamp_s, slam::ToString(r.status), int(r.keyframe), int(r.initialisation), r.scored, r.inliers,
        r.map_points, r.new_points, r.adjusted, r.removed, r.reproj_mean_px, r.reproj_median_px, r.track_ms, r.map_ms,
        r.adjust_ms, r.init_ms, te, re, row.features, s.tracked, s.detected, row.lost_tracks, s.lost_status, s.lost_forward_backward,
        s.lost_patch_error, s.lost_outside, s.lost_anchor, s.anchored, s.reanchored, s.mean_anchor_shift_px, s.retried, s.recovered, s.remap_requests, s.remapped, s.remap_refused_id,
        s.remap_outside, s.remap_no_candidate, s.remap_no_match, s.remap_over_budget, s.refreshed, s.jolt_recovered, row.decode_ms, row.backend_ms, s.convert_ms, s.pyramid_ms, s.track_ms, s.anchor_ms, s.detect_ms, s.remap_ms, s.describe_ms,
        s.describe_wait_ms, s.total_ms, row.frame_ms, clean(r.note));
  }
  if (!f) throw std::runtime_error(fmt::format("error while writing '{}'", path));
}

}  // namespace

// ---- options ---------------------------------------------------------------------------------------------

void ImageJobOptions::Check() const {
  try {
    io::ParseDatasetKind(dataset);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("--dataset: {}", e.what()));
  }
  if (format != "tum" && format != "kitti")
    throw std::invalid_argument(fmt::format("--format must be tum or kitti, got '{}'", format));
  if (start < 0) throw std::invalid_argument(fmt::format("--start must be >= 0, got {}", start));
  if (end >= 0 && end < start)
    throw std::invalid_argument(fmt::format("--end {} is before --start {}", end, start));
  if (end < -1) throw std::invalid_argument(fmt::format("--end must be >= 0 (or -1: to the end), got {}", end));
  if (!(fps >= 0) || !std::isfinite(fps)) throw std::invalid_argument(fmt::format("--fps must be >= 0, got {}", fps));
  if (!overlay_path.empty() && Lower(fs::path(overlay_path).extension().string()) != ".mp4")
    throw std::invalid_argument(fmt::format("--overlay {}: the overlay is an .mp4 file (mp4v)", overlay_path));
  if (!plot_path.empty() && !cv::haveImageWriter(plot_path))
    throw std::invalid_argument(fmt::format("--plot {}: not an image file name OpenCV can write (use .png)", plot_path));
  try {
    frontend.Check();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("front end: {}", e.what()));
  }
}

void AddImageJobFlags(CLI::App* cmd, ImageJobOptions* o) {
  cmd->add_option("--dataset", o->dataset,
                  "Input kind: auto, folder (images), video, webcam, kitti, tum, euroc, 7scenes, synthetic (auto: from the "
                  "content; a folder with observations.txt is run as observations)")
      ->capture_default_str();
  cmd->add_option("--camera", o->camera_path,
                  "Camera replacing the dataset's: a YAML file (ORB-SLAM or mcslam style), a text file with the line "
                  "'fx fy cx cy [k1 k2 p1 p2 [k3]]', a KITTI calib.txt (its P0 line), or those numbers given inline "
                  "in quotes (image size from the frames)");
  cmd->add_option("--gt", o->gt_path, "Ground truth replacing the dataset's (TUM, KITTI or EuRoC file, world_from_cam)");
  cmd->add_option("--format", o->format, "Trajectory format: tum (trajectory.txt) or kitti (also trajectory_kitti.txt + times)")
      ->check(CLI::IsMember({"tum", "kitti"}))
      ->capture_default_str();
  cmd->add_option("--overlay", o->overlay_path, "AR overlay video (.mp4): tracked features and a cube in the map");
  cmd->add_option("--plot", o->plot_path, "Top view of the trajectory against the ground truth (.png)");
  cmd->add_option("--start", o->start, "First frame to process (index in the source)")->capture_default_str();
  cmd->add_option("--end", o->end, "Last frame to process, inclusive (-1: to the end)")->capture_default_str();
  cmd->add_option("--fps", o->fps, "Frame rate for the stamps of sources without their own (0: the source's)")
      ->capture_default_str();
  cmd->add_option("--max-features", o->frontend.max_features, "Front end: most tracks at once")->capture_default_str();
  cmd->add_flag("--no-relocalise{false}", o->relocalise,
                "Once lost, only the last pose is searched around (default: the features are also matched to the map "
                "by their descriptors, and a pose from those restarts the tracking)");
  cmd->add_option("--descriptor-refresh-frames", o->frontend.descriptor_refresh_frames,
                  "Front end: a track is described again once its descriptor is this many frames old, so that a lost "
                  "map point is matched with how it looked when last seen (0: birth descriptors only)")
      ->check(NonNegative())
      ->capture_default_str();
  cmd->add_flag("--no-jolt-recovery{false}", o->frontend.jolt_recovery,
                "Front end: do not retry the tracks LK lost from where the image's measured global shift puts them");
  cmd->add_option("--anchor-every", o->frontend.anchor_every,
                  "Front end: frames between alignments of each track with the patch it was born with (0: off)")
      ->capture_default_str();
  cmd->add_option("--anchor-patch-px", o->frontend.anchor_patch_px, "Front end: side of the patch a track keeps from its birth")
      ->capture_default_str();
  cmd->add_option("--anchor-min-correlation", o->frontend.anchor_min_correlation,
                  "Front end: a track whose birth patch correlates less than this (normalised, affine) is a mismatch")
      ->capture_default_str();
  cmd->add_option_function<std::string>(
         "--anchor-mismatch",
         [o](const std::string& v) {
           using AM = frontend::FrontendOptions::AnchorMismatch;
           o->frontend.anchor_mismatch = v == "drop" ? AM::kDrop : v == "reanchor" ? AM::kReanchor : AM::kAuto;
         },
         "Front end: a track that no longer matches its birth patch is dropped (drop), or keeps going with a new "
         "patch (reanchor), or, per frame, the one or the other by how many tracks mismatch (auto) [default: auto]")
      ->check(CLI::IsMember({"auto", "drop", "reanchor"}));
}

bool IsImageInput(const std::string& input, const ImageJobOptions& options) {
  if (Lower(options.dataset) != "auto") return true;
  std::error_code ec;
  return !fs::is_regular_file(fs::path(input) / "observations.txt", ec);
}

// ---- the job ---------------------------------------------------------------------------------------------

ImageJobSummary RunImageJob(const std::string& input, const std::string& out_dir, const slam::SystemOptions& system_in,
                            const std::string& backend, const ImageJobOptions& options) {
  options.Check();
  // ---- everything that can be checked before any work ----
  io::DatasetOptions dopt;
  dopt.kind = io::ParseDatasetKind(options.dataset);
  std::error_code ec;
  if (dopt.kind == io::DatasetKind::kAuto && AllDigits(input) && !fs::exists(input, ec))
    dopt.kind = io::DatasetKind::kWebcam;  // "mcslam run 0": the first webcam
  dopt.camera_path = options.camera_path;
  dopt.fps = options.fps;
  // --camera: a file, or the numbers inline ("fx fy cx cy ..."); io::OpenDataset tells which, or says neither.
  if (!options.camera_path.empty() && fs::is_directory(options.camera_path, ec))
    throw std::runtime_error(fmt::format("--camera {}: a folder, not a camera file", options.camera_path));
  if (!options.gt_path.empty() && !fs::exists(options.gt_path, ec))
    throw std::runtime_error(fmt::format("--gt {}: the file does not exist", options.gt_path));
  if (!options.gt_path.empty() && !fs::is_regular_file(options.gt_path, ec))
    throw std::runtime_error(fmt::format("--gt {}: is not a regular file (a folder, pipe or device)", options.gt_path));
  io::Dataset data = io::OpenDataset(input, dopt);
  for (const std::string& note : data.notes) spdlog::warn("{}", note);
  if (!data.camera)
    throw std::runtime_error(fmt::format(
        "{}: no camera: give one with --camera FILE (YAML, or a text line 'fx fy cx cy [k1 k2 p1 p2 [k3]]')",
        data.source->Description()));
  const PinholeCamera camera = *data.camera;
  camera.Check();
  if (!data.image_size)
    spdlog::warn("{}: the image size is not known before reading; frames of another size than the camera's {}x{} "
                 "will be skipped",
                 data.source->Description(), camera.width, camera.height);

  std::optional<io::Trajectory> gt = data.ground_truth;
  std::string gt_origin = gt ? fmt::format("{} ({})", data.path, io::ToString(data.kind)) : "";
  if (!options.gt_path.empty()) {
    gt = io::ReadTrajectory(options.gt_path);
    gt_origin = options.gt_path;
    if (gt->empty()) throw std::runtime_error(fmt::format("--gt {}: holds no pose", options.gt_path));
  }

  const std::optional<int64_t> count = data.source->FrameCount();
  // A video's frame count is the container's word and may be off; only lists of images are exact.
  const bool exact_count = count && data.kind != io::DatasetKind::kVideo && data.kind != io::DatasetKind::kWebcam;
  if (exact_count && options.start >= *count)
    throw std::invalid_argument(
        fmt::format("--start {} is out of range: {} has {} frames (0..{})", options.start, data.source->Description(),
                    *count, *count - 1));
  if (exact_count && options.end >= *count)
    throw std::invalid_argument(fmt::format("--end {} is out of range: {} has {} frames (0..{})", options.end,
                                            data.source->Description(), *count, *count - 1));

  slam::SystemOptions sys_opts = system_in;
  sys_opts.Check();
  auto pose_kernel = MakePoseKernelFor(backend);
  auto point_kernel = MakePointKernelFor(backend);

  fs::create_directories(out_dir, ec);
  if (!fs::is_directory(out_dir, ec)) throw std::runtime_error(fmt::format("--out {}: cannot create the folder", out_dir));
  const fs::path out(out_dir);
  // The overlay and the plot may go elsewhere: their folders are made now, so that the end of a long run
  // cannot fail for want of one.
  for (const std::string& path : {options.overlay_path, options.plot_path})
    if (const fs::path parent = fs::path(path).parent_path(); !path.empty() && !parent.empty())
      fs::create_directories(parent, ec);

  double video_fps = 30.0;
  if (options.fps > 0) {
    video_fps = options.fps;
  } else if (data.kind == io::DatasetKind::kKitti) {
    video_fps = 10.0;
  } else if (auto* vs = dynamic_cast<io::VideoSource*>(data.source.get()); vs && vs->fps() > 0) {
    video_fps = vs->fps();
  }
  std::unique_ptr<Overlay> overlay;
  if (!options.overlay_path.empty()) overlay = std::make_unique<Overlay>(options.overlay_path, camera, video_fps);

  pipeline::VisualSlamOptions vs_opts;
  vs_opts.frontend = options.frontend;
  vs_opts.frontend.describe_async = true;  // SIFT of the new tracks runs while the back end estimates the pose
  vs_opts.system = sys_opts;
  vs_opts.relocalise = options.relocalise;
  const frontend::FrontendOptions& fe_opts = vs_opts.frontend;
  pipeline::VisualSlam slam(camera, vs_opts, std::move(pose_kernel), std::move(point_kernel));
  const slam::System& system = slam.system();
  if (options.gt_scale) {
    if (!gt) throw std::invalid_argument("--gt-scale needs a ground truth: the dataset has none and no --gt was given");
    slam.system().SetBaselineOracle(BaselineOracle(*gt));
  }

  const int64_t last = options.end >= 0 ? options.end : (count ? *count - 1 : -1);
  spdlog::info("{}: {} camera {} ({}); frames {}..{}; {} hypotheses/frame, {} samples/point, backend {}; "
               "initialisation after a median feature motion of {:.2f} deg and a median parallax of {:.1f} deg; rotation "
               "samples {:.2f} deg; new points from {:.1f} deg of parallax",
               data.source->Description(), io::ToString(data.kind), camera.ToString(), data.camera_origin,
               options.start, last >= 0 ? fmt::format("{}", last) : std::string("end"), sys_opts.tracker.hypotheses,
               sys_opts.mapping.samples, backend, sys_opts.init.min_median_motion_deg,
               sys_opts.init.min_median_parallax_deg, sys_opts.tracker.sigma_rot_deg, sys_opts.mapping.min_parallax_deg);
  if (gt) spdlog::info("ground truth: {} poses from {}", gt->size(), gt_origin);

  InstallInterruptHandler();
  std::vector<FrameRow> rows;
  ReportLog log;
  std::vector<slam::FrameReport>& reports = log.reports;
  const std::map<int64_t, size_t>& report_of_index = log.index_of_frame;
  std::optional<int64_t> init_frame;
  std::string init_note, failure;
  nlohmann::json init_rejections = nlohmann::json::array();  // initialisations found and refused, and why
  int tracked = 0, lost = 0;
  bool was_lost = false;  // for the log: the last frame was lost
  int64_t frames_processed = 0, frames_read = 0;
  int64_t frames_decoded = 0;  // frames the source gave, from its first (before --start included)
  bool source_ended = false;   // the source ran out (not --end, an interrupt or a failure)
  Progress progress(last >= 0 ? std::optional<int64_t>(last) : std::nullopt);
  const RunClock clock;  // wall and process CPU time of the frames' processing
  const auto t_start = Clock::now();
  auto elapsed_s = [&] { return std::chrono::duration<double>(Clock::now() - t_start).count(); };

  try {
    io::Frame frame;
    while (!Interrupted()) {
      const auto t_frame = Clock::now();
      if (!data.source->Next(&frame)) {
        source_ended = true;
        break;
      }
      frames_decoded = frame.index + 1;
      const double decode_ms = MsSince(t_frame);
      if (frame.index < options.start) continue;
      if (options.end >= 0 && frame.index > options.end) break;
      ++frames_read;
      FrameRow row;
      row.index = frame.index;
      row.stamp_s = frame.stamp_s;
      row.name = frame.name;
      row.decode_ms = decode_ms;
      if (frame.ok() && (frame.image.cols != camera.width || frame.image.rows != camera.height))
        frame.error = fmt::format("the image is {}x{} but the camera is {}x{}", frame.image.cols, frame.image.rows,
                                  camera.width, camera.height),
        frame.image.release();
      if (!frame.ok()) {
        progress.Clear();
        spdlog::warn("frame {} ({}) skipped: {}", frame.index, frame.name, frame.error);
        row.skipped = true;
        slam.SkipFrame();
        row.error = frame.error;
        row.frame_ms = MsSince(t_frame);
        rows.push_back(std::move(row));
        continue;
      }

      pipeline::VisualSlamStep step;
      try {
        step = slam.Process(frame.image, frame.index, frame.stamp_s);
      } catch (const pipeline::UnusableFrame& e) {  // a pixel type the front end does not take: this frame only
        progress.Clear();
        spdlog::warn("frame {} ({}) skipped: {}", frame.index, frame.name, e.what());
        row.skipped = true;
        row.error = e.what();
        row.frame_ms = MsSince(t_frame);
        rows.push_back(std::move(row));
        continue;
      }
      const frontend::FrameResult& fr = step.frontend;
      row.fe = fr.stats;
      row.features = static_cast<int>(fr.features.size());
      row.lost_tracks = static_cast<int>(fr.lost.size());
      row.before_init = step.before_init;
      row.reloc_tried = step.reloc_tried;
      row.reloc_matches = step.reloc_matches;
      row.reloc_inliers = step.reloc_inliers;
      row.reloc_ms = step.reloc_ms;
      row.backend_ms = step.backend_ms;
      if (step.reloc_inliers > 0) {
        progress.Clear();
        spdlog::info("frame {}: relocalised from {} of {} features matched to the map", frame.index, row.reloc_inliers,
                     row.reloc_matches);
      }
      ++frames_processed;
      const slam::FrameReport* current = nullptr;
      for (const slam::FrameReport& r : step.reports) {
        if (const std::optional<slam::FrameStatus> replaced = log.Put(r)) {
          tracked -= *replaced == slam::FrameStatus::kTracked;
          lost -= *replaced == slam::FrameStatus::kLost;
        }
        tracked += r.status == slam::FrameStatus::kTracked;
        lost += r.status == slam::FrameStatus::kLost;
        if (r.init_rejected) init_rejections.push_back({{"frame", r.index}, {"why", r.note}});
        if (r.initialisation && !r.note.empty() && !init_frame) {
          init_frame = r.index;
          init_note = r.note;
          progress.Clear();
          spdlog::info("frame {}: {}", r.index, r.note);
        }
      }
      if (auto it = report_of_index.find(frame.index); it != report_of_index.end()) current = &reports[it->second];
      if (current) {
        const bool is_lost = current->status == slam::FrameStatus::kLost;
        if (is_lost && !was_lost) progress.Clear(), spdlog::warn("frame {} lost: {}", current->index, current->note);
        if (!is_lost && was_lost && current->status == slam::FrameStatus::kTracked)
          progress.Clear(), spdlog::info("frame {}: tracking resumed", current->index);
        was_lost = is_lost;
      }
      if (overlay) {
        if (init_frame) {
          std::vector<Eigen::Vector3d> pts;
          for (const slam::MapPoint& p : system.map().points())
            if (p.state != slam::PointState::kRemoved) pts.push_back(p.position_in_world);
          overlay->Anchor(pts);
        }
        overlay->Write(frame.image, fr, system.map(), current);
      }
      row.frame_ms = MsSince(t_frame);
      rows.push_back(std::move(row));
      progress.Update(frames_processed, frame.index, tracked, lost, system.map().points().size(),
                      frames_processed / std::max(elapsed_s(), 1e-9));
    }
  } catch (const std::exception& e) {
    failure = e.what();  // outputs first, then the error
  }
  const RunTimes times = clock.Elapsed();
  const double wall_s = times.wall_s;
  progress.Update(frames_processed, rows.empty() ? 0 : rows.back().index, tracked, lost, system.map().points().size(),
                  frames_processed / std::max(wall_s, 1e-9), true);
  progress.Clear();
  const bool interrupted = Interrupted();
  if (interrupted) spdlog::warn("interrupted: writing the {} frames done so far", rows.size());
  // A video that ends well before the frame count its header promises was cut off or is damaged: the run is
  // what it is, but it says so (log and report.json's notes) instead of passing for the whole video. Container
  // counts are estimates for some codecs: a few frames short (2 %, at least 2) is not reported.
  std::vector<std::string> notes = data.notes;
  if (source_ended && data.kind == io::DatasetKind::kVideo && count &&
      static_cast<double>(frames_decoded) < 0.98 * static_cast<double>(*count) - 2.0) {
    notes.push_back(fmt::format("{}: the video ended after {} of the {} frames its header promises (cut off or "
                                "damaged?); the run covers only those",
                                input, frames_decoded, *count));
    spdlog::warn("{}", notes.back());
  }
  if (frames_read == 0 && failure.empty() && !interrupted)
    failure = options.start > 0 ? fmt::format("--start {}: {} ended before that frame (no frame to process)",
                                              options.start, data.source->Description())
                                : fmt::format("{}: no frame to process", data.source->Description());

  // ---- outputs (whatever happened above, what was computed is written) ----
  // The trajectory, with the frame index of each pose.
  io::Trajectory traj, smooth;
  std::vector<int64_t> traj_frames;
  for (const slam::FrameReport& r : reports) {
    if (!r.has_pose) continue;
    traj.stamps_s.push_back(r.stamp_s), smooth.stamps_s.push_back(r.stamp_s);
    traj.world_from_cam.push_back(r.cam_from_world.Inverse());
    smooth.world_from_cam.push_back(r.smoothed_cam_from_world.Inverse());
    traj_frames.push_back(r.index);
  }
  io::WriteTum((out / "trajectory.txt").string(), traj);
  io::WriteTum((out / "trajectory_smoothed.txt").string(), smooth);
  if (options.format == "kitti")
    io::WriteKitti((out / "trajectory_kitti.txt").string(), traj, (out / "trajectory_kitti_times.txt").string());
  io::PointCloud cloud;
  for (const slam::MapPoint& p : system.map().points()) {
    if (p.state == slam::PointState::kRemoved) continue;
    cloud.points.push_back(p.position_in_world);
    cloud.ids.push_back(p.id);
  }
  io::WritePly((out / "map.ply").string(), cloud);

  std::optional<eval::TrajectoryErrors> errors;
  std::string eval_failure;
  if (gt && traj.size() >= 3) {
    // A ground truth without stamps (a KITTI poses file without times) pairs by frame index: pose i is frame
    // i of the source, so both sides carry the frame index as their stamp for the evaluation.
    io::Trajectory gt_eval = *gt, est_eval = traj;
    if (!gt->has_stamps) {
      for (size_t i = 0; i < gt_eval.size(); ++i) gt_eval.stamps_s[i] = static_cast<double>(i);
      for (size_t i = 0; i < est_eval.size(); ++i) est_eval.stamps_s[i] = static_cast<double>(traj_frames[i]);
      gt_eval.has_stamps = true;
    }
    try {
      errors = eval::EvaluateTrajectory(gt_eval, est_eval, {});
    } catch (const std::exception& e) {
      eval_failure = e.what();
      spdlog::warn("no evaluation against the ground truth: {}", eval_failure);
    }
  } else if (gt) {
    eval_failure = fmt::format("only {} posed frames (3 needed for a Sim(3) alignment)", traj.size());
  }
  std::map<int64_t, const eval::FrameError*> error_of_index;
  if (errors)
    for (const eval::FrameError& e : errors->frames) error_of_index[traj_frames[e.est_index]] = &e;
  WriteFramesCsv((out / "frames.csv").string(), rows, reports, report_of_index, error_of_index);

  // Counts and per-stage times.
  ImageJobSummary sum;
  sum.frames = frames_processed;
  sum.interrupted = interrupted;
  sum.initialised = system.initialised();
  Stage decode, fe_convert, fe_pyramid, fe_track, fe_anchor, fe_detect, fe_remap, fe_describe, fe_wait, fe_total, be_track, be_map,
      be_adjust, be_init, be_total, frame_total;
  int64_t remap_requests = 0, remapped = 0, remap_outside = 0, remap_no_candidate = 0, remap_no_match = 0,
          remap_over_budget = 0, remap_refused = 0, refreshed = 0;
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
    remap_refused += row.fe.remap_refused_id;
    refreshed += row.fe.refreshed;
    be_total.Add(row.backend_ms);
    // The System reports the time of its failed initialisation attempts on 'waiting' reports, which the
    // initialisation then replaces; the wall time of Process before the map exists is that time, all of it.
    if (row.before_init) be_init.Add(row.backend_ms);
    features_sum += row.features;
  }
  int64_t rotation_only = 0;  // of the tracked: posed by their turn about the last centre (the map out of view)
  for (const slam::FrameReport& r : reports) {
    rotation_only += r.rotation_only;
    sum.tracked += r.status == slam::FrameStatus::kTracked;
    sum.lost += r.status == slam::FrameStatus::kLost;
    sum.not_initialised += r.status == slam::FrameStatus::kWaitingForInit;
    sum.keyframes += r.keyframe;
    be_track.Add(r.track_ms), be_map.Add(r.map_ms), be_adjust.Add(r.adjust_ms);
  }
  sum.map_points = static_cast<int64_t>(cloud.points.size());
  sum.fps = frames_processed / std::max(wall_s, 1e-9);
  if (errors) sum.ate_rmse_m = errors->ate_m.rmse;

  nlohmann::json j;
  j["input"] = input;
  j["dataset"] = io::ToString(data.kind);
  j["source"] = data.source->Description();
  j["camera"] = {{"fx", camera.fx}, {"fy", camera.fy}, {"cx", camera.cx}, {"cy", camera.cy},
                 {"width", camera.width}, {"height", camera.height}, {"distorted", camera.HasDistortion()},
                 {"origin", data.camera_origin}};
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
                  {"init_min_median_parallax_deg", sys_opts.init.min_median_parallax_deg},
                  {"sigma_rot_deg", sys_opts.tracker.sigma_rot_deg},
                  {"new_point_min_parallax_deg", sys_opts.mapping.min_parallax_deg},
                  {"max_features", fe_opts.max_features},
                  {"describe_async", fe_opts.describe_async},
                  {"start", options.start},
                  {"end", options.end}};
  j["frames"] = frames_processed;
  j["frames_read"] = frames_read;
  j["skipped"] = sum.skipped;
  j["skipped_frames"] = skipped_frames;
  j["tracked"] = sum.tracked;
  j["lost"] = sum.lost;
  j["not_initialised"] = sum.not_initialised;
  j["keyframes"] = sum.keyframes;
  j["rotation_only"] = rotation_only;
  j["map_points"] = sum.map_points;
  j["initialised"] = sum.initialised;
  j["initialisation"] = init_frame ? nlohmann::json{{"frame", *init_frame}, {"note", init_note}} : nlohmann::json(nullptr);
  j["initialisation_rejections"] = init_rejections;
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
                   {"descriptors_refreshed", refreshed}};
  {
    // tried: frames after a lost or skipped one; pose_found: PnP found a pose; tracked: ... and the frame's
    // pose step succeeded from it.
    int64_t tried = 0, pose_found = 0, reloc_tracked = 0;
    Stage reloc_ms;
    for (const FrameRow& row : rows) {
      if (!row.reloc_tried) continue;
      ++tried;
      reloc_ms.Add(row.reloc_ms);
      if (row.reloc_inliers == 0) continue;
      ++pose_found;
      if (auto it = report_of_index.find(row.index);
          it != report_of_index.end() && reports[it->second].status == slam::FrameStatus::kTracked)
        ++reloc_tracked;
    }
    j["relocalisation"] = {{"enabled", options.relocalise},
                           {"tried", tried},
                           {"pose_found", pose_found},
                           {"tracked", reloc_tracked},
                           {"ms", StageJson(reloc_ms)}};
  }
  // Front end stages and back end stages, over the frames where each did some work (map and adjust run on
  // keyframes only, init before the map exists: the whole of System::Process then, the successful call too).
  j["stages_ms"] = {{"decode", StageJson(decode)},
                    {"frontend_total", StageJson(fe_total)},
                    {"frontend_convert", StageJson(fe_convert)},
                    {"frontend_pyramid", StageJson(fe_pyramid)},
                    {"frontend_track", StageJson(fe_track)},
                    {"frontend_anchor", StageJson(fe_anchor)},
                    {"frontend_detect", StageJson(fe_detect)},
                    {"frontend_remap", StageJson(fe_remap)},
                    {"frontend_describe", StageJson(fe_describe)},
                    {"frontend_describe_wait", StageJson(fe_wait)},
                    {"init", StageJson(be_init)},
                    {"track", StageJson(be_track)},
                    {"map", StageJson(be_map)},
                    {"adjust", StageJson(be_adjust)},
                    {"backend_total", StageJson(be_total)},
                    {"frame_total", StageJson(frame_total)}};
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
  if (overlay) overlay.reset();  // closes the file

  std::string line = fmt::format(
      "frames={} tracked={} lost={} not_initialised={} skipped={} keyframes={} map_points={} fps={:.2f}", sum.frames,
      sum.tracked, sum.lost, sum.not_initialised, sum.skipped, sum.keyframes, sum.map_points, sum.fps);
  if (errors)
    line += fmt::format(" ate_rmse={:.6g} ate_mean={:.6g} rot_mean_deg={:.6g} rpe_trans_rmse={:.6g} scale={:.6g}",
                        errors->ate_m.rmse, errors->ate_m.mean, errors->rot_deg.mean, errors->rpe_trans_m.rmse,
                        errors->alignment_result.gt_world_from_est_world.scale);
  line += RunTimesFields(times);
  fmt::print("{}\n", line);
  std::fflush(stdout);

  if (!failure.empty()) throw std::runtime_error(fmt::format("{} (outputs so far written to {})", failure, out_dir));
  if (interrupted) throw InterruptedError();
  if (!sum.initialised)
    throw ExitError(kExitNotInitialised, fmt::format(
        "the sequence never moved enough to initialise ({} frames; outputs written to {}): the features must move by a "
        "median of {:.2f} deg with a median parallax of {:.1f} deg between two frames (last: {})",
        frames_processed, out_dir, sys_opts.init.min_median_motion_deg, sys_opts.init.min_median_parallax_deg,
        reports.empty() ? std::string("no frame") : reports.back().note));
  return sum;
}

}  // namespace mcslam::apps
