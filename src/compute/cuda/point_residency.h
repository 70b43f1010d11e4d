#pragma once
// The point kernel's data kept on the device across calls (DESIGN.md, "GPU mapping": pose history and feature
// positions live on the device). A point adjustment runs at every keyframe over a window of keyframes chosen
// back from it; from one call to the next the window gains a keyframe and most of its poses and of its
// features (a keyframe's view of a point) are the ones of the call before. So the device keeps two keyed
// stores, mirrored on the host by SlotMirror (slot_mirror.h):
//   - poses, keyed by the keyframe's id (PointAdjustProblem::pose_ids): its ScaledPose;
//   - features, keyed by (keyframe id, point id): the keyframe's slot in the pose store and the feature (u, v).
// A call sends only what the stores do not hold yet (a new keyframe's pose and its features, a pose a
// settling adjustment moved) and, for every observation, the feature's slot (4 bytes instead of 12); the
// centres and spreads are the call's own and always travel. The scoring kernel reads an observation through
// ResidentObservations, the copy into the stores is ApplyResidentUpdate: both MCSLAM_HOST_DEVICE, so the host
// tests run the very code the device runs. The host side (PointResidency) is plain C++17.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include "compute/cuda/point_staging.h"
#include "compute/cuda/slot_mirror.h"
#include "compute/point_kernel.h"
#include "core/host_device.h"

namespace mcslam::compute::cuda {

// One entry of the device's feature store.
struct FeatureEntry {
  int pose_slot;  // the keyframe's slot in the pose store
  float u, v;     // undistorted pixels minus the principal point
};

// A value to copy into a store slot: the records a call sends for what the device does not hold yet.
struct PoseUpdate {
  int slot;
  ScaledPose pose;
};
struct FeatureUpdate {
  int slot;
  FeatureEntry entry;
};

// Update i of a call (pose updates first, then feature updates): the device runs it once per i, in any order
// (every slot is written at most once a call: SlotMirror hands out one slot per key and a key once a call).
MCSLAM_HOST_DEVICE MCSLAM_INLINE void ApplyResidentUpdate(int i, const PoseUpdate* pose_updates, int num_pose_updates,
                                                          const FeatureUpdate* feature_updates,
                                                          int num_feature_updates, ScaledPose* pose_store,
                                                          FeatureEntry* feature_store) {
  if (i < num_pose_updates) {
    pose_store[pose_updates[i].slot] = pose_updates[i].pose;
  } else if (i - num_pose_updates < num_feature_updates) {
    const FeatureUpdate& f = feature_updates[i - num_pose_updates];
    feature_store[f.slot] = f.entry;
  }
}

// Observation o as the scoring loop reads it: the keyframe pose and the feature.
struct DirectObservations {  // the call's own arrays (PointAdjustProblem as given, obs_begin rebased)
  const ScaledPose* poses;
  const int* obs_pose;
  const float* obs_u;
  const float* obs_v;
  MCSLAM_HOST_DEVICE MCSLAM_INLINE const ScaledPose& Pose(int o) const { return poses[obs_pose[o]]; }
  MCSLAM_HOST_DEVICE MCSLAM_INLINE float U(int o) const { return obs_u[o]; }
  MCSLAM_HOST_DEVICE MCSLAM_INLINE float V(int o) const { return obs_v[o]; }
};
struct ResidentObservations {  // through the stores: observation o is feature obs_feature[o]
  const ScaledPose* pose_store;
  const FeatureEntry* feature_store;
  const int* obs_feature;
  MCSLAM_HOST_DEVICE MCSLAM_INLINE const ScaledPose& Pose(int o) const {
    return pose_store[feature_store[obs_feature[o]].pose_slot];
  }
  MCSLAM_HOST_DEVICE MCSLAM_INLINE float U(int o) const { return feature_store[obs_feature[o]].u; }
  MCSLAM_HOST_DEVICE MCSLAM_INLINE float V(int o) const { return feature_store[obs_feature[o]].v; }
};

struct FeatureKey {
  int64_t pose_id;
  int64_t point_id;
  bool operator==(const FeatureKey& o) const { return pose_id == o.pose_id && point_id == o.point_id; }
};
struct FeatureKeyHash {
  size_t operator()(const FeatureKey& k) const {
    return std::hash<int64_t>()(k.pose_id) * 0x9E3779B97F4A7C15ull ^ std::hash<int64_t>()(k.point_id);
  }
};

// Byte offsets of a resident call's sections in its one staged buffer (each aligned to 256 bytes).
struct ResidentPointLayout {
  int num_points = 0, num_obs = 0, num_pose_updates = 0, num_feature_updates = 0;
  size_t centres = 0;          // 6 columns of num_points floats: cx, cy, cz, sx, sy, sz
  size_t obs_begin = 0;        // num_points + 1 ints, rebased to 0
  size_t obs_feature = 0;      // num_obs ints: the feature store slot of each observation
  size_t pose_updates = 0;     // num_pose_updates PoseUpdate
  size_t feature_updates = 0;  // num_feature_updates FeatureUpdate
  size_t bytes = 0;
};

class PointResidency {
 public:
  explicit PointResidency(int min_capacity = 1024, int keep_calls = 64)
      : poses_(min_capacity / 16 > 0 ? min_capacity / 16 : 1, keep_calls), features_(min_capacity, keep_calls) {}

