// Map files (io/map_file.h): exact round trips, and every kind of bad file refused in words that name it.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "io/map_file.h"
#include "../test_util.h"

namespace mcslam::io {
namespace {

using mcslam::testing::ExpectThrowsWith;
using mcslam::testing::TempDir;

// Numbers with every bit of their mantissa in use (1/3, sines), so that any rounding on the way would show.
MapFile MakeMap(int points, int keyframes) {
  MapFile m;
  m.camera = PinholeCamera(525.0 + 1.0 / 3.0, 524.5, 319.7, 241.1, 640, 480, {0.1, -0.02, 1e-4, -2e-4, 1e-3});
  m.options = {{"backend", "cpu"}, {"system", {{"seed", 7}}}};
  for (int i = 0; i < points; ++i) {
    MapFilePoint p;
    p.id = 3 * i + 1;
    p.position_in_world = {std::sin(i) / 3.0, std::cos(i) * 1e-3, 2.0 + i / 7.0};
    if (i % 3 != 2) {
      p.descriptor.emplace();
      for (int k = 0; k < kMapDescriptorLength; ++k) (*p.descriptor)[k] = static_cast<float>(std::sin(i + k)) * 200.f;
    }
    if (i % 2 == 0) {
      p.first_descriptor.emplace();
      for (int k = 0; k < kMapDescriptorLength; ++k) (*p.first_descriptor)[k] = static_cast<float>(k) / 3.f;
    }
    m.points.push_back(p);
  }
  for (int k = 0; k < keyframes; ++k) {
    MapFileKeyframe f;
    f.index = 10 + k;
    f.stamp_s = k / 30.0;
    f.cam_from_world = Pose(Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * k + 1.0 / 3.0, Eigen::Vector3d(1, 2, 3).normalized())),
                            Eigen::Vector3d(k / 3.0, -k / 7.0, 0.5));
    for (int i = 0; i < 5 + k; ++i) {
      f.feature_ids.push_back(2 * i + k);
      f.uv_px.emplace_back(100.0 / 3.0 + i, 200.0 / 7.0 - i);
    }
    m.keyframes.push_back(f);
  }
  return m;
}

void ExpectSameMaps(const MapFile& a, const MapFile& b) {
  EXPECT_EQ(CameraDifference(a.camera, b.camera), "");
  EXPECT_EQ(a.camera.fx, b.camera.fx);  // bit for bit, not within the tolerance of CameraDifference
  EXPECT_EQ(a.camera.dist.p2, b.camera.dist.p2);
  EXPECT_EQ(a.options, b.options);
  ASSERT_EQ(a.points.size(), b.points.size());
  for (size_t i = 0; i < a.points.size(); ++i) {
    EXPECT_EQ(a.points[i].id, b.points[i].id);
    EXPECT_EQ(a.points[i].position_in_world, b.points[i].position_in_world);
    EXPECT_EQ(a.points[i].descriptor, b.points[i].descriptor);
    EXPECT_EQ(a.points[i].first_descriptor, b.points[i].first_descriptor);
  }
  ASSERT_EQ(a.keyframes.size(), b.keyframes.size());
  for (size_t k = 0; k < a.keyframes.size(); ++k) {
    EXPECT_EQ(a.keyframes[k].index, b.keyframes[k].index);
    EXPECT_EQ(a.keyframes[k].stamp_s, b.keyframes[k].stamp_s);
    EXPECT_EQ(a.keyframes[k].cam_from_world.q.coeffs(), b.keyframes[k].cam_from_world.q.coeffs());
    EXPECT_EQ(a.keyframes[k].cam_from_world.t, b.keyframes[k].cam_from_world.t);
    EXPECT_EQ(a.keyframes[k].feature_ids, b.keyframes[k].feature_ids);
    EXPECT_EQ(a.keyframes[k].uv_px, b.keyframes[k].uv_px);
  }
}

