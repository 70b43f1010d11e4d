#pragma once
// Internal to the io layer (datasets.cc, dataset_layouts.cc): what opening a dataset's folder shares, and the
// openers of each dataset layout. Not part of the public io API.
#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <map>
#include <optional>
#include <regex>
#include <stdexcept>
#include <system_error>
#include <vector>

#include "io/camera_io.h"
#include "io/datasets.h"
#include "io/image_source.h"
#include "io/text_util.h"

namespace mcslam::io::detail {
namespace fs = std::filesystem;

// The P<cam> line of a KITTI calib.txt as a camera (dataset_layouts.cc).
PinholeCamera ReadKittiCalib(const std::string& path, int cam, const cv::Size& size);



inline bool IsFile(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}
inline bool IsDir(const fs::path& p) {
  std::error_code ec;
  return fs::is_directory(p, ec);
}

inline bool HasImageFile(const fs::path& dir) {
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
    if (IsImageFileName(it->path().filename().string())) return true;
  return false;
}

// "webcam:3" -> 3.
inline std::optional<int> WebcamIndex(const std::string& path) {
  static const std::regex re(R"(webcam:(\d{1,4}))");
  std::smatch m;
  if (std::regex_match(path, m, re)) return std::stoi(m[1].str());
  return std::nullopt;
}

inline double KindDefaultFps(DatasetKind kind) { return kind == DatasetKind::kKitti ? 10.0 : 30.0; }

inline double Fps(const DatasetOptions& options, DatasetKind kind) {
  return options.fps > 0 ? options.fps : KindDefaultFps(kind);
}

// Nanoseconds to seconds without going through a double of ~1e18 (which would lose the last digits).
inline double NanosecondsToSeconds(int64_t ns) {
  constexpr int64_t kNsPerS = 1'000'000'000;
  return static_cast<double>(ns / kNsPerS) + static_cast<double>(ns % kNsPerS) * 1e-9;
}

// The size that cameras without one in their file take: the frames'.
inline cv::Size RequireImageSize(ImageSource& source, const std::string& path) {
  const std::optional<cv::Size> size = source.ImageSize();
  if (!size)
    throw std::runtime_error(fmt::format(
        "{}: cannot read any of the first frames, so the image size (needed for the camera) is unknown", path));
  return *size;
}

// "fx fy cx cy [k1 k2 p1 p2 [k3]]" given inline (the text of --camera): the numbers, or nullopt when the text
// is not 4, 8 or 9 numbers.
inline std::optional<std::vector<double>> InlineCameraNumbers(const std::string& text) {
  const auto tok = detail::SplitWhitespace(text);
  if (tok.size() != 4 && tok.size() != 8 && tok.size() != 9) return std::nullopt;
  std::vector<double> v;
  for (auto t : tok) {
    double x = 0;
    if (!detail::TryParseDouble(t, &x)) return std::nullopt;
    v.push_back(x);
  }
  return v;
}

// A camera from 'fx fy cx cy [k1 k2 p1 p2 [k3]]' (4, 8 or 9 numbers; the missing distortion terms are 0) and
// the image size; PinholeCamera::Check's std::invalid_argument when the numbers make no camera. The text
// camera file and the numbers given inline to --camera both come here.
inline PinholeCamera CameraFromNumbers(const std::vector<double>& v, int width, int height) {
  double n[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
  std::copy_n(v.begin(), std::min<size_t>(v.size(), 9), n);
  PinholeCamera camera(n[0], n[1], n[2], n[3], width, height, Distortion{n[4], n[5], n[6], n[7], n[8]});
  camera.Check();
  return camera;
}

// The first data line of a text file has 12 numbers (or "P<k>:" and 12): a KITTI calib.txt.
inline bool LooksLikeKittiCalib(const std::string& path) {
  LineReader r(path);
  std::string line;
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    const auto tok = detail::SplitWhitespace(line);
    return tok.size() == 12 || (tok.size() == 13 && !tok[0].empty() && tok[0].back() == ':');
  }
  return false;
}

inline PinholeCamera ReadCameraFile(const std::string& path, ImageSource& source, const std::string& dataset_path) {
  const std::string ext = Lower(fs::path(path).extension().string());
  if (ext == ".yaml" || ext == ".yml") return ReadCameraYaml(path);
  detail::RequireRegularFileIfPresent(path);
  if (!IsFile(path)) {
    const std::optional<std::vector<double>> v = InlineCameraNumbers(path);
    if (!v)
      throw std::runtime_error(fmt::format(
          "camera '{}': no such file, nor 'fx fy cx cy [k1 k2 p1 p2 [k3]]' given inline (4, 8 or 9 numbers)", path));
    for (double x : *v)
      if (!std::isfinite(x)) throw std::runtime_error(fmt::format("camera '{}': {} is not finite", path, x));
    const cv::Size size = RequireImageSize(source, dataset_path);
    try {
      return CameraFromNumbers(*v, size.width, size.height);
    } catch (const std::invalid_argument& e) {
      throw std::runtime_error(fmt::format("camera '{}': {}", path, e.what()));
    }
  }
  const cv::Size size = RequireImageSize(source, dataset_path);
  // A KITTI calib.txt: its P0 line (the left grey camera; a KITTI folder given as the input picks P0 or P2 by
  // its images).
  if (LooksLikeKittiCalib(path)) return ReadKittiCalib(path, 0, size);
  return ReadCameraText(path, size.width, size.height);
}

// Frames of a list, in order; the Dataset's frames are its source's frames.
inline std::unique_ptr<ImageListSource> MakeList(std::vector<std::string> paths, std::vector<double> stamps,
                                          const std::string& description) {
  return std::make_unique<ImageListSource>(std::move(paths), std::move(stamps), description);
}

// Ground truth that holds one pose per frame, in frame order: restamped with the frames' stamps.
inline void SetPerFrameGroundTruth(Dataset* d, const std::vector<Pose>& poses, const std::vector<double>& frame_stamps) {
  Trajectory gt;
  for (size_t i = 0; i < poses.size() && i < frame_stamps.size(); ++i) {
    gt.stamps_s.push_back(frame_stamps[i]);
    gt.world_from_cam.push_back(poses[i]);
    d->ground_truth_frames.push_back(static_cast<int64_t>(i));
  }
  gt.has_stamps = true;
  d->ground_truth = std::move(gt);
}

inline void SetSampledGroundTruth(Dataset* d, const Trajectory& samples, const std::vector<double>& frame_stamps,
                           double max_dt_s, const std::string& gt_path) {
  std::vector<int64_t> used;
  Trajectory gt = SampleTrajectoryAt(samples, frame_stamps, max_dt_s, &used);
  if (gt.empty()) {
    d->notes.push_back(
        fmt::format("{}: no ground-truth sample within {} s of any frame; no ground truth", gt_path, max_dt_s));
    return;
  }
  if (gt.size() < frame_stamps.size())
    d->notes.push_back(fmt::format("{}: {} of {} frames have ground truth (the others have no sample within {} s)",
                                   gt_path, gt.size(), frame_stamps.size(), max_dt_s));
  d->ground_truth = std::move(gt);
  d->ground_truth_frames = std::move(used);
}


// Each layout's opener fills the dataset's source, camera (when own_camera) and ground truth (dataset_layouts.cc).
void OpenKitti(Dataset* d, const DatasetOptions& options, bool own_camera);
void OpenTum(Dataset* d, const DatasetOptions& options, bool own_camera);
void OpenEuroc(Dataset* d, const DatasetOptions& options, bool own_camera);
void OpenSevenScenes(Dataset* d, const DatasetOptions& options, bool own_camera);
void OpenSynthetic(Dataset* d, const DatasetOptions& options, bool own_camera);

}  // namespace mcslam::io::detail
