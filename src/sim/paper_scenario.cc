#include "sim/paper_scenario.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <fmt/format.h>

#include "core/random.h"

namespace mcslam::sim {

std::string detail::Num(double v) { return fmt::format("{}", v); }

namespace {

using namespace detail;  // the seed's streams, Num

// A sinusoid of the camera path: amplitude * sin(2 pi t / period + phase), phase drawn from the seed.
struct Wave {
  double amplitude;
  double period_s;
  double phase = 0;
  double At(double t) const { return amplitude * std::sin(2.0 * kPi * t / period_s + phase); }
};

// The hand-held path around the box, a function of (speed-scaled) time. Periods are incommensurate so the
// motion does not visibly repeat; amplitudes keep the box in view (see the header's promises and the tests).
class PaperPath {
 public:
  explicit PaperPath(uint64_t seed) {
    CounterRng rng(seed, kStreamPath);
    // The main sweep: azimuth from about -40 deg to +40 deg over the default 10 s, then back.
    sweep_phase_ = rng.Uniform(-0.15, 0.15);
    for (Wave* w : {&az_wiggle_, &el_[0], &el_[1], &radius_[0], &radius_[1], &aim_x_, &aim_z_, &pan_[0], &pan_[1],
                    &tilt_[0], &tilt_[1], &roll_[0], &roll_[1]}) {
      w->phase = rng.Uniform(0.0, 2.0 * kPi);
    }
  }

  // Always inlined: how the compiler fuses its products into FMAs depends on where it is inlined, and the
  // paper's files (its ground truth to the last bit) must stay what they were when this had one caller.
  [[gnu::always_inline]] Pose CamFromWorld(double t) const {
    const double az = -DegToRad(40.0) * std::cos(kPi * t / 10.0 + sweep_phase_) + az_wiggle_.At(t);
    const double el = DegToRad(20.0) + el_[0].At(t) + el_[1].At(t);
    const double r = 3.0 + radius_[0].At(t) + radius_[1].At(t);
    const Eigen::Vector3d center_in_world(r * std::cos(el) * std::sin(az), -r * std::cos(el) * std::cos(az),
                                          r * std::sin(el));
    // Aim near the box centre, wandering enough that the box's edge now and then leaves the image (points
    // are then lost at the border too); camera z forward, x right, y down (world +z is up).
    const Eigen::Vector3d aim_in_world(aim_x_.At(t), 0.0, aim_z_.At(t));
    const Eigen::Vector3d z_axis = (aim_in_world - center_in_world).normalized();
    const Eigen::Vector3d x_axis = z_axis.cross(Eigen::Vector3d::UnitZ()).normalized();
    const Eigen::Vector3d y_axis = z_axis.cross(x_axis);
    Eigen::Matrix3d world_from_lookat;
    world_from_lookat << x_axis, y_axis, z_axis;
    // Hand wobble in the camera's own axes: pan about y, tilt about x, roll about z.
    const Eigen::Quaterniond wobble = QuaternionFromRotationVector(Eigen::Vector3d::UnitZ() * Sum(roll_, t)) *
                                      QuaternionFromRotationVector(Eigen::Vector3d::UnitX() * Sum(tilt_, t)) *
                                      QuaternionFromRotationVector(Eigen::Vector3d::UnitY() * Sum(pan_, t));
    const Pose world_from_cam(Eigen::Quaterniond(world_from_lookat) * wobble, center_in_world);
    return world_from_cam.Inverse();
  }

 private:
  static double Sum(const std::array<Wave, 2>& waves, double t) { return waves[0].At(t) + waves[1].At(t); }

