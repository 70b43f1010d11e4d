#include "io/datasets.h"

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
#include "io/text_util.h"

namespace mcslam::io {
namespace fs = std::filesystem;
namespace {

using detail::LineReader;

bool IsFile(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}
bool IsDir(const fs::path& p) {
  std::error_code ec;
  return fs::is_directory(p, ec);
}

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

bool HasImageFile(const fs::path& dir) {
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
    if (IsImageFileName(it->path().filename().string())) return true;
  return false;
}

// "webcam:3" -> 3.
std::optional<int> WebcamIndex(const std::string& path) {
  static const std::regex re(R"(webcam:(\d{1,4}))");
  std::smatch m;
  if (std::regex_match(path, m, re)) return std::stoi(m[1].str());
  return std::nullopt;
}

double KindDefaultFps(DatasetKind kind) { return kind == DatasetKind::kKitti ? 10.0 : 30.0; }

double Fps(const DatasetOptions& options, DatasetKind kind) {
  return options.fps > 0 ? options.fps : KindDefaultFps(kind);
}

// Nanoseconds to seconds without going through a double of ~1e18 (which would lose the last digits).
double NanosecondsToSeconds(int64_t ns) {
  constexpr int64_t kNsPerS = 1'000'000'000;
  return static_cast<double>(ns / kNsPerS) + static_cast<double>(ns % kNsPerS) * 1e-9;
}

// The size that cameras without one in their file take: the frames'.
cv::Size RequireImageSize(ImageSource& source, const std::string& path) {
  const std::optional<cv::Size> size = source.ImageSize();
  if (!size)
    throw std::runtime_error(fmt::format(
        "{}: cannot read any of the first frames, so the image size (needed for the camera) is unknown", path));
  return *size;
}

PinholeCamera ReadKittiCalib(const std::string& path, int cam, const cv::Size& size);

// "fx fy cx cy [k1 k2 p1 p2 [k3]]" given inline (the text of --camera): the numbers, or nullopt when the text
// is not 4, 8 or 9 numbers.
std::optional<std::vector<double>> InlineCameraNumbers(const std::string& text) {
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
PinholeCamera CameraFromNumbers(const std::vector<double>& v, int width, int height) {
  double n[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
  std::copy_n(v.begin(), std::min<size_t>(v.size(), 9), n);
  PinholeCamera camera(n[0], n[1], n[2], n[3], width, height, Distortion{n[4], n[5], n[6], n[7], n[8]});
  camera.Check();
  return camera;
}

// The first data line of a text file has 12 numbers (or "P<k>:" and 12): a KITTI calib.txt.
bool LooksLikeKittiCalib(const std::string& path) {
  LineReader r(path);
  std::string line;
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    const auto tok = detail::SplitWhitespace(line);
    return tok.size() == 12 || (tok.size() == 13 && !tok[0].empty() && tok[0].back() == ':');
  }
  return false;
}

PinholeCamera ReadCameraFile(const std::string& path, ImageSource& source, const std::string& dataset_path) {
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
std::unique_ptr<ImageListSource> MakeList(std::vector<std::string> paths, std::vector<double> stamps,
                                          const std::string& description) {
  return std::make_unique<ImageListSource>(std::move(paths), std::move(stamps), description);
}

// Ground truth that holds one pose per frame, in frame order: restamped with the frames' stamps.
void SetPerFrameGroundTruth(Dataset* d, const std::vector<Pose>& poses, const std::vector<double>& frame_stamps) {
  Trajectory gt;
  for (size_t i = 0; i < poses.size() && i < frame_stamps.size(); ++i) {
    gt.stamps_s.push_back(frame_stamps[i]);
    gt.world_from_cam.push_back(poses[i]);
    d->ground_truth_frames.push_back(static_cast<int64_t>(i));
  }
  gt.has_stamps = true;
  d->ground_truth = std::move(gt);
}

void SetSampledGroundTruth(Dataset* d, const Trajectory& samples, const std::vector<double>& frame_stamps,
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

// ---- image folder, video, webcam ------------------------------------------------------------------------

void OpenImages(Dataset* d, const DatasetOptions& options, bool own_camera) {
  ImageFolderOptions fo;
  fo.fps = Fps(options, DatasetKind::kImageFolder);
  fo.timestamps_path = options.timestamps_path;
  d->source = OpenImageFolder(d->path, fo);
  if (!own_camera) return;
  const fs::path dir(d->path);
  for (const char* name : {"camera.yaml", "camera.yml", "camera.txt"}) {
    if (IsFile(dir / name)) {
      d->camera = ReadCameraFile((dir / name).string(), *d->source, d->path);
      d->camera_origin = (dir / name).string();
      return;
    }
  }
}

// ---- KITTI ----------------------------------------------------------------------------------------------

// The P<cam> line of a KITTI calib.txt: "P0: 12 numbers" or, without prefixes, line <cam> of 12 numbers.
PinholeCamera ReadKittiCalib(const std::string& path, int cam, const cv::Size& size) {
  LineReader r(path);
  std::string line;
  int data_line = 0;
  const std::string key = fmt::format("P{}:", cam);
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    auto tok = detail::SplitWhitespace(line);
    bool match = false;
    if (!tok.empty() && !tok[0].empty() && std::isalpha(static_cast<unsigned char>(tok[0][0]))) {
      match = tok[0] == key;
      tok.erase(tok.begin());
    } else {
      match = data_line == cam;
    }
    ++data_line;
    if (!match) continue;
    if (tok.size() != 12)
      r.Fail(fmt::format("P{} must have 12 numbers (a 3x4 projection matrix), found {}", cam, tok.size()));
    double p[12];
    for (int i = 0; i < 12; ++i) p[i] = detail::ParseFinite(tok[i], r, fmt::format("P{}[{}]", cam, i));
    if (p[1] != 0.0)
      r.Fail(fmt::format("P{} has a skew term ({}); a pinhole camera without skew is expected", cam, p[1]));
    PinholeCamera camera(p[0], p[5], p[2], p[6], size.width, size.height);
    try {
      camera.Check();
    } catch (const std::invalid_argument& e) {
      r.Fail(e.what());
    }
    return camera;
  }
  detail::Fail(path,
               fmt::format("no P{} line (expected 'P{}: 12 numbers' or 12 numbers on line {})", cam, cam, cam + 1));
}

void OpenKitti(Dataset* d, const DatasetOptions& options, bool own_camera) {
  const fs::path dir(d->path);
  int cam = 0;
  fs::path image_dir = dir / "image_0";
  if (!IsDir(image_dir) && IsDir(dir / "image_2")) {
    cam = 2;
    image_dir = dir / "image_2";
  }
  if (!IsDir(image_dir))
    throw std::runtime_error(fmt::format("{}: no image_0/ folder (KITTI odometry layout)", d->path));
  std::vector<std::string> paths = ListImageFiles(image_dir.string());
  if (paths.empty()) throw std::runtime_error(fmt::format("{}: no images", image_dir.string()));
  std::vector<double> stamps;
  const fs::path times = dir / "times.txt";
  if (IsFile(times)) {
    stamps = ReadTimestampsFile(times.string());
    if (stamps.size() < paths.size())
      throw std::runtime_error(fmt::format("{}: {} timestamps for {} images in {}", times.string(), stamps.size(),
                                           paths.size(), image_dir.string()));
    if (stamps.size() > paths.size())
      d->notes.push_back(fmt::format("{}: {} timestamps for {} images; the first {} are used", times.string(),
                                     stamps.size(), paths.size(), paths.size()));
    stamps.resize(paths.size());
  } else {
    const double fps = Fps(options, DatasetKind::kKitti);
    for (size_t i = 0; i < paths.size(); ++i) stamps.push_back(static_cast<double>(i) / fps);
    d->notes.push_back(fmt::format("{}: no times.txt; stamps are index / {} Hz", d->path, fps));
  }
  const size_t n = paths.size();
  auto list = MakeList(std::move(paths), stamps, fmt::format("KITTI sequence {} ({} images)", d->path, n));
  ImageListSource& source = *list;
  d->source = std::move(list);

  if (own_camera) {
    const fs::path calib = dir / "calib.txt";
    if (!IsFile(calib)) throw std::runtime_error(fmt::format("{}: no calib.txt (the camera's P{} line)", d->path, cam));
    d->camera = ReadKittiCalib(calib.string(), cam, RequireImageSize(source, d->path));
    d->camera_origin = fmt::format("{} P{}", calib.string(), cam);
  }

  // Ground truth: poses.txt beside the images, or the benchmark layout <root>/poses/<seq>.txt for
  // <root>/sequences/<seq>/.
  fs::path poses = dir / "poses.txt";
  if (!IsFile(poses)) {
    const fs::path canonical = fs::weakly_canonical(dir);
    const fs::path bench = canonical.parent_path().parent_path() / "poses" / (canonical.filename().string() + ".txt");
    if (IsFile(bench)) poses = bench;
  }
  if (!IsFile(poses)) {
    d->notes.push_back(fmt::format("{}: no poses.txt; no ground truth", d->path));
    return;
  }
  const Trajectory raw = ReadKitti(poses.string());
  if (raw.size() < n)
    throw std::runtime_error(fmt::format("{}: {} poses for {} images in {}; KITTI pairs them one to one by index",
                                         poses.string(), raw.size(), n, image_dir.string()));
  if (raw.size() > n)
    d->notes.push_back(
        fmt::format("{}: {} poses for {} images; the first {} are used", poses.string(), raw.size(), n, n));
  SetPerFrameGroundTruth(d, raw.world_from_cam, stamps);
}

// ---- TUM RGB-D ------------------------------------------------------------------------------------------

// "freiburg3" / "fr3" in the folder name: TUM's camera of that Freiburg setup.
std::optional<int> TumFreiburgFromName(const std::string& path) {
  static const std::regex re(R"((?:freiburg|fr)([123])(?![0-9]))", std::regex::icase);
  const std::string name = fs::weakly_canonical(fs::path(path)).filename().string();
  std::smatch m;
  if (std::regex_search(name, m, re)) return std::stoi(m[1].str());
  return std::nullopt;
}

void OpenTum(Dataset* d, const DatasetOptions& options, bool own_camera) {
  const fs::path dir(d->path);
  const fs::path rgb = dir / "rgb.txt";
  LineReader r(rgb.string());
  std::vector<std::string> paths;
  std::vector<double> stamps;
  std::string line;
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    const auto tok = detail::SplitWhitespace(line);
    if (tok.size() < 2) r.Fail("expected 'timestamp filename'");
    detail::AppendStamp(stamps, detail::ParseFinite(tok[0], r, "timestamp"), tok[0], r);
    paths.push_back((dir / std::string(tok[1])).string());
  }
  if (paths.empty()) throw std::runtime_error(fmt::format("{}: lists no image", rgb.string()));
  const size_t n = paths.size();
  auto list = MakeList(std::move(paths), stamps, fmt::format("TUM RGB-D sequence {} ({} images)", d->path, n));
  ImageListSource& source = *list;
  d->source = std::move(list);

  if (own_camera) {
    for (const char* name : {"camera.yaml", "camera.yml", "camera.txt"}) {
      if (IsFile(dir / name)) {
        d->camera = ReadCameraFile((dir / name).string(), source, d->path);
        d->camera_origin = (dir / name).string();
        break;
      }
    }
    if (!d->camera) {
      if (const auto fr = TumFreiburgFromName(d->path)) {
        d->camera = TumColorCamera(*fr);
        d->camera_origin = fmt::format("TUM Freiburg {} colour camera (from the folder name)", *fr);
      } else {
        d->notes.push_back(fmt::format(
            "{}: no camera file and the folder name names no Freiburg setup (fr1/fr2/fr3); give the camera", d->path));
      }
    }
  }

  const fs::path gt = dir / "groundtruth.txt";
  if (!IsFile(gt)) {
    d->notes.push_back(fmt::format("{}: no groundtruth.txt; no ground truth", d->path));
    return;
  }
  SetSampledGroundTruth(d, ReadTum(gt.string()), stamps, options.gt_max_dt_s, gt.string());
}

// ---- EuRoC ----------------------------------------------------------------------------------------------

std::vector<double> YamlNumbers(const YAML::Node& node, const std::string& path, const std::string& key, size_t n) {
  if (!node.IsDefined() || !node.IsSequence() || node.size() != n)
    detail::Fail(path, fmt::format("key '{}' must be a list of {} numbers", key, n));
  std::vector<double> v(n);
  for (size_t i = 0; i < n; ++i) {
    if (!node[i].IsScalar() || !detail::TryParseDouble(detail::Trim(node[i].Scalar()), &v[i]) || !std::isfinite(v[i]))
      detail::Fail(path, fmt::format("key '{}' item {} is not a finite number", key, i));
  }
  return v;
}

struct EurocCamera {
  PinholeCamera camera;
  Pose body_from_cam;
};

EurocCamera ReadEurocSensorYaml(const std::string& path) {
  if (!IsFile(path)) detail::Fail(path, "camera file does not exist (EuRoC cam0/sensor.yaml)");
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::Exception& e) {
    detail::Fail(path, fmt::format("YAML error: {}", e.what()));
  }
  if (!root.IsMap()) detail::Fail(path, "expected a YAML map");
  if (root["camera_model"].IsDefined() && root["camera_model"].Scalar() != "pinhole")
    detail::Fail(path,
                 fmt::format("camera_model '{}' is not supported (expected pinhole)", root["camera_model"].Scalar()));
  const auto res = YamlNumbers(root["resolution"], path, "resolution", 2);
  const auto k = YamlNumbers(root["intrinsics"], path, "intrinsics", 4);
  EurocCamera out;
  out.camera = PinholeCamera(k[0], k[1], k[2], k[3], static_cast<int>(res[0]), static_cast<int>(res[1]));
  if (root["distortion_coefficients"].IsDefined()) {
    const std::string model =
        root["distortion_model"].IsDefined() ? root["distortion_model"].Scalar() : "radial-tangential";
    if (model != "radial-tangential" && model != "radtan")
      detail::Fail(path, fmt::format("distortion_model '{}' is not supported (expected radial-tangential)", model));
    const YAML::Node dn = root["distortion_coefficients"];
    const size_t nd = dn.IsSequence() ? dn.size() : 0;
    if (nd != 4 && nd != 5)
      detail::Fail(path, "key 'distortion_coefficients' must list 4 or 5 numbers (k1 k2 p1 p2 [k3])");
    const auto dc = YamlNumbers(dn, path, "distortion_coefficients", nd);
    out.camera.dist = {dc[0], dc[1], dc[2], dc[3], nd == 5 ? dc[4] : 0.0};
  }
  if (res[0] != std::floor(res[0]) || res[1] != std::floor(res[1]))
    detail::Fail(path, "key 'resolution' must hold integers");
  try {
    out.camera.Check();
  } catch (const std::invalid_argument& e) {
    detail::Fail(path, e.what());
  }
  if (root["T_BS"].IsDefined()) {
    const auto t = YamlNumbers(root["T_BS"]["data"], path, "T_BS.data", 16);
    Eigen::Matrix4d m;
    for (int i = 0; i < 16; ++i) m(i / 4, i % 4) = t[i];
    out.body_from_cam = Pose::FromMatrix(m);
  }
  return out;
}

void OpenEuroc(Dataset* d, const DatasetOptions& options, bool own_camera) {
  fs::path mav = fs::path(d->path) / "mav0";
  if (!IsDir(mav)) mav = fs::path(d->path);  // the path is mav0 itself
  const fs::path cam = mav / "cam0";
  const fs::path csv = cam / "data.csv";
  LineReader r(csv.string());
  std::vector<std::string> paths;
  std::vector<double> stamps;
  std::string line;
  bool first = true;
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    const auto tok = detail::SplitCommas(line);
    // A header without '#': the first line starting with a letter.
    if (first && !tok.empty() && !tok[0].empty() && std::isalpha(static_cast<unsigned char>(tok[0][0]))) {
      first = false;
      continue;
    }
    first = false;
    if (tok.size() < 2) r.Fail("expected 'timestamp [ns],filename'");
    const int64_t ns = detail::ParseInteger(tok[0], r, "timestamp [ns]");
    detail::AppendStamp(stamps, NanosecondsToSeconds(ns), tok[0], r);
    paths.push_back((cam / "data" / std::string(tok[1])).string());
  }
  if (paths.empty()) throw std::runtime_error(fmt::format("{}: lists no image", csv.string()));
  const size_t n = paths.size();
  d->source = MakeList(std::move(paths), stamps, fmt::format("EuRoC sequence {} ({} images)", d->path, n));

