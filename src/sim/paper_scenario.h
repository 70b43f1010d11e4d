#pragma once
// The synthetic world of the paper's §8.1 (Sánchez, Álvarez & Borro, ISMAR 2010): a virtual 320x240 camera
// with f = 500 px moves by hand-held-like motion around a textured box about 1 m wide, about 3 m away, and
// observes the exact projections of the box's surface points, with optional Gaussian pixel noise and a
// fraction of wrong matches (outliers). The back end consumes these observations directly, without images.
//
// World frame: the box is centred at the origin with its edges along the axes; +z is up. The camera moves
// on an arc about 3 m (2.8-3.2 m) from the box centre, 13-27 deg above the box, sweeping in azimuth from
// about -40 deg (the -x side of the box in view) to about +40 deg (the +x side) over the first 10 s of path
// time and back over the next 10 s, with a vertical bob, a radial in/out motion, a wandering aim point and a
// few degrees of pan/tilt/roll wobble, all sums of low-frequency sinusoids whose phases come from the seed.
// Hence side faces come into and out of view, and now and then the box's edge leaves the image.
// At speed 1 and 30 fps (the defaults) the camera moves on average 1-3 cm and 0.3-1 deg a frame (at most
// about 5 cm and 1.5 deg), and, with 400 points, sees about 150-200 points in every frame (never < 100).
// The path is a function of speed * time: frame k at speed 2 is frame 2k at speed 1.
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/camera.h"
#include "core/pose.h"
#include "io/observations_io.h"
#include "io/ply.h"
#include "io/trajectory_io.h"
#include "sim/scene.h"

namespace mcslam::sim {

// Fixed parts of the scenario (the paper's values where it gives them).
inline constexpr double kPaperFocalPx = 500.0;
inline constexpr int kPaperWidthPx = 320;
inline constexpr int kPaperHeightPx = 240;
// Box edges along x, y, z in metres (about 1 m wide, as in the paper).
inline constexpr double kPaperBoxSizeM[3] = {1.0, 0.7, 0.6};
// A point closer than this to the camera plane is not observed.
inline constexpr double kMinDepthM = 0.1;
// An outlier is placed at least this far from the true projection of its point.
inline constexpr double kMinOutlierDistancePx = 10.0;

struct PaperScenarioOptions {
  int frames = 300;                 // number of frames, >= 1
  double fps = 30.0;                // frame rate; frame i has timestamp i / fps seconds
  double noise_px = 0.0;            // standard deviation of the Gaussian pixel noise, per coordinate, >= 0
  double outlier_fraction = 0.0;    // probability that an observation is a wrong match, in [0, 1]
  double speed = 1.0;               // multiplies the speed along the (fixed) camera path, > 0
  int num_points = 400;             // points on the box surfaces, >= 1
  uint64_t seed = 1;                // seeds the points, the path's phases, the noise and the outliers
  // The lens the images are seen through (radial-tangential, as a camera file declares it); none by default.
  // Real cameras bend: a webcam's or a drone's lens moves the corners by tens of pixels, and the camera file
  // says by how much. The rendered images and the observations both go through it.
  Distortion lens{};
  // The image's size and focal length scaled together (the same field of view at another resolution), > 0:
  // 2 makes the paper's 320x240 camera 640x480 at f = 1000 px. Users' cameras run from 320x240 to 4K.
  double image_scale = 1.0;
  // The camera's horizontal field of view in degrees, the focal length set to give it (the image size and the
  // principal point kept); 0: the scenario's own (the paper's camera sees 35.5 degrees). Users' cameras see
  // 60-80 degrees (a webcam, a phone, TUM's and 7-Scenes' Kinect, EuRoC, KITTI), where the paper's is narrow.
  double hfov_deg = 0;

