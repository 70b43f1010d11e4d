#include "io/trajectory_io.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <stdexcept>

#include <fmt/format.h>

#include "io/text_util.h"

namespace mcslam::io {
namespace {

using detail::LineReader;
using detail::Lower;

// Below this length a quaternion read from a file carries no direction: the file is wrong.
constexpr double kMinQuaternionNorm = 1e-9;

bool HasCsvExtension(const std::string& path) {
  return Lower(std::filesystem::path(path).extension().string()) == ".csv";
}

// q given as w, x, y, z; normalised, or an error at the reader's line.
Eigen::Quaterniond MakeUnitQuaternion(double w, double x, double y, double z, const LineReader& r) {
  Eigen::Quaterniond q(w, x, y, z);
  const double n = q.norm();
  if (!(n > kMinQuaternionNorm)) r.Fail("quaternion has zero length");
  q.coeffs() /= n;
  return q;
}

// Writers refuse what their readers would refuse, so a written file always reads back.
void CheckWritable(const Trajectory& traj, const std::string& path) {
  if (traj.stamps_s.size() != traj.world_from_cam.size())
    throw std::invalid_argument(fmt::format("{}: trajectory has {} stamps but {} poses", path, traj.stamps_s.size(),
                                            traj.world_from_cam.size()));
  for (size_t i = 0; i < traj.size(); ++i) {
    if (!std::isfinite(traj.stamps_s[i]) || !traj.world_from_cam[i].AllFinite())
      throw std::invalid_argument(fmt::format("{}: pose {} (stamp {}) is not finite", path, i, traj.stamps_s[i]));
    if (!(traj.world_from_cam[i].q.norm() > kMinQuaternionNorm))
      throw std::invalid_argument(fmt::format("{}: pose {} has a zero quaternion", path, i));
  }
}

// Nanoseconds to seconds without going through a double of ~1e18 (which would lose the last digits).
double NanosecondsToSeconds(int64_t ns) {
  constexpr int64_t kNsPerS = 1'000'000'000;
  return static_cast<double>(ns / kNsPerS) + static_cast<double>(ns % kNsPerS) * 1e-9;
}

int64_t SecondsToNanoseconds(double s, const std::string& path) {
  // int64 nanoseconds reach about 9.2e9 s (year 2262).
  if (!(std::abs(s) < 9.2e9)) throw std::invalid_argument(fmt::format("{}: stamp {} s does not fit in int64 ns", path, s));
  double whole = std::floor(s);
  int64_t frac_ns = std::llround((s - whole) * 1e9);
  if (frac_ns >= 1'000'000'000) {
    frac_ns -= 1'000'000'000;
    whole += 1.0;
  }
  return static_cast<int64_t>(whole) * 1'000'000'000 + frac_ns;
}

}  // namespace

TrajectoryFormat ParseTrajectoryFormat(const std::string& name) {
  const std::string n = Lower(name);
  if (n == "auto") return TrajectoryFormat::kAuto;
  if (n == "tum") return TrajectoryFormat::kTum;
  if (n == "kitti") return TrajectoryFormat::kKitti;
  if (n == "euroc") return TrajectoryFormat::kEuroc;
  throw std::invalid_argument(fmt::format("unknown trajectory format '{}' (expected auto, tum, kitti or euroc)", name));
}

std::string ToString(TrajectoryFormat f) {
  switch (f) {
    case TrajectoryFormat::kAuto: return "auto";
    case TrajectoryFormat::kTum: return "tum";
    case TrajectoryFormat::kKitti: return "kitti";
    case TrajectoryFormat::kEuroc: return "euroc";
  }
  return "unknown";
}

TrajectoryFormat DetectTrajectoryFormat(const std::string& path) {
  LineReader r(path);  // opens first so that a missing file is reported as such, whatever its extension
  if (HasCsvExtension(path)) return TrajectoryFormat::kEuroc;
  std::string line;
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    if (line.find(',') != std::string::npos) return TrajectoryFormat::kEuroc;
    const size_t cols = detail::SplitWhitespace(line).size();
    if (cols == 8) return TrajectoryFormat::kTum;
    if (cols == 12) return TrajectoryFormat::kKitti;
    r.Fail(fmt::format(
        "cannot tell the trajectory format: first data line has {} columns (8: TUM, 12: KITTI, comma-separated: "
        "EuRoC); give the format explicitly",
        cols));
  }
  detail::Fail(path, "cannot tell the trajectory format: the file has no data lines");
}