  // T_BS is needed for the ground truth even when the camera is overridden.
  const fs::path yaml = cam / "sensor.yaml";
  std::optional<EurocCamera> ec;
  if (own_camera || IsFile(yaml)) ec = ReadEurocSensorYaml(yaml.string());
  if (own_camera) {
    d->camera = ec->camera;
    d->camera_origin = yaml.string();
  }
  const fs::path gt = mav / "state_groundtruth_estimate0" / "data.csv";
  if (!IsFile(gt)) {
    d->notes.push_back(fmt::format("{}: no state_groundtruth_estimate0/data.csv; no ground truth", mav.string()));
    return;
  }
  Trajectory body = ReadEuroc(gt.string());
  // The file holds world_from_body; the camera is at body_from_cam.
  if (ec) {
    for (Pose& p : body.world_from_cam) p = p * ec->body_from_cam;
  } else {
    d->notes.push_back(
        fmt::format("{}: no sensor.yaml, so no T_BS: the ground truth is the body's pose", cam.string()));
  }
  SetSampledGroundTruth(d, body, stamps, options.gt_max_dt_s, gt.string());
}

// ---- 7-Scenes -------------------------------------------------------------------------------------------

// 4x4 camera-to-world, 4 lines of 4 numbers. nullopt when the file is missing or holds a non-finite
// value (7-Scenes style data marks failed tracking with inf).
std::optional<Pose> ReadPose4x4(const std::string& path) {
  if (!IsFile(path)) return std::nullopt;
  LineReader r(path);
  std::vector<double> v;
  std::string line;
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    for (auto tok : detail::SplitWhitespace(line)) {
      double x = 0;
      if (!detail::TryParseDouble(tok, &x)) r.Fail(fmt::format("'{}' is not a number", tok));
      v.push_back(x);
    }
  }
  if (v.size() != 16) detail::Fail(path, fmt::format("expected a 4x4 matrix (16 numbers), found {}", v.size()));
  Eigen::Matrix4d m;
  for (int i = 0; i < 16; ++i) m(i / 4, i % 4) = v[i];
  if (!m.allFinite()) return std::nullopt;
  return Pose::FromMatrix(m);
}

