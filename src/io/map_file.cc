#include "io/map_file.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <stdexcept>
#include <unordered_set>

#include <fmt/format.h>

#include "io/text_util.h"

namespace mcslam::io {

namespace {

using nlohmann::json;
constexpr const char* kFormatName = "mcslam-map";
constexpr int64_t kMaxMapId = int64_t{1} << 62;  // ids are track ids: counted from 0, never near this
constexpr int kMaxDepth = 16;                    // the format nests 4 deep; options, as report.json, a few more

bool Finite(const Eigen::Vector3d& v) { return v.allFinite(); }

json CameraJson(const PinholeCamera& c) {
  return {{"fx", c.fx}, {"fy", c.fy}, {"cx", c.cx}, {"cy", c.cy}, {"width", c.width}, {"height", c.height},
          {"k1", c.dist.k1}, {"k2", c.dist.k2}, {"p1", c.dist.p1}, {"p2", c.dist.p2}, {"k3", c.dist.k3},
          {"k4", c.dist.k4}, {"model", ToString(c.dist.model)}};
}

// nlohmann's CBOR reader recurses once per nesting level without a limit: a file of a million nested arrays
// would overflow the stack. Its document builder, behind a SAX interface that refuses to go deeper than
// kMaxDepth (the parse then stops, and says so).
class DepthLimitedBuilder {
 public:
  explicit DepthLimitedBuilder(json* root) : dom_(*root) {}
  bool null() { return dom_.null(); }
  bool boolean(bool v) { return dom_.boolean(v); }
  bool number_integer(json::number_integer_t v) { return dom_.number_integer(v); }
  bool number_unsigned(json::number_unsigned_t v) { return dom_.number_unsigned(v); }
  bool number_float(json::number_float_t v, const json::string_t& s) { return dom_.number_float(v, s); }
  bool string(json::string_t& v) { return dom_.string(v); }
  bool binary(json::binary_t& v) { return dom_.binary(v); }
  bool start_object(std::size_t n) { return ++depth_ <= kMaxDepth && dom_.start_object(n); }
  bool key(json::string_t& k) { return dom_.key(k); }
  bool end_object() { return --depth_, dom_.end_object(); }
  bool start_array(std::size_t n) { return ++depth_ <= kMaxDepth && dom_.start_array(n); }
  bool end_array() { return --depth_, dom_.end_array(); }
  bool parse_error(std::size_t at, const std::string& token, const nlohmann::detail::exception& e) {
    return dom_.parse_error(at, token, e);  // throws it
  }
  bool too_deep() const { return depth_ > kMaxDepth; }

 private:
  nlohmann::detail::json_sax_dom_parser<json> dom_;
  int depth_ = 0;
};

// A field of an object, checked: `where` names it in errors ("keyframes[3].q").
class Reader {
 public:
  explicit Reader(std::string what) : what_(std::move(what)) {}
  [[noreturn]] void Fail(const std::string& where, const std::string& why) const {
    throw std::runtime_error(fmt::format("{}: {}{}", what_, where.empty() ? "" : where + ": ", why));
  }
  const json& Field(const json& obj, const char* key, const std::string& where) const {
    if (!obj.is_object()) Fail(where, "is not an object");
    auto it = obj.find(key);
    if (it == obj.end()) Fail(where.empty() ? key : where + "." + key, "is missing");
    return *it;
  }
  double Number(const json& obj, const char* key, const std::string& where) const {
    const json& v = Field(obj, key, where);
    if (!v.is_number()) Fail(Join(where, key), "is not a number");
    const double d = v.get<double>();
    if (!std::isfinite(d)) Fail(Join(where, key), "is not finite");
    return d;
  }
  int64_t Integer(const json& obj, const char* key, const std::string& where) const {
    const json& v = Field(obj, key, where);
    if (!v.is_number_integer()) Fail(Join(where, key), "is not an integer");
    if (v.is_number_unsigned() && v.get<uint64_t>() > static_cast<uint64_t>(INT64_MAX))
      Fail(Join(where, key), "is out of range");
    return v.get<int64_t>();
  }
  // An array of exactly n finite numbers (n < 0: any length).
  std::vector<double> Numbers(const json& obj, const char* key, const std::string& where, long n) const {
    const json& v = Field(obj, key, where);
    if (!v.is_array()) Fail(Join(where, key), "is not an array");
    if (n >= 0 && static_cast<long>(v.size()) != n)
      Fail(Join(where, key), fmt::format("has {} numbers, {} expected", v.size(), n));
    std::vector<double> out;
    out.reserve(v.size());
    for (const json& e : v) {
      if (!e.is_number()) Fail(Join(where, key), "holds something that is not a number");
      out.push_back(e.get<double>());
      if (!std::isfinite(out.back())) Fail(Join(where, key), "holds a number that is not finite");
    }
    return out;
  }
  static std::string Join(const std::string& where, const char* key) { return where.empty() ? key : where + "." + key; }

