// The System's bridge over the unmapped (SystemOptions::bridge): after a turn that took the map out of view ends
// in a move, a provisional map from two views anchored at the turn's last frame, its scale guessed from the map's
// depth before the turn, and its join with the map when a frame is relocalised against the map again.
#include "slam/system.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "core/median.h"
#include "slam/system_internal.h"

namespace mcslam::slam {

namespace {

// The join's checks: the two poses of the joining frame must agree in orientation and in the direction the
// camera moved from the anchor (the provisional map's two views fix both; only the scale was guessed), and the
// camera must have moved far enough from the anchor for the ratio of the two distances to mean something.
constexpr double kJoinMaxRotationDeg = 5.0;
constexpr double kJoinMaxDirectionDeg = 30.0;
constexpr double kJoinMinMoveOfDepth = 0.05;  // of the map's depth before the turn
constexpr double kJoinMaxScaleRatio = 10.0;

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / M_PI;
}

}  // namespace

bool System::StartBridge(int slot) {
  const int anchor = slot - 1;
  // The map's depth before the turn: the median depth of the map points that the latest frame posed by the pose
  // step saw.
  std::vector<double> depths;
  for (int s = anchor; s >= 0 && depths.empty(); --s) {
    const FrameRecord& f = map_.frames[s];
    if (!f.has_pose || f.pose_inliers <= 0) continue;
    for (const FeatureUndistorted& o : f.features)
      if (const MapPoint* p = map_.Find(o.id); p && p->state != PointState::kRemoved)
        if (const double z = (f.cam_from_world * p->position_in_world).z(); z > 0) depths.push_back(z);
  }
  if (depths.empty()) return false;
  bridge_.emplace();
  bridge_->anchor_slot = anchor;
  bridge_->depth_prior = UpperMedian(depths);
  return true;
}

void System::AbandonBridge(int64_t frame_index) {
  settling_ = false;
  for (int64_t id : bridge_->points)
    if (MapPoint* p = map_.Find(id); p && p->state != PointState::kRemoved) {
      p->state = PointState::kRemoved;
      p->removed_frame = frame_index;
    }
  bridge_.reset();
}

std::vector<FrameReport> System::TryBridge(int slot) {
  const InitOptions& io = options_.init;
  const int a = bridge_->anchor_slot;
  const FrameRecord& anchor = map_.frames[a];
  const FrameRecord& cur = map_.frames[slot];
  FrameReport lost;
  lost.index = cur.index;
  lost.stamp_s = cur.stamp_s;
  lost.status = FrameStatus::kLost;
  lost.map_points = map_.CountInState(PointState::kActive) + map_.CountInState(PointState::kLost);
  auto wait = [&](const std::string& why) {
    lost.note = "the map is out of view; a provisional map from the turn's last frame (" +
                std::to_string(anchor.index) + "): " + why;
    return std::vector<FrameReport>{lost};
  };
  // The tracks the anchor and this frame share (no map point: the map is out of view), and the counts the
  // initialisation asks for.
  const Correspondences c = Correspond(a, slot);
  const InitCounts need = NeededCounts(slot);
  if (static_cast<int>(c.ids.size()) < need.common) {
    std::vector<FrameReport> out = wait(fmt::format("given up, only {} tracks shared with it", c.ids.size()));
    bridge_.reset();
    return out;
  }
  const double med_motion = UpperMedian(c.motion_deg);
  if (med_motion < io.min_median_motion_deg)
    return wait(fmt::format("median feature motion {:.2f} deg < {:.2f} deg", med_motion, io.min_median_motion_deg));
  std::vector<int> window;
  for (int s = a; s <= slot; ++s) window.push_back(s);
  if (static_cast<int>(window.size()) < io.min_window_frames) return wait("too few frames since it");
  std::string why;
  bool rejected = false;
  const std::optional<InitHypothesis> best =
      SolveInitWindow(window, c.n1, c.n2, c.ids, need.inliers, need.points, &why, &rejected);
  if (!best) return wait(why);

  // Into the map's frame: the anchor's pose is the reference, the scale puts the points as deep as the map's were.
  std::vector<double> z;
  for (const Eigen::Vector3d& X : best->points) z.push_back(X.z());
  const double s = bridge_->depth_prior / UpperMedian(z);
  const Pose world_from_anchor = anchor.cam_from_world.Inverse();
  for (size_t i = 0; i < best->points.size(); ++i) {
    MapPoint p;
    p.id = best->point_ids[i];
    p.position_in_world = world_from_anchor * (s * best->points[i]);
    p.last_seen_frame = cur.index;
    if (MapPoint* existing = map_.Find(p.id))
      *existing = p;  // a removed point's track, triangulated again
    else
      map_.Add(p);
    bridge_->points.insert(p.id);
  }
  for (size_t w = 0; w < window.size(); ++w) {
    FrameRecord& f = map_.frames[window[w]];
    if (w > 0) {
      f.has_pose = true;
      f.cam_from_world = Pose(best->poses[w].q, s * best->poses[w].t) * anchor.cam_from_world;
    }
    map_.keyframes.push_back(window[w]);
  }
  bridge_->built = true;
  // Settled as the first map is (InitOptions::settle_parallax_deg): the provisional map's frames and points refined
  // together as the parallax from the anchor grows, the anchor held and the first baseline keeping its length.
  reference_slot_ = a;
  posed_from_ = a;
  BeginSettling(slot,
                (cur.cam_from_world.OriginOfTargetInSource() - anchor.cam_from_world.OriginOfTargetInSource()).norm(),
                best->two_view_parallax_deg, need.points);
  last_posed_slot_ = slot;
  panorama_bearings_.clear();
  MarkSeen(slot);
  RefreshInlierFlags(slot);
  smoother_.Reset();
  std::vector<FrameReport> out;
  for (size_t w = 1; w < window.size(); ++w) {
    FrameReport r = PosedReport(window[w]);
    r.keyframe = true;
    r.provisional = true;
    r.smoothed_cam_from_world = smoother_.Update(r.cam_from_world);
    r.map_points = map_.CountInState(PointState::kActive) + map_.CountInState(PointState::kLost);
    if (w + 1 == window.size()) {
      r.new_points = static_cast<int>(best->points.size());
      r.note = fmt::format(
          "provisional map from frames {} (the turn's last, the map out of view) and {}: {} points, median parallax "
          "{:.2f} deg, scale guessed from the map's depth before the turn ({:.3g})",
          anchor.index, cur.index, best->points.size(), best->two_view_parallax_deg, bridge_->depth_prior);
    }
    out.push_back(r);
  }
  return out;
}

