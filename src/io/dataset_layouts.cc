// The dataset layouts mcslam reads: KITTI odometry, TUM RGB-D, EuRoC MAV, 7-Scenes, and the folders `mcslam synth`
// writes. Each opener finds the images, the camera and the ground truth where that layout keeps them.
#include "io/dataset_common.h"
#include <limits>

namespace mcslam::io::detail {

using detail::LineReader;

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
  for (double v : res)  // an image size: checked before it becomes an int (a cast out of range is undefined)
    if (v != std::floor(v) || v <= 0 || v > std::numeric_limits<int>::max())
      detail::Fail(path, fmt::format("key 'resolution' must list two positive integers (got {})", v));
  const auto k = YamlNumbers(root["intrinsics"], path, "intrinsics", 4);
  EurocCamera out;
  out.camera = PinholeCamera(k[0], k[1], k[2], k[3], static_cast<int>(res[0]), static_cast<int>(res[1]));
  if (root["distortion_coefficients"].IsDefined()) {
    const std::string model =
        root["distortion_model"].IsDefined() ? root["distortion_model"].Scalar() : "radial-tangential";
    const bool fisheye = model == "equidistant";  // Kalibr's name for Kannala-Brandt (TUM-VI, EuRoC-style fisheyes)
    if (model != "radial-tangential" && model != "radtan" && !fisheye)
      detail::Fail(path, fmt::format("distortion_model '{}' is not supported (expected radial-tangential or "
                                     "equidistant)", model));
    const YAML::Node dn = root["distortion_coefficients"];
    const size_t nd = dn.IsSequence() ? dn.size() : 0;
    if (fisheye && nd != 4)
      detail::Fail(path, "key 'distortion_coefficients' must list 4 numbers (k1 k2 k3 k4) for the equidistant model");
    if (nd != 4 && nd != 5)
      detail::Fail(path, "key 'distortion_coefficients' must list 4 or 5 numbers (k1 k2 p1 p2 [k3])");
    const auto dc = YamlNumbers(dn, path, "distortion_coefficients", nd);
    if (fisheye) {
      out.camera.dist = Distortion::Equidistant(dc[0], dc[1], dc[2], dc[3]);
    } else {
      out.camera.dist = {dc[0], dc[1], dc[2], dc[3], nd == 5 ? dc[4] : 0.0};
    }
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

}  // namespace mcslam::io::detail
