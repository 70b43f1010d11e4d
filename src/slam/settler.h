#pragma once
// The settling of a map just made from two views (the first map, or a provisional one): the frames since the
// reference and the points refined together by bundle adjustment as their parallax grows, the depth-reversal test
// made again over that window, and the lens' self-calibration when it has settled (InitOptions::self_calibrate).
#include <cstdint>
#include <string>
#include <vector>

#include "core/pose.h"
#include "slam/frame_report.h"
#include "slam/slam_state.h"

namespace mcslam::slam {

class Initializer;

// What the self-calibration (InitOptions::self_calibrate) measured, and whether it replaced the camera's k1.
struct SelfCalibration {
  bool tried = false;
  bool accepted = false;
  int64_t frame = -1;          // the frame whose settling measured it
  double k1_given = 0;         // the camera's k1 before
  double k1_measured = 0;      // the window's best k1 (the camera's k1 after, when accepted)
  double sigma_k1 = 0;         // the standard deviation its likelihood ratio implies
  double z = 0;                // |k1_measured - k1_given| / sigma_k1: the square root of the likelihood ratio
  double corner_shift_px = 0;  // how far the change moves a feature seen at the image's farthest corner
  double k1_half[2] = {0, 0}, sigma_k1_half[2] = {0, 0};  // the same fit on each half of the points (alternate)
  double min_half_share = 0;   // the smaller of the halves' changes of k1 over the whole's (negative: opposite)
  double max_half_share = 0;   // the larger
  double min_half_z = 0;       // the smaller of the halves' own likelihood ratios, in standard deviations (0: the
                               // half's k1-free fit did not lower its cost)
  int frames = 0, points = 0, observations = 0;
  std::string note;            // one line: what was measured and what was done
};

// Whether a measured k1 replaces the camera's (InitOptions::calibration_min_z, calibration_min_shift_px,
// calibration_min_half_share, calibration_min_half_z): significant, material, and repeated by each half of the
// points, significantly, within a factor of 1 / calibration_min_half_share of the whole's change, either way.
bool SelfCalibrationIsTaken(const SelfCalibration& c, const InitOptions& io);

class Settler {
 public:
  Settler(SlamState& s, const Initializer& init) : s_(s), init_(init) {}

  // Settling under way: the map is refined again whenever the parallax from the reference reaches the next step.
  bool active() const { return settling_; }
  void Stop() { settling_ = false; }
  // The posed frame `slot` has reached the next step of parallax from the reference.
  bool Due(int slot) const { return settling_ && ParallaxFromReference(slot) >= next_settle_parallax_deg_; }
  // After a refinement of the window since the reference (on a frame posed in it, *out holding its report): its
  // note says what was done, and the reports of the earlier frames moved are appended.
  void Settle(int slot, std::vector<FrameReport>* out);
  const SelfCalibration& self_calibration() const { return self_calibration_; }

  // Settling (InitOptions::settle_parallax_deg) of a map just made from two views ending at init_slot, whose first
  // baseline is `baseline` long, from the reference frame SlamState::reference_slot.
  void BeginSettling(int init_slot, double baseline, double two_view_parallax_deg, int min_points);
  double ParallaxFromReference(int slot) const;

 private:
  // The depth-reversal test of the initialisation, again over a settling window: the map as it is and its
  // mirror in depth (in the window's first camera), each placed and refined over the window (the map's own
  // adjusted fit counted too); when the mirror explains the window clearly better (InitOptions::ambiguity_chi2
  // and kFlipCostRatio), *cams and wp->X become the mirror's (in the world frame, the first camera where it was)
  // and *why says so.
  // A lead must be confirmed: the step before it found the mirror ahead too, by less (a mirror that is the scene
  // pulls away as the window's parallax grows; a lead that noise gives one of two near-equal fits does not); one
  // first found at the settling's `last` step (no later one to confirm it) is taken.
  bool FlipIfMirrored(const std::vector<int>& window, bool last, std::vector<Pose>* cams, WindowPoints* wp,
                      std::string* why);
  static constexpr int kFlipCheckFrames = 20;
  static constexpr double kFlipCostRatio = 1.6;  // the map's cost over its mirror's needed to flip (and chi-square)
  // InitOptions::self_calibrate, on the settling's last window after its adjustment (cams, wp.X: adjusted): true
  // when the camera's k1 was replaced (every stored feature then undistorted again with it).
  static constexpr int kCalibrationFrames = 40;
  bool SelfCalibrate(const std::vector<int>& window, const std::vector<Pose>& cams, const WindowPoints& wp, int slot);

  SlamState& s_;
  const Initializer& init_;
  bool settling_ = false;
  double next_settle_parallax_deg_ = 0;
  int init_slot_ = -1;          // the frame the initialisation ended on
  double init_baseline_ = 1.0;  // its distance from the reference camera: the scale, kept by every settling
  double mirror_lead_ = 0;      // the mirror's lead (the map's cost over its mirror's) at the step before, 0: none
  int init_min_points_ = 0;     // the point count the initialisation asked for (InitOptions::min_points, lowered)
  SelfCalibration self_calibration_;
};

}  // namespace mcslam::slam
