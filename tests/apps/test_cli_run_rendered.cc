// The whole pipeline through `mcslam synth --render` and `mcslam run` on rendered scenarios: the paper's scene,
// a turn away from the map and the provisional map that bridges it, a car's bend, a gap of unreadable frames, a
// blackout that leaves the camera where nothing can be relocalised.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>

#include "cli_report.h"
#include "test_util.h"

namespace mcslam {
namespace {

using testing::Field;
using testing::RunMcslam;
using testing::TempDir;

TEST(CliRun, RenderedPaperScenarioEndToEndFromImages) {
  // mcslam synth --render: the textured box ray-cast for each exact pose; then the whole pipeline, front end
  // included, from the images alone.
  TempDir dir;
  const auto s = RunMcslam("synth --scenario paper --frames 90 --render --out " + dir / "s");
  ASSERT_EQ(s.exit_code, 0) << s.output;
  ASSERT_TRUE(std::filesystem::exists(dir / "s/images/000089.png"));
  const auto r = RunMcslam("run " + dir / "s --dataset synthetic --hypotheses 65536 --out " + dir / "r");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("tracked=90 lost=0"), std::string::npos) << r.output;
  // Measured 4.6 mm (Sim(3) RMSE) on this 90-frame run; 2 cm, the paper's bound, leaves a 4x margin.
  const double ate = std::stod(r.output.substr(r.output.find("ate_rmse=") + 9));
  EXPECT_LT(ate, 0.02);
  // --gt-scale on the image path: the first baseline gets its true length, so the Sim(3) alignment needs
  // (almost) no scale. Scale drift over 90 frames stays within 25 % here.
  const auto g = RunMcslam("run " + dir / "s --dataset synthetic --gt-scale --hypotheses 65536 --out " + dir / "g");
  ASSERT_EQ(g.exit_code, 0) << g.output;
  const double scale = std::stod(g.output.substr(g.output.find(" scale=") + 7));
  EXPECT_NEAR(scale, 1.0, 0.25) << g.output;
}

// --save-tracks: the front end's tracks as a folder of observations. Run as such, the back end alone gives the
// image run's trajectory to the last digit (same seed: the back end sees the same features in the same order;
// no frame here is blurred or relocalised, the two things the saved tracks do not carry), and the folder holds the
// ground truth to evaluate it.
TEST(CliRun, SavedTracksReplayTheBackEndExactly) {
  TempDir dir;
  ASSERT_EQ(RunMcslam("synth --scenario paper --frames 60 --render --out " + dir / "s").exit_code, 0);
  const auto r = RunMcslam("run " + dir / "s --dataset synthetic --hypotheses 16384 --save-tracks " + dir / "t" +
                           " --out " + dir / "r");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* f : {"observations.txt", "camera.yaml", "groundtruth.txt"})
    ASSERT_TRUE(std::filesystem::exists(std::filesystem::path(dir / "t") / f)) << f;
  const std::string obs = testing::ReadText(dir / "t/observations.txt");
  EXPECT_NE(obs.find("\n59 "), std::string::npos) << "the last frame's tracks are written";
  const auto b = RunMcslam("run " + dir / "t --hypotheses 16384 --out " + dir / "b");
  ASSERT_EQ(b.exit_code, 0) << b.output;
  EXPECT_NE(b.output.find("ate_rmse="), std::string::npos) << "evaluated against the folder's ground truth";
  const std::string image_run = testing::ReadText(dir / "r/trajectory.txt");
  EXPECT_FALSE(image_run.empty());
  EXPECT_EQ(testing::ReadText(dir / "b/trajectory.txt"), image_run);
  // A folder that cannot be made is refused before any frame, naming the flag.
  const auto bad = RunMcslam("run " + dir / "s --dataset synthetic --save-tracks " + dir / "t/observations.txt/x" +
                             " --out " + dir / "bad");
  EXPECT_EQ(bad.exit_code, 1) << bad.output;
  EXPECT_NE(bad.output.find("--save-tracks"), std::string::npos) << bad.output;
}