Trajectory ReadTrajectory(const std::string& path, TrajectoryFormat format, const std::string& kitti_times_path) {
  if (format == TrajectoryFormat::kAuto) format = DetectTrajectoryFormat(path);
  if (!kitti_times_path.empty() && format != TrajectoryFormat::kKitti)
    throw std::runtime_error(fmt::format("{}: a times file ({}) was given, but the trajectory is in {} format, not KITTI",
                                         path, kitti_times_path, ToString(format)));
  switch (format) {
    case TrajectoryFormat::kTum: return ReadTum(path);
    case TrajectoryFormat::kKitti: return ReadKitti(path, kitti_times_path);
    case TrajectoryFormat::kEuroc: return ReadEuroc(path);
    case TrajectoryFormat::kAuto: break;
  }
  throw std::logic_error("ReadTrajectory: unhandled format");
}

Trajectory ReadTum(const std::string& path) {
  LineReader r(path);
  Trajectory traj;
  std::string line;
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    const auto tok = detail::SplitWhitespace(line);
    if (tok.size() != 8)
      r.Fail(fmt::format("expected 8 columns (timestamp tx ty tz qx qy qz qw), found {}", tok.size()));
    static constexpr const char* kNames[8] = {"timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"};
    double v[8];
    for (int i = 0; i < 8; ++i) v[i] = detail::ParseFinite(tok[i], r, kNames[i]);
    const Eigen::Quaterniond q = MakeUnitQuaternion(v[7], v[4], v[5], v[6], r);
    traj.stamps_s.push_back(v[0]);
    Pose pose;
    pose.q = q;
    pose.t = Eigen::Vector3d(v[1], v[2], v[3]);
    traj.world_from_cam.push_back(pose);
  }
  traj.has_stamps = true;
  return traj;
}

Trajectory ReadKitti(const std::string& path, const std::string& times_path) {
  LineReader r(path);
  Trajectory traj;
  std::string line;
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    const auto tok = detail::SplitWhitespace(line);
    if (tok.size() != 12) r.Fail(fmt::format("expected 12 columns (row-major 3x4 [R|t]), found {}", tok.size()));
    Eigen::Matrix<double, 3, 4> m;
    for (int i = 0; i < 12; ++i) m(i / 4, i % 4) = detail::ParseFinite(tok[i], r, fmt::format("entry {}", i + 1));
    if (m.leftCols<3>().norm() < kMinQuaternionNorm) r.Fail("rotation block is zero");
    traj.world_from_cam.push_back(Pose::FromMatrix(m));  // re-orthonormalises the rotation (SVD)
  }
  if (times_path.empty()) {
    traj.has_stamps = false;
    for (size_t i = 0; i < traj.size(); ++i) traj.stamps_s.push_back(static_cast<double>(i));
    return traj;
  }
  LineReader tr(times_path);
  while (tr.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    const auto tok = detail::SplitWhitespace(line);
    if (tok.size() != 1) tr.Fail(fmt::format("expected one timestamp a line, found {} columns", tok.size()));
    traj.stamps_s.push_back(detail::ParseFinite(tok[0], tr, "timestamp"));
  }
  if (traj.stamps_s.size() != traj.world_from_cam.size())
    throw std::runtime_error(fmt::format("{}: {} timestamps, but {} has {} poses; they must match one to one", times_path,
                                         traj.stamps_s.size(), path, traj.world_from_cam.size()));
  traj.has_stamps = true;
  return traj;
}

Trajectory ReadEuroc(const std::string& path) {
  LineReader r(path);
  Trajectory traj;
  std::string line;
  bool seen_data_line = false;
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    const auto tok = detail::SplitCommas(line);
    // Some tools write the column names without the leading '#': a first data line starting with a letter.
    const bool first_data_line = !seen_data_line;
    seen_data_line = true;
    double unused = 0;
    if (first_data_line && !tok[0].empty() && std::isalpha(static_cast<unsigned char>(tok[0][0])) &&
        !detail::TryParseDouble(tok[0], &unused))
      continue;
    // Ground-truth files have 17 columns (also velocities and IMU biases); only the pose is read.
    if (tok.size() < 8)
      r.Fail(fmt::format("expected at least 8 comma-separated columns (timestamp_ns, px, py, pz, qw, qx, qy, qz), "
                         "found {}",
                         tok.size()));
    double stamp_s = 0;
    int64_t ns = 0;
    if (detail::TryParseInt(tok[0], &ns)) {
      stamp_s = NanosecondsToSeconds(ns);
    } else {
      // Some tools write ns as a float; EuRoC's stamps are int64 ns, and one beyond them cannot be written back.
      const double ns_float = detail::ParseFinite(tok[0], r, "timestamp [ns]");
      if (!(std::abs(ns_float) < 9.2e18))
        r.Fail(fmt::format("timestamp {} ns does not fit in 64 bits (EuRoC stamps are int64 nanoseconds)", tok[0]));
      stamp_s = ns_float * 1e-9;
    }
    static constexpr const char* kNames[8] = {"timestamp", "px", "py", "pz", "qw", "qx", "qy", "qz"};
    double v[8];
    for (int i = 1; i < 8; ++i) v[i] = detail::ParseFinite(tok[i], r, kNames[i]);
    Pose pose;
    pose.q = MakeUnitQuaternion(v[4], v[5], v[6], v[7], r);
    pose.t = Eigen::Vector3d(v[1], v[2], v[3]);
    traj.stamps_s.push_back(stamp_s);
    traj.world_from_cam.push_back(pose);
  }
  traj.has_stamps = true;
  return traj;
}

