#pragma once
// The visual front end (paper §6): per frame, Shi-Tomasi corners are detected only in image cells that
// hold no tracked feature, every track is followed by pyramidal Lucas-Kanade started from its own
// constant-velocity Kalman prediction and checked forward-backward, tracks get SIFT descriptors (each new
// one at its birth, or only those the caller lists: DescribeOnly; optionally on a TBB task, while the caller
// estimates the pose), and map points whose track was lost are re-attached (§6.4) when a new corner near their
// projection matches their descriptor.
// It knows images and nothing of 3D; its output is feature id -> distorted pixel, per frame.
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <span>
#include <vector>

namespace mcslam::frontend {

inline constexpr int kDescriptorLength = 128;
// SIFT as OpenCV computes it: 128 floats, L2 norm about 512 (entries 0..255).
using Descriptor = std::array<float, kDescriptorLength>;
float DescriptorDistance(const Descriptor& a, const Descriptor& b);  // L2

struct FrontendOptions {
  // ---- detection (Shi-Tomasi) -------------------------------------------------------------------------
  int max_features = 400;       // budget: tracks (re-attached ones included) never outnumber it
  int cell_size_px = 40;        // grid of square cells; new corners only in cells holding no tracked feature
  int max_new_per_cell = 2;     // new corners added to one empty cell in one frame
  double quality_level = 0.01;  // a corner's min eigenvalue must reach this fraction of the frame's largest
  // ... and what the frame's own noise reaches: corner_noise_margin times the response that pure noise of the
  // frame's measured sigma (FrameStats::noise_grey) exceeds at a corner_noise_fraction of its pixels (one in
  // 100,000: less than one pixel of a 320x240 frame; image_noise.h). A relative threshold alone lets a noisy
  // camera's noise through as corners: the paper scene with noise of 6 grey levels added took 3010 new corners in
  // 300 frames (261 clean), most lost again by the forward-backward check within a frame, and its ATE went from
  // 0.32 to 2.2 cm. The clean renders (sigma 1.2), KITTI (2.0) and 7-Scenes (0.5) never reach it. 0: off.
  double corner_noise_margin = 1.0;
  double corner_noise_fraction = 1e-5;
  double min_distance_px = 10;  // between new corners, and from a new corner to any tracked feature
  // The grid holds at least min_cells cells: in an image smaller than 48 cells of 40 px (the paper's 320x240)
  // the cells, and min_distance_px with them, shrink in proportion (GridFor); 320x240 and every larger image
  // keep the 40 px. A fixed 40 px grid left a 160x120 image 12 cells, and the paper scenario there 2.2 % of
  // its path off (0.17 % at 320x240), the rotation scenario lost for 76 frames, a car's 310x94 images lost from
  // frame 36 on.
  int min_cells = 48;
  int block_size = 3;           // structure tensor window (px)
  int border_px = 12;           // no corner nearer than this to the image edge
  // ---- tracking (pyramidal Lucas-Kanade) ----------------------------------------------------------------
  int pyramid_levels = 2;                // levels including full resolution (the paper: 2)
  int retry_pyramid_levels = 4;          // a track lost with pyramid_levels is tried once more with this many
                                         // levels (a young track, a jolt); <= pyramid_levels: no retry
  int window_px = 21;                    // LK window side (odd)
  // Jolt recovery: the tracks that failed (with the retry too) are tried once more from where the image's
  // global shift (phase correlation of a coarse pyramid level) puts them, when that is at least
  // jolt_min_shift_px from their own prediction. A sudden turn of the camera moves the whole image away from
  // the constant-velocity predictions; below a few pixels the retry already covers it.
  // Only in a frame where at least jolt_min_failed_fraction of the tracks failed: at 15x the paper's speed
  // 60-70 % of the tracks fail together in such frames; on a car's forward motion the failures are 5-25 % and
  // a global shift does not explain them.
  bool jolt_recovery = true;
  double jolt_min_shift_px = 3.0;
  double jolt_min_failed_fraction = 0.3;
  int max_iterations = 30;               // LK iterations per level
  double epsilon_px = 0.01;              // LK stops when an update is shorter
  double min_eigen_threshold = 1e-4;     // LK drops a point whose window has less texture than this
  double max_forward_backward_px = 1.0;  // round trip (track forward, then back) error above this drops a track
  double max_patch_error = 0.0;          // LK residual (mean |intensity difference|, 0-255) above this
                                         // drops a track; <= 0: off
  // The exposure change between two frames (the median ratio of the followed tracks' mean intensities) beyond
  // which the previous frame is brought to the new exposure and the tracks followed again (frontend_track.cc).
  // Frame to frame KITTI 06 changes by 1.7 % at the median and 5.9 % at most, hand-held 7-Scenes by 0.2 % and
  // 3.3 %; 0: never.
  double exposure_min_change = 0.08;
  int track_border_px = 10;              // a track nearer than this to the edge has left the image (half the LK
                                         // window: nearer, the window reads reflected pixels and the track drifts)
  // ---- anchoring (Shi and Tomasi's feature monitoring) ---------------------------------------------------
  // Frame-to-frame LK re-templates every frame, so a track slides along its texture (rounded corners seen at
  // another scale, an outline passing by): on the rendered scene a tenth of a pixel a frame, pixels after
  // a hundred frames. Every anchor_every frames each track is also aligned, by an affine warp maximising the
  // normalised correlation (frontend/patch_align.h), with the patch it was born with; the aligned centre
  // replaces the LK position, and a track whose patch no longer matches (occluded, slid onto something else)
  // is dropped.
  int anchor_every = 1;                  // frames between alignments of a track; 0: off
  int anchor_patch_px = 21;              // side of the patch kept at birth (odd)
  double anchor_min_correlation = 0.9;   // normalised correlation below this: a mismatch
  double anchor_max_shift_px = 2.0;      // alignment moving the track further than this from LK: a mismatch
  // On a mismatch the track is dropped (a corner on an outline, an occluded point: the rendered scene's
  // tracks stay within 0.1 px of their scene point), or it keeps its LK position and takes a new patch there
  // (fast forward motion, KITTI at 10 Hz: a tenth of the tracks change look that much in one frame, and
  // dropping them all starves the initialisation). kAuto decides per frame from what it measures: when more
  // than anchor_auto_reanchor_fraction of the tracks aligned in a frame mismatch, the scene's look is changing
  // faster than birth patches can follow (forward motion, fast turns, blur) and that frame's mismatches take
  // new patches; a few mismatches are the occlusions and slid tracks that the check is there to drop.
  enum class AnchorMismatch { kAuto, kDrop, kReanchor };
  AnchorMismatch anchor_mismatch = AnchorMismatch::kAuto;
  double anchor_auto_reanchor_fraction = 0.05;
  // A frame whose aligned tracks' patches are, at the median, less sharp than their birth patches by more than
  // this ratio (AffinePatch::sharpness: squared gradient over variance) is blurred: its mismatches keep their LK
  // positions and no track takes a new patch in it (frontend_track.cc). Sharp frames measure 0.86-1.0 at the
  // median (rendered scenes; KITTI 06 0.90 at its least), hand-held 7-Scenes 0.72-0.79 in its three blurriest
  // of 300 and 0.86 at the 5th percentile; a Gaussian blur of sigma 2 px 0.40-0.47.
  double anchor_blur_ratio = 0.75;
  double anchor_max_scale_change = 1.5;  // the warp grew or shrank the patch more (or sheared it as much):
                                         // a new patch is taken where the track is now
  // A patch whose structure tensor is this far from isotropic (smallest over largest eigenvalue) holds little
  // more than an edge: its alignment can slide along the edge and still correlate well, so such a track (at
  // birth or when it takes a new patch) goes on unmonitored. Birth patches at Shi-Tomasi corners measure
  // 0.04 at their 1st percentile and 0.4 at the median (KITTI 06).
  double anchor_min_texture_ratio = 0.02;
  // The alignment's Gauss-Newton stops when an update moves the patch's corners by less than
  // anchor_epsilon_px, or after anchor_max_iterations. On real frames it converges linearly (each update
  // 0.5-0.9 of the last; 7-Scenes: 16 iterations a call on average, 7 % of the calls at the cap), so the stop
  // sets the stage's cost. Looser stops were measured and left: at 0.005-0.02 px fewer tracks survive (likely
  // those whose correlation reaches the anchor_min_correlation line only as it converges; the rendered paper
  // scene, seed 2: 39 two-view inliers at frame 43 instead of 44, so the initialisation waits), and a cap
  // of 20 turned the rotation scenario's seed 2 into a wrong track after a relocalisation (35 cm against 2.8).
  int anchor_max_iterations = 50;
  double anchor_epsilon_px = 0.001;
  // ---- Kalman prediction (state u, v, du, dv per track) -----------------------------------------------
  bool use_kalman_prediction = true;   // false: LK starts where the feature was (zero motion)
  double kalman_accel_sigma_px = 2.0;  // change of image velocity per frame (px/frame^2)
  double kalman_measurement_sigma_px = 0.5;
  double init_velocity_radius_px = 80;  // a new track starts at the median velocity of tracks this near; 0: at rest
  // ---- descriptors (SIFT: at birth, or once listed; refreshed) ----------------------------------------
  double descriptor_size_px = 6.0;  // keypoint size given to SIFT (its patch is ~6x this wide); upright
  bool describe_async = false;      // describe new tracks on a TBB task, joined when next needed
  // A track is described again (where it is then, with the new tracks of that frame) once its descriptor is
  // this many frames old, so that a lost map point is looked for with how it looked when last seen. SIFT of
  // one tracked point drifts with the view: median L2 distance to its birth descriptor 132 after 10 frames,
  // 228 after 40 (the paper scenario, against 520 between different points; 7-Scenes: 94 and 186), so with
  // remap_max_distance 250 a birth descriptor stops matching after about a second of hand-held motion.
  // 0: never (birth descriptors only).
  int descriptor_refresh_frames = 10;
  // ---- remapping of lost map points (§6.4) ------------------------------------------------------------
  int remap_window_px = 15;           // half-side of the square search window around the projection
  int remap_max_candidates = 5;       // strongest new corners described per window
  double remap_max_distance = 250.0;  // SIFT L2 distance of an accepted match
  double remap_ratio = 0.8;           // best distance < ratio * second best (Lowe's test)