void OpenSevenScenes(Dataset* d, const DatasetOptions& options, bool own_camera) {
  const fs::path dir(d->path);
  const bool split = IsDir(dir / "color");
  const fs::path color_dir = split ? dir / "color" : dir;
  const fs::path pose_dir = split ? dir / "pose" : dir;
  static const std::regex re(R"(frame-(\d+)\.color\.(jpg|jpeg|png))", std::regex::icase);
  std::vector<std::pair<int64_t, std::string>> frames;
  std::error_code ec;
  for (fs::directory_iterator it(color_dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    std::smatch m;
    if (std::regex_match(name, m, re)) frames.emplace_back(std::stoll(m[1].str()), name);
  }
  if (frames.empty())
    throw std::runtime_error(fmt::format("{}: no frame-NNNNNN.color.jpg/.png images", color_dir.string()));
  std::sort(frames.begin(), frames.end());
  const double fps = Fps(options, DatasetKind::kSevenScenes);
  std::vector<std::string> paths;
  std::vector<double> stamps;
  std::vector<Pose> poses;
  std::vector<int64_t> gt_frames;
  Trajectory gt;
  int missing = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    paths.push_back((color_dir / frames[i].second).string());
    // No stamps in 7-Scenes: the frame number at the nominal rate (30 Hz), so gaps in the numbering stay gaps.
    stamps.push_back(static_cast<double>(frames[i].first) / fps);
    const std::string stem = frames[i].second.substr(0, frames[i].second.find(".color."));
    if (const auto pose = ReadPose4x4((pose_dir / (stem + ".pose.txt")).string())) {
      gt.stamps_s.push_back(stamps.back());
      gt.world_from_cam.push_back(*pose);
      gt_frames.push_back(static_cast<int64_t>(i));
    } else {
      ++missing;
    }
  }
  const size_t n = paths.size();
  auto list = MakeList(std::move(paths), stamps, fmt::format("7-Scenes sequence {} ({} images)", d->path, n));
  ImageListSource& source = *list;
  d->source = std::move(list);
  if (!gt.empty()) {
    gt.has_stamps = true;
    d->ground_truth = std::move(gt);
    d->ground_truth_frames = std::move(gt_frames);
  }
  if (missing > 0)
    d->notes.push_back(fmt::format("{}: {} of {} frames have no (finite) pose file", pose_dir.string(), missing, n));

  if (own_camera) {
    const fs::path k = dir / "camera-intrinsics.txt";
    const cv::Size size = RequireImageSize(source, d->path);
    if (IsFile(k)) {
      d->camera = ReadIntrinsicsMatrix(k.string(), size.width, size.height);
      d->camera_origin = k.string();
      d->notes.push_back(fmt::format(
          "{}: 7-Scenes does not calibrate the colour camera; this file usually holds the depth camera's K "
          "(fx = fy = 585); the colour camera is commonly taken as fx = fy = 525, cx = 320, cy = 240: pass a "
          "camera to use that",
          k.string()));
    } else {
      d->camera = PinholeCamera(525.0, 525.0, 320.0, 240.0, size.width, size.height);
      d->camera_origin = "7-Scenes colour camera default (fx = fy = 525, cx = 320, cy = 240)";
    }
  }
}