void WriteTrajectory(const std::string& path, const Trajectory& traj, TrajectoryFormat format) {
  // kAuto: by extension, .csv -> EuRoC, anything else -> TUM (the only other format with stamps in the file).
  if (format == TrajectoryFormat::kAuto)
    format = HasCsvExtension(path) ? TrajectoryFormat::kEuroc : TrajectoryFormat::kTum;
  switch (format) {
    case TrajectoryFormat::kTum: return WriteTum(path, traj);
    case TrajectoryFormat::kKitti: return WriteKitti(path, traj);
    case TrajectoryFormat::kEuroc: return WriteEuroc(path, traj);
    case TrajectoryFormat::kAuto: break;
  }
  throw std::logic_error("WriteTrajectory: unhandled format");
}

void WriteTum(const std::string& path, const Trajectory& traj) {
  CheckWritable(traj, path);
  std::ofstream out = detail::OpenForWrite(path);
  out << "# timestamp tx ty tz qx qy qz qw (world_from_cam)\n";
  for (size_t i = 0; i < traj.size(); ++i) {
    const Pose& p = traj.world_from_cam[i];
    const Eigen::Quaterniond q = p.q.normalized();
    out << fmt::format("{} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g}\n", detail::FormatStamp(traj.stamps_s[i]),
                       p.t.x(), p.t.y(), p.t.z(), q.x(), q.y(), q.z(), q.w());
  }
  detail::FinishWrite(out, path);
}

void WriteKitti(const std::string& path, const Trajectory& traj, const std::string& times_path) {
  CheckWritable(traj, path);
  std::ofstream out = detail::OpenForWrite(path);  // KITTI files have no comment lines: tools would choke on one
  for (const Pose& p : traj.world_from_cam) {
    const Eigen::Matrix<double, 3, 4> m = Pose(p.q, p.t).Matrix3x4();
    std::string row;
    for (int i = 0; i < 12; ++i) row += fmt::format("{}{:.17g}", i ? " " : "", m(i / 4, i % 4));
    out << row << '\n';
  }
  detail::FinishWrite(out, path);
  if (times_path.empty()) return;
  std::ofstream times = detail::OpenForWrite(times_path);
  for (double s : traj.stamps_s) times << detail::FormatStamp(s) << '\n';
  detail::FinishWrite(times, times_path);
}

void WriteEuroc(const std::string& path, const Trajectory& traj) {
  CheckWritable(traj, path);
  std::vector<int64_t> ns(traj.size());
  for (size_t i = 0; i < traj.size(); ++i) ns[i] = SecondsToNanoseconds(traj.stamps_s[i], path);
  std::ofstream out = detail::OpenForWrite(path);
  out << "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n";
  for (size_t i = 0; i < traj.size(); ++i) {
    const Pose& p = traj.world_from_cam[i];
    const Eigen::Quaterniond q = p.q.normalized();
    out << fmt::format("{},{:.17g},{:.17g},{:.17g},{:.17g},{:.17g},{:.17g},{:.17g}\n", ns[i], p.t.x(), p.t.y(), p.t.z(),
                       q.w(), q.x(), q.y(), q.z());
  }
  detail::FinishWrite(out, path);
}

int NearestStampIndex(const Trajectory& traj, double t, double max_dt_s) {
  int best = -1;
  for (size_t i = 0; i < traj.stamps_s.size(); ++i)
    if (std::abs(traj.stamps_s[i] - t) <= max_dt_s &&
        (best < 0 || std::abs(traj.stamps_s[i] - t) < std::abs(traj.stamps_s[best] - t)))
      best = static_cast<int>(i);
  return best;
}

}  // namespace mcslam::io
