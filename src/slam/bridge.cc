// The bridge over the unmapped (bridge.h, SystemOptions::bridge): after a turn that took the map out of view ends
// in a move, a provisional map from two views anchored at the turn's last pure-rotation frame, its scale guessed
// from the map's depth before the turn, and its join with the map when a frame is relocalised against the map
// again (scaled, then adjusted between its two ends).
#include "slam/bridge.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include <fmt/format.h>

#include "core/median.h"
#include "slam/frame_tracker.h"
#include "slam/initializer.h"
#include "slam/mapper.h"
#include "slam/settler.h"
#include "slam/slam_state.h"
#include "slam/system_internal.h"

namespace mcslam::slam {

namespace {

// The join's checks: the two poses of the joining frame must agree in orientation (detail::kJoinMaxRotationDeg)
// and in the direction the camera moved from the anchor (the provisional map's two views fix both; only the scale
// was guessed), and the camera must have moved far enough from the anchor for the ratio of the two distances to
// mean something.
constexpr double kJoinMaxDirectionDeg = 30.0;
constexpr double kJoinMinMoveOfDepth = 0.05;  // of the map's depth before the turn
constexpr double kJoinMaxScaleRatio = 10.0;

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return AngleBetween(a, b) * 180.0 / M_PI;
}

}  // namespace

int64_t Bridge::anchor_index() const { return s_.map.frames[state_->anchor_slot].index; }

bool Bridge::Start(int slot) {
  // The anchor: the turn's last frame, unless the camera had begun to move there already. Below a quarter pixel the
  // rotation-only test cannot tell a move from the images' own wander (TrackRotationOnly), so a frame 1 cm into the
  // move can still pass as a turn; its pose (a rotation about the turn's centre) is then off by the move, and the
  // provisional map built on it solves the move with the wrong parallax (rotation scenario, seed 7: 0.29 px rms
  // at the turn's last frame against 0.1 px before, the provisional map 14 deg off the 3 deg the camera moved). The
  // anchor is the latest frame of the turn whose residual stays within kAnchorMaxRmsOfLeast times the turn's least
  // (rendered images wander 0.08-0.12 px while turning, within 1.5 times).
  constexpr double kAnchorMaxRmsOfLeast = 2.0;
  int anchor = s_.last_posed_slot;  // the turn's last frame (slot - 1, or slot - 2 after a frame whose residual jumped)
  const std::vector<std::pair<int, double>>& turn = tracker_.turn_rms_px();
  for (auto it = turn.rbegin(); it != turn.rend(); ++it) {
    if (it->first != anchor) break;  // the turn's frames, consecutive up to the last
    if (it->second <= kAnchorMaxRmsOfLeast * tracker_.turn_min_rms_px() || std::next(it) == turn.rend()) break;
    anchor = std::next(it)->first;
  }
  // The map's depth before the turn: the median depth of the map points that the latest frame posed by the pose
  // step saw.
  std::optional<double> depth;
  for (int s = anchor; s >= 0 && !depth; --s)
    if (s_.map.frames[s].has_pose && s_.map.frames[s].pose_inliers > 0) depth = s_.MedianDepthSeenBy(s);
  if (!depth) return false;
  state_.emplace();
  state_->anchor_slot = anchor;
  state_->depth_prior = *depth;
  return true;
}

void Bridge::Abandon(int64_t frame_index) {
  settler_.Stop();
  for (int64_t id : state_->points)
    if (MapPoint* p = s_.map.Find(id); p && p->state != PointState::kRemoved) {
      p->state = PointState::kRemoved;
      p->removed_frame = frame_index;
    }
  state_.reset();
}

