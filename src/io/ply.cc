#include "io/ply.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <fmt/format.h>

#include "io/text_util.h"

namespace mcslam::io {
namespace {

using detail::LineReader;

struct PlyProperty {
  std::string name;
  std::string type;       // scalar type, or the item type of a list
  bool is_list = false;
  bool is_integer = false;
};

struct PlyElement {
  std::string name;
  int64_t count = 0;
  std::vector<PlyProperty> properties;
};

bool IsIntegerType(const std::string& t) {
  return t == "char" || t == "uchar" || t == "short" || t == "ushort" || t == "int" || t == "uint" || t == "int8" ||
         t == "uint8" || t == "int16" || t == "uint16" || t == "int32" || t == "uint32";
}

bool IsKnownType(const std::string& t) {
  return IsIntegerType(t) || t == "float" || t == "double" || t == "float32" || t == "float64";
}

int FindProperty(const PlyElement& e, const std::string& name) {
  for (size_t i = 0; i < e.properties.size(); ++i)
    if (e.properties[i].name == name && !e.properties[i].is_list) return static_cast<int>(i);
  return -1;
}

}  // namespace

void WritePly(const std::string& path, const PointCloud& cloud) {
  const size_t n = cloud.points.size();
  if (!cloud.ids.empty() && cloud.ids.size() != n)
    throw std::invalid_argument(fmt::format("{}: {} ids for {} points", path, cloud.ids.size(), n));
  if (!cloud.rgb.empty() && cloud.rgb.size() != n)
    throw std::invalid_argument(fmt::format("{}: {} colours for {} points", path, cloud.rgb.size(), n));
  for (size_t i = 0; i < n; ++i)
    if (!cloud.points[i].allFinite()) throw std::invalid_argument(fmt::format("{}: point {} is not finite", path, i));
  // PLY's "int" is 32-bit; ids beyond it would be silently cut by other readers.
  for (int64_t id : cloud.ids)
    if (id < std::numeric_limits<int32_t>::min() || id > std::numeric_limits<int32_t>::max())
      throw std::invalid_argument(fmt::format("{}: point id {} does not fit in a PLY int (32-bit)", path, id));

  std::ofstream out = detail::OpenForWrite(path);
  out << "ply\nformat ascii 1.0\ncomment mcslam\n";
  out << "element vertex " << n << "\n";
  out << "property double x\nproperty double y\nproperty double z\n";
  if (!cloud.rgb.empty()) out << "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  if (!cloud.ids.empty()) out << "property int id\n";
  out << "end_header\n";
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d& p = cloud.points[i];
    std::string line = fmt::format("{:.17g} {:.17g} {:.17g}", p.x(), p.y(), p.z());
    if (!cloud.rgb.empty()) line += fmt::format(" {} {} {}", int(cloud.rgb[i][0]), int(cloud.rgb[i][1]), int(cloud.rgb[i][2]));
    if (!cloud.ids.empty()) line += fmt::format(" {}", cloud.ids[i]);
    out << line << '\n';
  }
  detail::FinishWrite(out, path);
}