  // True when the problem carries the ids that let its data stay on the device; both or neither (else
  // std::invalid_argument).
  static bool Wanted(const PointAdjustProblem& pr) {
    if ((pr.pose_ids == nullptr) != (pr.point_ids == nullptr))
      FailPointProblem(std::string(pr.pose_ids ? "pose_ids is given without point_ids" : "point_ids is given without pose_ids"));
    return pr.pose_ids != nullptr;
  }

  // Decides what this call sends. `checked` is PlanPointStaging's layout of the same problem (the checks that
  // keep every index in bounds have passed). Throws std::invalid_argument, with the stores' record left
  // invalid (so the next call sends all it needs), when a keyframe id or a (keyframe, point) pair appears
  // twice. Call Write next, then copy, apply the updates and score; on any failure of those, Invalidate().
  const ResidentPointLayout& Plan(const PointAdjustProblem& pr, const PointStagingLayout& checked) {
    l_ = ResidentPointLayout{};
    pose_updates_.clear();
    feature_updates_.clear();
    obs_feature_.clear();
    if (checked.num_points == 0) return l_;
    try {
      PlanStores(pr, checked);
    } catch (...) {
      Invalidate();
      throw;
    }
    l_.num_points = checked.num_points;
    l_.num_obs = checked.num_obs;
    l_.num_pose_updates = static_cast<int>(pose_updates_.size());
    l_.num_feature_updates = static_cast<int>(feature_updates_.size());
    const size_t np = static_cast<size_t>(l_.num_points), no = static_cast<size_t>(l_.num_obs);
    size_t at = 0;
    l_.centres = at;
    at = AlignStaging(at + sizeof(float) * 6 * np);
    l_.obs_begin = at;
    at = AlignStaging(at + sizeof(int) * (np + 1));
    l_.obs_feature = at;
    at = AlignStaging(at + sizeof(int) * no);
    l_.pose_updates = at;
    at = AlignStaging(at + sizeof(PoseUpdate) * pose_updates_.size());
    l_.feature_updates = at;
    at = AlignStaging(at + sizeof(FeatureUpdate) * feature_updates_.size());
    l_.bytes = at;
    return l_;
  }

  // Writes the planned call into dst (layout().bytes bytes).
  void Write(const PointAdjustProblem& pr, const PointStagingLayout& checked, unsigned char* dst) const {
    if (l_.num_points == 0) return;
    const size_t np = static_cast<size_t>(l_.num_points);
    const float* columns[6] = {pr.cx, pr.cy, pr.cz, pr.sx, pr.sy, pr.sz};
    for (int c = 0; c < 6; ++c) std::memcpy(dst + l_.centres + sizeof(float) * np * c, columns[c], sizeof(float) * np);
    int* begin = reinterpret_cast<int*>(dst + l_.obs_begin);
    for (size_t p = 0; p <= np; ++p) begin[p] = pr.obs_begin[p] - checked.first_obs;
    if (!obs_feature_.empty()) std::memcpy(dst + l_.obs_feature, obs_feature_.data(), sizeof(int) * obs_feature_.size());
    if (!pose_updates_.empty())
      std::memcpy(dst + l_.pose_updates, pose_updates_.data(), sizeof(PoseUpdate) * pose_updates_.size());
    if (!feature_updates_.empty())
      std::memcpy(dst + l_.feature_updates, feature_updates_.data(), sizeof(FeatureUpdate) * feature_updates_.size());
  }

