#pragma once
// Shared by the libFuzzer targets: each writes the fuzzer's bytes to files in a private temporary folder and
// hands the path to one of mcslam's readers, exactly as a user's file would reach it. A reader may refuse
// the input (any std::exception: the message names the file); it must not crash, hang, leak or hit undefined
// behaviour (the targets are built with AddressSanitizer and UndefinedBehaviorSanitizer), and what it accepts
// must survive the matching writer and be read back the same (checked with Require, which aborts: a finding).
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

#include <unistd.h>

namespace mcslam::fuzz {

// One folder per fuzzing process, removed at exit.
class Workspace {
 public:
  Workspace() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "mcslam_fuzz_XXXXXX").string();
    if (mkdtemp(tmpl.data()) == nullptr) std::abort();
    dir_ = tmpl;
  }
  ~Workspace() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  // Writes `bytes` to dir/relative (creating its folders) and returns the full path.
  std::string Write(const std::string& relative, std::string_view bytes) const {
    const std::filesystem::path p = dir_ / relative;
    std::filesystem::create_directories(p.parent_path());
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    return p.string();
  }
  void Remove(const std::string& relative) const {
    std::error_code ec;
    std::filesystem::remove(dir_ / relative, ec);
  }
  std::string Path(const std::string& relative) const { return (dir_ / relative).string(); }
  const std::filesystem::path& dir() const { return dir_; }

 private:
  std::filesystem::path dir_;
};

inline Workspace& TheWorkspace() {
  static Workspace w;
  return w;
}

// The input as a selector byte (which reader or layout) and the rest; the rest split into files at lines
// "--8<--" (the seed corpus uses it; the fuzzer finds it). There is always at least one part (maybe empty).
struct Input {
  uint8_t selector = 0;
  std::vector<std::string_view> parts;
};
inline Input Split(const uint8_t* data, size_t size) {
  Input in;
  if (size == 0) {
    in.parts.emplace_back();
    return in;
  }
  in.selector = data[0];
  std::string_view rest(reinterpret_cast<const char*>(data + 1), size - 1);
  constexpr std::string_view kCut = "\n--8<--\n";
  while (true) {
    const size_t at = rest.find(kCut);
    if (at == std::string_view::npos) break;
    in.parts.push_back(rest.substr(0, at));
    rest.remove_prefix(at + kCut.size());
  }
  in.parts.push_back(rest);
  return in;
}

// A property that must hold: its failure is a finding (abort, so libFuzzer saves the input).
inline void Require(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "mcslam fuzz: property failed: %s\n", what);
    std::abort();
  }
}

}  // namespace mcslam::fuzz
