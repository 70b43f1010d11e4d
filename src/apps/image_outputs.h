#pragma once
// What a run on pixels shows while and after it runs: the progress line, the AR overlay video and the top view
// of the trajectory.
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <spdlog/spdlog.h>

#include "core/camera.h"
#include "core/median.h"
#include "frontend/frontend.h"
#include "slam/map.h"
#include "slam/system.h"

namespace mcslam::apps {
// ---- progress --------------------------------------------------------------------------------------------

// A carriage-return line on an interactive terminal, plain log lines every few seconds otherwise.
class Progress {
 public:
  explicit Progress(std::optional<int64_t> total) : total_(total), interactive_(isatty(fileno(stderr)) != 0) {}
  void Update(int64_t frames, int64_t index, int tracked, int lost, size_t map_points, double fps, bool force = false) {
    const auto now = std::chrono::steady_clock::now();
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
  std::chrono::steady_clock::time_point last_{};
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
  // The camera the cube is drawn with: the map's (its k1 may be self-calibrated during the run).
  void SetCamera(const PinholeCamera& camera) { camera_ = camera; }
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
                  const std::vector<Eigen::Vector3d>& estimate, const std::vector<std::string>& caption);

}  // namespace mcslam::apps
