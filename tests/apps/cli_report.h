#pragma once
// What the CLI tests read back from a run: fields of the summary line and report.json.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <regex>
#include <string>

#include <nlohmann/json.hpp>

#include "test_util.h"

namespace mcslam::testing {

// The value of `key=` in the summary line, NaN when absent.
inline double Field(const std::string& output, const std::string& key) {
  std::smatch m;
  if (!std::regex_search(output, m, std::regex("(^|\\s)" + key + "=([^\\s]+)"))) return std::nan("");
  return std::stod(m[2].str());
}

inline nlohmann::json ReadJson(const std::string& path) {
  std::ifstream f(path);
  return nlohmann::json::parse(f);
}

// Every `mcslam run` reports its wall time, the process's CPU time (user + system, every thread) and their
// ratio, in report.json and on its summary line (`output`). They must be there and make sense: some CPU
// time was used, the parts add up, and the ratio is at most the machine's hardware threads plus one (the
// margin: the kernel accounts CPU time per scheduler tick, so a short run may be over by a fraction of a core).
inline void ExpectSaneRunTimes(const std::string& output, const std::string& report_path) {
  const nlohmann::json j = ReadJson(report_path);
  for (const char* key : {"wall_s", "cpu_user_s", "cpu_sys_s", "cpu_s", "cpu_ratio", "hardware_threads"})
    ASSERT_TRUE(j.contains(key) && j[key].is_number()) << key << " missing from " << report_path << ": " << j.dump();
  const double wall = j["wall_s"], user = j["cpu_user_s"], sys = j["cpu_sys_s"], cpu = j["cpu_s"], ratio = j["cpu_ratio"];
  const int threads = j["hardware_threads"];
  EXPECT_GT(wall, 0.0);
  EXPECT_GT(cpu, 0.0);
  EXPECT_GE(user, 0.0);
  EXPECT_GE(sys, 0.0);
  EXPECT_NEAR(cpu, user + sys, 1e-9 * cpu);
  EXPECT_NEAR(ratio, cpu / wall, 1e-9 * ratio);
  EXPECT_GE(ratio, 0.0);
  EXPECT_GT(threads, 0);
  EXPECT_LE(ratio, threads + 1.0);
  // The summary line carries the same figures, rounded (3 decimals for seconds, 2 for the ratio).
  EXPECT_NEAR(Field(output, "wall_s"), wall, 5e-4 + 1e-9) << output;
  EXPECT_NEAR(Field(output, "cpu_s"), cpu, 5e-4 + 1e-9) << output;
  EXPECT_NEAR(Field(output, "cpu_ratio"), ratio, 5e-3 + 1e-9) << output;
}

// The folder of a real sequence of the data folder (MCSLAM_DATA or ../shared/data); empty when absent.
inline std::string RealSequence(const std::string& name) {
  const std::string data = DataDir();
  if (data.empty() || !std::filesystem::is_directory(std::filesystem::path(data) / name)) return "";
  return (std::filesystem::path(data) / name).string();
}

// The folder of a real sequence in `var`, or the test skipped (visibly) when it is not there.
#define REAL_SEQUENCE_OR_SKIP(var, name)                   \
  const std::string var = mcslam::testing::RealSequence(name); \
  if (var.empty()) GTEST_SKIP() << name << " not found (set MCSLAM_DATA or ../shared/data)"

}  // namespace mcslam::testing
