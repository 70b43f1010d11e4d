#include "io/datasets.h"

#include "io/dataset_common.h"

namespace mcslam::io {

using namespace detail;  // the helpers and openers of dataset_common.h
namespace {

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