// ---- synthetic ------------------------------------------------------------------------------------------

void OpenSynthetic(Dataset* d, const DatasetOptions& options, bool own_camera) {
  const fs::path dir(d->path);
  const Trajectory gt = ReadTum((dir / "groundtruth.txt").string());
  const fs::path images = dir / "images";
  std::vector<std::string> paths;
  if (IsDir(images)) paths = ListImageFiles(images.string());
  if (paths.size() > gt.size())
    throw std::runtime_error(fmt::format("{}: {} images but groundtruth.txt has {} poses; they pair one to one",
                                         images.string(), paths.size(), gt.size()));
  std::vector<double> stamps(gt.stamps_s.begin(), gt.stamps_s.begin() + static_cast<std::ptrdiff_t>(paths.size()));
  if (paths.empty()) {
    d->notes.push_back(fmt::format("{}: no images/ folder; the sequence has observations only", d->path));
  } else if (paths.size() < gt.size()) {
    d->notes.push_back(fmt::format("{}: {} images for {} poses; the first {} poses are used", images.string(),
                                   paths.size(), gt.size(), paths.size()));
  }
  const size_t n = paths.size();
  d->source = MakeList(std::move(paths), stamps, fmt::format("synthetic sequence {} ({} images)", d->path, n));
  if (own_camera) {
    d->camera = ReadCameraYaml((dir / "camera.yaml").string());
    d->camera_origin = (dir / "camera.yaml").string();
  }
  if (n > 0) SetPerFrameGroundTruth(d, gt.world_from_cam, stamps);
}

}  // namespace