 private:
  std::string what_;
};

}  // namespace

std::string CameraDifference(const PinholeCamera& a, const PinholeCamera& b) {
  auto differs = [](double x, double y) { return std::abs(x - y) > 1e-9 * std::max({1.0, std::abs(x), std::abs(y)}); };
  std::vector<std::string> d;
  if (a.width != b.width || a.height != b.height)
    d.push_back(fmt::format("size {}x{} against {}x{}", a.width, a.height, b.width, b.height));
  const std::pair<const char*, std::pair<double, double>> fields[] = {
      {"fx", {a.fx, b.fx}},           {"fy", {a.fy, b.fy}},           {"cx", {a.cx, b.cx}},
      {"cy", {a.cy, b.cy}},           {"k1", {a.dist.k1, b.dist.k1}}, {"k2", {a.dist.k2, b.dist.k2}},
      {"p1", {a.dist.p1, b.dist.p1}}, {"p2", {a.dist.p2, b.dist.p2}}, {"k3", {a.dist.k3, b.dist.k3}},
      {"k4", {a.dist.k4, b.dist.k4}}};
  if (a.dist.model != b.dist.model)
    d.push_back(fmt::format("lens model {} against {}", ToString(a.dist.model), ToString(b.dist.model)));
  for (const auto& [name, v] : fields)
    if (differs(v.first, v.second)) d.push_back(fmt::format("{} {:.10g} against {:.10g}", name, v.first, v.second));
  std::string out;
  for (const std::string& s : d) out += (out.empty() ? "" : ", ") + s;
  return out;
}

std::vector<uint8_t> SerialiseMapFile(const MapFile& map) {
  json j;
  j["format"] = kFormatName;
  j["version"] = kMapFormatVersion;
  j["camera"] = CameraJson(map.camera);
  j["options"] = map.options;
  json points = json::array();
  std::unordered_set<int64_t> ids;
  for (const MapFilePoint& p : map.points) {
    if (!Finite(p.position_in_world))
      throw std::invalid_argument(fmt::format("map point {}: its position is not finite", p.id));
    if (!ids.insert(p.id).second) throw std::invalid_argument(fmt::format("map point {}: the id is there twice", p.id));
    json jp = {{"id", p.id}, {"xyz", {p.position_in_world.x(), p.position_in_world.y(), p.position_in_world.z()}}};
    if (p.descriptor) jp["descriptor"] = *p.descriptor;
    if (p.first_descriptor) jp["first_descriptor"] = *p.first_descriptor;
    points.push_back(std::move(jp));
  }
  j["points"] = std::move(points);
  json keyframes = json::array();
  for (const MapFileKeyframe& k : map.keyframes) {
    if (!k.cam_from_world.AllFinite() || !std::isfinite(k.stamp_s))
      throw std::invalid_argument(fmt::format("keyframe {}: its pose or stamp is not finite", k.index));
    if (k.feature_ids.size() != k.uv_px.size())
      throw std::invalid_argument(fmt::format("keyframe {}: {} feature ids but {} positions", k.index,
                                              k.feature_ids.size(), k.uv_px.size()));
    json uv = json::array();
    for (size_t i = 0; i < k.uv_px.size(); ++i) {
      if (!k.uv_px[i].allFinite() || (i > 0 && k.feature_ids[i] <= k.feature_ids[i - 1]))
        throw std::invalid_argument(fmt::format("keyframe {}: feature {} is not finite or out of order", k.index,
                                                k.feature_ids[i]));
      uv.push_back(k.uv_px[i].x());
      uv.push_back(k.uv_px[i].y());
    }
    const Pose& T = k.cam_from_world;
    keyframes.push_back({{"index", k.index},
                         {"stamp", k.stamp_s},
                         {"q", {T.q.w(), T.q.x(), T.q.y(), T.q.z()}},
                         {"t", {T.t.x(), T.t.y(), T.t.z()}},
                         {"ids", k.feature_ids},
                         {"uv", std::move(uv)}});
  }
  j["keyframes"] = std::move(keyframes);
  return json::to_cbor(j);
}

void WriteMapFile(const std::string& path, const MapFile& map) {
  const std::vector<uint8_t> bytes = SerialiseMapFile(map);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw std::runtime_error(fmt::format("{}: cannot open the map file for writing", path));
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) throw std::runtime_error(fmt::format("{}: writing the map file failed (disk full?)", path));
}

