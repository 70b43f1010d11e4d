// `mcslam view OUT_DIR`: the run in a browser (apps/viewer.h): writes OUT_DIR/viewer.html (or --out FILE).
#include <cstdio>
#include <memory>
#include <optional>
#include <string>

#include <fmt/format.h>

#include "apps/commands.h"
#include "apps/viewer.h"
#include "io/trajectory_io.h"

namespace mcslam::apps {

namespace {

struct ViewArgs {
  std::string out_dir, html_path, gt_path, map_path, three_dir = ViewerOptions{}.three_dir;
};

void RunView(const ViewArgs& a) {
  ViewerOptions o;
  if (!a.gt_path.empty()) o.ground_truth = io::ReadTrajectory(a.gt_path);
  o.map_file = a.map_path;
  o.three_dir = a.three_dir;
  const std::string html = a.html_path.empty() ? a.out_dir + "/viewer.html" : a.html_path;
  WriteViewer(a.out_dir, html, o);
  std::fputs(fmt::format("viewer written to {} (open it in a browser)\n", html).c_str(), stdout);
}

}  // namespace

void RegisterView(CLI::App& app) {
  auto args = std::make_shared<ViewArgs>();
  CLI::App* cmd = app.add_subcommand(
      "view", "Write a web page (three.js) that shows a run: map points, trajectory, keyframes, a replay slider and "
              "the per-frame figures");
  cmd->add_option("OUT_DIR", args->out_dir, "The --out folder of `mcslam run`")->required();
  cmd->add_option("--gt", args->gt_path, "Ground truth (TUM, KITTI or EuRoC): drawn, and the run aligned onto it");
  cmd->add_option("--map", args->map_path, "The run's map file (--save-map): the slider shows what each keyframe saw");
  cmd->add_option("--out", args->html_path, "The page to write (default OUT_DIR/viewer.html)");
  cmd->add_option("--three-dir", args->three_dir, "Where three.js is (Debian's libjs-three)")->capture_default_str();
  cmd->callback([args] { RunView(*args); });
}

}  // namespace mcslam::apps
