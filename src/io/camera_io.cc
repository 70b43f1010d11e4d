#include "io/camera_io.h"

#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "io/text_util.h"

namespace mcslam::io {
namespace {

// Keys of one file style. In ORB-SLAM files the dots are part of the key ("Camera.fx" is one flat key).
struct CameraKeys {
  const char* style;
  std::string fx, fy, cx, cy, k1, k2, p1, p2, k3, width, height, k4;
};

CameraKeys KeysWithPrefix(const char* style, const std::string& intrinsics, const std::string& size) {
  return {style,           intrinsics + "fx", intrinsics + "fy", intrinsics + "cx", intrinsics + "cy",
          intrinsics + "k1", intrinsics + "k2", intrinsics + "p1", intrinsics + "p2", intrinsics + "k3",
          size + "width",  size + "height", intrinsics + "k4"};
}

// Reads a YAML file whose keys are looked up by name; errors name the file, the key and its line.
class YamlFile {
 public:
  explicit YamlFile(const std::string& path) : path_(path) {
    detail::RequireRegularFileIfPresent(path);
    std::ifstream in(path);
    if (!in) detail::Fail(path, "cannot open file for reading");
    std::stringstream ss;
    ss << in.rdbuf();
    std::string text = ss.str();
    // OpenCV FileStorage files start with "%YAML:1.0", a directive yaml-cpp rejects. Blank it (keeping the
    // newline, so that line numbers in yaml-cpp's messages still match the file).
    if (text.rfind("%YAML", 0) == 0) text.erase(0, text.find('\n') == std::string::npos ? text.size() : text.find('\n'));
    try {
      root_ = YAML::Load(text);
    } catch (const YAML::Exception& e) {
      if (e.mark.line >= 0) detail::FailAt(path, e.mark.line + 1, fmt::format("YAML syntax error: {}", e.msg));
      detail::Fail(path, fmt::format("YAML syntax error: {}", e.msg));
    }
    if (!root_.IsMap()) detail::Fail(path, "expected a YAML map of keys (e.g. 'Camera.fx: 500.0')");
  }

  bool Has(const std::string& key) const { return root_[key].IsDefined() && !root_[key].IsNull(); }

  double Double(const std::string& key, const CameraKeys& keys) const {
    const YAML::Node node = Get(key, keys);
    double v = 0;
    if (!node.IsScalar() || !detail::TryParseDouble(detail::Trim(node.Scalar()), &v))
      FailKey(node, key, fmt::format("is not a number (got '{}')", node.IsScalar() ? node.Scalar() : "a non-scalar"));
    if (!std::isfinite(v)) FailKey(node, key, fmt::format("is not finite ({})", node.Scalar()));
    return v;
  }
  double DoubleOr(const std::string& key, const CameraKeys& keys, double fallback) const {
    return Has(key) ? Double(key, keys) : fallback;
  }
  // An image size; "640" and "640.0" are both accepted (OpenCV writes either).
  int PositiveInt(const std::string& key, const CameraKeys& keys) const {
    const double v = Double(key, keys);
    if (v != std::floor(v) || v <= 0 || v > std::numeric_limits<int>::max())
      FailKey(root_[key], key, fmt::format("must be a positive integer (got {})", v));
    return static_cast<int>(v);
  }
  std::string String(const std::string& key) const {
    const YAML::Node node = root_[key];
    if (!node.IsScalar()) FailKey(node, key, "is not a string");
    return node.Scalar();
  }

 private:
  YAML::Node Get(const std::string& key, const CameraKeys& keys) const {
    const YAML::Node node = root_[key];
    if (!node.IsDefined() || node.IsNull()) {
      std::string hint;
      if (key == keys.width || key == keys.height)
        hint = fmt::format(" (the image size is needed: add {}: and {}: to the file; ORB-SLAM2 files often leave it out)",
                           keys.width, keys.height);
      detail::Fail(path_, fmt::format("missing key '{}' in this {} camera file{}", key, keys.style, hint));
    }
    return node;
  }
  [[noreturn]] void FailKey(const YAML::Node& node, const std::string& key, const std::string& what) const {
    const int line = node.Mark().line;  // -1 when yaml-cpp does not know it
    if (line >= 0) detail::FailAt(path_, line + 1, fmt::format("key '{}' {}", key, what));
    detail::Fail(path_, fmt::format("key '{}' {}", key, what));
  }