  // Throws std::invalid_argument naming the bad field and its value.
  void Check() const;
};

// The detection grid of a W x H image: cell size and the least distance between corners (FrontendOptions::min_cells).
struct DetectionGrid {
  int cell_px = 0;
  double min_distance_px = 0;
};
DetectionGrid GridFor(const FrontendOptions& o, int width, int height);

// The candidate nearest to `query` (L2) when it passes the remapping's tests: within
// options.remap_max_distance, and nearer than options.remap_ratio times the second nearest (Lowe's test).
// Null candidates are skipped; of equal distances the first wins. Remapping and relocalisation both match so.
struct DescriptorMatch {
  size_t index = 0;  // into `candidates`
  float distance = 0;
};
std::optional<DescriptorMatch> MatchDescriptor(const Descriptor& query, std::span<const Descriptor* const> candidates,
                                               const FrontendOptions& options);

// A map point whose track was lost, projected with the current pose estimate.
struct RemapRequest {
  int64_t feature_id = 0;                           // the id its track had (from this front end)
  Descriptor descriptor{};                          // from when it was tracked (Frontend::GetDescriptor, LostTrack)
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();  // projection in this frame (distorted pixels)
  // Backed off (the caller failed to find it many times here): tried only when a corner that would start a new
  // track in this frame lies in its window, i.e. something appeared where it should be (the end of an
  // occlusion); otherwise it costs nothing and counts as deferred. A new track would take that corner, and a
  // corner taken by a track is never a remapping candidate.
  bool only_near_new_corner = false;
  // Its look when its track began, if the caller kept it: a place seen again from where the point was first seen
  // looks like that (a second run in a loaded map above all); the nearer of the two looks' matches is taken.
  std::optional<Descriptor> first_look = std::nullopt;
};

struct TrackedFeature {
  int64_t feature_id = 0;
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();  // as seen (distorted pixels)
  int age_frames = 0;                               // frames since it was born or re-attached (0 in that frame)
  bool remapped = false;                            // re-attached to a lost map point in this frame
};

struct LostTrack {
  int64_t feature_id = 0;
  Eigen::Vector2d last_uv_px = Eigen::Vector2d::Zero();  // where it was last seen (previous frame)
  std::optional<Descriptor> descriptor;                  // its SIFT descriptor (always set once described)
};

struct FrameStats {
  int tracked = 0;                // tracks carried over from the previous frame that survived
  int retried = 0;                // tracks lost with pyramid_levels and tried with retry_pyramid_levels
  int recovered = 0;              // ... of which the retry kept
  int jolt_recovered = 0;         // tracks that failed twice and followed from the jolt-shifted prediction
  int lost_status = 0;            // LK failed (no convergence, too little texture)
  int lost_forward_backward = 0;  // round trip error above max_forward_backward_px
  int lost_patch_error = 0;       // LK residual above max_patch_error
  int lost_outside = 0;           // left the image
  int lost_anchor = 0;            // no longer matches the patch it was born with (see anchor_every)
  int anchored = 0;               // tracks aligned with their birth patch in this frame
  int reanchored = 0;             // ... of which took a new patch (the view changed too much)
  float noise_grey = 0;           // the image's measured noise (grey levels, sigma): detection, birth-patch alignment
  float anchor_sharpness = 0;     // median over the aligned tracks of their patch's sharpness over their birth patch's
  float exposure_gain = 1;        // the gain the previous frame was brought to this frame's exposure with (1: none)
  bool blurred = false;           // anchor_sharpness < anchor_blur_ratio: no track dropped or re-anchored on a mismatch
  int detected = 0;               // new tracks born in this frame
  int remap_requests = 0;
  int remapped = 0;
  int described_for_remap = 0;  // new tracks that took the descriptor a remapping window gave their corner
  int refreshed = 0;           // tracks described again (FrontendOptions::descriptor_refresh_frames)
  int described_listed = 0;    // tracks described first in this frame, once the caller listed them (DescribeOnly)
  int remap_refused_id = 0;    // the id is tracked now, repeated, or was never issued here
  int remap_outside = 0;       // projection outside the image
  int remap_no_candidate = 0;  // no new corner in the window
  int remap_no_match = 0;      // candidates, but none passed the distance and ratio tests
  int remap_over_budget = 0;   // matched, but the tracks already number max_features
  int remap_deferred = 0;      // backed off and no new corner in the window: not tried (RemapRequest)
  // Mean distance of the surviving tracks from where LK started (the Kalman prediction) and from where they
  // were in the previous frame: how much the prediction saves LK.
  double mean_prediction_error_px = 0;
  double mean_displacement_px = 0;
  double mean_anchor_shift_px = 0;  // how far the alignment moved the anchored tracks from where LK put them
  // Milliseconds. describe_ms: describing this frame's new tracks when synchronous; with describe_async,
  // the task's own time for the previous frame's tracks, and describe_wait_ms the time Process waited for it.
  double convert_ms = 0, pyramid_ms = 0, track_ms = 0, anchor_ms = 0, detect_ms = 0, remap_ms = 0, describe_ms = 0,
         describe_wait_ms = 0, total_ms = 0;
};

struct FrameResult {
  int64_t index = 0;
  double stamp_s = 0;
  std::vector<TrackedFeature> features;  // every live track in this frame, ids unique
  std::vector<LostTrack> lost;           // tracks that ended in this frame
  std::vector<int64_t> remapped_ids;     // requests re-attached in this frame
  FrameStats stats;
};

// Throws std::invalid_argument, naming the frame and the pixel type, for an image the front end does not take
// (empty, or not 8- or 16-bit gray, BGR or BGRA); Frontend::Process checks the same.
void CheckImage(const cv::Mat& image, int64_t index);

// One thread drives a Frontend (Process, GetDescriptor, Reset, ...); with describe_async the description
// runs on a TBB task that the Frontend itself joins before anything reads what it writes.
class Frontend {
 public:
  // Throws std::invalid_argument (options.Check()).
  explicit Frontend(const FrontendOptions& options = {});
  ~Frontend();
  Frontend(const Frontend&) = delete;
  Frontend& operator=(const Frontend&) = delete;