std::vector<FrameReport> Bridge::Try(int slot) {
  const InitOptions& io = s_.options.init;
  const int a = state_->anchor_slot;
  const FrameRecord& anchor = s_.map.frames[a];
  const FrameRecord& cur = s_.map.frames[slot];
  FrameReport lost;
  lost.index = cur.index;
  lost.stamp_s = cur.stamp_s;
  lost.status = FrameStatus::kLost;
  lost.map_points = s_.MapPoints();
  auto wait = [&](const std::string& why) {
    lost.note = "the map is out of view; a provisional map from the turn's last pure-rotation frame (" +
                std::to_string(anchor.index) + "): " + why;
    return std::vector<FrameReport>{lost};
  };
  // The tracks the anchor and this frame share (no map point: the map is out of view), and the counts the
  // initialisation asks for.
  const Initializer::Correspondences c = init_.Correspond(a, slot);
  const Initializer::InitCounts need = init_.NeededCounts(slot);
  if (static_cast<int>(c.ids.size()) < need.common) {
    std::vector<FrameReport> out = wait(fmt::format("given up, only {} tracks shared with it", c.ids.size()));
    state_.reset();
    return out;
  }
  if (std::optional<std::string> short_of = init_.MotionShort(c)) return wait(*short_of);
  std::vector<int> window;
  for (int s = a; s <= slot; ++s) window.push_back(s);
  if (static_cast<int>(window.size()) < io.min_window_frames) return wait("too few frames since it");
  std::string why;
  bool rejected = false;
  const std::optional<Initializer::InitHypothesis> best =
      init_.SolveInitWindow(window, c.n1, c.n2, c.ids, need.inliers, need.points, &why, &rejected);
  if (!best) return wait(why);

  // Into the map's frame: the anchor's pose is the reference, the scale puts the points as deep as the map's were.
  std::vector<double> z;
  for (const Eigen::Vector3d& X : best->points) z.push_back(X.z());
  const double s = state_->depth_prior / UpperMedian(z);
  const Pose world_from_anchor = anchor.cam_from_world.Inverse();
  for (size_t i = 0; i < best->points.size(); ++i) {
    MapPoint p;
    p.id = best->point_ids[i];
    p.position_in_world = world_from_anchor * (s * best->points[i]);
    p.last_seen_frame = cur.index;
    if (MapPoint* existing = s_.map.Find(p.id))
      *existing = p;  // a removed point's track, triangulated again
    else
      s_.map.Add(p);
    state_->points.insert(p.id);
  }
  for (size_t w = 0; w < window.size(); ++w) {
    FrameRecord& f = s_.map.frames[window[w]];
    if (w > 0) {
      f.has_pose = true;
      f.cam_from_world = Pose(best->poses[w].q, s * best->poses[w].t) * anchor.cam_from_world;
    }
    s_.map.keyframes.push_back(window[w]);
  }
  state_->built = true;
  // Settled as the first map is (InitOptions::settle_parallax_deg): the provisional map's frames and points refined
  // together as the parallax from the anchor grows, the anchor held and the first baseline keeping its length.
  s_.reference_slot = a;
  s_.posed_from = a;
  settler_.BeginSettling(slot,
                (cur.cam_from_world.OriginOfTargetInSource() - anchor.cam_from_world.OriginOfTargetInSource()).norm(),
                best->two_view_parallax_deg, need.points);
  s_.last_posed_slot = slot;
  tracker_.EndTurn();
  s_.MarkSeen(slot);
  s_.RefreshInlierFlags(slot);
  s_.smoother.Reset();
  std::vector<FrameReport> out;
  for (size_t w = 1; w < window.size(); ++w) {
    FrameReport r = s_.PosedReport(window[w]);
    r.keyframe = true;
    r.provisional = true;
    r.smoothed_cam_from_world = s_.smoother.Update(r.cam_from_world);
    r.map_points = s_.MapPoints();
    if (w + 1 == window.size()) {
      r.new_points = static_cast<int>(best->points.size());
      r.note = fmt::format(
          "provisional map from frames {} (the turn's last pure-rotation frame, the map out of view) and {}: {} points, median parallax "
          "{:.2f} deg, scale guessed from the map's depth before the turn ({:.3g})",
          anchor.index, cur.index, best->points.size(), best->two_view_parallax_deg, state_->depth_prior);
    }
    out.push_back(r);
  }
  return out;
}