// ---- public ---------------------------------------------------------------------------------------------

DatasetKind ParseDatasetKind(const std::string& name) {
  const std::string n = Lower(name);
  if (n == "auto") return DatasetKind::kAuto;
  if (n == "images" || n == "folder") return DatasetKind::kImageFolder;
  if (n == "video") return DatasetKind::kVideo;
  if (n == "webcam") return DatasetKind::kWebcam;
  if (n == "kitti") return DatasetKind::kKitti;
  if (n == "tum") return DatasetKind::kTum;
  if (n == "euroc") return DatasetKind::kEuroc;
  if (n == "7scenes" || n == "7-scenes") return DatasetKind::kSevenScenes;
  if (n == "synthetic" || n == "synth") return DatasetKind::kSynthetic;
  throw std::invalid_argument(fmt::format(
      "unknown dataset kind '{}' (expected auto, images, video, webcam, kitti, tum, euroc, 7scenes or synthetic)",
      name));
}

std::string ToString(DatasetKind kind) {
  switch (kind) {
    case DatasetKind::kAuto:
      return "auto";
    case DatasetKind::kImageFolder:
      return "images";
    case DatasetKind::kVideo:
      return "video";
    case DatasetKind::kWebcam:
      return "webcam";
    case DatasetKind::kKitti:
      return "kitti";
    case DatasetKind::kTum:
      return "tum";
    case DatasetKind::kEuroc:
      return "euroc";
    case DatasetKind::kSevenScenes:
      return "7scenes";
    case DatasetKind::kSynthetic:
      return "synthetic";
  }
  return "unknown";
}

