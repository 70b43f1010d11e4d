#pragma once
// What the CLI tests read back from a command: fields of its summary line, and report.json.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <regex>
#include <string>

#include <nlohmann/json.hpp>

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

}  // namespace mcslam::testing