MapFile ParseMapFile(const std::vector<uint8_t>& bytes, const std::string& what) {
  const Reader rd(what);
  if (bytes.empty()) rd.Fail("", "is empty, not an mcslam map file");
  json j;
  try {
    DepthLimitedBuilder builder(&j);
    const bool complete = json::sax_parse(bytes, &builder, json::input_format_t::cbor);
    if (builder.too_deep()) rd.Fail("", fmt::format("is not an mcslam map file (nested deeper than {})", kMaxDepth));
    if (!complete) rd.Fail("", "is not an mcslam map file, or it is truncated or corrupt");
  } catch (const json::exception& e) {
    rd.Fail("", fmt::format("is not an mcslam map file, or it is truncated or corrupt (CBOR: {})", e.what()));
  }
  if (!j.is_object() || !j.contains("format") || j["format"] != kFormatName)
    rd.Fail("", "is not an mcslam map file (no \"format\": \"mcslam-map\" in it)");
  const int64_t version = rd.Integer(j, "version", "");
  if (version > kMapFormatVersion)
    rd.Fail("", fmt::format("was written in map format version {}, newer than this mcslam reads ({}): use the "
                            "mcslam that made it, or a newer one",
                            version, kMapFormatVersion));
  if (version < 1) rd.Fail("version", fmt::format("{} is not a map format version", version));

  MapFile map;
  const json& cam = rd.Field(j, "camera", "");
  map.camera.fx = rd.Number(cam, "fx", "camera");
  map.camera.fy = rd.Number(cam, "fy", "camera");
  map.camera.cx = rd.Number(cam, "cx", "camera");
  map.camera.cy = rd.Number(cam, "cy", "camera");
  const int64_t w = rd.Integer(cam, "width", "camera"), h = rd.Integer(cam, "height", "camera");
  if (w <= 0 || h <= 0 || w > 1'000'000 || h > 1'000'000)
    rd.Fail("camera", fmt::format("image size {}x{} is not a camera's", w, h));
  map.camera.width = static_cast<int>(w);
  map.camera.height = static_cast<int>(h);
  map.camera.dist = {rd.Number(cam, "k1", "camera"), rd.Number(cam, "k2", "camera"), rd.Number(cam, "p1", "camera"),
                     rd.Number(cam, "p2", "camera"), rd.Number(cam, "k3", "camera")};
  // The lens model and k4 came with the fisheye model; a map without them is radial-tangential.
  if (cam.contains("k4")) map.camera.dist.k4 = rd.Number(cam, "k4", "camera");
  if (cam.contains("model")) {
    const json& m = cam["model"];
    if (!m.is_string()) rd.Fail("camera.model", "is not a string");
    const std::string model = m.get<std::string>();
    if (model == ToString(LensModel::kEquidistant))
      map.camera.dist.model = LensModel::kEquidistant;
    else if (model != ToString(LensModel::kRadialTangential))
      rd.Fail("camera.model", fmt::format("'{}' is not a lens model (radial-tangential or equidistant)", model));
  }
  try {
    map.camera.Check();
  } catch (const std::invalid_argument& e) {
    rd.Fail("camera", e.what());
  }
  map.options = rd.Field(j, "options", "");
  if (!map.options.is_object()) rd.Fail("options", "is not an object");

  const json& points = rd.Field(j, "points", "");
  if (!points.is_array()) rd.Fail("points", "is not an array");
  std::unordered_set<int64_t> ids;
  for (size_t i = 0; i < points.size(); ++i) {
    const std::string where = fmt::format("points[{}]", i);
    MapFilePoint p;
    p.id = rd.Integer(points[i], "id", where);
    if (p.id < 0 || p.id >= kMaxMapId) rd.Fail(where + ".id", fmt::format("{} is not a point id (0 .. 2^62)", p.id));
    if (!ids.insert(p.id).second) rd.Fail(where, fmt::format("point id {} is there twice", p.id));
    const std::vector<double> xyz = rd.Numbers(points[i], "xyz", where, 3);
    p.position_in_world = {xyz[0], xyz[1], xyz[2]};
    for (auto [key, out] : {std::pair{"descriptor", &p.descriptor}, std::pair{"first_descriptor", &p.first_descriptor}}) {
      if (!points[i].contains(key)) continue;
      const std::vector<double> d = rd.Numbers(points[i], key, where, kMapDescriptorLength);
      out->emplace();
      for (int k = 0; k < kMapDescriptorLength; ++k) {
        // Descriptors are floats: a finite double beyond a float's range would be written back as infinity.
        if (!(std::abs(d[k]) <= std::numeric_limits<float>::max()))
          rd.Fail(where + "." + key, fmt::format("holds {} (beyond a float's range)", d[k]));
        (**out)[k] = static_cast<float>(d[k]);
      }
    }
    map.points.push_back(std::move(p));
  }
  const json& keyframes = rd.Field(j, "keyframes", "");
  if (!keyframes.is_array()) rd.Fail("keyframes", "is not an array");
  for (size_t i = 0; i < keyframes.size(); ++i) {
    const std::string where = fmt::format("keyframes[{}]", i);
    const json& jk = keyframes[i];
    MapFileKeyframe k;
    k.index = rd.Integer(jk, "index", where);
    k.stamp_s = rd.Number(jk, "stamp", where);
    const std::vector<double> q = rd.Numbers(jk, "q", where, 4), t = rd.Numbers(jk, "t", where, 3);
    const Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
    if (std::abs(quat.norm() - 1.0) > 1e-6)
      rd.Fail(where + ".q", fmt::format("is not a unit quaternion (norm {:.9g})", quat.norm()));
    // Kept as written when it is unit to rounding (a map read back and written again is the same file);
    // normalised otherwise.
    k.cam_from_world.q = std::abs(quat.norm() - 1.0) > 1e-12 ? quat.normalized() : quat;
    k.cam_from_world.t = Eigen::Vector3d(t[0], t[1], t[2]);
    const json& jids = rd.Field(jk, "ids", where);
    if (!jids.is_array()) rd.Fail(where + ".ids", "is not an array");
    for (const json& e : jids) {
      if (!e.is_number_integer() || (e.is_number_unsigned() && e.get<uint64_t>() > static_cast<uint64_t>(INT64_MAX)))
        rd.Fail(where + ".ids", "holds something that is not an id");
      k.feature_ids.push_back(e.get<int64_t>());
      if (k.feature_ids.back() < 0 || k.feature_ids.back() >= kMaxMapId)
        rd.Fail(where + ".ids", fmt::format("{} is not a feature id (0 .. 2^62)", k.feature_ids.back()));
      if (k.feature_ids.size() > 1 && k.feature_ids.back() <= k.feature_ids[k.feature_ids.size() - 2])
        rd.Fail(where + ".ids", "are not in increasing order");
    }
    const std::vector<double> uv = rd.Numbers(jk, "uv", where, 2 * static_cast<long>(k.feature_ids.size()));
    for (size_t f = 0; f < k.feature_ids.size(); ++f) k.uv_px.emplace_back(uv[2 * f], uv[2 * f + 1]);
    map.keyframes.push_back(std::move(k));
  }
  return map;
}

MapFile ReadMapFile(const std::string& path) {
  detail::RequireRegularFileIfPresent(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(fmt::format("{}: cannot open the map file (missing or unreadable)", path));
  const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw std::runtime_error(fmt::format("{}: read error", path));
  return ParseMapFile(bytes, path);
}

}  // namespace mcslam::io