PointCloud ReadPly(const std::string& path) {
  LineReader r(path);
  std::string line;
  if (!r.Next(line) || detail::Trim(line) != "ply") r.Fail("not a PLY file (first line must be 'ply')");

  // ---- header
  std::vector<PlyElement> elements;
  bool have_format = false, have_end = false;
  while (r.Next(line)) {
    const auto tok = detail::SplitWhitespace(line);
    if (tok.empty()) continue;
    const std::string_view key = tok[0];
    if (key == "comment" || key == "obj_info") continue;
    if (key == "end_header") {
      have_end = true;
      break;
    }
    if (key == "format") {
      if (tok.size() < 2) r.Fail("malformed format line");
      if (tok[1] == "binary_little_endian" || tok[1] == "binary_big_endian")
        r.Fail(fmt::format("binary PLY not supported ({}); convert it to ASCII first", tok[1]));
      if (tok[1] != "ascii") r.Fail(fmt::format("unknown PLY format '{}'", tok[1]));
      have_format = true;
    } else if (key == "element") {
      if (tok.size() != 3) r.Fail("malformed element line (expected 'element <name> <count>')");
      PlyElement e;
      e.name = std::string(tok[1]);
      e.count = detail::ParseInteger(tok[2], r, "element count");
      if (e.count < 0) r.Fail("negative element count");
      elements.push_back(e);
    } else if (key == "property") {
      if (elements.empty()) r.Fail("property before any element");
      PlyProperty p;
      if (tok.size() == 5 && tok[1] == "list") {
        if (!IsIntegerType(std::string(tok[2])) || !IsKnownType(std::string(tok[3])))
          r.Fail(fmt::format("unknown list types '{} {}'", tok[2], tok[3]));
        p.is_list = true;
        p.type = std::string(tok[3]);
        p.name = std::string(tok[4]);
      } else if (tok.size() == 3) {
        p.type = std::string(tok[1]);
        p.name = std::string(tok[2]);
        if (!IsKnownType(p.type)) r.Fail(fmt::format("unknown property type '{}'", p.type));
      } else {
        r.Fail("malformed property line");
      }
      p.is_integer = IsIntegerType(p.type);
      elements.back().properties.push_back(p);
    } else {
      r.Fail(fmt::format("unknown header keyword '{}'", key));
    }
  }
  if (!have_end) detail::Fail(path, "PLY header has no end_header line");
  if (!have_format) detail::Fail(path, "PLY header has no format line");

  size_t vertex_index = elements.size();
  for (size_t i = 0; i < elements.size(); ++i)
    if (elements[i].name == "vertex") {
      vertex_index = i;
      break;
    }
  if (vertex_index == elements.size()) detail::Fail(path, "PLY file has no vertex element");
  const PlyElement& vertex = elements[vertex_index];
  const int ix = FindProperty(vertex, "x"), iy = FindProperty(vertex, "y"), iz = FindProperty(vertex, "z");
  for (auto [idx, name] : {std::pair{ix, "x"}, std::pair{iy, "y"}, std::pair{iz, "z"}})
    if (idx < 0) detail::Fail(path, fmt::format("PLY vertex element has no '{}' property", name));
  const int ir = FindProperty(vertex, "red"), ig = FindProperty(vertex, "green"), ib = FindProperty(vertex, "blue");
  const bool has_rgb = ir >= 0 && ig >= 0 && ib >= 0;
  const int iid = FindProperty(vertex, "id");
  if (iid >= 0 && !vertex.properties[iid].is_integer)
    detail::Fail(path, fmt::format("PLY vertex property 'id' has type {}, expected an integer type",
                                   vertex.properties[iid].type));

  // ---- body: in ASCII PLY every element instance is one line
  auto next_data_line = [&](const std::string& what) {
    do {
      if (!r.Next(line)) detail::Fail(path, fmt::format("file ends before {}", what));
    } while (detail::Trim(line).empty());
  };
  for (size_t e = 0; e < vertex_index; ++e)
    for (int64_t k = 0; k < elements[e].count; ++k)
      next_data_line(fmt::format("all {} '{}' elements were read", elements[e].count, elements[e].name));

  PointCloud cloud;
  cloud.points.reserve(static_cast<size_t>(std::min<int64_t>(vertex.count, 1 << 20)));  // the header may lie
  std::vector<double> values(vertex.properties.size());
  for (int64_t k = 0; k < vertex.count; ++k) {
    next_data_line(fmt::format("all {} vertices were read (got {})", vertex.count, k));
    const auto tok = detail::SplitWhitespace(line);
    size_t t = 0;
    for (size_t p = 0; p < vertex.properties.size(); ++p) {
      const PlyProperty& prop = vertex.properties[p];
      if (t >= tok.size()) r.Fail(fmt::format("vertex line has too few values (property '{}' missing)", prop.name));
      if (prop.is_list) {  // skipped: count, then that many items
        const int64_t len = detail::ParseInteger(tok[t], r, fmt::format("list length of '{}'", prop.name));
        if (len < 0) r.Fail(fmt::format("negative list length for '{}'", prop.name));
        t += 1 + static_cast<size_t>(len);
        continue;
      }
      if (static_cast<int>(p) == iid) {
        cloud.ids.push_back(detail::ParseInteger(tok[t], r, "id"));
      } else if (static_cast<int>(p) == ix || static_cast<int>(p) == iy || static_cast<int>(p) == iz ||
                 (has_rgb && (static_cast<int>(p) == ir || static_cast<int>(p) == ig || static_cast<int>(p) == ib))) {
        values[p] = detail::ParseFinite(tok[t], r, prop.name);
      }  // other properties are skipped unparsed
      ++t;
    }
    if (t != tok.size())
      r.Fail(fmt::format("vertex line has {} values, the header declares {}", tok.size(), t));
    cloud.points.emplace_back(values[ix], values[iy], values[iz]);
    if (has_rgb) {
      Eigen::Matrix<uint8_t, 3, 1> c;
      int ch = 0;
      for (int idx : {ir, ig, ib}) {
        const double v = values[idx];
        if (v < 0 || v > 255 || v != std::floor(v))
          r.Fail(fmt::format("colour '{}' = {} is not an integer in 0..255", vertex.properties[idx].name, v));
        c[ch++] = static_cast<uint8_t>(v);
      }
      cloud.rgb.push_back(c);
    }
  }
  return cloud;  // elements after the vertices (faces, ...) are not needed and not read
}

}  // namespace mcslam::io