  const ResidentPointLayout& layout() const { return l_; }
  // Slots the device stores must have for this call (they only grow; growing changes generation()).
  size_t pose_capacity() const { return poses_.capacity(); }
  size_t feature_capacity() const { return features_.capacity(); }
  // Change whenever a store's device copy is lost: a device array reallocated to the capacities above holds
  // nothing valid, and the record knows it.
  uint64_t pose_generation() const { return poses_.generation(); }
  uint64_t feature_generation() const { return features_.generation(); }
  size_t live_features() const { return features_.live(); }
  // The device copy of this call's updates did not arrive: the next call sends everything it needs.
  void Invalidate() {
    poses_.Invalidate();
    features_.Invalidate();
  }

 private:
  void PlanStores(const PointAdjustProblem& pr, const PointStagingLayout& checked) {
    // Only the keyframes some observation refers to are asked for: a window pose nobody sees costs nothing.
    std::vector<int> pose_slot(static_cast<size_t>(checked.num_poses), -1);
    const int o0 = checked.first_obs, o1 = checked.first_obs + checked.num_obs;
    for (int o = o0; o < o1; ++o) pose_slot[static_cast<size_t>(pr.obs_pose[o])] = -2;  // wanted
    poses_.BeginCall();
    for (int k = 0; k < checked.num_poses; ++k)
      if (pose_slot[static_cast<size_t>(k)] == -2) poses_.Touch(pr.pose_ids[k]);
    poses_.MakeRoom();
    for (int k = 0; k < checked.num_poses; ++k) {
      if (pose_slot[static_cast<size_t>(k)] != -2) continue;
      bool send = false;
      const int slot = Acquire(poses_, pr.pose_ids[k], pr.poses[k], &send,
                               [&] { return "keyframe id " + std::to_string(pr.pose_ids[k]); });
      pose_slot[static_cast<size_t>(k)] = slot;
      if (send) pose_updates_.push_back(PoseUpdate{slot, pr.poses[k]});
    }
    features_.BeginCall();
    for (int p = 0; p < checked.num_points; ++p)
      for (int o = pr.obs_begin[p]; o < pr.obs_begin[p + 1]; ++o)
        features_.Touch(FeatureKey{pr.pose_ids[pr.obs_pose[o]], pr.point_ids[p]});
    features_.MakeRoom();
    obs_feature_.reserve(static_cast<size_t>(checked.num_obs));
    for (int p = 0; p < checked.num_points; ++p) {
      for (int o = pr.obs_begin[p]; o < pr.obs_begin[p + 1]; ++o) {
        const int k = pr.obs_pose[o];
        const FeatureEntry e{pose_slot[static_cast<size_t>(k)], pr.obs_u[o], pr.obs_v[o]};
        bool send = false;
        const int slot = Acquire(features_, FeatureKey{pr.pose_ids[k], pr.point_ids[p]}, e, &send, [&] {
          return "(keyframe id, point id) (" + std::to_string(pr.pose_ids[k]) + ", " + std::to_string(pr.point_ids[p]) + ")";
        });
        obs_feature_.push_back(slot);
        if (send) feature_updates_.push_back(FeatureUpdate{slot, e});
      }
    }
  }

  // The mirror's Acquire, its "asked for twice" error said with the ids (`what` makes the words).
  template <typename Mirror, typename K, typename V, typename What>
  static int Acquire(Mirror& m, const K& key, const V& value, bool* send, const What& what) {
    try {
      return m.Acquire(key, value, send);
    } catch (const std::invalid_argument&) {
      FailPointProblem(what() + " appears twice in one call");
    }
  }

  SlotMirror<int64_t, ScaledPose> poses_;
  SlotMirror<FeatureKey, FeatureEntry, FeatureKeyHash> features_;
  ResidentPointLayout l_;
  std::vector<int> obs_feature_;
  std::vector<PoseUpdate> pose_updates_;
  std::vector<FeatureUpdate> feature_updates_;
};

}  // namespace mcslam::compute::cuda
