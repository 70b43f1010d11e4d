#include "sim/scenarios.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <functional>
#include <limits>
#include <stdexcept>

#include <fmt/format.h>

#include "core/random.h"

namespace mcslam::sim {
namespace {

using namespace detail;  // the seed's streams (paper_scenario.h), Num

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// ---- cameras -----------------------------------------------------------------------------------------------

// KITTI's field of view (1241x376, f = 718 px) at half the resolution, to keep rendering cheap.
PinholeCamera ForwardCamera() { return PinholeCamera(359.0, 359.0, 309.5, 93.5, 620, 188); }

// ---- path helpers ------------------------------------------------------------------------------------------

double Smoothstep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

// Path progress under a piecewise-linear rate: tau(t) = integral of rate from 0 to t, with knots (time,
// rate) starting at time 0 (the last rate holds after the last knot). Where the rate is 0 at both ends of a
// piece, tau is the same double all along it: the camera does not move by even a rounding error.
class TimeWarp {
 public:
  explicit TimeWarp(std::vector<std::pair<double, double>> knots) : knots_(std::move(knots)) {
    cumulative_.push_back(0.0);
    for (size_t i = 0; i + 1 < knots_.size(); ++i)
      cumulative_.push_back(cumulative_.back() + Piece(i, knots_[i + 1].first));
  }
  double operator()(double t) const {
    for (size_t i = 0; i + 1 < knots_.size(); ++i)
      if (t <= knots_[i + 1].first) return cumulative_[i] + Piece(i, t);
    return cumulative_.back() + (t - knots_.back().first) * knots_.back().second;
  }

