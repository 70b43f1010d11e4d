#pragma once
// The bridge over the unmapped (SystemOptions::bridge): after a turn that took the map out of view ends in a move,
// a provisional map from two views anchored at the turn's last pure-rotation frame, its scale guessed from the
// map's depth before the turn, and its join with the map when a frame is relocalised against the map again
// (scaled, then adjusted between its two ends).
#include <cstdint>
#include <optional>
#include <string>
#include <unordered_set>
#include <vector>

#include "core/pose.h"
#include "slam/frame_report.h"

namespace mcslam::slam {

struct SlamState;
class Initializer;
class Settler;
class FrameTracker;
class Mapper;

// The provisional map of a Bridge, from a turn's last frame to where the map is found again. (Outside Bridge:
// clang 14 cannot construct a nested struct with member initialisers in an optional.)
struct BridgeState {
  int anchor_slot = -1;    // the turn's last frame: its pose is the provisional map's reference
  double depth_prior = 0;  // the map's median depth before the turn: the guessed scale
  bool built = false;      // the provisional map exists (before: waiting for two views that make one)
  std::unordered_set<int64_t> points;  // its points
};

class Bridge {
 public:
  Bridge(SlamState& s, const Initializer& init, Settler& settler, FrameTracker& tracker, const Mapper& mapper)
      : s_(s), init_(init), settler_(settler), tracker_(tracker), mapper_(mapper) {}

  // A provisional map is being tracked.
  bool active() const { return state_ && state_->built; }
  // Waiting for the two views that make one (Start was called, the map is not built yet).
  bool waiting() const { return state_ && !state_->built; }
  bool Provisional(int64_t point_id) const { return active() && state_->points.count(point_id) > 0; }
  // A point the pose step and the remapping may use now: any, or while a provisional map is tracked only its own
  // (the rest of the map is at another scale).
  bool AtCurrentScale(int64_t point_id) const { return !active() || Provisional(point_id); }
  // A point triangulated while the provisional map is tracked is one of its points.
  void AddPoint(int64_t point_id) { state_->points.insert(point_id); }
  // The anchor's frame index (while one is set).
  int64_t anchor_index() const;

  // After a turn ended in a move at `slot`: a bridge anchored at the turn's last pure-rotation frame; false (and no
  // bridge) when the map's depth before the turn cannot be measured.
  bool Start(int slot);
  // Waiting for the provisional map: its two-view solution between the anchor and `slot`. The reports of the
  // frames it poses, or this frame's 'lost' report saying why not yet.
  std::vector<FrameReport> Try(int slot);
  // A frame relocalised against the map while bridging: tracked in the provisional map, which is then scaled to
  // agree and joins the map.
  std::vector<FrameReport> Join(int slot, const Pose& cam_from_world);
  // The provisional map is lost: its points leave the map.
  void Abandon(int64_t frame_index);
  // Relocalised in the map itself before a provisional map was made: none is needed.
  void Drop() { state_.reset(); }

 private:
  // After the scaling of a join: the bridge's keyframes (and the joining frame) and its points adjusted together,
  // the anchor and the map's points fixed. slot_in_bridge: the joining frame's pose in the scaled provisional map
  // (r says whether it was posed by a turn). Returns how many keyframes were adjusted (0: too few points).
  int AdjustJoined(int slot, const Pose& slot_in_bridge, FrameReport* r);

  SlamState& s_;
  const Initializer& init_;
  Settler& settler_;
  FrameTracker& tracker_;
  const Mapper& mapper_;
  std::optional<BridgeState> state_;
};

}  // namespace mcslam::slam