// The issue's target for the rendered paper scenario (`make demo`): the whole 300-frame sequence from its
// images, mean translation error <= 2 cm and mean rotation error <= 1 degree after Sim(3) alignment.
TEST(CliRun, RenderedPaperScenarioMeetsThePapersPrecisionFromImages) {
  TempDir dir;
  const auto s = RunMcslam("synth --scenario paper --seed 1 --render --out " + dir / "s");
  ASSERT_EQ(s.exit_code, 0) << s.output;
  const auto r = RunMcslam("run " + dir / "s --dataset synthetic --out " + dir / "r");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("tracked=300 lost=0"), std::string::npos) << r.output;
  // Measured 0.65 cm and 0.60 deg (seed 1; seeds 2 and 3: 0.30 cm / 0.13 deg, 1.8 cm / 0.98 deg). Before the
  // tracks were aligned with their birth patch (--anchor-every 0) 8.2 cm and 3.5 deg: the bounds are the issue's.
  EXPECT_LT(Field(r.output, "ate_mean"), 0.02) << r.output;
  EXPECT_LT(Field(r.output, "rot_mean_deg"), 1.0) << r.output;
}

// A second of unreadable frames (120-149 of 170). Most tracks survive the jump, but the pose is too far from
// the last one for the Monte Carlo search around it: frame 150 finds 10 of 37 points agreeing (lost: before
// the inlier-ratio rule that was taken as tracking, 0.77 m off, and every later frame followed it, 0.5-0.8 m).
// Relocalisation, tried after skipped frames (RANSAC PnP on the frame's features matched to map points),
// finds the pose at frame 150 with 36 of 37, and tracking goes on (measured: 140 tracked, worst 1.3 cm);
// without it every frame after the gap is lost. Either way no frame is tracked wrong.
struct GapRun {
  int tracked_after_gap = 0;
  double worst_m = 0;
  std::string output;
};
GapRun RunOverAGap(const std::string& scenario, const std::string& out, const std::string& flags) {
  GapRun g;
  const auto r = RunMcslam("run " + scenario + " --dataset synthetic --out " + out + " " + flags);
  g.output = r.output;
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(Field(r.output, "skipped"), 30) << r.output;
  const std::string csv = out + "/frames.csv";
  const std::vector<std::string> index = testing::CsvColumn(csv, "index"), status = testing::CsvColumn(csv, "status"),
                                 terr = testing::CsvColumn(csv, "trans_err_m");  // after the Sim(3) alignment
  EXPECT_FALSE(index.empty());
  for (size_t i = 0; i < index.size(); ++i) {
    if (status[i] != "tracked") continue;
    if (terr[i].empty()) {
      ADD_FAILURE() << "tracked frame " << index[i] << " has no error against the ground truth";
      continue;
    }
    g.tracked_after_gap += std::stoi(index[i]) >= 150;
    g.worst_m = std::max(g.worst_m, std::stod(terr[i]));
  }
  return g;
}

// Renders the rotation scenario of `seed` into dir/s and runs it with default settings (and `extra`) into dir/r;
// the run's result (its exit code asserted by the caller).
testing::CommandResult RunRenderedRotation(const TempDir& dir, int seed, const std::string& extra = "",
                                           const std::string& synth_extra = "") {
  const auto s =
      RunMcslam(fmt::format("synth --scenario rotation --seed {} --render {} --out {}", seed, synth_extra, dir / "s"));
  EXPECT_EQ(s.exit_code, 0) << s.output;
  return RunMcslam(fmt::format("run {} --dataset synthetic --seed {} {} --out {}", dir / "s", seed, extra, dir / "r"));
}