DatasetKind DetectDatasetKind(const std::string& path) {
  if (WebcamIndex(path)) return DatasetKind::kWebcam;
  std::error_code ec;
  const fs::path p(path);
  if (!fs::exists(p, ec)) throw std::runtime_error(fmt::format("{}: does not exist", path));
  if (!IsDir(p)) return DatasetKind::kVideo;
  if (IsFile(p / "mav0" / "cam0" / "data.csv") || IsFile(p / "cam0" / "data.csv")) return DatasetKind::kEuroc;
  if (IsFile(p / "rgb.txt")) return DatasetKind::kTum;
  if (IsDir(p / "image_0") || (IsDir(p / "image_2") && IsFile(p / "calib.txt"))) return DatasetKind::kKitti;
  if (IsFile(p / "camera.yaml") && IsFile(p / "groundtruth.txt")) return DatasetKind::kSynthetic;
  if (IsDir(p / "color") || IsFile(p / "camera-intrinsics.txt")) return DatasetKind::kSevenScenes;
  {
    static const std::regex re(R"(frame-\d+\.color\.(jpg|jpeg|png))", std::regex::icase);
    for (fs::directory_iterator it(p, ec), end; !ec && it != end; it.increment(ec))
      if (std::regex_match(it->path().filename().string(), re)) return DatasetKind::kSevenScenes;
  }
  if (HasImageFile(p)) return DatasetKind::kImageFolder;
  throw std::runtime_error(fmt::format(
      "{}: cannot tell what dataset this is: no mav0/cam0/data.csv (EuRoC), rgb.txt (TUM), image_0/ (KITTI), "
      "color/ (7-Scenes), camera.yaml + groundtruth.txt (synthetic) or image files (folder)",
      path));
}