  std::string path_;
  YAML::Node root_;
};

// A double that YAML and OpenCV read back as a real ("500.0", not "500"), exact to the last bit.
std::string YamlReal(double v) {
  std::string s = detail::FormatExact(v);
  if (s.find_first_of(".eEn") == std::string::npos) s += ".0";
  return s;
}

}  // namespace

PinholeCamera ReadCameraYaml(const std::string& path) {
  const YamlFile yaml(path);

  CameraKeys keys;
  if (yaml.Has("Camera1.fx")) {
    keys = KeysWithPrefix("ORB-SLAM3", "Camera1.", "Camera.");
  } else if (yaml.Has("Camera.fx")) {
    keys = KeysWithPrefix("ORB-SLAM2", "Camera.", "Camera.");
  } else if (yaml.Has("fx")) {
    keys = KeysWithPrefix("mcslam", "", "");
  } else {
    detail::Fail(path, "no camera intrinsics found: expected 'Camera.fx' (ORB-SLAM2), 'Camera1.fx' (ORB-SLAM3) or "
                       "'fx' (mcslam) keys");
  }
  // ORB-SLAM's Camera.type: "PinHole" (radial-tangential) or "KannalaBrandt8" (a fisheye: k1-k4 of the equidistant
  // model); mcslam's own files say `model: equidistant` for the latter.
  bool fisheye = false;
  if (yaml.Has("Camera.type")) {
    const std::string type = yaml.String("Camera.type");
    fisheye = type == "KannalaBrandt8";
    if (!fisheye && type != "PinHole" && type != "Rectified")
      detail::Fail(path, fmt::format("Camera.type '{}' is not supported (expected \"PinHole\" or \"KannalaBrandt8\")",
                                     type));
  } else if (yaml.Has("model")) {
    const std::string model = yaml.String("model");
    fisheye = model == "equidistant" || model == "kannala-brandt";
    if (!fisheye && model != "radial-tangential" && model != "pinhole")
      detail::Fail(path, fmt::format("model '{}' is not supported (expected radial-tangential or equidistant)", model));
  }

  PinholeCamera cam;
  cam.fx = yaml.Double(keys.fx, keys);
  cam.fy = yaml.Double(keys.fy, keys);
  cam.cx = yaml.Double(keys.cx, keys);
  cam.cy = yaml.Double(keys.cy, keys);
  cam.dist.k1 = yaml.DoubleOr(keys.k1, keys, 0.0);
  cam.dist.k2 = yaml.DoubleOr(keys.k2, keys, 0.0);
  cam.dist.k3 = yaml.DoubleOr(keys.k3, keys, 0.0);
  if (fisheye) {
    cam.dist.model = LensModel::kEquidistant;
    cam.dist.k4 = yaml.DoubleOr(keys.k4, keys, 0.0);
  } else {
    cam.dist.p1 = yaml.DoubleOr(keys.p1, keys, 0.0);
    cam.dist.p2 = yaml.DoubleOr(keys.p2, keys, 0.0);
  }
  cam.width = yaml.PositiveInt(keys.width, keys);
  cam.height = yaml.PositiveInt(keys.height, keys);
  try {
    cam.Check();
  } catch (const std::invalid_argument& e) {
    detail::Fail(path, e.what());
  }
  return cam;
}

void WriteCameraYaml(const std::string& path, const PinholeCamera& camera, double fps) {
  try {
    camera.Check();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("{}: not writing an invalid camera: {}", path, e.what()));
  }
  std::ofstream out = detail::OpenForWrite(path);
  out << "%YAML:1.0\n\n";
  if (camera.dist.IsFisheye()) {
    out << "# Camera calibration written by mcslam (ORB-SLAM style; fisheye, the equidistant / Kannala-Brandt model)\n";
    out << "Camera.type: \"KannalaBrandt8\"\n";
  } else {
    out << "# Camera calibration written by mcslam (ORB-SLAM2 style; pinhole, radial-tangential distortion)\n";
  }
  out << "Camera.fx: " << YamlReal(camera.fx) << "\n";
  out << "Camera.fy: " << YamlReal(camera.fy) << "\n";
  out << "Camera.cx: " << YamlReal(camera.cx) << "\n";
  out << "Camera.cy: " << YamlReal(camera.cy) << "\n\n";
  out << "Camera.k1: " << YamlReal(camera.dist.k1) << "\n";
  out << "Camera.k2: " << YamlReal(camera.dist.k2) << "\n";
  if (camera.dist.IsFisheye()) {
    out << "Camera.k3: " << YamlReal(camera.dist.k3) << "\n";
    out << "Camera.k4: " << YamlReal(camera.dist.k4) << "\n\n";
  } else {
    out << "Camera.p1: " << YamlReal(camera.dist.p1) << "\n";
    out << "Camera.p2: " << YamlReal(camera.dist.p2) << "\n";
    out << "Camera.k3: " << YamlReal(camera.dist.k3) << "\n\n";
  }
  out << "Camera.width: " << camera.width << "\n";
  out << "Camera.height: " << camera.height << "\n";
  if (fps > 0) out << "\nCamera.fps: " << YamlReal(fps) << "\n";
  detail::FinishWrite(out, path);
}

}  // namespace mcslam::io
