#pragma once
// Relocalisation: after the track is lost, a frame placed in the map by its features matched to map points by their
// look alone (no pose prior), by RANSAC PnP on the points that are in the map.
#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"

namespace mcslam::slam {

struct SlamState;
class Bridge;

// A feature of the current frame matched (by descriptor) to a map point: an input of Relocalise (System::Relocalise).
struct RelocalisationMatch {
  int64_t point_id = 0;
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();  // as the camera saw it (distorted pixels)
};
struct Relocalisation {
  Pose cam_from_world;
  std::vector<int64_t> inlier_point_ids;  // the matches that agree with it
  int matches = 0;
  // Found among the poses near a provisional map's orientation, the free search having found none or one
  // that disagreed with it (System::Relocalise).
  bool near_provisional_orientation = false;
};

// The pose of a frame from its matches, or nullopt when fewer than SystemOptions::relocalise_min_inliers matches
// agree, or before initialisation. Changes nothing; the caller passes the pose as the frame's pose_hint with the
// inlier features under their map points' ids. While a provisional map is tracked, its points are left out (only
// the map it joins) and the search keeps to poses near its orientation when the free one disagrees with it.
std::optional<Relocalisation> Relocalise(const SlamState& s, const Bridge& bridge,
                                         const std::vector<RelocalisationMatch>& matches);

// The same search on the frame's own tracks of map points (the frame in slot, its features under their points' ids):
// a frame that follows enough of the map's points needs no descriptor to be placed by them. Tracks are not matches
// by look alone: as many as the pose step needs to track a frame (PoseTrackerOptions::min_inliers) agree.
std::optional<Relocalisation> RelocaliseByTracks(const SlamState& s, const Bridge& bridge, int slot);

}  // namespace mcslam::slam