void DatasetOptions::Check() const {
  if (!(fps >= 0) || !std::isfinite(fps))
    throw std::invalid_argument(fmt::format("DatasetOptions.fps must be >= 0 and finite (got {})", fps));
  if (!(gt_max_dt_s > 0) || !std::isfinite(gt_max_dt_s))
    throw std::invalid_argument(
        fmt::format("DatasetOptions.gt_max_dt_s must be positive and finite (got {})", gt_max_dt_s));
  if (camera) {
    try {
      camera->Check();
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(fmt::format("DatasetOptions.camera: {}", e.what()));
    }
  }
}

Dataset OpenDataset(const std::string& path, const DatasetOptions& options) {
  options.Check();
  Dataset d;
  d.path = path;
  d.kind = options.kind == DatasetKind::kAuto ? DetectDatasetKind(path) : options.kind;
  if (d.kind != DatasetKind::kWebcam && d.kind != DatasetKind::kVideo && !IsDir(path)) {
    std::error_code ec;
    throw std::runtime_error(fmt::format("{}: {} (a {} dataset is a folder)", path,
                                         fs::exists(path, ec) ? "is not a folder" : "does not exist",
                                         ToString(d.kind)));
  }
  const bool own_camera = !options.camera && options.camera_path.empty();
  switch (d.kind) {
    case DatasetKind::kImageFolder:
      OpenImages(&d, options, own_camera);
      break;
    case DatasetKind::kVideo:
      d.source = VideoSource::OpenFile(path, options.fps);
      break;
    case DatasetKind::kWebcam: {
      std::optional<int> index = WebcamIndex(path);
      int64_t v = 0;
      if (!index && detail::TryParseInt(path, &v) && v >= 0 && v < 10000) index = static_cast<int>(v);
      if (!index) throw std::runtime_error(fmt::format("'{}' is not a webcam (expected 'webcam:N' or N)", path));
      d.source = VideoSource::OpenCamera(*index);
      break;
    }
    case DatasetKind::kKitti:
      OpenKitti(&d, options, own_camera);
      break;
    case DatasetKind::kTum:
      OpenTum(&d, options, own_camera);
      break;
    case DatasetKind::kEuroc:
      OpenEuroc(&d, options, own_camera);
      break;
    case DatasetKind::kSevenScenes:
      OpenSevenScenes(&d, options, own_camera);
      break;
    case DatasetKind::kSynthetic:
      OpenSynthetic(&d, options, own_camera);
      break;
    case DatasetKind::kAuto:
      throw std::logic_error("OpenDataset: kind not resolved");
  }
  if (options.camera) {
    d.camera = *options.camera;
    d.camera_origin = "given camera";
  } else if (!options.camera_path.empty()) {
    d.camera = ReadCameraFile(options.camera_path, *d.source, path);
    d.camera_origin = options.camera_path;
  }
  d.image_size = d.source->ImageSize();
  if (d.camera && options.check_image_size && d.image_size)
    CheckCameraMatchesImageSize(*d.camera, *d.image_size,
                                fmt::format("{} (camera from {})", d.source->Description(), d.camera_origin));
  return d;
}

void CheckCameraMatchesImageSize(const PinholeCamera& camera, const cv::Size& size, const std::string& what) {
  if (camera.width == size.width && camera.height == size.height) return;
  std::string hint;
  const double sx = static_cast<double>(size.width) / camera.width;
  const double sy = static_cast<double>(size.height) / camera.height;
  if (camera.width > 0 && camera.height > 0 && std::abs(sx - sy) < 1e-3 * std::max(sx, sy))
    hint = fmt::format(" (same aspect ratio: the camera scaled by {:.6g} would fit)", sx);
  throw std::runtime_error(fmt::format("the camera is {}x{} but the frames of {} are {}x{}{}", camera.width,
                                       camera.height, what, size.width, size.height, hint));
}