std::vector<FrameReport> System::JoinBridge(int slot, const Pose& cam_from_world) {
  FrameReport r = TrackFrame(slot, std::nullopt);  // in the provisional map
  if (!bridging()) {  // its tracking failed: the map's pose stands (and no new bridge is needed, the map is found)
    bridge_.reset();
    std::vector<FrameReport> out{TrackFrame(slot, cam_from_world)};
    out.front().note += "; relocalised in the map after the provisional map was lost";
    return out;
  }
  const FrameRecord& anchor = map_.frames[bridge_->anchor_slot];
  const Eigen::Vector3d c_anchor = anchor.cam_from_world.OriginOfTargetInSource();
  const Eigen::Vector3d in_bridge = map_.frames[slot].cam_from_world.OriginOfTargetInSource() - c_anchor;
  const Eigen::Vector3d in_map = cam_from_world.OriginOfTargetInSource() - c_anchor;
  const double rotation_deg = AngularDistanceDeg(map_.frames[slot].cam_from_world.q, cam_from_world.q);
  const double direction_deg = AngleDeg(in_bridge, in_map);
  const double ratio = in_bridge.norm() > 0 ? in_map.norm() / in_bridge.norm() : 0.0;
  std::string refused;
  if (rotation_deg > kJoinMaxRotationDeg)
    refused = fmt::format("orientations {:.1f} deg apart", rotation_deg);
  else if (in_map.norm() < kJoinMinMoveOfDepth * bridge_->depth_prior)
    refused = fmt::format("the camera moved {:.3g} from the anchor, too little to scale by", in_map.norm());
  else if (direction_deg > kJoinMaxDirectionDeg)
    refused = fmt::format("the moves from the anchor {:.1f} deg apart", direction_deg);
  else if (!(ratio > 1.0 / kJoinMaxScaleRatio && ratio < kJoinMaxScaleRatio))
    refused = fmt::format("scale ratio {:.3g}", ratio);
  if (!refused.empty()) {
    r.note += (r.note.empty() ? "" : "; ") + fmt::format("relocalised in the map but not joined: {}", refused);
    return {r};
  }
  settling_ = false;
  // Scale the provisional map about the anchor's centre.
  auto scaled = [&](const Eigen::Vector3d& x) -> Eigen::Vector3d { return c_anchor + ratio * (x - c_anchor); };
  for (int64_t id : bridge_->points)
    if (MapPoint* p = map_.Find(id); p && p->state != PointState::kRemoved) p->position_in_world = scaled(p->position_in_world);
  std::vector<FrameReport> out;
  smoother_.Reset();
  for (int k = bridge_->anchor_slot + 1; k <= slot; ++k) {
    FrameRecord& f = map_.frames[k];
    if (!f.has_pose) continue;
    f.cam_from_world.t = -(f.cam_from_world.q * scaled(f.cam_from_world.OriginOfTargetInSource()));
    if (k == slot) continue;
    FrameReport u = PosedReport(k);
    u.pose_update = true;
    out.push_back(u);
  }
  bridge_.reset();
  // The frame posed again from the relocalised pose, by the pose step on every point it sees: the provisional
  // map's rotation drifted a little while it was alone (degrees), and the points of the map must score the next
  // frame too.
  FrameRecord& fr = map_.frames[slot];
  std::vector<PointObservation> obs;
  for (const FeatureUndistorted& f : fr.features)
    if (const MapPoint* p = map_.Find(f.id); p && p->state != PointState::kRemoved)
      obs.push_back({p->position_in_world, f.uv_px, true});
  std::vector<double> res;
  std::vector<uint8_t> inl;
  tracker_->ClassifyInliers(cam_from_world, obs, &res, &inl);
  for (size_t i = 0; i < obs.size(); ++i) obs[i].was_inlier = inl[i] != 0;
  if (const PoseEstimate est = tracker_->Track(cam_from_world, obs, static_cast<uint64_t>(fr.index), &res, &inl);
      est.tracked) {
    fr.cam_from_world = est.cam_from_world;
    fr.pose_inliers = est.inliers;
    r.inliers = est.inliers;
  }
  RefreshInlierFlags(slot);
  r.cam_from_world = map_.frames[slot].cam_from_world;
  r.smoothed_cam_from_world = smoother_.Update(r.cam_from_world);
  ResidualStats(slot, &r);
  r.note += (r.note.empty() ? "" : "; ") +
            fmt::format("relocalised in the map: the provisional map joins it, scaled by {:.3f} (moves {:.1f} deg "
                        "apart, orientations {:.1f} deg)",
                        ratio, direction_deg, rotation_deg);
  out.insert(out.begin(), r);
  return out;
}

}  // namespace mcslam::slam
