#include "apps/viewer.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <unordered_map>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "eval/trajectory_eval.h"
#include "io/map_file.h"
#include "io/ply.h"

namespace mcslam::apps {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::string ReadWhole(const fs::path& path, const std::string& what_for) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(fmt::format("{}: cannot read it ({})", path.string(), what_for));
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// frames.csv as columns by name (every cell a string); empty when the file is absent.
std::map<std::string, std::vector<std::string>> ReadColumns(const fs::path& path) {
  std::map<std::string, std::vector<std::string>> cols;
  std::ifstream in(path);
  if (!in) return cols;
  std::string line;
  std::vector<std::string> names;
  auto split = [](const std::string& l) {
    std::vector<std::string> out;
    std::string cell;
    std::istringstream ss(l);
    while (std::getline(ss, cell, ',')) out.push_back(cell);
    if (!l.empty() && l.back() == ',') out.emplace_back();
    return out;
  };
  if (!std::getline(in, line)) return cols;
  names = split(line);
  while (std::getline(in, line)) {
    const std::vector<std::string> cells = split(line);
    for (size_t c = 0; c < names.size(); ++c) cols[names[c]].push_back(c < cells.size() ? cells[c] : "");
  }
  return cols;
}

double Number(const std::string& s) {
  try {
    size_t used = 0;
    const double v = std::stod(s, &used);
    return used == s.size() && std::isfinite(v) ? v : std::nan("");
  } catch (const std::exception&) {
    return std::nan("");
  }
}

json NumberOrNull(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

}  // namespace

void WriteViewer(const std::string& out_dir, const std::string& html_path, const ViewerOptions& options) {
  const fs::path dir(out_dir);
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw std::runtime_error(fmt::format("{}: not a run's output folder", out_dir));
  const fs::path traj_path = dir / "trajectory.txt";
  if (!fs::exists(traj_path, ec))
    throw std::runtime_error(fmt::format("{}: no trajectory.txt (not the --out folder of `mcslam run`?)", out_dir));
  // trajectory.txt is TUM (what `run` writes); a run that never initialised wrote one without poses, which the
  // TUM reader takes as an empty trajectory (the format-detecting reader would refuse it).
  const io::Trajectory traj = io::ReadTum(traj_path.string());
  io::PointCloud cloud;
  if (fs::exists(dir / "map.ply", ec)) cloud = io::ReadPly((dir / "map.ply").string());
  const std::string three = ReadWhole(fs::path(options.three_dir) / "three.min.js",
                                      "the viewer needs three.js: apt-get install libjs-three");
  const std::string orbit = ReadWhole(fs::path(options.three_dir) / "examples/js/controls/OrbitControls.js",
                                      "the viewer needs three.js' OrbitControls: apt-get install libjs-three");

  // The frame index of each pose: frames.csv's posed rows in order of their stamps.
  const auto cols = ReadColumns(dir / "frames.csv");
  std::vector<int64_t> frame_of_pose(traj.size());
  for (size_t i = 0; i < traj.size(); ++i) frame_of_pose[i] = static_cast<int64_t>(i);
  std::vector<bool> keyframe(traj.size(), false);
  if (cols.count("index") && cols.count("stamp")) {
    const auto& idx = cols.at("index");
    const auto& stamp = cols.at("stamp");
    std::map<double, size_t> row_of_stamp;  // one row a frame, so one a stamp
    for (size_t r = 0; r < idx.size(); ++r)
      if (const double t = Number(stamp[r]); std::isfinite(t)) row_of_stamp.emplace(t, r);
    for (size_t i = 0; i < traj.size(); ++i) {
      const auto it = row_of_stamp.lower_bound(traj.stamps_s[i] - 1e-6);
      if (it == row_of_stamp.end() || it->first > traj.stamps_s[i] + 1e-6) continue;
      frame_of_pose[i] = static_cast<int64_t>(Number(idx[it->second]));
      if (cols.count("keyframe")) keyframe[i] = cols.at("keyframe")[it->second] == "1";
    }
  }

  // Everything in the ground truth's world (metres) when one is given: the estimate aligned onto it (Sim(3)).
  std::vector<Pose> world_from_cam = traj.world_from_cam;
  std::vector<Eigen::Vector3d> points = cloud.points;
  json gt_positions = nullptr;
  std::string units = "map units (a monocular map's scale is its own)";
  if (options.ground_truth && traj.size() >= 3) {
    // A ground truth without stamps (KITTI poses) pairs by frame index, as the run's own evaluation does.
    io::Trajectory gt = *options.ground_truth, est = traj;
    if (!gt.has_stamps) {
      for (size_t i = 0; i < gt.size(); ++i) gt.stamps_s[i] = static_cast<double>(i);
      for (size_t i = 0; i < est.size(); ++i) est.stamps_s[i] = static_cast<double>(frame_of_pose[i]);
      gt.has_stamps = true;
    }
    const eval::TrajectoryErrors errors = eval::EvaluateTrajectory(gt, est, {});
    const eval::Similarity3& s = errors.alignment_result.gt_world_from_est_world;
    for (Pose& p : world_from_cam) p = s.Apply(p);
    for (Eigen::Vector3d& p : points) p = s * p;
    gt_positions = json::array();
    for (const eval::FrameError& e : errors.frames)
      for (int k = 0; k < 3; ++k) gt_positions.push_back(e.gt_position[k]);
    units = fmt::format("metres, aligned to the ground truth (Sim(3); ATE {:.4f} m)", errors.ate_m.rmse);
  }

  json data;
  json title = options.title.empty() ? out_dir : options.title;
  if (options.title.empty() && fs::exists(dir / "report.json", ec)) {
    try {
      std::ifstream in(dir / "report.json");
      const json report = json::parse(in);
      if (report.contains("input")) title = report["input"];
    } catch (const std::exception&) {
      // A report that does not parse only costs the title.
    }
  }
  data["title"] = title;
  data["units"] = units;
  json pos = json::array(), quat = json::array(), frames = json::array(), kf = json::array();
  Eigen::Vector3d up = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < world_from_cam.size(); ++i) {
    const Pose& p = world_from_cam[i];
    for (int k = 0; k < 3; ++k) pos.push_back(p.t[k]);
    quat.push_back(p.q.x()), quat.push_back(p.q.y()), quat.push_back(p.q.z()), quat.push_back(p.q.w());
    frames.push_back(frame_of_pose[i]);
    if (keyframe[i]) kf.push_back(i);
    up += p.q * Eigen::Vector3d(0, -1, 0);  // the image's up, in the world
  }
  data["up"] = up.norm() > 0 ? json{up.x() / up.norm(), up.y() / up.norm(), up.z() / up.norm()} : json{0, 1, 0};
  data["trajectory"] = {{"positions", pos}, {"quaternions", quat}, {"frames", frames}, {"keyframes", kf}};
  data["ground_truth"] = gt_positions;
  json pts = json::array();
  for (const Eigen::Vector3d& p : points)
    for (int k = 0; k < 3; ++k) pts.push_back(p[k]);
  data["points"] = pts;
  // Per frame: what frames.csv says.
  json stats = json::object();
  for (const char* name : {"index", "inliers", "reproj_median_px", "frame_ms", "backend_ms"}) {
    if (!cols.count(name)) continue;
    json v = json::array();
    for (const std::string& cell : cols.at(name)) v.push_back(NumberOrNull(Number(cell)));
    stats[name] = v;
  }
  if (cols.count("status")) stats["status"] = cols.at("status");
  data["stats"] = stats;
  // The points each keyframe saw, from the map file (by the ids map.ply gives its points).
  json observed = json::object();
  if (!options.map_file.empty()) {
    const io::MapFile map = io::ReadMapFile(options.map_file);
    std::unordered_map<int64_t, size_t> index_of;
    for (size_t i = 0; i < cloud.ids.size(); ++i) index_of[cloud.ids[i]] = i;
    for (const io::MapFileKeyframe& k : map.keyframes) {
      json seen = json::array();
      for (int64_t id : k.feature_ids)
        if (auto it = index_of.find(id); it != index_of.end()) seen.push_back(it->second);
      observed[std::to_string(k.index)] = seen;
    }
  }
  data["observed"] = observed;

  const std::string page = ViewerPage(three, orbit, data.dump(-1, ' ', false, json::error_handler_t::replace));
  std::ofstream out(html_path, std::ios::binary | std::ios::trunc);
  if (!out) throw std::runtime_error(fmt::format("{}: cannot open for writing", html_path));
  out << page;
  out.close();
  if (!out) throw std::runtime_error(fmt::format("{}: writing failed (disk full?)", html_path));
}

}  // namespace mcslam::apps