PinholeCamera ReadCameraText(const std::string& path, int width, int height) {
  LineReader r(path);
  std::string line;
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    const auto tok = detail::SplitWhitespace(line);
    if (tok.size() != 4 && tok.size() != 8 && tok.size() != 9)
      r.Fail(fmt::format("expected 'fx fy cx cy [k1 k2 p1 p2 [k3]]' (4, 8 or 9 numbers), found {}", tok.size()));
    static constexpr const char* kNames[9] = {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"};
    std::vector<double> v;
    for (size_t i = 0; i < tok.size(); ++i) v.push_back(detail::ParseFinite(tok[i], r, kNames[i]));
    try {
      return CameraFromNumbers(v, width, height);
    } catch (const std::invalid_argument& e) {
      r.Fail(e.what());
    }
  }
  detail::Fail(path, "no camera line (expected 'fx fy cx cy [k1 k2 p1 p2 [k3]]')");
}

PinholeCamera ReadIntrinsicsMatrix(const std::string& path, int width, int height) {
  LineReader r(path);
  std::vector<double> v;
  std::string line;
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    for (auto tok : detail::SplitWhitespace(line)) v.push_back(detail::ParseFinite(tok, r, "K entry"));
  }
  if (v.size() != 9)
    detail::Fail(path, fmt::format("expected a 3x3 intrinsics matrix (9 numbers), found {}", v.size()));
  if (v[1] != 0 || v[3] != 0 || v[6] != 0 || v[7] != 0 || v[8] != 1)
    detail::Fail(path, "expected K = [fx 0 cx; 0 fy cy; 0 0 1] (zero skew, last row 0 0 1)");
  PinholeCamera camera(v[0], v[4], v[2], v[5], width, height);
  try {
    camera.Check();
  } catch (const std::invalid_argument& e) {
    detail::Fail(path, e.what());
  }
  return camera;
}

PinholeCamera TumColorCamera(int freiburg) {
  // TUM RGB-D "file formats" page, calibration of the colour cameras (distortion k1 k2 p1 p2 k3).
  switch (freiburg) {
    case 1:
      return PinholeCamera(517.306408, 516.469215, 318.643040, 255.313989, 640, 480,
                           Distortion{0.262383, -0.953104, -0.005358, 0.002628, 1.163314});
    case 2:
      return PinholeCamera(520.908620, 521.007327, 325.141442, 249.701764, 640, 480,
                           Distortion{0.231222, -0.784899, -0.003257, -0.000105, 0.917205});
    case 3:
      return PinholeCamera(535.4, 539.2, 320.1, 247.6, 640, 480);
    default:
      break;
  }
  throw std::invalid_argument(fmt::format("TUM Freiburg setup must be 1, 2 or 3 (got {})", freiburg));
}

Trajectory SampleTrajectoryAt(const Trajectory& samples, const std::vector<double>& stamps_s, double max_dt_s,
                              std::vector<int64_t>* used) {
  Trajectory out;
  out.has_stamps = true;
  if (used) used->clear();
  const auto& ts = samples.stamps_s;
  for (size_t i = 0; i < stamps_s.size(); ++i) {
    const double t = stamps_s[i];
    const size_t b = static_cast<size_t>(std::lower_bound(ts.begin(), ts.end(), t) - ts.begin());
    std::optional<Pose> pose;
    if (b < ts.size() && ts[b] == t) {
      pose = samples.world_from_cam[b];
    } else if (b == 0 || b == ts.size()) {
      const size_t k = b == 0 ? 0 : ts.size() - 1;
      if (!ts.empty() && std::abs(ts[k] - t) <= max_dt_s) pose = samples.world_from_cam[k];
    } else {
      const size_t a = b - 1;
      const double da = t - ts[a], db = ts[b] - t;
      if (std::min(da, db) <= max_dt_s) {
        if (ts[b] - ts[a] > 2 * max_dt_s) {
          pose = samples.world_from_cam[da <= db ? a : b];  // a gap in the samples: no interpolation across it
        } else {
          const double w = da / (ts[b] - ts[a]);
          const Pose& pa = samples.world_from_cam[a];
          const Pose& pb = samples.world_from_cam[b];
          pose = Pose(pa.q.slerp(w, pb.q).normalized(), (1 - w) * pa.t + w * pb.t);
        }
      }
    }
    if (!pose) continue;
    out.stamps_s.push_back(t);
    out.world_from_cam.push_back(*pose);
    if (used) used->push_back(static_cast<int64_t>(i));
  }
  return out;
}

}  // namespace mcslam::io