std::vector<uint8_t> ReadBytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void WriteBytes(const std::filesystem::path& p, const std::vector<uint8_t>& bytes) {
  std::ofstream out(p, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

TEST(MapFile, RoundTripIsExactToTheByte) {
  TempDir dir;
  const MapFile m = MakeMap(40, 6);
  WriteMapFile(dir / "a.map", m);
  const MapFile back = ReadMapFile(dir / "a.map");
  ExpectSameMaps(m, back);
  WriteMapFile(dir / "b.map", back);
  EXPECT_EQ(ReadBytes(dir / "a.map"), ReadBytes(dir / "b.map"));
}

// A fisheye camera keeps its model and k4 (a map of a radial-tangential camera written before them reads as such).
TEST(MapFile, AFisheyeCameraRoundTrips) {
  TempDir dir;
  MapFile m = MakeMap(10, 3);
  m.camera.dist = Distortion::Equidistant(0.0034, 0.0007, -0.002, 0.0002);
  WriteMapFile(dir / "f.map", m);
  const MapFile back = ReadMapFile(dir / "f.map");
  ExpectSameMaps(m, back);
  EXPECT_EQ(back.camera.dist.model, LensModel::kEquidistant);
  EXPECT_EQ(back.camera.dist.k4, 0.0002);
  PinholeCamera pinhole = m.camera;
  pinhole.dist.model = LensModel::kRadialTangential;
  pinhole.dist.k4 = 0;
  EXPECT_NE(CameraDifference(m.camera, pinhole).find("lens model equidistant against radial-tangential"),
            std::string::npos);
}

TEST(MapFile, AnEmptyMapRoundTrips) {
  TempDir dir;
  const MapFile m = MakeMap(0, 0);
  WriteMapFile(dir / "e.map", m);
  ExpectSameMaps(m, ReadMapFile(dir / "e.map"));
}

TEST(MapFile, MissingFolderAndEmptyFilesAreNamed) {
  TempDir dir;
  ExpectThrowsWith([&] { ReadMapFile(dir / "nope.map"); }, "nope.map", "cannot open");
  ExpectThrowsWith([&] { ReadMapFile(dir.path().string()); }, "is a folder");
  WriteBytes(dir / "empty.map", {});
  ExpectThrowsWith([&] { ReadMapFile(dir / "empty.map"); }, "empty.map", "is empty");
}

TEST(MapFile, EveryTruncationIsRefusedNamingTheFile) {
  TempDir dir;
  const std::vector<uint8_t> bytes = SerialiseMapFile(MakeMap(5, 2));
  // Every cut: none may parse into a map (a cut CBOR document is never complete) or crash.
  for (size_t n = 1; n < bytes.size(); n += 1) {
    const std::vector<uint8_t> cut(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(n));
    try {
      ParseMapFile(cut, "cut.map");
      ADD_FAILURE() << "a cut at " << n << " of " << bytes.size() << " bytes was read as a map";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("cut.map"), std::string::npos) << e.what();
    }
  }
  WriteBytes(dir / "half.map", std::vector<uint8_t>(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(bytes.size() / 2)));
  ExpectThrowsWith([&] { ReadMapFile(dir / "half.map"); }, "half.map", "truncated or corrupt");
}

TEST(MapFile, RandomBytesAndOtherDocumentsAreNotMaps) {
  std::mt19937 rng(5);
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<uint8_t> junk(1 + rng() % 2000);
    for (uint8_t& b : junk) b = static_cast<uint8_t>(rng());
    ExpectThrowsWith([&] { ParseMapFile(junk, "junk.map"); }, "junk.map");
  }
  ExpectThrowsWith([&] { ParseMapFile(nlohmann::json::to_cbor(nlohmann::json{{"format", "ply"}}), "other.map"); },
                   "other.map", "is not an mcslam map file");
  ExpectThrowsWith([&] { ParseMapFile(nlohmann::json::to_cbor(nlohmann::json::array({1, 2})), "arr.map"); },
                   "is not an mcslam map file");
}

// The document of a good map with one change made to it.
std::vector<uint8_t> Edited(const std::function<void(nlohmann::json&)>& edit) {
  nlohmann::json j = nlohmann::json::from_cbor(SerialiseMapFile(MakeMap(4, 2)));
  edit(j);
  return nlohmann::json::to_cbor(j);
}

TEST(MapFile, DeepNestingIsRefusedNotAStackOverflow) {
  // A million nested one-element arrays inside "options": the CBOR reader would recurse a million times.
  std::vector<uint8_t> bytes = nlohmann::json::to_cbor(nlohmann::json{{"format", "mcslam-map"}, {"version", 1}});
  bytes[0] = 0xA3;  // the map now has 3 pairs: the third follows
  const std::vector<uint8_t> key = nlohmann::json::to_cbor("options");
  bytes.insert(bytes.end(), key.begin(), key.end());
  bytes.insert(bytes.end(), 1'000'000, 0x81);
  bytes.push_back(0xF6);  // null, the innermost element
  ExpectThrowsWith([&] { ParseMapFile(bytes, "deep.map"); }, "deep.map", "nested deeper than");
}