 private:
  // The integral over [t_i, t] of the rate on piece i (trapezoid: exact for a linear rate).
  double Piece(size_t i, double t) const {
    const auto [t0, r0] = knots_[i];
    const auto [t1, r1] = knots_[i + 1];
    const double r = r0 + (r1 - r0) * (t - t0) / (t1 - t0);
    return (t - t0) * (r0 + r) / 2.0;
  }
  std::vector<std::pair<double, double>> knots_;
  std::vector<double> cumulative_;
};

std::vector<PathWave> SeededPathWaves(std::vector<PathWave> waves, uint64_t seed) {
  CounterRng rng(seed, kStreamScenarioPath);
  for (PathWave& w : waves) w.phase = rng.Uniform(0.0, 2.0 * kPi);
  return waves;
}

// The camera's orientation looking along forward_in_world (not vertical): camera z forward, x right, y
// down, world +z up, no roll; then hand wobble in the camera's own axes (radians): pan about y, tilt about
// x, roll about z. The paper's path computes the same, written out in paper_scenario.cc.
Eigen::Quaterniond WorldFromLookAt(const Eigen::Vector3d& forward_in_world, double pan, double tilt, double roll) {
  const Eigen::Vector3d z_axis = forward_in_world.normalized();
  const Eigen::Vector3d x_axis = z_axis.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d y_axis = z_axis.cross(x_axis);
  Eigen::Matrix3d world_from_lookat;
  world_from_lookat << x_axis, y_axis, z_axis;
  return Eigen::Quaterniond(world_from_lookat) * QuaternionFromRotationVector(Eigen::Vector3d::UnitZ() * roll) *
         QuaternionFromRotationVector(Eigen::Vector3d::UnitX() * tilt) *
         QuaternionFromRotationVector(Eigen::Vector3d::UnitY() * pan);
}

using Path = std::function<Pose(double stamp_s)>;

// ---- forward: a car in a street ----------------------------------------------------------------------------

// The route: north along street A (x = 0) from y = 0, a left turn of radius kTurnRadiusM starting at
// y = kTurnStartM, then west along street B (y = kStreetBY).
constexpr double kTurnStartM = 50.0;
constexpr double kTurnRadiusM = 12.0;
constexpr double kStreetBY = kTurnStartM + kTurnRadiusM;
constexpr double kCameraHeightM = 1.6;

Eigen::Vector2d RoutePoint(double s) {
  const double arc = kPi / 2 * kTurnRadiusM;
  if (s < kTurnStartM) return {0.0, s};
  if (s < kTurnStartM + arc) {
    const double phi = (s - kTurnStartM) / kTurnRadiusM;
    return {-kTurnRadiusM + kTurnRadiusM * std::cos(phi), kTurnStartM + kTurnRadiusM * std::sin(phi)};
  }
  return {-kTurnRadiusM - (s - kTurnStartM - arc), kStreetBY};
}

Path ForwardPath(uint64_t seed, double speed) {
  // Lane keeping (a sway of a few decimetres), road bumps, and the small pitch, roll and yaw of a car body.
  const std::vector<PathWave> w = SeededPathWaves({{0.30, 37.0}, {0.08, 13.0}, {0.015, 7.3}, {DegToRad(0.4), 11.0},
                                           {DegToRad(0.3), 17.0}, {DegToRad(0.4), 23.0}},
                                          seed);
  const auto center = [w](double s) {
    const Eigen::Vector2d p = RoutePoint(s);
    const Eigen::Vector2d ahead = RoutePoint(s + 0.5) - RoutePoint(s - 0.5);
    const Eigen::Vector2d left = Eigen::Vector2d(-ahead.y(), ahead.x()).normalized();
    const Eigen::Vector2d xy = p + (w[0].At(s) + w[1].At(s)) * left;
    return Eigen::Vector3d(xy.x(), xy.y(), kCameraHeightM + w[2].At(s));
  };
  return [w, center, speed](double t) {
    const double s = kForwardSpeedMps * speed * t;  // metres along the route
    const Eigen::Vector3d c = center(s);
    // The car points along its own track (the sway included), plus a little yaw wobble.
    Eigen::Vector3d ahead = center(s + 0.5) - center(s - 0.5);
    ahead.z() = 0;
    const Pose world_from_cam(WorldFromLookAt(ahead, w[5].At(s), w[3].At(s), w[4].At(s)), c);
    return world_from_cam.Inverse();
  };
}

// One side of a street: buildings one after another from `from_m` to `to_m` along `along` (from the street's
// origin point), each a facade facing the street at 4.5-12 m from its centre line, 6-16 m high and 8-20 m
// wide, with two side walls 10 m deep, and about every other one followed by a 2-8 m gap.
void AddStreetSide(const Eigen::Vector2d& origin, const Eigen::Vector2d& along, const Eigen::Vector2d& out,
                   double from_m, double to_m, CounterRng& rng, Scene* scene) {
  constexpr double kDepthM = 10.0, kTexelsPerM = 40.0;
  const auto at = [&](double a, double d) {
    const Eigen::Vector2d p = origin + a * along + d * out;
    return Eigen::Vector3d(p.x(), p.y(), 0.0);
  };
  const Eigen::Vector3d along3(along.x(), along.y(), 0), out3(out.x(), out.y(), 0);
  for (double a = from_m; a < to_m - 1.0;) {
    const double width = std::min(rng.Uniform(8.0, 20.0), to_m - a);
    const double setback = rng.Uniform(4.5, 12.0), height = rng.Uniform(6.0, 16.0);
    const float light = static_cast<float>(rng.Uniform(0.75, 1.0));
    const Eigen::Vector3d up(0, 0, height);
    scene->quads.push_back(
        MakeQuad(at(a, setback), width * along3, up, -out3, TextureStyle::kFacade, kTexelsPerM, light, 1.0));
    for (const double end : {0.0, 1.0}) {
      const Eigen::Vector3d facing = end == 0.0 ? Eigen::Vector3d(-along3) : along3;
      scene->quads.push_back(MakeQuad(at(a + end * width, setback), kDepthM * out3, up, facing, TextureStyle::kFacade,
                                      kTexelsPerM, 0.85f * light, 0.3));
    }
    a += width;
    if (rng.Below(2) == 0) a += rng.Uniform(2.0, 8.0);
  }
}

// Ground tiles over [x0, x1] x [y0, y1], about tile_m square, each its own texture (no repetition).
void AddGround(double x0, double x1, double y0, double y1, double tile_m, double texels_per_m, double point_weight,
               Scene* scene) {
  const int nx = std::max(1, static_cast<int>(std::ceil((x1 - x0) / tile_m)));
  const int ny = std::max(1, static_cast<int>(std::ceil((y1 - y0) / tile_m)));
  const double dx = (x1 - x0) / nx, dy = (y1 - y0) / ny;
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < ny; ++j)
      scene->quads.push_back(MakeQuad(Eigen::Vector3d(x0 + i * dx, y0 + j * dy, 0), Eigen::Vector3d(dx, 0, 0),
                                      Eigen::Vector3d(0, dy, 0), Eigen::Vector3d::UnitZ(), TextureStyle::kGround,
                                      texels_per_m, 0.8f, point_weight));
}

Scene ForwardScene(uint64_t seed) {
  CounterRng rng(seed, kStreamWorld);
  Scene scene;
  scene.background = 0.7f;  // an overcast sky: flat, so no corner there
  // Road and pavement within 12 m of the centre lines (points), beyond it ground seen only through gaps.
  AddGround(-12, 12, -20, kTurnStartM, 10, 32, 0.3, &scene);
  AddGround(-150, 12, kTurnStartM, kStreetBY + 12, 10, 32, 0.3, &scene);
  AddGround(-24, -12, -20, kTurnStartM, 12, 16, 0.0, &scene);
  AddGround(12, 24, -20, kStreetBY + 24, 12, 16, 0.0, &scene);
  AddGround(-150, 12, kStreetBY + 12, kStreetBY + 24, 12, 16, 0.0, &scene);
  AddGround(-150, -24, kTurnStartM - 12, kTurnStartM, 12, 16, 0.0, &scene);
  // Street A's sides end where street B's begin; B's north side closes the view ahead of the start.
  const Eigen::Vector2d a_origin(0, 0), north(0, 1), east(1, 0);
  const Eigen::Vector2d b_origin(0, kStreetBY), west(-1, 0);
  AddStreetSide(a_origin, north, east, -20, kStreetBY + 4, rng, &scene);
  AddStreetSide(a_origin, north, west, -20, kStreetBY - 5.5, rng, &scene);
  AddStreetSide(b_origin, west, north, -15, 150, rng, &scene);
  AddStreetSide(b_origin, west, -north, 5.5, 150, rng, &scene);
  // The far end of street B.
  scene.quads.push_back(MakeQuad(Eigen::Vector3d(-150, kStreetBY - 22, 0), Eigen::Vector3d(0, 44, 0),
                                 Eigen::Vector3d(0, 0, 15), Eigen::Vector3d::UnitX(), TextureStyle::kFacade, 40, 0.9f));
  return scene;
}

// ---- rotation: a room, pans in place ------------------------------------------------------------------------

Scene RoomScene() {
  constexpr double kHalfM = 4.5, kHeightM = 2.7, kTexelsPerM = 128;
  Scene scene = PaperScene(kHalfM);
  // Box faces much denser in points than the walls, as in the paper; the floor and ceiling sparser.
  for (int i = 0; i < 6; ++i) scene.quads[static_cast<size_t>(i)].point_weight = 20.0;
  Quad& floor = scene.quads[6];
  floor = MakeQuad(floor.corner_in_world, floor.edge_u_in_world, floor.edge_v_in_world, floor.normal_in_world,
                   TextureStyle::kGround, kTexelsPerM, floor.brightness, 2.0);
  const double z0 = floor.corner_in_world.z();
  const Eigen::Vector3d up(0, 0, kHeightM);
  // Four walls facing in, each its own texture and light.
  const struct {
    Eigen::Vector3d corner, edge, normal;
    float light;
  } walls[4] = {{{-kHalfM, kHalfM, z0}, {2 * kHalfM, 0, 0}, {0, -1, 0}, 0.9f},
                {{-kHalfM, -kHalfM, z0}, {2 * kHalfM, 0, 0}, {0, 1, 0}, 0.8f},
                {{kHalfM, -kHalfM, z0}, {0, 2 * kHalfM, 0}, {-1, 0, 0}, 0.95f},
                {{-kHalfM, -kHalfM, z0}, {0, 2 * kHalfM, 0}, {1, 0, 0}, 0.85f}};
  for (const auto& w : walls)
    scene.quads.push_back(MakeQuad(w.corner, w.edge, up, w.normal, TextureStyle::kFacade, kTexelsPerM, w.light, 6.0));
  scene.quads.push_back(MakeQuad(Eigen::Vector3d(-kHalfM, -kHalfM, z0 + kHeightM), Eigen::Vector3d(2 * kHalfM, 0, 0),
                                 Eigen::Vector3d(0, 2 * kHalfM, 0), -Eigen::Vector3d::UnitZ(), TextureStyle::kGround,
                                 kTexelsPerM, 0.6f, 1.0));
  return scene;
}

Path RotationPath(uint64_t seed, double speed) {
  // Plain copies, not structured bindings: a lambda below captures them (clang 14 cannot capture bindings).
  const double s1 = kRotationPureSegmentsS[0].first, e1 = kRotationPureSegmentsS[0].second;
  const double s2 = kRotationPureSegmentsS[1].first, e2 = kRotationPureSegmentsS[1].second;
  // Translation progress: 2 % of the paper's speed while the opening pan lasts, none in the pure-rotation
  // segments, ramps of 0.2-0.3 s between (no jump in velocity).
  const TimeWarp warp({{0.0, 0.02},
                       {kRotationOpeningS, 0.02},
                       {kRotationOpeningS + 0.3, 1.0},
                       {s1 - 0.2, 1.0},
                       {s1, 0.0},
                       {e1, 0.0},
                       {e1 + 0.2, 1.0},
                       {s2 - 0.2, 1.0},
                       {s2, 0.0},
                       {e2, 0.0},
                       {e2 + 0.2, 1.0}});
  const PaperPathFunction paper = MakePaperPath(seed);
  const std::vector<PathWave> w = SeededPathWaves({{DegToRad(0.5), 2.3}, {DegToRad(0.4), 3.1}}, seed);
  return [=](double t) {
    const double tp = speed * t;
    // Yaw about the vertical through the camera centre: 30 deg off the box to start with, turning to it over
    // the opening; +45 deg in the first segment, -55 deg in the second.
    const double pan = DegToRad(30.0) * (1.0 - Smoothstep(tp / kRotationOpeningS)) +
                       DegToRad(45.0) * Smoothstep((tp - s1) / (e1 - s1)) -
                       DegToRad(55.0) * Smoothstep((tp - s2) / (e2 - s2));
    const Pose base = paper(warp(tp)).Inverse();  // world_from_cam; t is the centre
    const Eigen::Quaterniond q = Eigen::Quaterniond(Eigen::AngleAxisd(pan, Eigen::Vector3d::UnitZ())) * base.q *
                                 QuaternionFromRotationVector(Eigen::Vector3d(w[0].At(tp), 0.0, w[1].At(tp)));
    return Pose(q.normalized(), base.t).Inverse();
  };
}

// ---- planar: a poster on a wall ----------------------------------------------------------------------------

// The wall is the plane y = 0 facing -y: a poster in the middle, wallpaper around it, coplanar quads.
Scene PosterScene() {
  Scene scene;
  const Eigen::Vector3d normal(0, -1, 0);
  const auto add = [&](double x0, double x1, double z0, double z1, TextureStyle style, double texels_per_m, float light) {
    scene.quads.push_back(MakeQuad(Eigen::Vector3d(x0, 0, z0), Eigen::Vector3d(x1 - x0, 0, 0),
                                   Eigen::Vector3d(0, 0, z1 - z0), normal, style, texels_per_m, light));
  };
  constexpr double kPx = 1.0, kPz0 = 0.55, kPz1 = 1.85;  // the poster: 2.0 x 1.3 m
  constexpr double kWx = 1.9, kWz0 = 0.1, kWz1 = 2.3;    // the wall around it
  // Texel densities give blobs of 10-70 px at the usual 1.2 m, like the paper's box.
  add(-kPx, kPx, kPz0, kPz1, TextureStyle::kBlobs, 640, 1.0f);
  add(-kWx, -kPx, kWz0, kWz1, TextureStyle::kFacade, 400, 0.8f);
  add(kPx, kWx, kWz0, kWz1, TextureStyle::kFacade, 400, 0.8f);
  add(-kPx, kPx, kWz0, kPz0, TextureStyle::kFacade, 400, 0.85f);
  add(-kPx, kPx, kPz1, kWz1, TextureStyle::kFacade, 400, 0.85f);
  return scene;
}

Path PlanarPath(uint64_t seed, double speed) {
  // Side to side, towards and away from the wall (0.9-1.6 m), up and down, aiming about the poster's centre.
  const std::vector<PathWave> w = SeededPathWaves({{0.45, 9.0},
                                           {0.06, 2.3},
                                           {0.35, 7.0},
                                           {0.15, 6.3},
                                           {0.20, 5.1},
                                           {0.12, 4.4},
                                           {DegToRad(1.0), 3.1},
                                           {DegToRad(1.0), 2.7},
                                           {DegToRad(3.0), 4.9}},
                                          seed);
  return [w, speed](double t) {
    const double tp = speed * t;
    const Eigen::Vector3d center(w[0].At(tp) + w[1].At(tp), -(1.25 + w[2].At(tp)), 1.2 + w[3].At(tp));
    const Eigen::Vector3d aim(w[4].At(tp), 0.0, 1.2 + w[5].At(tp));
    const Pose world_from_cam(WorldFromLookAt(aim - center, w[6].At(tp), w[7].At(tp), w[8].At(tp)),
                              center);
    return world_from_cam.Inverse();
  };
}

// ---- the paper's world, other motions or textures ---------------------------------------------------------

Scene SmoothPaperScene() {
  Scene scene = PaperScene();
  for (Quad& q : scene.quads) q.style = TextureStyle::kSmooth;
  return scene;
}

Path PaperPathAt(uint64_t seed, double speed) {
  const PaperPathFunction paper = MakePaperPath(seed);
  return [paper, speed](double t) { return paper(speed * t); };
}

Path StillStartPath(uint64_t seed, double speed) {
  // Still, then the paper's motion, its speed ramping up over half a second (a hand starting to move).
  const TimeWarp warp({{0.0, 0.0}, {kStillStartS, 0.0}, {kStillStartS + 0.5, 1.0}});
  const PaperPathFunction paper = MakePaperPath(seed);
  return [paper, warp, speed](double t) { return paper(speed * warp(t)); };
}

Path StopAndGoPath(uint64_t seed, double speed) {
  // The paper's motion, brought to a full stop twice (a hand that pauses, a car at a light): the path slows to
  // nothing over kStopRampS, stays exactly still for kStopS, and speeds up again over kStopRampS.
  std::vector<std::pair<double, double>> knots = {{0.0, 1.0}};
  for (const double start : kStopAndGoStopsS) {
    knots.push_back({start, 1.0});
    knots.push_back({start + kStopRampS, 0.0});
    knots.push_back({start + kStopRampS + kStopS, 0.0});
    knots.push_back({start + 2 * kStopRampS + kStopS, 1.0});
  }
  const TimeWarp warp(knots);
  const PaperPathFunction paper = MakePaperPath(seed);
  // The stops are in the camera's time, whatever the speed: the warp is applied before the speed scales the path.
  return [paper, warp, speed](double t) { return paper(speed * warp(t)); };
}

Path ScenarioPath(const std::string& name, uint64_t seed, double speed) {
  if (name == "forward") return ForwardPath(seed, speed);
  if (name == "rotation") return RotationPath(seed, speed);
  if (name == "planar") return PlanarPath(seed, speed);
  if (name == "fast") return PaperPathAt(seed, kFastSpeedFactor * speed);
  if (name == "still-start") return StillStartPath(seed, speed);
  if (name == "stop-and-go") return StopAndGoPath(seed, speed);
  return PaperPathAt(seed, speed);  // paper, sparse
}

}  // namespace

