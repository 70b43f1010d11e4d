#pragma once
// Internal to the io layer: reading text files line by line with line numbers, strict number parsing,
// and errors of the form "<path>:<line>: <what>". Not part of the public io API.
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include <fmt/format.h>

namespace mcslam::io::detail {

[[noreturn]] inline void FailAt(const std::string& path, int line, const std::string& what) {
  throw std::runtime_error(fmt::format("{}:{}: {}", path, line, what));
}

[[noreturn]] inline void Fail(const std::string& path, const std::string& what) {
  throw std::runtime_error(fmt::format("{}: {}", path, what));
}

// Refuses what is not a plain file before anything opens it: a folder ("read error after line 0" otherwise), and
// a pipe, device or socket, whose open or read would block forever (a FIFO with no writer) or never end
// (/dev/zero). Symbolic links are followed. A missing file is left to the caller's own message.
inline void RequireRegularFileIfPresent(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || st.type() == fs::file_type::not_found || st.type() == fs::file_type::regular) return;
  if (st.type() == fs::file_type::directory) Fail(path, "is a folder, not a file");
  Fail(path, "is not a regular file (a pipe, device or socket); give a file");
}

// Reads a text file one line at a time, counting lines from 1 and dropping a trailing '\r' (CRLF files).
class LineReader {
 public:
  explicit LineReader(const std::string& path) : path_(path) {
    RequireRegularFileIfPresent(path);
    in_.open(path);
    if (!in_) detail::Fail(path, "cannot open file for reading");
  }
  bool Next(std::string& line) {
    if (!std::getline(in_, line)) {
      if (in_.bad()) detail::Fail(path_, fmt::format("read error after line {}", line_));
      return false;
    }
    ++line_;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return true;
  }
  int line() const { return line_; }
  const std::string& path() const { return path_; }
  [[noreturn]] void Fail(const std::string& what) const { FailAt(path_, line_, what); }

 private:
  std::string path_;
  std::ifstream in_;
  int line_ = 0;
};

// ASCII lower case (file extensions, dataset and format names).
inline std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

inline bool IsSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f'; }

inline std::string_view Trim(std::string_view s) {
  while (!s.empty() && IsSpace(s.front())) s.remove_prefix(1);
  while (!s.empty() && IsSpace(s.back())) s.remove_suffix(1);
  return s;
}

// Blank lines and lines whose first non-space character is '#' carry no data.
inline bool IsBlankOrComment(std::string_view line) {
  const std::string_view t = Trim(line);
  return t.empty() || t.front() == '#';
}

inline std::vector<std::string_view> SplitWhitespace(std::string_view s) {
  std::vector<std::string_view> out;
  size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && IsSpace(s[i])) ++i;
    const size_t start = i;
    while (i < s.size() && !IsSpace(s[i])) ++i;
    if (i > start) out.push_back(s.substr(start, i - start));
  }
  return out;
}

// Fields between commas, each trimmed; "a,,b" gives an empty middle field.
inline std::vector<std::string_view> SplitCommas(std::string_view s) {
  std::vector<std::string_view> out;
  size_t start = 0;
  while (true) {
    const size_t comma = s.find(',', start);
    out.push_back(Trim(s.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start)));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return out;
}

// Whole-token parse; a leading '+' is accepted (std::from_chars does not take it). No exceptions.
inline bool TryParseDouble(std::string_view tok, double* value) {
  if (!tok.empty() && tok.front() == '+') tok.remove_prefix(1);
  if (tok.empty()) return false;
  const auto [end, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), *value);
  return ec == std::errc() && end == tok.data() + tok.size();
}

inline bool TryParseInt(std::string_view tok, int64_t* value) {
  if (!tok.empty() && tok.front() == '+') tok.remove_prefix(1);
  if (tok.empty()) return false;
  const auto [end, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), *value);
  return ec == std::errc() && end == tok.data() + tok.size();
}

// A finite number, or an error naming the file, line and field.
inline double ParseFinite(std::string_view tok, const LineReader& r, std::string_view field) {
  double v = 0;
  if (!TryParseDouble(tok, &v)) r.Fail(fmt::format("{} '{}' is not a number", field, tok));
  if (!std::isfinite(v)) r.Fail(fmt::format("{} is not finite ({})", field, tok));
  return v;
}

// Appends the stamp t (read from the text `tok`) to `stamps`, or fails naming it when it goes back in time.
inline void AppendStamp(std::vector<double>& stamps, double t, std::string_view tok, const LineReader& r) {
  if (!stamps.empty() && t < stamps.back()) r.Fail(fmt::format("timestamp {} goes back in time", tok));
  stamps.push_back(t);
}

inline int64_t ParseInteger(std::string_view tok, const LineReader& r, std::string_view field) {
  int64_t v = 0;
  if (!TryParseInt(tok, &v)) r.Fail(fmt::format("{} '{}' is not an integer", field, tok));
  return v;
}

// Shortest text that reads back to exactly the same double.
inline std::string FormatExact(double v) { return fmt::format("{}", v); }

// Timestamps: nanosecond resolution ("%.9f", what the TUM tools write) when that reads back exactly, else
// the shortest exact form, so that no stamp ever changes on a round trip.
inline std::string FormatStamp(double s) {
  std::string text = fmt::format("{:.9f}", s);
  double back = 0;
  if (TryParseDouble(text, &back) && back == s) return text;
  return FormatExact(s);
}

// Opens `path` for writing (truncating), or throws naming it.
inline std::ofstream OpenForWrite(const std::string& path) {
  std::ofstream out(path, std::ios::out | std::ios::trunc);
  if (!out) Fail(path, "cannot open file for writing");
  return out;
}

inline void FinishWrite(std::ofstream& out, const std::string& path) {
  out.flush();
  if (!out) Fail(path, "write failed");
  out.close();
  if (out.fail()) Fail(path, "write failed on close");
}

}  // namespace mcslam::io::detail