std::vector<FrameReport> Bridge::Join(int slot, const Pose& cam_from_world) {
  FrameReport r = tracker_.TrackFrame(slot, std::nullopt);  // in the provisional map
  // A frame the provisional map did not pose cannot join it. FrameTracker keeps the provisional map (and the turn)
  // over a frame whose turn residual jumped, for the next frame to tell: the join waits for that frame too (the map
  // is looked for in every frame while bridging), which then joins from its pose in the provisional map, or loses
  // it. Any other frame the provisional map loses gives it up, the turn with it (its centre is a provisional
  // frame's). Rotation scenario with two of every ten frames blurred and exposure steps, seed 8: the map was found
  // in the second blurred frame of a pair, whose residual jumped as the first's did; the provisional map of 147
  // points was given up there and the rest of the run went on at the old map's scale (5.6 % of the path).
  if (active() && !s_.map.frames[slot].has_pose) {
    if (s_.options.bridge_join_waits_over_a_jump && tracker_.TurnKeptOver(slot)) {
      r.note += "; the map is found again: the join waits for the next frame";
      return {r};
    }
    Abandon(s_.map.frames[slot].index);
    tracker_.EndTurn();
  }
  if (!active()) {  // its tracking failed: the map's pose stands (and no new bridge is needed, the map is found)
    state_.reset();
    std::vector<FrameReport> out{tracker_.TrackFrame(slot, cam_from_world)};
    out.front().note += "; relocalised in the map after the provisional map was lost";
    return out;
  }
  const FrameRecord& anchor = s_.map.frames[state_->anchor_slot];
  const Eigen::Vector3d c_anchor = anchor.cam_from_world.OriginOfTargetInSource();
  const Eigen::Vector3d in_bridge = s_.map.frames[slot].cam_from_world.OriginOfTargetInSource() - c_anchor;
  const Eigen::Vector3d in_map = cam_from_world.OriginOfTargetInSource() - c_anchor;
  const double rotation_deg = AngularDistanceDeg(s_.map.frames[slot].cam_from_world.q, cam_from_world.q);
  const double direction_deg = AngleDeg(in_bridge, in_map);
  const double ratio = in_bridge.norm() > 0 ? in_map.norm() / in_bridge.norm() : 0.0;
  std::string refused;
  if (rotation_deg > detail::kJoinMaxRotationDeg)
    refused = fmt::format("orientations {:.1f} deg apart", rotation_deg);
  else if (in_map.norm() < kJoinMinMoveOfDepth * state_->depth_prior)
    refused = fmt::format("the camera moved {:.3g} from the anchor, too little to scale by", in_map.norm());
  else if (direction_deg > kJoinMaxDirectionDeg)
    refused = fmt::format("the moves from the anchor {:.1f} deg apart", direction_deg);
  else if (!(ratio > 1.0 / kJoinMaxScaleRatio && ratio < kJoinMaxScaleRatio))
    refused = fmt::format("scale ratio {:.3g}", ratio);
  if (!refused.empty()) {
    r.note += (r.note.empty() ? "" : "; ") + fmt::format("relocalised in the map but not joined: {}", refused);
    return {r};
  }
  settler_.Stop();
  // Scale the provisional map about the anchor's centre.
  auto scaled = [&](const Eigen::Vector3d& x) -> Eigen::Vector3d { return c_anchor + ratio * (x - c_anchor); };
  for (int64_t id : state_->points)
    if (MapPoint* p = s_.map.Find(id); p && p->state != PointState::kRemoved) p->position_in_world = scaled(p->position_in_world);
  std::vector<FrameReport> out;
  s_.smoother.Reset();
  for (int k = state_->anchor_slot + 1; k <= slot; ++k) {
    FrameRecord& f = s_.map.frames[k];
    if (f.has_pose) f.cam_from_world.t = -(f.cam_from_world.q * scaled(f.cam_from_world.OriginOfTargetInSource()));
  }
  const Pose slot_in_bridge = s_.map.frames[slot].cam_from_world;  // scaled
  // The frame posed again from the relocalised pose, by the pose step on every point it sees: the provisional
  // map's rotation drifted a little while it was alone (degrees), and the points of the map must score the next
  // frame too.
  FrameRecord& fr = s_.map.frames[slot];
  std::vector<PointObservation> obs;
  for (const FeatureUndistorted& f : fr.features)
    if (const MapPoint* p = s_.map.Find(f.id); p && p->state != PointState::kRemoved)
      obs.push_back({p->position_in_world, f.uv_px, true});
  std::vector<double> res;
  std::vector<uint8_t> inl;
  s_.pose_step->ClassifyInliers(cam_from_world, obs, &res, &inl);
  for (size_t i = 0; i < obs.size(); ++i) obs[i].was_inlier = inl[i] != 0;
  if (const PoseEstimate est = s_.pose_step->Track(cam_from_world, obs, static_cast<uint64_t>(fr.index), &res, &inl);
      est.tracked) {
    fr.cam_from_world = est.cam_from_world;
    fr.pose_inliers = est.inliers;
    r.inliers = est.inliers;
  }
  const int adjusted = AdjustJoined(slot, slot_in_bridge, &r);
  for (int k = state_->anchor_slot + 1; k < slot; ++k)
    if (s_.map.frames[k].has_pose) {
      FrameReport u = s_.PosedReport(k);
      u.pose_update = true;
      u.joined = true;
      out.push_back(u);
    }
  state_.reset();
  // A turn under way was about a centre in the provisional map, which the join has just moved: the next turn
  // starts afresh from this frame.
  tracker_.EndTurn();
  s_.RefreshInlierFlags(slot);
  r.cam_from_world = s_.map.frames[slot].cam_from_world;
  r.smoothed_cam_from_world = s_.smoother.Update(r.cam_from_world);
  r.joined = true;
  s_.ResidualStats(slot, &r);
  r.note += (r.note.empty() ? "" : "; ") +
            fmt::format("relocalised in the map: the provisional map joins it, scaled by {:.3f} (moves {:.1f} deg "
                        "apart, orientations {:.1f} deg), {} of its keyframes adjusted between the anchor and this frame",
                        ratio, direction_deg, rotation_deg, adjusted);
  out.insert(out.begin(), r);
  return out;
}