const std::vector<std::string>& ScenarioNames() {
  static const std::vector<std::string> kNames = {"paper", "forward", "rotation", "planar",
                                                  "fast",  "still-start", "stop-and-go", "sparse"};
  return kNames;
}

ScenarioInfo DescribeScenario(const std::string& name) {
  ScenarioInfo info;
  info.name = name;
  info.camera = PaperCamera();
  info.max_path_s = kInfinity;
  if (name == "paper" || name == "still-start" || name == "stop-and-go") {
  } else if (name == "forward") {
    info.camera = ForwardCamera();
    info.fps = 10;
    info.frames = 120;
    info.num_points = 4000;
    info.max_path_s = kForwardRouteM / kForwardSpeedMps;
  } else if (name == "rotation") {
    info.frames = 270;
    info.num_points = 3200;
  } else if (name == "planar") {
    info.num_points = 4000;
  } else if (name == "fast") {
    info.frames = 150;
  } else if (name == "sparse") {
    info.num_points = 70;
  } else {
    std::string known;
    for (const std::string& n : ScenarioNames()) known += (known.empty() ? "" : ", ") + n;
    throw std::invalid_argument("unknown scenario '" + name + "' (known: " + known + ")");
  }
  return info;
}

Scene ScenarioScene(const std::string& name, uint64_t seed) {
  DescribeScenario(name);  // refuses unknown names
  if (name == "forward") return ForwardScene(seed);
  if (name == "rotation") return RoomScene();
  if (name == "planar") return PosterScene();
  if (name == "sparse") return SmoothPaperScene();
  return PaperScene();  // paper, fast, still-start, stop-and-go
}