  double sweep_phase_ = 0;
  Wave az_wiggle_{DegToRad(4.0), 3.7};
  std::array<Wave, 2> el_{{{DegToRad(5.0), 4.3}, {DegToRad(1.5), 2.1}}};
  std::array<Wave, 2> radius_{{{0.15, 6.1}, {0.04, 1.9}}};
  Wave aim_x_{0.25, 5.7};
  Wave aim_z_{0.12, 4.1};
  std::array<Wave, 2> pan_{{{DegToRad(2.0), 3.1}, {DegToRad(0.8), 1.3}}};
  std::array<Wave, 2> tilt_{{{DegToRad(1.5), 2.7}, {DegToRad(0.7), 1.1}}};
  std::array<Wave, 2> roll_{{{DegToRad(2.5), 4.9}, {DegToRad(0.8), 1.7}}};
};

// Points on the six faces of the box, uniform on each face, counts proportional to area (largest remainder,
// so they add up to num_points exactly).
void MakeBoxPoints(int num_points, uint64_t seed, std::vector<Eigen::Vector3d>* points,
                   std::vector<Eigen::Vector3d>* normals) {
  const Eigen::Vector3d half(kPaperBoxSizeM[0] / 2, kPaperBoxSizeM[1] / 2, kPaperBoxSizeM[2] / 2);
  struct Face {
    int axis;     // the normal's axis
    double sign;  // +1 or -1
  };
  const std::array<Face, 6> faces{{{0, 1}, {0, -1}, {1, 1}, {1, -1}, {2, 1}, {2, -1}}};
  std::vector<double> area(6);
  for (int f = 0; f < 6; ++f) {
    const int a = (faces[f].axis + 1) % 3, b = (faces[f].axis + 2) % 3;
    area[f] = 4.0 * half[a] * half[b];
  }
  const std::vector<int> count = LargestRemainderCounts(area, num_points);

  CounterRng rng(seed, kStreamPoints);
  points->clear();
  normals->clear();
  points->reserve(num_points);
  normals->reserve(num_points);
  for (int f = 0; f < 6; ++f) {
    const int axis = faces[f].axis, a = (axis + 1) % 3, b = (axis + 2) % 3;
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    normal[axis] = faces[f].sign;
    for (int k = 0; k < count[f]; ++k) {
      Eigen::Vector3d p;
      p[axis] = faces[f].sign * half[axis];
      p[a] = rng.Uniform(-half[a], half[a]);
      p[b] = rng.Uniform(-half[b], half[b]);
      points->push_back(p);
      normals->push_back(normal);
    }
  }
}

}  // namespace

PaperPathFunction MakePaperPath(uint64_t seed) {
  const PaperPath path(seed);
  return [path](double t) { return path.CamFromWorld(t); };
}

void PaperScenarioOptions::Check() const {
  if (frames < 1) throw std::invalid_argument("frames must be >= 1, got " + std::to_string(frames));
  if (!(std::isfinite(fps) && fps > 0)) throw std::invalid_argument("fps must be > 0, got " + Num(fps));
  if (!(std::isfinite(noise_px) && noise_px >= 0))
    throw std::invalid_argument("noise_px must be >= 0 and finite, got " + Num(noise_px));
  if (!(outlier_fraction >= 0 && outlier_fraction <= 1))
    throw std::invalid_argument("outlier_fraction must be in [0, 1], got " + Num(outlier_fraction));
  if (!(std::isfinite(speed) && speed > 0))
    throw std::invalid_argument("speed must be > 0 and finite, got " + Num(speed));
  if (num_points < 1) throw std::invalid_argument("num_points must be >= 1, got " + std::to_string(num_points));
  if (!(std::isfinite(image_scale) && image_scale > 0 && std::lround(kPaperHeightPx * image_scale) >= 8))
    throw std::invalid_argument("image_scale must be > 0, finite and leave an image of at least 8 rows, got " +
                                Num(image_scale));
  if (!(hfov_deg == 0 || (std::isfinite(hfov_deg) && hfov_deg >= 5 && hfov_deg <= 150)))
    throw std::invalid_argument("hfov_deg must be 0 (the scenario's own) or in [5, 150] degrees, got " +
                                Num(hfov_deg));
  CheckLens(ScenarioCamera(PaperCamera(), {}, image_scale, hfov_deg), lens);
}

PinholeCamera ScenarioCamera(const PinholeCamera& camera, const Distortion& lens, double image_scale,
                             double hfov_deg) {
  PinholeCamera c = image_scale == 1.0 ? camera : camera.Scaled(image_scale);
  if (hfov_deg != 0) c.fx = c.fy = 0.5 * c.width / std::tan(0.5 * hfov_deg * M_PI / 180.0);
  c.dist = lens;
  return c;
}

void CheckLens(const PinholeCamera& camera, const Distortion& lens) {
  const double c[6] = {lens.k1, lens.k2, lens.p1, lens.p2, lens.k3, lens.k4};
  const auto name = [&] {
    return lens.IsFisheye() ? fmt::format("fisheye lens k1 {} k2 {} k3 {} k4 {}", lens.k1, lens.k2, lens.k3, lens.k4)
                            : fmt::format("lens distortion k1 {} k2 {} p1 {} p2 {} k3 {}", lens.k1, lens.k2, lens.p1,
                                          lens.p2, lens.k3);
  };
  for (double v : c)
    if (!std::isfinite(v)) throw std::invalid_argument(name() + ": every coefficient must be finite");
  if (lens.IsFisheye() && (lens.p1 != 0 || lens.p2 != 0))
    throw std::invalid_argument(name() + ": the equidistant model has no tangential terms");
  if (!lens.IsFisheye() && lens.k4 != 0) throw std::invalid_argument(name() + ": k4 is the fisheye model's only");
  if (lens.IsZero()) return;
  // The radial polynomial r (1 + k1 r^2 + k2 r^4 + k3 r^6) must grow from the centre until it reaches the
  // farthest corner's distorted radius (normalised units); past a turn two rays would land on one pixel.
  double corner = 0;
  for (double u : {0.0, camera.width - 1.0})
    for (double v : {0.0, camera.height - 1.0})
      corner = std::max(corner, camera.PixelToNormalized({u, v}).norm());
  // The distorted radius of a ray at normalised (pinhole) radius r: the polynomial of r (radial-tangential), or of
  // the ray's angle theta = atan(r) (equidistant).
  const auto radial = [&](double r) {
    if (lens.IsFisheye()) {
      const double t = std::atan(r), t2 = t * t;
      return t * (1 + t2 * (lens.k1 + t2 * (lens.k2 + t2 * (lens.k3 + t2 * lens.k4))));
    }
    const double r2 = r * r;
    return r * (1 + r2 * (lens.k1 + r2 * (lens.k2 + r2 * lens.k3)));
  };
  constexpr double kStep = 1e-3, kMaxRadius = 20.0;  // 20: 87 degrees off the axis
  double prev = 0;
  for (double r = kStep; prev < corner; r += kStep) {
    if (r > kMaxRadius)
      throw std::invalid_argument(fmt::format("{}: the image's corner is more than 87 degrees off the axis", name()));
    const double d = radial(r);
    if (!(d > prev))
      throw std::invalid_argument(fmt::format(
          "{}: the lens turns back {:.3f} off the axis (normalised radius), before the image's corner at distorted "
          "radius {:.3f}: it does not map the image one to one",
          name(), r, corner));
    prev = d;
  }
}

PinholeCamera PaperCamera() {
  return PinholeCamera(kPaperFocalPx, kPaperFocalPx, (kPaperWidthPx - 1) / 2.0, (kPaperHeightPx - 1) / 2.0,
                       kPaperWidthPx, kPaperHeightPx);
}

bool RayLandsOnItsPixel(const PinholeCamera& camera, const Eigen::Vector3d& point_in_cam, const Eigen::Vector2d& uv_px) {
  if (!camera.HasDistortion()) return true;
  const Eigen::Vector2d ray = point_in_cam.head<2>() / point_in_cam.z();
  return (camera.Undistort(camera.PixelToNormalized(uv_px)) - ray).norm() < 1e-6;
}

bool IsPointVisible(const PinholeCamera& camera, const Pose& cam_from_world, const Eigen::Vector3d& point_in_world,
                    const Eigen::Vector3d& normal_in_world, Eigen::Vector2d* uv_px) {
  const Eigen::Vector3d center_in_world = cam_from_world.OriginOfTargetInSource();
  if (normal_in_world.dot(center_in_world - point_in_world) <= 0) return false;
  const Eigen::Vector3d point_in_cam = cam_from_world * point_in_world;
  Eigen::Vector2d uv;
  if (!camera.Project(point_in_cam, &uv, nullptr, kMinDepthM)) return false;
  if (!camera.InImage(uv) || !RayLandsOnItsPixel(camera, point_in_cam, uv)) return false;
  if (uv_px) *uv_px = uv;
  return true;
}

SyntheticSequence MakePaperScenario(const PaperScenarioOptions& options) {
  options.Check();
  SyntheticSequence seq;
  seq.camera = ScenarioCamera(PaperCamera(), options.lens, options.image_scale, options.hfov_deg);
  seq.fps = options.fps;
  seq.scene = PaperScene();
  MakeBoxPoints(options.num_points, options.seed, &seq.points_in_world, &seq.normals_in_world);

  const PaperPath path(options.seed);
  seq.cam_from_world.reserve(options.frames);
  seq.stamps_s.reserve(options.frames);
  for (int i = 0; i < options.frames; ++i) {
    const double stamp_s = i / options.fps;
    seq.stamps_s.push_back(stamp_s);
    seq.cam_from_world.push_back(path.CamFromWorld(options.speed * stamp_s));
  }
  // The box is convex: a point whose face faces the camera is not hidden by the box, and the floor (no
  // points) is below it; the face test is exact occlusion here.
  ObservePoints(options.noise_px, options.outlier_fraction, options.seed,
                [&](const Pose& cam_from_world, size_t j, Eigen::Vector2d* uv_px) {
                  return IsPointVisible(seq.camera, cam_from_world, seq.points_in_world[j], seq.normals_in_world[j],
                                        uv_px);
                },
                &seq);
  return seq;
}

void ObservePoints(double noise_px, double outlier_fraction, uint64_t seed, const PointVisibility& visible,
                   SyntheticSequence* seq) {
  CounterRng noise_rng(seed, kStreamNoise);
  CounterRng pick_rng(seed, kStreamOutlierPick);
  CounterRng pixel_rng(seed, kStreamOutlierPixel);
  const PinholeCamera& cam = seq->camera;
  seq->frames.assign(seq->cam_from_world.size(), SyntheticFrame{});
  for (size_t i = 0; i < seq->cam_from_world.size(); ++i) {
    std::vector<SyntheticObservation>& obs = seq->frames[i].observations;
    for (size_t j = 0; j < seq->points_in_world.size(); ++j) {
      Eigen::Vector2d uv_true;
      if (!visible(seq->cam_from_world[i], j, &uv_true)) continue;
      // Fixed draws per visible point in each stream keep the streams aligned whatever the options.
      const double nu = noise_rng.Normal(), nv = noise_rng.Normal();
      const bool outlier = pick_rng.Uniform() < outlier_fraction;
      SyntheticObservation o;
      o.feature_id = static_cast<int64_t>(j);
      o.uv_true_px = uv_true;
      o.is_outlier = outlier;
      if (outlier) {
        // Rejection sampling: the excluded disc is a tiny part of the image, so this ends fast.
        // v drawn before u: the order in which GCC evaluated Eigen::Vector2d(Uniform(), Uniform())'s arguments
        // (unspecified in C++; clang goes left to right), which the scenarios' figures depend on.
        do {
          const double v = pixel_rng.Uniform(0.0, cam.height - 1.0);
          const double u = pixel_rng.Uniform(0.0, cam.width - 1.0);
          o.uv_px = Eigen::Vector2d(u, v);
        } while ((o.uv_px - uv_true).norm() < kMinOutlierDistancePx);
      } else {
        o.uv_px = uv_true + noise_px * Eigen::Vector2d(nu, nv);
        if (!cam.InImage(o.uv_px)) continue;  // documented: dropped, not clamped
      }
      obs.push_back(o);
    }
  }
}

std::vector<io::ObservationFrame> ToObservationFrames(const SyntheticSequence& sequence) {
  std::vector<io::ObservationFrame> out(sequence.frames.size());
  for (size_t i = 0; i < sequence.frames.size(); ++i) {
    out[i].index = static_cast<int64_t>(i);
    out[i].stamp_s = sequence.stamps_s[i];
    out[i].observations.reserve(sequence.frames[i].observations.size());
    for (const SyntheticObservation& o : sequence.frames[i].observations) {
      out[i].observations.push_back({o.feature_id, o.uv_px.x(), o.uv_px.y()});
    }
  }
  return out;
}

io::Trajectory ToTrajectory(const SyntheticSequence& sequence) {
  io::Trajectory traj;
  traj.stamps_s = sequence.stamps_s;
  traj.world_from_cam.reserve(sequence.cam_from_world.size());
  for (const Pose& p : sequence.cam_from_world) traj.world_from_cam.push_back(p.Inverse());
  traj.has_stamps = true;
  return traj;
}

io::PointCloud ToPointCloud(const SyntheticSequence& sequence) {
  io::PointCloud cloud;
  cloud.points = sequence.points_in_world;
  cloud.ids.resize(sequence.points_in_world.size());
  for (size_t i = 0; i < cloud.ids.size(); ++i) cloud.ids[i] = static_cast<int64_t>(i);
  return cloud;
}

SequenceSummary Summarize(const SyntheticSequence& sequence) {
  SequenceSummary s;
  s.frames = static_cast<int>(sequence.frames.size());
  s.points = static_cast<int>(sequence.points_in_world.size());
  s.min_visible = sequence.frames.empty() ? 0 : std::numeric_limits<int>::max();
  for (const SyntheticFrame& f : sequence.frames) {
    const int n = static_cast<int>(f.observations.size());
    s.observations += n;
    s.min_visible = std::min(s.min_visible, n);
    s.max_visible = std::max(s.max_visible, n);
    for (const SyntheticObservation& o : f.observations) s.outliers += o.is_outlier;
  }
  s.mean_visible = s.frames > 0 ? static_cast<double>(s.observations) / s.frames : 0.0;
  return s;
}

std::string SequenceSummary::ToString() const {
  return fmt::format("{} frames, {} points, {} observations ({:.1f} a frame on average, min {}, max {}), {} outliers",
                     frames, points, observations, mean_visible, min_visible, max_visible, outliers);
}

}  // namespace mcslam::sim
