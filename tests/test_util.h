#pragma once
#include <algorithm>
// Helpers shared by the tests: scratch folders and running the mcslam binary.
#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <string>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include "core/pose.h"

namespace mcslam::testing {

// A fresh folder under the system temp dir, removed with everything in it when the object dies.
class TempDir {
 public:
  TempDir() {
    std::random_device rd;
    path_ = std::filesystem::temp_directory_path() / ("mcslam_test_" + std::to_string(rd()) + std::to_string(rd()));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::string operator/(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};

// Runs a shell command line; `output` is what it writes to stdout (add 2>&1 for stderr too).
inline CommandResult RunShell(const std::string& cmd) {
  CommandResult r;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf{};
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.output.append(buf.data(), n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// Runs `mcslam <args>` (the binary this build made) through the shell, stdout and stderr together.
inline CommandResult RunMcslam(const std::string& args) { return RunShell(std::string(MCSLAM_BIN) + " " + args + " 2>&1"); }

inline void WriteText(const std::string& path, const std::string& text) {
  std::ofstream f(path);
  f << text;
}

inline std::string ReadText(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// Lines of a text file that are neither empty nor '#' comments.
inline int CountDataLines(const std::string& path) {
  std::istringstream in(ReadText(path));
  std::string line;
  int n = 0;
  while (std::getline(in, line))
    if (!line.empty() && line[0] != '#') ++n;
  return n;
}

// Lines of a CSV file (header first) whose number of comma-separated cells differs from the header's, as
// "line N: K cells, the header has H"; empty when every line has the header's shape.
inline std::vector<std::string> CsvShapeErrors(const std::string& path) {
  std::istringstream in(ReadText(path));
  std::string line;
  std::vector<std::string> errors;
  auto cells = [](const std::string& l) { return 1 + static_cast<int>(std::count(l.begin(), l.end(), ',')); };
  if (!std::getline(in, line)) return {"no header"};
  const int header = cells(line);
  for (int n = 2; std::getline(in, line); ++n)
    if (!line.empty() && cells(line) != header)
      errors.push_back("line " + std::to_string(n) + ": " + std::to_string(cells(line)) + " cells, the header has " +
                       std::to_string(header));
  return errors;
}

// The cells of the column named `name` of a CSV file, one per data line (empty when the header has no such column).
inline std::vector<std::string> CsvColumn(const std::string& path, const std::string& name) {
  std::istringstream in(ReadText(path));
  auto split = [](const std::string& l) {
    std::vector<std::string> c(1);
    for (char ch : l) {
      if (ch == ',') c.emplace_back();
      else c.back().push_back(ch);
    }
    return c;
  };
  std::string line;
  if (!std::getline(in, line)) return {};
  const std::vector<std::string> header = split(line);
  const auto col = std::find(header.begin(), header.end(), name);
  if (col == header.end()) return {};
  const size_t k = static_cast<size_t>(col - header.begin());
  std::vector<std::string> out;
  while (std::getline(in, line))
    if (!line.empty()) {
      const std::vector<std::string> c = split(line);
      out.push_back(k < c.size() ? c[k] : std::string());
    }
  return out;
}

// Folder of the real sequences: $MCSLAM_DATA, else ../shared/data beside the source tree. Empty when absent.
inline std::string DataDir() {
  if (const char* env = std::getenv("MCSLAM_DATA"); env && *env) return env;
  if (std::filesystem::is_directory(MCSLAM_DATA_DIR_DEFAULT)) return MCSLAM_DATA_DIR_DEFAULT;
  return "";
}

// Expects f to throw an exception whose message contains needle1 (and needle2 when given).
inline void ExpectThrowsWith(const std::function<void()>& f, const std::string& needle1, const std::string& needle2 = "") {
  try {
    f();
    ADD_FAILURE() << "no exception; expected one containing '" << needle1 << "'";
  } catch (const std::exception& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(needle1), std::string::npos) << what;
    if (!needle2.empty()) {
      EXPECT_NE(what.find(needle2), std::string::npos) << what;
    }
  }
}

// A camera at center_in_world looking at target_in_world, world +z up (camera y down): cam_from_world.
inline Pose LookAt(const Eigen::Vector3d& center_in_world, const Eigen::Vector3d& target_in_world) {
  const Eigen::Vector3d z = (target_in_world - center_in_world).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d world_from_cam_rot;
  world_from_cam_rot << x, y, z;
  return Pose::FromRotationTranslation(world_from_cam_rot, center_in_world).Inverse();
}

}  // namespace mcslam::testing
