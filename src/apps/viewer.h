#pragma once
// The browser viewer (`mcslam view OUT_DIR`, `run --viewer`): one self-contained HTML page (three.js from
// Debian's libjs-three inlined, the run's data as JSON) with the map points coloured by height, the estimated
// trajectory and, when a ground truth is given, the true one after a Sim(3) alignment (everything drawn in the
// ground truth's metres then), keyframe frusta, a time slider that replays the run (the camera, and the map
// points its keyframe saw when a map file is given), and the per-frame figures of frames.csv as plots.
#include <optional>
#include <string>

#include "io/trajectory_io.h"

namespace mcslam::apps {

struct ViewerOptions {
  std::optional<io::Trajectory> ground_truth;
  std::string map_file;      // a map file (--save-map) of the run: which points each keyframe saw; empty: none
  std::string title;         // the page's title; empty: report.json's input, or the folder
  std::string three_dir = "/usr/share/javascript/three";  // three.min.js, examples/js/controls/OrbitControls.js
};

// Reads the run folder `out_dir` (trajectory.txt; map.ply, frames.csv and report.json when present) and writes
// the page to `html_path`. Throws std::runtime_error naming the file that is missing or unreadable (three.js
// included: "apt-get install libjs-three").
void WriteViewer(const std::string& out_dir, const std::string& html_path, const ViewerOptions& options);

// The page around its data: three.js, OrbitControls and the data JSON inserted into the template.
std::string ViewerPage(const std::string& three_js, const std::string& orbit_js, const std::string& data_json);

}  // namespace mcslam::apps