int ScenarioOptions::MaxFrames() const {
  const ScenarioInfo info = DescribeScenario(name);
  if (!std::isfinite(info.max_path_s)) return INT_MAX;
  // The last frame, (frames - 1) / fps seconds in, must stay on the path: speed * (frames - 1) / fps <= max.
  const double frames_that_fit = std::floor(info.max_path_s * fps.value_or(info.fps) / speed + 1e-9) + 1.0;
  return static_cast<int>(std::min(frames_that_fit, static_cast<double>(INT_MAX)));
}

void ScenarioOptions::Check() const {
  const ScenarioInfo info = DescribeScenario(name);
  PaperScenarioOptions shared;  // the checks every scenario shares
  shared.frames = frames.value_or(info.frames);
  shared.fps = fps.value_or(info.fps);
  shared.noise_px = noise_px;
  shared.outlier_fraction = outlier_fraction;
  shared.speed = speed;
  shared.num_points = num_points.value_or(info.num_points);
  shared.image_scale = image_scale;
  shared.hfov_deg = hfov_deg;
  shared.Check();
  CheckLens(ScenarioCamera(info.camera, {}, image_scale, hfov_deg), lens);
  if (shared.frames > MaxFrames())
    throw std::invalid_argument(fmt::format(
        "frames must be at most {} for the {} scenario at speed {} and fps {} (its path ends after {} s of path "
        "time), got {}",
        MaxFrames(), name, Num(speed), Num(shared.fps), Num(info.max_path_s), shared.frames));
}