// The rendered rotation scenario: the camera pans away from everything mapped (a turn, tracked about the last
// centre), moves on through the unmapped half of the room, and pans back. Before the bridge every frame of the
// move was lost (205 and 200 of 270 frames tracked on seeds 3 and 4); now a provisional map made from two views
// at the turn's end carries the track (settled as the first map is), and joins the map when the pan back
// relocalises a frame against it: scaled about the anchor (seeds 1 and 3: its scale had been guessed 0.959x and
// 1.457x off), then its keyframes adjusted between the anchor and the joining frame. Seed 1 also anchors the
// provisional map one frame before the turn's last accepted one, where the tracks had begun to disagree (0.29
// px rms against 0.1). Measured 270 / 270 frames tracked on both seeds, ATE 0.71 / 0.27 cm (seed 1 was 35 cm at
// e47f435 and 4.0 cm with the anchor alone, the join scaled but not adjusted; seeds 1 and 3-10 now 0.27-3.0 cm,
// docs/rotation_only.md). Bounds: every frame tracked but 3; ATE under 2 cm (3x seed 1, and under the median of
// the seeds without the adjustment, 3.3 cm); the join adjusted the bridge's keyframes.
TEST(CliRun, AProvisionalMapBridgesTheMoveAfterATurnAwayFromTheMapAndJoinsIt) {
  for (const int seed : {1, 3}) {
    TempDir dir;
    const auto r = RunRenderedRotation(dir, seed);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_GE(Field(r.output, "tracked"), 267) << "seed " << seed << ": " << r.output;
    EXPECT_LT(Field(r.output, "ate_rmse"), 0.02) << "seed " << seed << ": " << r.output;
    const nlohmann::json report = testing::ReadJson(dir / "r/report.json");
    EXPECT_GT(report["provisional"].get<int>(), 20) << "seed " << seed;
    int made = 0, joined = 0, adjusted = 0;
    for (const std::string& note : testing::CsvColumn(dir / "r/frames.csv", "note")) {
      made += note.find("provisional map from frames") != std::string::npos;
      joined += note.find("the provisional map joins it") != std::string::npos;
      if (const size_t at = note.find(" of its keyframes adjusted"); at != std::string::npos) {
        const size_t from = note.rfind(' ', at - 1) + 1;
        adjusted = std::max(adjusted, std::stoi(note.substr(from, at - from)));
      }
    }
    EXPECT_GE(made, 1) << "seed " << seed;  // measured: one each, joined once
    EXPECT_GE(joined, 1) << "seed " << seed;
    EXPECT_GT(adjusted, 20) << "seed " << seed;  // measured: 70 on both
    // Joined, no frame keeps the guessed scale.
    EXPECT_EQ(report["guessed_scale"].get<int>(), 0) << "seed " << seed;
    const std::vector<std::string> guessed = testing::CsvColumn(dir / "r/frames.csv", "guessed_scale");
    EXPECT_EQ(std::count(guessed.begin(), guessed.end(), "1"), 0) << "seed " << seed;
  }
}

// A join that comes while the camera is still turning back to the map: the joining frame sees none of the provisional
// map's points, only the map's few that relocalised it, and nothing but the anchor held the provisional map's far
// end, so it was joined scaled but not adjusted. Now the turn ties it: the joining frame turned about the centre of
// the keyframe the turn started from, so its observations of the map, turned back, are that keyframe's, and the
// bridge is adjusted between the anchor and it. The rotation scenario rendered with noise of 6 grey levels
// (docs/rotation_only.md): seed 2 22.1 -> 3.1 cm, seed 9 4.6 -> 4.1 cm with the join's note saying 0 and then 65
// and 70 keyframes adjusted. Seeds 1, 2, 9, 12 and 17 join in a turn on both builds measured (2026-12-06, the
// native AVX-512 build and the portable AVX2 one): ATE 2.5, 3.1, 4.1, 1.4, 2.1 cm (median 2.5) and 2.1, 9.5, 2.7,
// 1.6, 2.3 cm (median 2.3). Which seed goes worst differs with the vector width (AVX2's seed 2 joins three frames
// earlier, on 17 relocalised points, scaled 1.368 against 1.200), so the outcome is held over the five: the median
// under 4 cm (1.6x the worse median, 1.2 % of the 3.3 m path; seeds 1, 2 and 9 without the adjustment measured 4.3,
// 22.1 and 4.6 cm) and every seed under 15 cm (1.6x the worst, under seed 2's 22.1 cm without the adjustment).
// Each seed: one join made in a turn, with more than 20 keyframes adjusted (64-71 measured).
TEST(CliRun, AJoinMadeInATurnAdjustsTheProvisionalMapThroughTheTurn) {
  std::vector<double> ate;
  for (const int seed : {1, 2, 9, 12, 17}) {
    TempDir dir;
    const auto r = RunRenderedRotation(dir, seed, "", "--image-noise 6");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    ate.push_back(Field(r.output, "ate_rmse"));
    EXPECT_LT(ate.back(), 0.15) << "seed " << seed << ": " << r.output;
    int joined_in_turn = 0, adjusted = 0;
    for (const std::string& note : testing::CsvColumn(dir / "r/frames.csv", "note")) {
      if (note.find("the provisional map joins it") == std::string::npos || note.find("rotation only") == std::string::npos)
        continue;
      ++joined_in_turn;
      if (const size_t at = note.find(" of its keyframes adjusted"); at != std::string::npos) {
        const size_t from = note.rfind(' ', at - 1) + 1;
        adjusted = std::max(adjusted, std::stoi(note.substr(from, at - from)));
      }
    }
    EXPECT_EQ(joined_in_turn, 1) << "seed " << seed;
    EXPECT_GT(adjusted, 20) << "seed " << seed;
  }
  std::nth_element(ate.begin(), ate.begin() + 2, ate.end());
  EXPECT_LT(ate[2], 0.04) << "median ATE of seeds 1, 2, 9, 12, 17";
}