  // One frame: 8-bit gray, BGR or BGRA, or 16-bit gray/BGR (scaled to 8 bit). Throws std::invalid_argument
  // for an empty image, another pixel type, or a size that differs from the previous frames' (call Reset
  // first). `remap` is optional: lost map points to try to re-attach in this frame.
  FrameResult Process(const cv::Mat& image, int64_t index, double stamp_s, std::span<const RemapRequest> remap = {});

  // Joins the pending description task (with describe_async); a no-op when none is pending.
  void WaitForDescriptors();
  // The descriptor of a live track (waits for it when still pending); nullopt for an id not tracked now.
  std::optional<Descriptor> GetDescriptor(int64_t feature_id);
  // The same without waiting: nullopt also while the track's description is still pending (the task writes
  // its own buffers, never the tracks, so reading them meanwhile is safe).
  std::optional<Descriptor> DescriptorIfDone(int64_t feature_id) const;

  // Which tracks are described (SIFT, the looks remapping and relocalisation match). By default every new track at
  // its birth. After DescribeOnly(wanted), from the next Process on, only the live tracks for which `wanted` (called
  // here, once per live track, on the caller's thread) said true: each in the next frame if it has no descriptor yet
  // (from the frame it was born in while that is kept, Track::birth_image, else where it is; a listed track that
  // ends first is described at its end), and again every descriptor_refresh_frames; new tracks are not described at
  // their birth (unless a remapping window described their corner anyway). The caller's map points are what it
  // looks for again: most tracks never become one (KITTI 06: ~1,300 of 6,223 tracks born). DescribeEveryTrack()
  // goes back to the default.
  void DescribeOnly(const std::function<bool(int64_t)>& wanted);
  void DescribeEveryTrack();
  // The live tracks among `ids` that have no descriptor yet are described now, in the last frame (relocalisation
  // matches the new tracks by their looks). Returns how many were described.
  int DescribeMissing(std::span<const int64_t> ids);

  // Live tracks `ids` described again in the last frame with their descriptors' grids turned by each of
  // `angles_deg` (SiftDescriber::DescribeTurned): angles_deg.size() x ids.size() entries, angle by angle; nullopt for
  // an id not live, or a point that could not be described. Empty before the first frame.
  std::vector<std::optional<Descriptor>> DescribeTurned(std::span<const int64_t> ids, std::span<const float> angles_deg);

  // The live track `from` goes on as `to` (relocalisation matched it to that map point's feature): from
  // now on it is reported under `to` and keeps the descriptor `to` was described with. false (and no
  // change) when `from` is not live, or `to` is live or was never issued by this front end.
  bool Relabel(int64_t from, int64_t to, const std::optional<Descriptor>& descriptor = std::nullopt);

  // Drops every track (ids go on increasing, never reused) and forgets the previous frame.
  void Reset();
  size_t NumTracks() const;
  int64_t NextFeatureId() const;
  // New tracks get ids from `next` on (never lower than now): the ids below belong to something else, e.g. the
  // points of a map loaded from a file, which remapping and relocalisation may relabel tracks to.
  void ReserveIdsBelow(int64_t next);
  const FrontendOptions& options() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace mcslam::frontend