SyntheticSequence MakeScenario(const ScenarioOptions& options) {
  options.Check();
  const ScenarioInfo info = DescribeScenario(options.name);
  PaperScenarioOptions o;
  o.frames = options.frames.value_or(info.frames);
  o.fps = options.fps.value_or(info.fps);
  o.noise_px = options.noise_px;
  o.outlier_fraction = options.outlier_fraction;
  o.speed = options.speed;
  o.num_points = options.num_points.value_or(info.num_points);
  o.seed = options.seed;
  o.lens = options.lens;
  o.image_scale = options.image_scale;
  o.hfov_deg = options.hfov_deg;
  if (options.name == "paper") return MakePaperScenario(o);

  SyntheticSequence seq;
  seq.camera = ScenarioCamera(info.camera, options.lens, options.image_scale, options.hfov_deg);
  seq.fps = o.fps;
  seq.scene = ScenarioScene(options.name, o.seed);
  SamplePointsOnQuads(seq.scene, o.num_points, o.seed, kStreamPoints, &seq.points_in_world, &seq.normals_in_world);
  const Path path = ScenarioPath(options.name, o.seed, o.speed);
  seq.cam_from_world.reserve(static_cast<size_t>(o.frames));
  seq.stamps_s.reserve(static_cast<size_t>(o.frames));
  for (int i = 0; i < o.frames; ++i) {
    seq.stamps_s.push_back(i / o.fps);
    seq.cam_from_world.push_back(path(seq.stamps_s.back()));
  }
  const QuadIntersector scene(seq.scene);
  ObservePoints(o.noise_px, o.outlier_fraction, o.seed,
                [&](const Pose& cam_from_world, size_t j, Eigen::Vector2d* uv_px) {
                  return IsPointVisibleInScene(seq.camera, cam_from_world, scene, seq.points_in_world[j],
                                               seq.normals_in_world[j], uv_px);
                },
                &seq);
  return seq;
}

}  // namespace mcslam::sim