// One frame of a turn whose residual jumps is not yet a move. The rotation scenario rendered with noise of 6 grey
// levels, seed 3: the turn of frames 110-120 (the camera's centre fixed) was ended at frame 111 on 0.46 px against
// 0.32, a provisional map anchored at 110 saw only the turn (a homography explained every track) until the turn had
// swept most of its tracks out of view, and frames 111-190 were lost (186 of 270 tracked). Now frame 111 is lost
// alone and frame 112 turns on about the same centre (0.32 px). Measured 265 of 270 tracked, ATE 0.69 cm (the 186
// frames before: 0.54 cm); seeds 12 and 15 of the same renders 261 -> 268 tracked and 14.1 -> 1.4 cm, 186 -> 267
// tracked (docs/rotation_only.md). Which frames jump differs with the CPU's vector width: on a portable AVX2 build
// seed 3 tracks as well with no jump at all, while seeds 12 and 15 jump 2-3 times on both builds (AVX-512 and AVX2,
// 2026-12-06), each jump followed by a turned frame, 267-268 tracked, ATE 1.39-1.56 cm. So the three seeds run, each
// held to the outcome and the three together to the mechanism. Bounds: at least 255 frames tracked (186 before; the
// turn's 5 worst frames and a margin of as many again), ATE under 2.5 cm (1.6x the worst measured, under the
// scenario's 1 %-of-path rule: the path is 3.3 m), and at least one jump said in the notes with the frame after it
// turned.
// The renders these cases were found on: outlines shaded from the 2x2 grid of rays only (--edge-samples 0).
TEST(CliRun, OneFrameWhoseResidualJumpsDoesNotEndATurn) {
  int jumps = 0, turned_after = 0;
  for (const int seed : {3, 12, 15}) {
    TempDir dir;
    const auto r = RunRenderedRotation(dir, seed, "", "--image-noise 6 --edge-samples 0");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_GE(Field(r.output, "tracked"), 255) << "seed " << seed << ": " << r.output;
    EXPECT_LT(Field(r.output, "ate_rmse"), 0.025) << "seed " << seed << ": " << r.output;
    const std::vector<std::string> note = testing::CsvColumn(dir / "r/frames.csv", "note");
    for (size_t i = 0; i + 1 < note.size(); ++i)
      if (note[i].find("residual jumped") != std::string::npos) {
        ++jumps;
        turned_after += note[i + 1].find("rotation only") != std::string::npos;
      }
  }
  EXPECT_GE(jumps, 1);
  EXPECT_GE(turned_after, 1);
}

// A blurred pair of frames in a turn, with the map found again in the second: the rotation scenario rendered with
// exposure steps and two of every ten frames blurred (`--exposure-step 1.3 --blur-sigma 2`), seed 8. The turn at
// frames 192-196 runs through the blurred frames 193 and 194, whose residuals both jumped (0.52 and 0.50 px against
// 0.06); the second ended the turn, the relocalisation found the map in it, and the provisional map of 147 points
// under the turn was given up: the rest of the run went on at the old map's scale, ATE 17.4 cm (5.6 % of the path).
// Now a blurred frame after a jump keeps the turn too, the join waits for the next frame, which turns on (0.07 px)
// and joins: measured ATE 1.26 cm on an AVX-512 build, 262 of 270 tracked as before; on an AVX2 machine (2026-12-07,
// the same commit) the join waits and is made as well, 262 tracked, but the frames around it are 10-24 cm off and
// the ATE is 3.24 cm. Bounds: the join waited and was made, and ATE under 5 cm (1.5x the worse of the two vector
// widths' measurements, under a third of the former 17.4; the bound of 3.1 cm set from the AVX-512 run alone failed
// on AVX2).
TEST(CliRun, ABlurredPairInATurnKeepsTheTurnAndTheJoinWaitsForASharpFrame) {
  TempDir dir;
  const auto r = RunRenderedRotation(dir, 8, "", "--exposure-step 1.3 --blur-sigma 2");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_LT(Field(r.output, "ate_rmse"), 0.05) << r.output;
  int waited = 0, joined = 0;
  for (const std::string& note : testing::CsvColumn(dir / "r/frames.csv", "note")) {
    waited += note.find("the join waits for the next frame") != std::string::npos;
    joined += note.find("the provisional map joins it") != std::string::npos;
  }
  EXPECT_GE(waited, 1);
  EXPECT_GE(joined, 1);
}