int Bridge::AdjustJoined(int slot, const Pose& slot_in_bridge, FrameReport* r) {
  // Scaled, the provisional map still carries what its two views and its tracking alone got wrong: the direction
  // of the move and a drift of its orientation (the join accepts up to kJoinMaxDirectionDeg and
  // detail::kJoinMaxRotationDeg), all of it showing at the joining frame. Now that both its ends are known in the map (the
  // anchor, and this frame by the map's points), its keyframes and points are adjusted together (Ceres, Cauchy loss
  // as the local adjustment's) with the anchor and every point of the map held fixed, which spreads that error
  // over the bridge instead of leaving it at its end. Rotation scenario, seed 1: the bridge's frames were 5-9 cm
  // off after the scaling alone (the rest 2-3 cm).
  const MappingOptions& mo = s_.options.mapping;
  const int a = state_->anchor_slot;
  std::vector<int> keyframes;
  for (int k : s_.map.keyframes)
    if (k >= a && k < slot && s_.map.frames[k].has_pose) keyframes.push_back(k);
  std::sort(keyframes.begin(), keyframes.end());
  keyframes.erase(std::unique(keyframes.begin(), keyframes.end()), keyframes.end());
  if (keyframes.empty() || keyframes.front() != a) return 0;
  // The window's frames and poses; its last frame is the joining frame (placed by the map's points), or in the turn
  // case below the turn's centre keyframe (placed by its own points and the map's seen through the turn).
  std::vector<int> window;
  std::vector<Pose> cams, before;
  std::vector<bool> fixed;
  WindowPoints wp;
  std::vector<bool> fixed_points;
  std::vector<int> seen;
  int last_sees_bridge = 0;
  // A point the adjustment holds: the map's (or a loaded map's), not the bridge's own.
  const auto held = [&](int64_t id) { return !state_->points.count(id) || s_.IsLoaded(id); };
  // Its points seen twice or more, and every point of the map any of its frames sees (held fixed, one view
  // places a frame: the joining frame sees the map's points only once).
  // turned_from_last: in the turn case, the rotation from the window's last frame to the joining frame, whose
  // observations of the map's points are then the last frame's, turned back (a turn about one centre moves no
  // point's bearing but by the rotation).
  const auto gather = [&](std::vector<int> frames, const std::optional<Eigen::Quaterniond>& turned_from_last) {
    window = std::move(frames);
    cams.clear();
    for (int k : window) cams.push_back(s_.map.frames[k].cam_from_world);
    before = cams;
    fixed.assign(window.size(), false);
    fixed.front() = true;
    std::unordered_map<int64_t, int> count, index;
    for (int k : window)
      for (const FeatureUndistorted& f : s_.map.frames[k].features) ++count[f.id];
    wp = WindowPoints();
    fixed_points.clear();
    for (size_t w = 0; w < window.size(); ++w)
      for (const FeatureUndistorted& f : s_.map.frames[window[w]].features) {
        MapPoint* p = s_.map.Find(f.id);
        if (!p || p->state == PointState::kRemoved) continue;
        const bool is_held = held(f.id);
        if (!is_held && count[f.id] < 2) continue;
        auto [it, fresh] = index.try_emplace(f.id, static_cast<int>(wp.pts.size()));
        if (fresh) wp.pts.push_back(p), wp.X.push_back(p->position_in_world), fixed_points.push_back(is_held);
        wp.obs.push_back({static_cast<int>(w), it->second, s_.ideal.PixelToNormalized(f.uv_px)});
      }
    if (turned_from_last)
      for (const FeatureUndistorted& f : s_.map.frames[slot].features) {
        MapPoint* p = s_.map.Find(f.id);
        if (!p || p->state == PointState::kRemoved || !held(f.id)) continue;
        const Eigen::Vector3d ray = turned_from_last->conjugate() * s_.ideal.PixelToNormalized(f.uv_px).homogeneous();
        if (!(ray.z() > 0)) continue;
        auto [it, fresh] = index.try_emplace(f.id, static_cast<int>(wp.pts.size()));
        if (fresh) wp.pts.push_back(p), wp.X.push_back(p->position_in_world), fixed_points.push_back(true);
        wp.obs.push_back({static_cast<int>(window.size()) - 1, it->second, Eigen::Vector2d(ray.head<2>() / ray.z())});
      }
    seen.assign(window.size(), 0);
    last_sees_bridge = 0;
    for (const geometry::BundleObservation& o : wp.obs) {
      ++seen[static_cast<size_t>(o.camera)];
      last_sees_bridge += o.camera + 1 == static_cast<int>(window.size()) && !fixed_points[static_cast<size_t>(o.point)];
    }
  };
  std::vector<int> with_joining = keyframes;
  with_joining.push_back(slot);
  gather(with_joining, std::nullopt);
  // Each adjusted pose held by at least as many points as the pose step needs to track a frame, and the joining
  // frame seeing at least one of the bridge's own points: where it sees none (the join came in a turn that took
  // the bridge out of view), only the anchor ties the bridge and its scale is free (an adjustment tried so ran off:
  // seed 8, cameras thousands of units away at a lower residual). Measured at the joins of the rotation scenario:
  // the joining frame saw 0 of the bridge's points on seeds 6-8 (the adjustment changed their ATE by -0.1 to +0.3
  // cm), 1 on seed 9 (7.6 -> 2.1 cm), 3 on seed 4, and tens on seeds 1, 3, 5 and 10.
  // But a joining frame that the provisional map posed by a turn about the last centre ties the bridge through the
  // turn: its centre is that of the keyframe the turn started from, and its rotation from there is what every
  // track of the turn measured (tens of them). Its observations of the map's points, turned back by that rotation,
  // are then that keyframe's, and the bridge is adjusted between the anchor and it (the frames of the turn, the
  // joining one included, follow it). Rotation scenario rendered with noise of 6 grey levels, seed 2: the join came
  // three frames into the pan back, 4.0 deg off in orientation, and left unadjusted the bridge's points disagreed
  // with the map's (48 of 72 in view would have left it at once) and the run ended 22 cm off.
  bool through_turn = false;
  if (last_sees_bridge < 1 && r->rotation_only) {
    const Eigen::Vector3d centre = slot_in_bridge.OriginOfTargetInSource();
    const double tolerance = 1e-6 * std::max(1.0, (centre - cams.front().OriginOfTargetInSource()).norm());
    for (size_t i = keyframes.size(); i-- > 1;)
      if ((s_.map.frames[keyframes[i]].cam_from_world.OriginOfTargetInSource() - centre).norm() <= tolerance) {
        const Eigen::Quaterniond turned = slot_in_bridge.q * s_.map.frames[keyframes[i]].cam_from_world.q.conjugate();
        gather(std::vector<int>(keyframes.begin(), keyframes.begin() + static_cast<std::ptrdiff_t>(i) + 1), turned);
        through_turn = true;
        break;
      }
  }
  if (*std::min_element(seen.begin() + 1, seen.end()) < s_.options.tracker.min_inliers ||
      (!through_turn && last_sees_bridge < 1))
    return 0;
  // Through a turn the joining frame follows the centre keyframe's correction from the pose the turn gave it in the
  // bridge (the pose step on the map's points moved it since: it stands if the adjustment is refused below).
  const Pose joining_in_map = s_.map.frames[slot].cam_from_world;
  if (through_turn) s_.map.frames[slot].cam_from_world = slot_in_bridge;
  geometry::BundleAdjustOptions bo;
  bo.focal_px = s_.focal_px;
  bo.cauchy = true;
  bo.huber_px = std::max(mo.local_ba_min_loss_px, mo.local_ba_loss_sigmas * mapper_.RecentNoisePx().value_or(1.0));
  bo.max_iterations = 5 * s_.options.ba_iterations;  // the error spreads along a chain of tens of keyframes
  std::vector<Eigen::Vector3d> X_before = wp.X;
  geometry::BundleAdjust(cams, wp.X, wp.obs, fixed, bo, fixed_points);
  // Few ties (one point, say) and a wrong one among them: the adjustment may move the bridge further than its own
  // length, which no error the join accepts could need. Then the scaled bridge stands as it was.
  const double length = (before.back().OriginOfTargetInSource() - before.front().OriginOfTargetInSource()).norm();
  bool keep_joining = false;
  for (size_t k = 1; k < cams.size(); ++k)
    if (!((cams[k].OriginOfTargetInSource() - before[k].OriginOfTargetInSource()).norm() <= length)) {
      cams = before;
      wp.X = X_before;
      keep_joining = through_turn;
      break;
    }
  if (keep_joining) s_.map.frames[slot].cam_from_world = joining_in_map;
  // Frames of the bridge that are no keyframe follow the keyframe before them.
  size_t w = 0;
  for (int k = a + 1; k <= (keep_joining ? slot - 1 : slot); ++k) {
    while (w + 1 < window.size() && window[w + 1] <= k) ++w;
    FrameRecord& f = s_.map.frames[k];
    if (!f.has_pose) continue;
    if (window[w] == k)
      f.cam_from_world = cams[w];
    else  // the same correction of the world as its keyframe's
      f.cam_from_world = f.cam_from_world * (before[w].Inverse() * cams[w]);
  }
  r->removed += s_.StoreAdjustedPoints(cams, wp, s_.map.frames[slot].index);
  return static_cast<int>(window.size()) - 1;  // the anchor held
}

}  // namespace mcslam::slam
