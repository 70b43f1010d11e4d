// Relocalisation (relocaliser.h): RANSAC PnP on the map points a lost frame's features were matched to by look.
#include "slam/relocaliser.h"

#include <cstdint>

#include "geometry/pnp.h"
#include "slam/bridge.h"
#include "slam/slam_state.h"
#include "slam/system_internal.h"

namespace mcslam::slam {

namespace {

// Relocalise's search on matches already in undistorted pixels.
std::optional<Relocalisation> RelocaliseUndistorted(const SlamState& s, const Bridge& bridge,
                                                    const std::vector<FeatureUndistorted>& matches, int min_inliers) {
  if (!s.initialised) return std::nullopt;
  std::vector<PointObservation> obs;
  std::vector<Eigen::Vector3d> P;
  std::vector<Eigen::Vector2d> uv;
  std::vector<int64_t> ids;
  for (const FeatureUndistorted& m : matches) {
    const MapPoint* p = s.map.Find(m.id);
    if (!p || p->state == PointState::kRemoved || !m.uv_px.allFinite()) continue;
    if (bridge.Provisional(m.id)) continue;  // only the map the provisional one joins
    obs.push_back({p->position_in_world, m.uv_px, true});
    P.push_back(p->position_in_world);
    uv.push_back(s.ideal.PixelToNormalized(m.uv_px));
    ids.push_back(m.id);
  }
  if (static_cast<int>(P.size()) < min_inliers) return std::nullopt;
  geometry::PnpOptions po = s.TrackerPnpOptions(min_inliers);
  po.iterations = 500;  // no prior and maybe half the matches wrong
  std::optional<Pose> pose = geometry::SolvePnp(P, uv, po);
  bool guided = false;
  // While a provisional map is tracked, the frame's orientation is known: the provisional map's is the map's (it
  // was anchored at the turn, and drifts little), and a pose that disagrees cannot join it. Where a consensus of
  // wrong matches won the free search, the search is made again among poses so oriented (rotation scenario,
  // seed 2: frame 190 placed 10.9 deg off by 15 of 41 matches, the join refused, the provisional map never
  // joined).
  if (bridge.active() && s.last_posed_slot >= 0) {
    const Eigen::Quaterniond prior = s.map.frames[s.last_posed_slot].cam_from_world.q;
    if (!pose || AngularDistanceDeg(pose->q, prior) > detail::kJoinMaxRotationDeg) {
      pose = geometry::SolvePnpNearRotation(P, uv, po, prior, detail::kJoinMaxRotationDeg,
                                            s.options.seed ^ (static_cast<uint64_t>(s.last_posed_slot) * 0x9E3779B97F4A7C15ull));
      guided = true;
    }
  }
  if (!pose) return std::nullopt;
  Relocalisation r;
  r.cam_from_world = *pose;
  r.matches = static_cast<int>(P.size());
  r.near_provisional_orientation = guided;
  // Inliers as the pose step counts them.
  std::vector<double> res;
  std::vector<uint8_t> inl;
  s.pose_step->ClassifyInliers(*pose, obs, &res, &inl);
  for (size_t i = 0; i < ids.size(); ++i)
    if (inl[i]) r.inlier_point_ids.push_back(ids[i]);
  if (static_cast<int>(r.inlier_point_ids.size()) < min_inliers) return std::nullopt;
  return r;
}

}  // namespace

std::optional<Relocalisation> Relocalise(const SlamState& s, const Bridge& bridge,
                                         const std::vector<RelocalisationMatch>& matches) {
  std::vector<FeatureUndistorted> undistorted;
  for (const RelocalisationMatch& m : matches) {
    if (!m.uv_px.allFinite()) continue;
    const Eigen::Vector2d u = s.camera.UndistortPixel(m.uv_px);
    if (u.allFinite()) undistorted.push_back({m.point_id, u});
  }
  return RelocaliseUndistorted(s, bridge, undistorted, s.options.relocalise_min_inliers);
}

std::optional<Relocalisation> RelocaliseByTracks(const SlamState& s, const Bridge& bridge, int slot) {
  // Tracks are not matches by look: as many as the pose step needs to track a frame.
  return RelocaliseUndistorted(s, bridge, s.map.frames[slot].features, s.options.tracker.min_inliers);
}

}  // namespace mcslam::slam
