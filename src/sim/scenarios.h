#pragma once
// The scenario zoo (issue #16): synthetic sequences with exact ground truth for the motions and scenes that
// break monocular initialisation and tracking, each both observation-only (points sampled on the scene's
// quads, exact occlusion) and renderable (sim/render.h ray-casts the same quads). docs/scenarios.md has the
// measured statistics of each.
//
//   paper        the paper's §8.1: a textured box, hand-held orbit (MakePaperScenario, unchanged)
//   forward      a car: 1 m a frame at 10 Hz along a street with facades on both sides, a 90 deg left turn
//                in the middle; a KITTI-like wide camera (620x188, f = 359 px: KITTI's field of view)
//   rotation     a room around the box: the first second mostly panning in place, then hand-held motion
//                with two pure-rotation pans (camera centre fixed) mid-run
//   planar       a poster on a wall filling the view; the camera moves in front of it and towards it;
//                every point on one plane
//   fast         the paper's path at kFastSpeedFactor times its speed (large inter-frame displacement)
//   still-start  the camera exactly still for kStillStartS seconds, then the paper's motion
//   stop-and-go  the paper's motion, brought to a full stop twice mid-run (kStopAndGoStopsS), still for kStopS
//   sparse       the paper's box and floor with smooth, low-contrast textures and a few blobs; 70 points
//
// Every path is a function of time; the seed makes the path's phases, the world's layout (forward: the
// buildings), the points, the noise and the outliers, and (render seed) the textures. Same options, same
// sequence, bit for bit.
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/camera.h"
#include "sim/paper_scenario.h"
#include "sim/scene.h"

namespace mcslam::sim {

// The names accepted by MakeScenario, in the order the docs list them.
const std::vector<std::string>& ScenarioNames();

// The fast scenario's path runs this many times faster than the paper's (its --speed multiplies this).
inline constexpr double kFastSpeedFactor = 15.0;
// The still-start scenario's camera does not move during its first kStillStartS seconds (whatever the speed).
inline constexpr double kStillStartS = 2.0;
// The stop-and-go scenario's stops: each begins to slow down at one of these times (seconds of the camera's
// clock), reaches a standstill kStopRampS later, stays exactly still for kStopS and is back to speed kStopRampS
// after that.
inline constexpr double kStopAndGoStopsS[2] = {3.0, 6.5};
inline constexpr double kStopS = 1.5;
inline constexpr double kStopRampS = 0.4;
// The rotation scenario's pure-rotation segments, in path seconds (speed * time): the camera centre is fixed.
inline constexpr std::pair<double, double> kRotationPureSegmentsS[2] = {{3.2, 4.0}, {5.8, 6.8}};
// ... and its opening: panning in place (the centre drifts about 1 cm in all) until this path time.
inline constexpr double kRotationOpeningS = 1.0;
// The forward scenario's car: metres a second at speed 1, and the length of its street.
inline constexpr double kForwardSpeedMps = 10.0;
inline constexpr double kForwardRouteM = 160.0;

// What a scenario is when an option is not given.
struct ScenarioInfo {
  std::string name;
  PinholeCamera camera;
  double fps = 30;
  int frames = 300;
  int num_points = 400;
  // The path is defined for path times (speed * seconds) up to this; infinity when the path never ends.
  double max_path_s = 0;
};
// Throws std::invalid_argument listing the known names when `name` is not one.
ScenarioInfo DescribeScenario(const std::string& name);

struct ScenarioOptions {
  std::string name = "paper";
  std::optional<int> frames = std::nullopt;      // default: the scenario's
  std::optional<double> fps = std::nullopt;      // default: the scenario's; frame i has timestamp i / fps
  double noise_px = 0.0;                         // as PaperScenarioOptions
  double outlier_fraction = 0.0;
  double speed = 1.0;                            // multiplies the scenario's own speed along its path, > 0
  std::optional<int> num_points = std::nullopt;  // default: the scenario's
  uint64_t seed = 1;
  Distortion lens{};                             // as PaperScenarioOptions: the camera's lens, none by default
  double image_scale = 1.0;                      // as PaperScenarioOptions: the camera's resolution, scaled
  double hfov_deg = 0;                           // as PaperScenarioOptions: the field of view, 0 the scenario's

  // The most frames the scenario's path holds at this speed and fps (INT_MAX when the path never ends).
  int MaxFrames() const;
  // Throws std::invalid_argument naming the bad field and its value (an unknown name lists the known ones;
  // frames past the end of a bounded path say how many fit).
  void Check() const;
};

// Builds the scenario: camera, poses, stamps, points, observations and the scene to render. For "paper"
// this is MakePaperScenario (bit-identical to it). Throws std::invalid_argument (from Check()).
SyntheticSequence MakeScenario(const ScenarioOptions& options);

// The scenario's world (what MakeScenario puts in SyntheticSequence::scene); forward's layout depends on
// the seed, the others' do not.
Scene ScenarioScene(const std::string& name, uint64_t seed);

}  // namespace mcslam::sim