// A blurred frame's corners lie off where the sharp frames see them, all one way, so the first map's window is
// refined without the blurred frames, which are posed against the map after it. The planar scenario rendered with
// exposure steps and two of every ten frames blurred, seed 8: the window of frames 0-27 held six blurred frames, its
// first 40 frames came out 3.4 deg off in orientation and the run 25.9 cm off (8 % of the path) as the scale drifted
// on a 34-point map. Measured now: initialised at frame 16 as the clean render does, its blurred frames 3, 4, 13
// and 14 posed against the map, 300 of 300 tracked, ATE 0.72 cm (planar seeds 1-10 of these renders: 0.30-0.84 cm).
// Bounds: every frame tracked, every blurred frame of the window posed, ATE under 3.25 cm (the scenario's 1 %-of-path
// rule: 4.5x the measured, an eighth of the 25.9 cm before).
TEST(CliRun, BlurredFramesStayOutOfTheFirstMapsWindow) {
  TempDir dir;
  const auto s = RunMcslam(fmt::format(
      "synth --scenario planar --seed 8 --render --exposure-step 1.3 --blur-sigma 2 --out {}", dir / "s"));
  ASSERT_EQ(s.exit_code, 0) << s.output;
  const auto r = RunMcslam(fmt::format("run {} --dataset synthetic --seed 8 --out {}", dir / "s", dir / "r"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(Field(r.output, "tracked"), 300) << r.output;
  EXPECT_LT(Field(r.output, "ate_rmse"), 0.0325) << r.output;
  int blurred = 0, posed = 0;
  for (const std::string& note : testing::CsvColumn(dir / "r/frames.csv", "note"))
    if (note.find("a blurred frame of the initialisation's window") != std::string::npos)
      ++blurred, posed += note.find("posed against its map") != std::string::npos;
  EXPECT_GE(blurred, 2);
  EXPECT_EQ(posed, blurred);
}

// A provisional map that never joins the map (the run ends first, here; or it is lost) leaves its frames at the
// scale it guessed, a Sim(3) away from the map's: frames.csv's guessed_scale and report.json's say which and how
// many. Seed 1 cut at frame 180, before its join at 191: measured 59 frames (122-180, the provisional map's from
// its anchor on) flagged, all of the run's provisional ones, and its ATE 5.5 cm (the scale guessed 1.28x off)
// against 0.5 cm for the whole run. Bounds: at least 20 flagged, exactly the provisional frames, none before the
// note that made the provisional map's anchor; the whole run flags none (the test above).
TEST(CliRun, AProvisionalMapThatNeverJoinsLeavesItsFramesFlaggedAsAGuessedScale) {
  TempDir dir;
  const auto r = RunRenderedRotation(dir, 1, "--end 180");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json report = testing::ReadJson(dir / "r/report.json");
  EXPECT_GE(report["guessed_scale"].get<int>(), 20) << r.output;
  EXPECT_EQ(report["guessed_scale"].get<int>(), report["provisional"].get<int>());
  const std::vector<std::string> index = testing::CsvColumn(dir / "r/frames.csv", "index"),
                                 guessed = testing::CsvColumn(dir / "r/frames.csv", "guessed_scale"),
                                 note = testing::CsvColumn(dir / "r/frames.csv", "note");
  ASSERT_EQ(guessed.size(), index.size());
  EXPECT_EQ(std::count(guessed.begin(), guessed.end(), "1"), report["guessed_scale"].get<int>());
  // The anchor, as the note that made the provisional map names it: "provisional map from frames A (...".
  int anchor = -1;
  for (const std::string& n : note)
    if (const size_t at = n.find("provisional map from frames "); at != std::string::npos && anchor < 0)
      anchor = std::stoi(n.substr(at + std::string("provisional map from frames ").size()));
  ASSERT_GE(anchor, 0);
  for (size_t i = 0; i < index.size(); ++i)
    if (guessed[i] == "1") {
      EXPECT_GT(std::stoi(index[i]), anchor) << "frame " << index[i];
    }
}

// The bas-relief valley of a small-parallax window: held-out rotation seed 15 makes its provisional map from frames
// 121-130 at 3.7 deg of parallax, where the two views' cost has two minima along the valley and every two-view
// seed (8-point, 5-point) stopped in the wrong one: its rotation 6.6 deg where the camera turned 3.9, the move 55
// deg off; that map was lost at frame 206 and the trajectory ended 64 cm off (21 % of the 2.97 m path).
// The multi-start search of the valley (geometry::RelativePoseMinima) finds the other minimum, the true motion's,
// which explains the window better (mean squared residual 0.0068 against 0.0084 px^2) but, refined, falls short
// of the parallax asked for: it cannot be taken, and it stands against the wrong one, so the provisional map
// waits ("ambiguous initialisation", frames 130-140) and is made at frame 141 from 11.9 deg of parallax. Measured:
// the run to frame 210 (the provisional map joined at 196): 211 / 211 tracked, no frame at a guessed scale, ATE
// 1.31 cm (0.69 % of the 1.90 m path); with the run's seeds 1-8 on this scene 0.84-2.34 cm (0.44-1.23 %).
// Bounds: every frame tracked; none at a guessed scale; ATE under 3 % of the path (2.4x the worst run seed; the
// wrong minimum's map was lost at 206). The run stops at 210 because what follows the join is a stage of its own
// and chaotic on this scene: at frame 216 82 points are removed and the next ten frames are tracked on 10-20
// inliers, and one remap more or less there moved the whole run's ATE from 2.2 to 4.3 cm (measured 2026-11-28).
// The render the case was found on: outlines shaded from the 2x2 grid of rays only (--edge-samples 0).
TEST(CliRun, ASmallParallaxProvisionalMapTakesTheBetterMinimumOfTheBasReliefValley) {
  TempDir dir;
  const auto r = RunRenderedRotation(dir, 15, "--end 210", "--edge-samples 0");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(Field(r.output, "tracked"), 211) << r.output;
  EXPECT_LT(Field(r.output, "ate_rmse"), 0.03 * 1.90) << r.output;
  const nlohmann::json report = testing::ReadJson(dir / "r/report.json");
  EXPECT_GT(report["provisional"].get<int>(), 20) << r.output;
  EXPECT_EQ(report["guessed_scale"].get<int>(), 0) << r.output;
}

// A turn after a relocalisation is about the relocalised frame's centre. Rotation scenario with image noise 6,
// seed 6: the provisional map made after the first turn is lost at frame 195, where the map is found again (a
// frame relocalised from 17 matches); the next frames see 14-17 map points, fewer than a pose needs to stand
// against a turn, and their tracks agree on one. The turn's centre was taken from the best-posed frames before
// it, those of the provisional map just given up, 12 cm from the relocalised centre: frames 196-200 were placed
// there, their 14-17 map points 22-24 px from where they are seen. Now a turn's centre is looked for only among
// the frames posed since the last relocalisation. Measured: frames 196-199 turn about frame 195's centre,
// 0.78-0.87 px, 0.8 cm from the truth (12.9 cm before). Bounds: at least one such turn over a weak pose after
// the relocalisation (the case itself), each within the pose step's inlier threshold of 3 px. Frame 195's turn
// residual jumped; by default the join now waits for the next frame there (SystemOptions::
// bridge_join_waits_over_a_jump), which joins the provisional map instead of losing it, and the case does not
// arise: the test gives the provisional map up at that frame as before, to reach it.
// The render the case was found on: outlines shaded from the 2x2 grid of rays only (--edge-samples 0).
TEST(CliRun, ATurnOverAWeakPoseAfterARelocalisationFitsItsPoints) {
  TempDir dir;
  const auto s = RunMcslam(
      fmt::format("synth --scenario rotation --seed 6 --image-noise 6 --edge-samples 0 --render --out {}", dir / "s"));
  ASSERT_EQ(s.exit_code, 0) << s.output;
  testing::WriteText(dir / "o.json", R"({"options": {"system": {"bridge_join_waits_over_a_jump": false}}})");
  const auto r = RunMcslam(fmt::format("run {} --dataset synthetic --seed 6 --end 205 --options-from {} --out {}",
                                       dir / "s", dir / "o.json", dir / "r"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string csv = dir / "r/frames.csv";
  const std::vector<std::string> notes = testing::CsvColumn(csv, "note"), inliers = testing::CsvColumn(csv, "inliers"),
                                 residual = testing::CsvColumn(csv, "reproj_median_px");
  ASSERT_EQ(notes.size(), 206u);
  bool relocalised = false;
  int turns = 0;
  for (size_t i = 0; i < notes.size(); ++i) {
    relocalised = relocalised || notes[i].find("relocalised in the map") != std::string::npos;
    if (!relocalised || notes[i].rfind("rotation only", 0) != 0 || std::stoi(inliers[i]) == 0) continue;
    ++turns;
    EXPECT_LE(std::stod(residual[i]), 3.0) << "frame " << i << ": " << notes[i];
  }
  std::printf("[ turns    ] %d frames turned over a weak pose after the relocalisation\n", turns);
  EXPECT_GE(turns, 1) << r.output;
}

// A car at 1 m a frame (the forward scenario, rendered: a 90-degree bend, 119 m): the map renews itself every few
// frames, and with the paper's back end alone (poses and points never refined together) each generation of
// points passes its scale and heading errors on to the next. The local bundle adjustment after each keyframe
// holds them. Seed 9, measured: 120 / 120 tracked, ATE 16.2 cm with it (the scale of four 30-frame segments within
// 2.3 % of each other); without it, 79 / 120 (lost from the bend on) and 0.79 m over those, the scale 14 % off by
// frame 78 (before the pose step's translation prior, PoseTrackerOptions::translation_prior_steps: 117 / 120 and
// 5.2 m, the scale 1.9x after the bend). Over seeds 1-10 with it, 3-24 cm (docs/robustness.md). Bounds: every frame
// tracked; ATE under 0.5 m (0.4 % of the path; ~2x the worst seed); the run without it loses frames or is at least
// 5x worse.
TEST(CliRun, TheLocalBundleAdjustmentKeepsACarsScaleThroughItsBend) {
  TempDir dir;
  const auto s = RunMcslam("synth --scenario forward --seed 9 --render --out " + dir / "s");
  ASSERT_EQ(s.exit_code, 0) << s.output;
  const auto with = RunMcslam(fmt::format("run {} --dataset synthetic --seed 9 --out {}", dir / "s", dir / "r"));
  ASSERT_EQ(with.exit_code, 0) << with.output;
  EXPECT_EQ(Field(with.output, "tracked"), 120) << with.output;
  EXPECT_LT(Field(with.output, "ate_rmse"), 0.5) << with.output;
  const auto without = RunMcslam(
      fmt::format("run {} --dataset synthetic --seed 9 --local-ba-keyframes 0 --out {}", dir / "s", dir / "n"));
  ASSERT_EQ(without.exit_code, 0) << without.output;
  EXPECT_TRUE(Field(without.output, "tracked") < 120 ||
              Field(without.output, "ate_rmse") > 5 * Field(with.output, "ate_rmse"))
      << without.output;
}

// Frames 120-149 of the rendered paper scene unreadable: the camera moved on meanwhile. Scene seeds 1 and 2: on
// seed 2, with relocalisation off, the first try at frame 150 (normal spread) took a pose 50-55 cm off from 25
// of 46 stale tracks fitting loosely, until a first try after frames without a pose was checked as the second
// try's is (PoseTracker::FitLimitPx). Measured over scene seeds 1-6: the default run's worst tracked frame
// 1.3 / 1.4 / 2.7 / 4.0 / 7.0 / 1.7 cm (seed 5's: a frame relocalised from 32 matches all in one part of the
// image, 7 cm and 2 degrees off, a weakness of relocalisation left open); no frame tracked wrong in the runs
// without relocalisation.
TEST(CliRun, AfterAGapTheMapIsFoundAgainAndNoFrameIsTrackedWrong) {
  for (const int seed : {1, 2}) {
    SCOPED_TRACE(fmt::format("scene seed {}", seed));
    TempDir dir;
    const auto s = RunMcslam(fmt::format("synth --scenario paper --seed {} --render --frames 170 --out {}", seed,
                                         dir / "s"));
    ASSERT_EQ(s.exit_code, 0) << s.output;
    for (int i = 120; i < 150; ++i) testing::WriteText(dir / fmt::format("s/images/{:06d}.png", i), "");
    const GapRun with = RunOverAGap(dir / "s", dir / "r", "");
    EXPECT_GE(Field(with.output, "tracked"), 120 + 18) << with.output;  // all before; all but 1-2 after
    EXPECT_GE(with.tracked_after_gap, 18) << with.output;
    // A frame tracked wrong is tens of centimetres off; the runs before the gap alone have 1.1 cm at worst.
    EXPECT_LT(with.worst_m, 0.05);
    const nlohmann::json report = testing::ReadJson(dir / "r/report.json");
    EXPECT_GE(report["relocalisation"]["tracked"].get<int>(), 1) << report["relocalisation"].dump();
    EXPECT_NE(with.output.find("relocalised from"), std::string::npos) << with.output;

    // Neither relocalisation nor the pose step's wider second try: nothing after the gap (seed 2's first try is
    // refused: its loose fit is what the check is for).
    const GapRun without = RunOverAGap(dir / "s", dir / "n", "--no-relocalise --retry-rot-scale 0");
    EXPECT_EQ(without.tracked_after_gap, 0) << without.output;
    EXPECT_EQ(Field(without.output, "tracked"), 120) << without.output;
    EXPECT_LT(without.worst_m, 0.05);
    // The second try alone (4x the rotation spread) reaches across this gap too, and nothing it tracks is wrong:
    // its loose fits are refused (PoseTrackerOptions::retry_max_residual_ratio; measured on seed 1: frames 150 and
    // 151, 36 and 32 inliers at medians of 1.18 and 1.02 px against the recent frames' 0.08), then a frame is
    // found and 18-20 frames after the gap are tracked. Taken unchecked, frame 150 came out 47 cm off in one build.
    const GapRun wider = RunOverAGap(dir / "s", dir / "w", "--no-relocalise");
    EXPECT_GE(wider.tracked_after_gap, 10) << wider.output;
    EXPECT_LT(wider.worst_m, 0.05);
  }
}

// A blackout (frames 10-29 of the rendered car black: 20 m driven unseen) leaves the car where none of its first
// map can be relocalised. That map posed frames 0-9; once more frames were lost in a row than it posed, a new map
// is started (SystemOptions::restart_min_lost_frames), and once that one has posed more frames the first one's
// frames lose their poses. Measured (scene seeds 1-3): restarted at frame 20, frames 30-119 posed (90), ATE 2.8-13.8 cm over
// the 119 m path; without the restart 10 frames posed. Bounds: one restart, at frames 20-30; the new map's
// initialisation after the blackout; at least 80 frames posed, none of frames 0-9; ATE under 1 % of the path
// (1.19 m), the robustness matrix's rule.
TEST(CliRun, AfterABlackoutWithNothingToRelocaliseANewMapIsMade) {
  TempDir dir;
  const auto s = RunMcslam("synth --scenario forward --seed 1 --render --out " + dir / "s");
  ASSERT_EQ(s.exit_code, 0) << s.output;
  for (int i = 10; i < 30; ++i) {
    const std::string path = dir / fmt::format("s/images/{:06d}.png", i);
    cv::Mat img = cv::imread(path, cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(img.empty()) << path;
    img.setTo(0);
    ASSERT_TRUE(cv::imwrite(path, img)) << path;
  }
  const auto r = RunMcslam(fmt::format("run {} --dataset synthetic --seed 1 --out {}", dir / "s", dir / "r"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json report = testing::ReadJson(dir / "r/report.json");
  ASSERT_EQ(report["map_restarts"].size(), 1u) << report["map_restarts"].dump();
  const int restarted_at = report["map_restarts"][0]["frame"].get<int>();
  EXPECT_GE(restarted_at, 20);
  EXPECT_LE(restarted_at, 30);
  ASSERT_TRUE(report["initialisation"].is_object()) << report.dump();
  EXPECT_GE(report["initialisation"]["frame"].get<int>(), 30);
  EXPECT_GE(Field(r.output, "tracked"), 80) << r.output;
  EXPECT_LT(Field(r.output, "ate_rmse"), 1.19) << r.output;
  const std::vector<std::string> status = testing::CsvColumn(dir / "r/frames.csv", "status");
  ASSERT_GE(status.size(), 10u);
  for (int i = 0; i < 10; ++i) EXPECT_NE(status[static_cast<size_t>(i)], "tracked") << "frame " << i;
  EXPECT_NE(r.output.find("a new map is started"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace mcslam
