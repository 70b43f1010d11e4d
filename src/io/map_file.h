#pragma once
// Map files (`mcslam run --save-map` / `--load-map`): what a later run needs to localise in a map and extend
// it: the camera, the map points (id, position, SIFT descriptor when one is known), the keyframes (pose and
// undistorted features), the options of the run that made it. One CBOR document (RFC 8949, through nlohmann
// json), described field by field in docs/map_format.md:
//   {"format": "mcslam-map", "version": 1, "camera": {...}, "options": {...},
//    "points": [{"id", "xyz": [x, y, z], "descriptor": [128], "first_descriptor": [128]} (each absent when none)],
//    "keyframes": [{"index", "stamp", "q": [w, x, y, z], "t": [x, y, z], "ids": [...], "uv": [u0, v0, ...]}]}
// Every number is stored exactly (CBOR float64, or float32 where that holds the value exactly, as nlohmann
// writes them): a map read back and written again gives the same bytes. Keyframes keep the features the run
// still held (SystemOptions' history: the last 1000 frames by default); older keyframes are saved with none.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "core/camera.h"
#include "core/pose.h"

namespace mcslam::io {

inline constexpr int kMapFormatVersion = 1;
inline constexpr int kMapDescriptorLength = 128;

struct MapFilePoint {
  int64_t id = 0;
  Eigen::Vector3d position_in_world = Eigen::Vector3d::Zero();
  // SIFT descriptors: the latest (of its track when the run ended, or when its track ended) and the one of
  // its track when the point joined the map; either may be absent.
  std::optional<std::array<float, kMapDescriptorLength>> descriptor, first_descriptor;
};

struct MapFileKeyframe {
  int64_t index = 0;  // the frame's index in the run that made the map
  double stamp_s = 0;
  Pose cam_from_world;
  std::vector<int64_t> feature_ids;      // sorted, unique
  std::vector<Eigen::Vector2d> uv_px;    // undistorted pixels, one per id
};

struct MapFile {
  PinholeCamera camera;
  nlohmann::json options = nlohmann::json::object();  // the run's options (report.json's "options")
  std::vector<MapFilePoint> points;
  std::vector<MapFileKeyframe> keyframes;  // in the order the run posed them
};

// Writes `map` to `path` (replaced). Throws std::runtime_error naming the file when it cannot be written, and
// std::invalid_argument for a map that breaks its own rules (non-finite numbers, ids out of order).
void WriteMapFile(const std::string& path, const MapFile& map);
// Reads a map file. Throws std::runtime_error naming the file and what is wrong: missing, not a regular file,
// not CBOR or truncated, not an mcslam map, made by a newer format version, a field missing or of the wrong
// type, a camera that fails its checks, non-finite numbers, duplicate point ids.
MapFile ReadMapFile(const std::string& path);
// The same from bytes (`what` names the source in errors): the fuzz target's entry.
MapFile ParseMapFile(const std::vector<uint8_t>& bytes, const std::string& what);
std::vector<uint8_t> SerialiseMapFile(const MapFile& map);

// Empty when the two cameras are the same (intrinsics, size and distortion to a relative 1e-9), else what
// differs, e.g. "fx 525 against 520".
std::string CameraDifference(const PinholeCamera& a, const PinholeCamera& b);

}  // namespace mcslam::io