  // Throws std::invalid_argument naming the bad field and its value, e.g. "noise_px must be >= 0, got -1".
  void Check() const;
};

// Throws std::invalid_argument when `lens` on `camera` does not map its image one to one (the distortion
// polynomial turns back before the image's corners), naming the coefficients: such a lens cannot be undistorted
// and no real camera has one.
void CheckLens(const PinholeCamera& camera, const Distortion& lens);

struct SyntheticObservation {
  int64_t feature_id = 0;                             // = index of the point in points_in_world
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();     // what a tracker reports: noisy, or an outlier's pixel
  Eigen::Vector2d uv_true_px = Eigen::Vector2d::Zero();  // exact projection of the point
  bool is_outlier = false;
};

struct SyntheticFrame {
  std::vector<SyntheticObservation> observations;  // in increasing feature_id order
};

struct SyntheticSequence {
  PinholeCamera camera;
  double fps = 30.0;
  std::vector<Eigen::Vector3d> points_in_world;   // point i has feature id i for its whole life
  std::vector<Eigen::Vector3d> normals_in_world;  // outward unit normal of the face each point lies on
  std::vector<Pose> cam_from_world;               // one per frame
  std::vector<double> stamps_s;                   // one per frame
  std::vector<SyntheticFrame> frames;             // one per frame
  Scene scene;  // the world the points lie on, for rendering (sim/render.h)
};

// The paper's virtual camera: f = 500 px, 320x240, principal point at the image centre, no distortion.
PinholeCamera PaperCamera();

// `camera` with `lens`, scaled by `image_scale` (PinholeCamera::Scaled; 1 leaves it bit for bit) and, when hfov_deg is
// not 0, with the focal length (fx = fy) that gives it that horizontal field of view.
PinholeCamera ScenarioCamera(const PinholeCamera& camera, const Distortion& lens, double image_scale,
                             double hfov_deg = 0);

// True when the point is seen by the camera: its face faces the camera centre (n . (c - p) > 0, which for a
// convex box is exact occlusion), its depth exceeds kMinDepthM, and its exact projection is in the image.
// On true, *uv_px (when given) holds the exact projection.
bool IsPointVisible(const PinholeCamera& camera, const Pose& cam_from_world, const Eigen::Vector3d& point_in_world,
                    const Eigen::Vector3d& normal_in_world, Eigen::Vector2d* uv_px = nullptr);

// Through a lens, a point far off the axis can be bent back into the image (the distortion polynomial turns
// past the field of view): it is seen only if its pixel's ray, undistorted, is its own ray. Always true without
// distortion.
bool RayLandsOnItsPixel(const PinholeCamera& camera, const Eigen::Vector3d& point_in_cam, const Eigen::Vector2d& uv_px);

// Builds the scenario. Deterministic: the same options give bit-identical output, and a sequence of N frames
// is the first N frames of a longer one with the same other options (the path is a function of time).
// Every visible point is observed, with uv_px = exact projection + N(0, noise_px^2) per coordinate; with
// probability outlier_fraction, independently per observation, uv_px is instead uniform in the image at
// least kMinOutlierDistancePx from the true projection (is_outlier = true). An inlier whose noisy pixel
// falls outside the image is DROPPED (a tracker would not report it), never clamped.
// Throws std::invalid_argument (from options.Check()) on bad options.
SyntheticSequence MakePaperScenario(const PaperScenarioOptions& options);

// A sinusoid of a camera path: amplitude * sin(2 pi t / period_s + phase), the phase drawn from the seed.
struct PathWave {
  double amplitude;
  double period_s;
  double phase = 0;
  double At(double t) const { return amplitude * std::sin(2.0 * kPi * t / period_s + phase); }
};

// The paper's hand-held path about the box (the header comment above): cam_from_world at path time t
// (seconds at speed 1), its phases from the seed. Other scenarios reuse it (faster, paused, turned).
using PaperPathFunction = std::function<Pose(double t)>;
PaperPathFunction MakePaperPath(uint64_t seed);

// Fills sequence->frames (one per cam_from_world) with what the camera sees of sequence->points_in_world:
// every point for which visible(cam_from_world, point index, &uv_true_px) is true is observed, noisy or an
// outlier as MakePaperScenario documents, drawn from the seed's noise and outlier streams (the same streams
// for every scenario). The visibility rule is the scenario's.
using PointVisibility = std::function<bool(const Pose& cam_from_world, size_t point, Eigen::Vector2d* uv_true_px)>;
void ObservePoints(double noise_px, double outlier_fraction, uint64_t seed, const PointVisibility& visible,
                   SyntheticSequence* sequence);

// Conversions to the io types, for writing files and for code that consumes io types (the SLAM runner).
// Observation frames carry every frame, also those with no observation (index i, stamp stamps_s[i]).
std::vector<io::ObservationFrame> ToObservationFrames(const SyntheticSequence& sequence);
// Ground-truth trajectory: world_from_cam = cam_from_world.Inverse(), with the frame stamps.
io::Trajectory ToTrajectory(const SyntheticSequence& sequence);
// Ground-truth map: the points with ids = feature ids.
io::PointCloud ToPointCloud(const SyntheticSequence& sequence);

struct SequenceSummary {
  int frames = 0;
  int points = 0;
  int64_t observations = 0;
  int64_t outliers = 0;
  int min_visible = 0;  // observations per frame
  double mean_visible = 0;
  int max_visible = 0;
  std::string ToString() const;  // one line
};
SequenceSummary Summarize(const SyntheticSequence& sequence);

// Writes dir/groundtruth.txt (TUM, world_from_cam), dir/map_gt.ply (ids = feature ids), dir/camera.yaml
// (with fps) and dir/observations.txt, creating dir when needed. Throws std::runtime_error naming the path
// that could not be created or written.
void WriteSyntheticSequence(const SyntheticSequence& sequence, const std::string& dir);

namespace detail {
// One Philox stream of the seed per purpose, so that e.g. changing the outlier fraction leaves the noise unchanged.
// The paper's scenario draws 1-5; every scenario draws its points from 1 and its noise and outliers from 3-5
// (ObservePoints), the other scenarios their paths and worlds from 6 and 7.
constexpr uint32_t kStreamPoints = 1;
constexpr uint32_t kStreamPath = 2;
constexpr uint32_t kStreamNoise = 3;
constexpr uint32_t kStreamOutlierPick = 4;
constexpr uint32_t kStreamOutlierPixel = 5;
constexpr uint32_t kStreamScenarioPath = 6;
constexpr uint32_t kStreamWorld = 7;

// A number as the option checks' messages write it (the shortest text that reads back the same).
std::string Num(double v);
}  // namespace detail

}  // namespace mcslam::sim
