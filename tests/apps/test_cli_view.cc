// `mcslam view` and `run --viewer`: the page opened in headless Chromium (software WebGL), its status read from
// the DOM after the scripts ran, and a screenshot checked for what it must show. Skipped, visibly, where no
// Chromium or no three.js is installed (scripts/install-deps.sh installs both; the lent GPU machines have neither).
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <regex>
#include <string>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "apps/viewer.h"
#include "cli_report.h"
#include "test_util.h"

namespace mcslam {
namespace {

namespace fs = std::filesystem;
using testing::RunMcslam;
using testing::RunShell;
using testing::TempDir;

constexpr int kWidth = 1024, kHeight = 768;
constexpr int kViewWidth = 1000, kViewHeight = 480;  // the 3D view, fixed by the page's ?w=&h= (viewer_page.cc)

std::string Chromium() {
  for (const char* name : {"chromium", "chromium-browser"})
    if (RunShell(fmt::format("command -v {} >/dev/null 2>&1", name)).exit_code == 0) return name;
  return "";
}

// The page embeds Debian's three.js (libjs-three); without it `--viewer` fails by design, naming the package
// (AFolderThatIsNoRunIsAClearError checks that message), so the tests of a page skip instead.
bool ThreeJsInstalled() { return fs::exists(fs::path(apps::ViewerOptions{}.three_dir) / "three.min.js"); }
constexpr const char* kNoThreeJs = "no three.js installed: the viewer's page embeds it (apt-get install libjs-three)";

std::string Headless(const std::string& chromium) {
  return fmt::format("timeout 120 {} --headless --no-sandbox --disable-gpu --enable-unsafe-swiftshader "
                     "--use-angle=swiftshader --hide-scrollbars --window-size={},{} --virtual-time-budget=5000",
                     chromium, kWidth, kHeight);
}

struct PageResult {
  std::string status;        // #status's text once the scripts ran
  nlohmann::json ready;      // its JSON when it says "ready {...}"
  cv::Mat screenshot;        // BGR
};

PageResult OpenPage(const std::string& chromium, const std::string& html, const std::string& png) {
  PageResult p;
  const std::string url = fmt::format("file://{}?w={}&h={}", html, kViewWidth, kViewHeight);
  const auto dom = RunShell(fmt::format("{} --dump-dom '{}' 2>/dev/null", Headless(chromium), url));
  std::smatch m;
  if (std::regex_search(dom.output, m, std::regex("<div id=\"status\">([^<]*)</div>"))) p.status = m[1].str();
  if (p.status.rfind("ready ", 0) == 0) p.ready = nlohmann::json::parse(p.status.substr(6), nullptr, false);
  RunShell(fmt::format("{} --screenshot={} '{}' >/dev/null 2>&1", Headless(chromium), png, url));
  p.screenshot = cv::imread(png, cv::IMREAD_COLOR);
  return p;
}

// The estimate's colour (0x35d07f): green well above red and blue, as antialiasing leaves it.
bool Greenish(const cv::Vec3b& bgr) { return bgr[1] > 120 && bgr[1] > bgr[2] + 60 && bgr[1] > bgr[0] + 30; }

void ExpectPageShowsTheRun(const PageResult& p, int poses) {
  ASSERT_EQ(p.status.rfind("ready", 0), 0u) << "the page's status: '" << p.status << "' (a script error says so)";
  ASSERT_FALSE(p.ready.is_discarded());
  EXPECT_EQ(p.ready["poses"].get<int>(), poses);
  EXPECT_GT(p.ready["points"].get<int>(), 50);
  ASSERT_FALSE(p.screenshot.empty());
  ASSERT_EQ(p.screenshot.cols, kWidth);
  // The trajectory is drawn where its middle pose projects (within 4 px: line width and antialiasing).
  const int x = p.ready["middle_px"][0], y = p.ready["middle_px"][1];
  ASSERT_TRUE(x >= 0 && x < kViewWidth && y >= 0 && y < kViewHeight) << p.ready.dump();
  bool green = false;
  for (int dy = -4; dy <= 4 && !green; ++dy)
    for (int dx = -4; dx <= 4 && !green; ++dx) {
      const int u = x + dx, v = y + dy;
      if (u >= 0 && v >= 0 && u < kWidth && v < kHeight) green = Greenish(p.screenshot.at<cv::Vec3b>(v, u));
    }
  EXPECT_TRUE(green) << "no trajectory pixel near " << x << "," << y;
  // And the scene is not empty: pixels other than the background (0x15181c) over the 3D view, beyond the text.
  int drawn = 0;
  for (int v = 70; v < kViewHeight; ++v)
    for (int u = 0; u < kViewWidth; ++u) {
      const cv::Vec3b c = p.screenshot.at<cv::Vec3b>(v, u);
      drawn += std::abs(c[0] - 0x1c) + std::abs(c[1] - 0x18) + std::abs(c[2] - 0x15) > 40;
    }
  std::printf("page ready: %s; %d pixels drawn in the 3D view\n", p.ready.dump().c_str(), drawn);
  EXPECT_GT(drawn, 300) << "pixels drawn in the 3D view";
}

// The rendered paper scene: the page of `run --viewer` (with the run's ground truth and map file) and that of
// `mcslam view` on the same folder. Measured: 300 poses, 187 map points, the middle pose's pixels green,
// 3,600-4,600 pixels drawn in the view (a blank view: none; the bound is 300).
TEST(CliView, ThePageShowsTheMapAndTheTrajectoryInABrowser) {
  const std::string chromium = Chromium();
  if (chromium.empty()) GTEST_SKIP() << "no chromium installed: the viewer's browser test needs it (apt-get install chromium)";
  if (!ThreeJsInstalled()) GTEST_SKIP() << kNoThreeJs;
  TempDir dir;
  ASSERT_EQ(RunMcslam(fmt::format("synth --scenario paper --seed 1 --render --out {}", dir / "scene")).exit_code, 0);
  const auto run = RunMcslam(fmt::format("run {} --dataset synthetic --out {} --save-map {} --viewer", dir / "scene",
                                         dir / "out", dir / "out/room.map"));
  ASSERT_EQ(run.exit_code, 0) << run.output;
  ASSERT_TRUE(fs::exists(dir / "out/viewer.html"));
  ExpectPageShowsTheRun(OpenPage(chromium, dir / "out/viewer.html", dir / "run.png"), 300);

  const auto view = RunMcslam(fmt::format("view {} --out {}", dir / "out", dir / "plain.html"));
  ASSERT_EQ(view.exit_code, 0) << view.output;
  ExpectPageShowsTheRun(OpenPage(chromium, dir / "plain.html", dir / "plain.png"), 300);
}

// A page whose data does not parse says so instead of "ready": the test above would fail on a page that breaks.
TEST(CliView, APageWithBrokenDataIsNotReady) {
  const std::string chromium = Chromium();
  if (chromium.empty()) GTEST_SKIP() << "no chromium installed: the viewer's browser test needs it (apt-get install chromium)";
  if (!ThreeJsInstalled()) GTEST_SKIP() << kNoThreeJs;
  TempDir dir;
  ASSERT_EQ(RunMcslam(fmt::format("synth --scenario paper --frames 60 --render --out {}", dir / "scene")).exit_code, 0);
  ASSERT_EQ(RunMcslam(fmt::format("run {} --dataset synthetic --out {} --viewer", dir / "scene", dir / "out")).exit_code, 0);
  std::string page = testing::ReadText(dir / "out/viewer.html");
  const size_t at = page.find("\"trajectory\":");
  ASSERT_NE(at, std::string::npos);
  page.replace(at, 13, "\"trajectory\":}");  // no longer JSON
  testing::WriteText(dir / "broken.html", page);
  const PageResult p = OpenPage(chromium, dir / "broken.html", dir / "broken.png");
  EXPECT_EQ(p.status.rfind("error:", 0), 0u) << "the page's status: '" << p.status << "'";
}

// A run without a single pose still gets its page, and keeps its own exit status (3: never initialised), which a
// failing viewer would have replaced by 1.
TEST(CliView, ARunThatNeverInitialisedKeepsItsExitStatusAndGetsItsPage) {
  if (!ThreeJsInstalled()) GTEST_SKIP() << kNoThreeJs;
  TempDir dir;
  ASSERT_EQ(RunMcslam(fmt::format("synth --scenario still-start --frames 20 --render --out {}", dir / "scene")).exit_code, 0);
  const auto r = RunMcslam(fmt::format("run {} --dataset synthetic --out {} --viewer", dir / "scene", dir / "out"));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_TRUE(fs::exists(dir / "out/viewer.html")) << r.output;
  EXPECT_EQ(r.output.find("--viewer"), std::string::npos) << r.output;
}

TEST(CliView, AFolderThatIsNoRunIsAClearError) {
  TempDir dir;
  const auto r = RunMcslam(fmt::format("view {}", dir.path().string()));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("no trajectory.txt"), std::string::npos) << r.output;
  testing::WriteText(dir / "trajectory.txt", "0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n2 2 0 0 0 0 0 1\n");
  const auto t = RunMcslam(fmt::format("view {} --three-dir {}", dir.path().string(), dir / "nothree"));
  EXPECT_EQ(t.exit_code, 1) << t.output;
  EXPECT_NE(t.output.find("apt-get install libjs-three"), std::string::npos) << t.output;
}

}  // namespace
}  // namespace mcslam