TEST(MapFile, IdsOutOfRangeAreRefused) {
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["points"][0]["id"] = -4; }), "m"); },
                   "points[0].id", "not a point id");
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["points"][0]["id"] = uint64_t{1} << 63; }), "m"); },
                   "points[0].id", "out of range");
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["keyframes"][1]["ids"][0] = -1; }), "m"); },
                   "keyframes[1].ids", "not a feature id");
}

TEST(MapFile, ANewerVersionSaysSo) {
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["version"] = kMapFormatVersion + 1; }), "new.map"); },
                   "new.map", "newer than this mcslam reads");
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["version"] = 0; }), "old.map"); },
                   "not a map format version");
}

TEST(MapFile, BadFieldsAreNamed) {
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["camera"].erase("fx"); }), "m"); }, "camera.fx",
                   "missing");
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["camera"]["fx"] = -5.0; }), "m"); }, "camera");
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["camera"]["width"] = 0; }), "m"); },
                   "image size 0x480");
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["points"][1]["xyz"] = {1.0, 2.0}; }), "m"); },
                   "points[1].xyz", "has 2 numbers, 3 expected");
  ExpectThrowsWith(
      [] { ParseMapFile(Edited([](nlohmann::json& j) { j["points"][0]["xyz"][2] = std::numeric_limits<double>::infinity(); }), "m"); },
      "points[0].xyz", "not finite");
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["points"][2]["id"] = j["points"][0]["id"]; }), "m"); },
                   "points[2]", "is there twice");
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["points"][0]["descriptor"] = {1, 2, 3}; }), "m"); },
                   "points[0].descriptor", "has 3 numbers, 128 expected");
  // A finite double that no float holds (fuzz_map found it: it was read as infinity and then refused when
  // written).
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["points"][1]["descriptor"][7] = 1e300; }), "m"); },
                   "points[1].descriptor", "beyond a float's range");
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["keyframes"][1]["q"] = {2.0, 0.0, 0.0, 0.0}; }), "m"); },
                   "keyframes[1].q", "not a unit quaternion");
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["keyframes"][0]["ids"][1] = 0; }), "m"); },
                   "keyframes[0].ids", "increasing");
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["keyframes"][0]["uv"].erase(0); }), "m"); },
                   "keyframes[0].uv", "expected");
  ExpectThrowsWith([] { ParseMapFile(Edited([](nlohmann::json& j) { j["options"] = 3; }), "m"); }, "options",
                   "not an object");
}

TEST(MapFile, AMapThatBreaksItsRulesIsNotWritten) {
  TempDir dir;
  MapFile m = MakeMap(3, 1);
  m.points[1].position_in_world.x() = std::nan("");
  ExpectThrowsWith([&] { WriteMapFile(dir / "nan.map", m); }, "map point 4", "not finite");
  m = MakeMap(3, 1);
  m.points[2].id = m.points[0].id;
  ExpectThrowsWith([&] { WriteMapFile(dir / "dup.map", m); }, "there twice");
  m = MakeMap(3, 1);
  m.keyframes[0].uv_px.pop_back();
  ExpectThrowsWith([&] { WriteMapFile(dir / "uv.map", m); }, "feature ids but");
  ExpectThrowsWith([&] { WriteMapFile(dir / "no/such/folder.map", MakeMap(1, 1)); }, "folder.map",
                   "cannot open");
}

TEST(MapFile, CameraDifferenceNamesWhatDiffers) {
  const PinholeCamera a(500, 500, 160, 120, 320, 240);
  EXPECT_EQ(CameraDifference(a, a), "");
  PinholeCamera b = a;
  b.fx = 510;
  EXPECT_EQ(CameraDifference(a, b), "fx 500 against 510");
  b = a;
  b.width = 640;
  EXPECT_NE(CameraDifference(a, b).find("size 320x240 against 640x240"), std::string::npos);
  b = a;
  b.dist.k1 = 1e-3;
  EXPECT_NE(CameraDifference(a, b).find("k1"), std::string::npos);
  b = a;
  b.cx += 1e-12;  // below the relative 1e-9: the same camera written with other rounding
  EXPECT_EQ(CameraDifference(a, b), "");
}

}  // namespace
}  // namespace mcslam::io
