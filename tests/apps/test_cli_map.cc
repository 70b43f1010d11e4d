// `mcslam run --save-map / --load-map`: a second run of a sequence localised in the first run's map, on the
// rendered paper scenario and on 7-Scenes, and map files that cannot be used refused before any frame.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cli_report.h"
#include "io/map_file.h"
#include "test_util.h"

namespace mcslam {
namespace {

namespace fs = std::filesystem;
using testing::CsvColumn;
using testing::Field;
using testing::ReadJson;
using testing::RunMcslam;
using testing::TempDir;

struct TwoRuns {
  nlohmann::json first, second;  // report.json of each
  std::string first_dir, second_dir, second_output;
  double second_in_first_units = 0;  // ATE of the second trajectory against the first, no alignment at all
};

// Runs `input FLAGS` once with --save-map, then again with --load-map of that map; both must succeed.
TwoRuns RunTwice(const TempDir& dir, const std::string& input, const std::string& flags) {
  TwoRuns t;
  t.first_dir = dir / "first";
  t.second_dir = dir / "second";
  const auto r1 = RunMcslam(fmt::format("run {} {} --out {} --save-map {}", input, flags, t.first_dir, dir / "first.map"));
  EXPECT_EQ(r1.exit_code, 0) << r1.output;
  const auto r2 = RunMcslam(fmt::format("run {} {} --out {} --load-map {} --save-map {}", input, flags, t.second_dir,
                                        dir / "first.map", dir / "second.map"));
  EXPECT_EQ(r2.exit_code, 0) << r2.output;
  t.second_output = r2.output;
  if (r1.exit_code != 0 || r2.exit_code != 0) return t;
  t.first = ReadJson(t.first_dir + "/report.json");
  t.second = ReadJson(t.second_dir + "/report.json");
  const auto e = RunMcslam(fmt::format("eval {}/trajectory.txt {}/trajectory.txt --align none", t.first_dir, t.second_dir));
  EXPECT_EQ(e.exit_code, 0) << e.output;
  t.second_in_first_units = Field(e.output, "ate_rmse");
  return t;
}

// What a run in a loaded map must show: every frame posed from the first one, by relocalisation in the map at
// frame 0; the poses in the first run's frame and scale, with no alignment (the issue: within 2x the first
// run's own ATE); the map extended and saved again.
void ExpectLocalisedInTheFirstMap(const TwoRuns& t, int frames, std::optional<double> max_scale_change) {
  ASSERT_FALSE(t.first.is_null());
  ASSERT_FALSE(t.second.is_null());
  EXPECT_EQ(t.second["tracked"].get<int>(), frames) << t.second_output;
  EXPECT_EQ(CsvColumn(t.second_dir + "/frames.csv", "status").at(0), "tracked");
  EXPECT_NE(t.second_output.find("frame 0: relocalised"), std::string::npos) << t.second_output;
  const double scale1 = t.first["ground_truth"]["scale"], scale2 = t.second["ground_truth"]["scale"];
  const double ate1 = t.first["ground_truth"]["ate_m"]["rmse"];
  const double second_m = t.second_in_first_units * scale1;  // metres, through the first run's alignment scale
  std::printf("first run: ATE %.4f m, scale %.5f; second run: scale %.5f, %.4f m from the first run unaligned\n", ate1,
              scale1, scale2, second_m);
  EXPECT_LE(second_m, 2.0 * ate1);
  if (max_scale_change) {
    EXPECT_NEAR(scale2 / scale1, 1.0, *max_scale_change);
  }
  EXPECT_GT(t.second["map_points"].get<int>(), t.first["map_points"].get<int>());
  EXPECT_EQ(t.second["map_files"]["loaded"], t.first["map_files"]["saved"]);
}

// Measured (docs/map_seeds.md, scripts/map_seeds.sh), rendered paper scenario seeds 1-8: the second run relocalised at
// frame 0 and tracked 300/300 on every seed; unaligned, it is 0.72-2.30x the first run's ATE from the first run's
// poses (seed 1: 4.8 mm against 3.3 mm, 1.44x), its Sim(3) scale within 0.13 % of the first's on seed 1 (2.3 % at
// most, seed 4). Seed 4's 2.30x is the first run's own early poses: they were placed before later adjustments moved
// the points they see (~1 px off its final map), and the second run, placed against that final map, is 10.0 mm from
// the truth against the first run's 20.1. Bounds: the 2x, and 2 % of scale (15x seed 1's).
TEST(CliMap, ASecondRunLocalisesInTheFirstRunsMapFromItsFirstFrame) {
  TempDir dir;
  const auto s = RunMcslam(fmt::format("synth --scenario paper --seed 1 --render --out {}", dir / "scene"));
  ASSERT_EQ(s.exit_code, 0) << s.output;
  const TwoRuns t = RunTwice(dir, dir / "scene", "--dataset synthetic");
  ExpectLocalisedInTheFirstMap(t, 300, 0.02);
}

// 7-Scenes, seeds 1-8 (docs/map_seeds.md): relocalised at frame 0, 300/300; unaligned, 5.9-7.4 mm from the first
// run's poses against its own ATE of 36.7-39.0 mm (0.16-0.19x; the bound is 2x), the second run's Sim(3)
// scale within 0.9 % of the first's. Before the Monte Carlo point adjustment held the loaded points (558445f) it
// re-sampled those over its candidate threshold, and the second run followed them out of the map: 10.1-27.9 mm
// (0.26-0.74x) on an AVX-512 machine, and on the portable x86-64-v3 build with the start's adjustments solved
// iteratively 122 mm (3.4x, 9.6 % of scale). No scale bound here beyond what the unaligned error already holds.
TEST(CliMapReal, SevenScenesLocalisesInItsOwnMap) {
  REAL_SEQUENCE_OR_SKIP(seq, "7scenes_redkitchen_frames000-299");
  TempDir dir;
  testing::WriteText(dir / "camera.txt", "525 525 320 240\n");
  const TwoRuns t = RunTwice(dir, seq, fmt::format("--camera {}", dir / "camera.txt"));
  ExpectLocalisedInTheFirstMap(t, 300, std::nullopt);
}

std::vector<uint8_t> Bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void WriteBytes(const std::string& path, const std::vector<uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

// Every one refused with exit 1, naming the file and what is wrong, before any frame is processed (no
// outputs but the folder).
TEST(CliMap, MapFilesThatCannotBeUsedAreClearErrorsBeforeAnyFrame) {
  TempDir dir;
  ASSERT_EQ(RunMcslam(fmt::format("synth --scenario paper --frames 40 --render --out {}", dir / "scene")).exit_code, 0);
  const auto made = RunMcslam(fmt::format("run {} --dataset synthetic --out {} --save-map {}", dir / "scene",
                                          dir / "made", dir / "good.map"));
  ASSERT_EQ(made.exit_code, 0) << made.output;
  const std::vector<uint8_t> good = Bytes(dir / "good.map");
  ASSERT_GT(good.size(), 1000u);
  WriteBytes(dir / "truncated.map", std::vector<uint8_t>(good.begin(), good.begin() + static_cast<long>(good.size() / 3)));
  std::vector<uint8_t> noise(4096);
  for (size_t i = 0; i < noise.size(); ++i) noise[i] = static_cast<uint8_t>((i * 2654435761u) >> 13);
  WriteBytes(dir / "noise.map", noise);
  nlohmann::json doc = nlohmann::json::from_cbor(good);
  doc["version"] = io::kMapFormatVersion + 1;
  WriteBytes(dir / "newer.map", nlohmann::json::to_cbor(doc));
  const std::string scene = dir / "scene";
  const struct {
    std::string flags, needle1, needle2;
  } cases[] = {
      {"--load-map " + dir / "missing.map", "missing.map", "cannot open"},
      {"--load-map " + dir / "truncated.map", "truncated.map", "truncated or corrupt"},
      {"--load-map " + dir / "noise.map", "noise.map", "not an mcslam map file"},
      {"--load-map " + dir / "newer.map", "newer.map", "newer than this mcslam reads"},
      {"--load-map " + dir.path().string(), "is a folder", ""},
      // The rendered camera is f = 500: a map is tied to its camera.
      {"--load-map " + dir / "good.map" + " --camera '510 500 159.5 119.5'", "another camera", "fx 500 against 510"},
      {"--load-map " + dir / "good.map" + " --no-relocalise", "--load-map", "relocalis"},
      {"--load-map " + dir / "good.map" + " --gt-scale", "--gt-scale", "the map sets the scale"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.flags);
    const std::string out = dir / "out";
    fs::remove_all(out);
    const auto r = RunMcslam(fmt::format("run {} --dataset synthetic --out {} {}", scene, out, c.flags));
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find(c.needle1), std::string::npos) << r.output;
    EXPECT_NE(r.output.find(c.needle2), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(out + "/frames.csv")) << r.output;
  }
}

// A run in a map of somewhere else (the rendered poster on a wall, in the map of the paper's box): no frame
// relocalised, every frame reported lost, exit status 3 as for a run that never initialised, outputs written.
TEST(CliMap, ARunThatNeverFindsTheMapSaysSo) {
  TempDir dir;
  ASSERT_EQ(RunMcslam(fmt::format("synth --scenario paper --frames 40 --render --out {}", dir / "box")).exit_code, 0);
  ASSERT_EQ(RunMcslam(fmt::format("synth --scenario planar --frames 15 --render --out {}", dir / "wall")).exit_code, 0);
  ASSERT_EQ(RunMcslam(fmt::format("run {} --dataset synthetic --out {} --save-map {}", dir / "box", dir / "b",
                                  dir / "box.map"))
                .exit_code,
            0);
  const auto r = RunMcslam(fmt::format("run {} --dataset synthetic --out {} --load-map {}", dir / "wall", dir / "w",
                                       dir / "box.map"));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("no frame was relocalised in the map"), std::string::npos) << r.output;
  const nlohmann::json report = ReadJson(dir / "w/report.json");
  EXPECT_EQ(report["tracked"].get<int>(), 0);
  EXPECT_EQ(report["lost"].get<int>(), 15);
}

}  // namespace
}  // namespace mcslam
