#pragma once
// The point kernel's data kept on the device across calls (DESIGN.md, "GPU mapping": pose history and feature
// positions live on the device). A point adjustment runs at every keyframe over a window of keyframes chosen
// back from it; from one call to the next the window gains one keyframe and keeps most of the others. So the
// device keeps whole keyframes, by keyframe id (PointAdjustProblem::pose_ids): a slot holds the keyframe's
// ScaledPose and a block of all its features (u, v). A call sends its candidates' centres and spreads, one int
// per observation (its keyframe's slot and its feature's index in the block, packed), and only the keyframes the
// device does not hold as given: a new keyframe, one whose pose a settling adjustment moved, one whose slot was
// reused, and all of them after the stores were reallocated or a call failed. The host's record is a
// SlotMirror of the poses (slot_mirror.h) plus a copy of each slot's block, compared as a whole: no work per
// observation beyond packing its index, and no hashing per observation.
//
// The scoring kernel reads an observation through ResidentObservations, the update kernel is
// ApplyKeyframeUpdate: both MCSLAM_HOST_DEVICE, so the host tests run the very code the device runs.
// PointResidency (the host side) is plain C++17.
#include <climits>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "compute/cuda/point_staging.h"
#include "compute/cuda/slot_mirror.h"
#include "compute/point_kernel.h"
#include "core/host_device.h"

namespace mcslam::compute::cuda {

struct FeatureUV {
  float u, v;  // undistorted pixels minus the principal point
};

// A keyframe to put into slot `slot`: its pose, and its `count` features, which are update_features[first ..
// first + count) of the call's staged buffer.
struct KeyframeUpdate {
  int slot;
  int count;
  int first;
  ScaledPose pose;
};

// Part `i` of keyframe update `u`: i == 0 also writes the pose; every i < count writes feature i into the
// slot's block (block b holds features b << block_shift .. (b + 1) << block_shift - 1). The device runs one
// block of threads per update, i over the threads; every slot is written by one update at most a call.
MCSLAM_HOST_DEVICE MCSLAM_INLINE void ApplyKeyframeUpdate(const KeyframeUpdate& u, int i,
                                                          const FeatureUV* update_features, int block_shift,
                                                          ScaledPose* pose_store, FeatureUV* feature_store) {
  if (i == 0) pose_store[u.slot] = u.pose;
  if (i < u.count) feature_store[(static_cast<size_t>(u.slot) << block_shift) + static_cast<size_t>(i)] =
      update_features[u.first + i];
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
struct ResidentObservations {  // through the stores: observation o is feature obs_index[o] of the store
  const ScaledPose* pose_store;
  const FeatureUV* feature_store;
  const int* obs_index;  // (keyframe slot << block_shift) + the feature's index in the keyframe's block
  int block_shift;
  MCSLAM_HOST_DEVICE MCSLAM_INLINE const ScaledPose& Pose(int o) const { return pose_store[obs_index[o] >> block_shift]; }
  MCSLAM_HOST_DEVICE MCSLAM_INLINE float U(int o) const { return feature_store[obs_index[o]].u; }
  MCSLAM_HOST_DEVICE MCSLAM_INLINE float V(int o) const { return feature_store[obs_index[o]].v; }
};

// Byte offsets of a resident call's sections in its one staged buffer (each aligned to 256 bytes).
struct ResidentPointLayout {
  int num_points = 0, num_obs = 0, num_keyframe_updates = 0, num_update_features = 0;
  int block_shift = 0;
  size_t centres = 0;           // 6 columns of num_points floats: cx, cy, cz, sx, sy, sz
  size_t obs_begin = 0;         // num_points + 1 ints, rebased to 0
  size_t obs_index = 0;         // num_obs ints (ResidentObservations::obs_index)
  size_t keyframe_updates = 0;  // num_keyframe_updates KeyframeUpdate
  size_t update_features = 0;   // num_update_features FeatureUV
  size_t bytes = 0;
};

class PointResidency {
 public:
  // min_keyframes: pose slots of the first device array; keep_calls: how many calls an unused keyframe keeps
  // its slot (a Fibonacci window reaches back further than it asks for each keyframe, so keep generously).
  explicit PointResidency(int min_keyframes = 32, int keep_calls = 64) : poses_(min_keyframes, keep_calls) {}

  // True when the problem carries what lets its keyframes stay on the device (pose_ids, keyframe_begin,
  // keyframe_u, keyframe_v, obs_feature). Given one, the others are needed too (std::invalid_argument naming the
  // missing ones), except where there is nothing to point at: keyframe_u and keyframe_v for keyframes without
  // features, obs_feature without observations, pose_ids without poses. `checked`: PlanPointStaging's layout.
  static bool Wanted(const PointAdjustProblem& pr, const PointStagingLayout& checked) {
    if (!pr.pose_ids && !pr.keyframe_begin && !pr.keyframe_u && !pr.keyframe_v && !pr.obs_feature) return false;
    std::string missing;
    const auto need = [&missing](bool ok, const char* name) {
      if (!ok) missing += (missing.empty() ? "" : ", ") + std::string(name);
    };
    need(pr.pose_ids || checked.num_poses == 0, "pose_ids");
    need(pr.keyframe_begin != nullptr, "keyframe_begin");
    const bool features = pr.keyframe_begin && pr.keyframe_begin[checked.num_poses] > pr.keyframe_begin[0];
    need(pr.keyframe_u || !features, "keyframe_u");
    need(pr.keyframe_v || !features, "keyframe_v");
    need(pr.obs_feature || checked.num_obs == 0, "obs_feature");
    if (!missing.empty()) FailPointProblem("the keyframes are given without " + missing);
    return true;
  }

  // Checks the keyframes against the observations and decides what this call sends. `checked` is
  // PlanPointStaging's layout of the same problem (its checks have passed). Throws std::invalid_argument
  // (naming what is wrong) when a keyframe id appears twice, keyframe_begin decreases, an observation's feature
  // index is outside its keyframe's features, or that feature is not the observation's (u, v) bit for bit: the
  // device reads the keyframe's feature, the CPU the observation's, and they must be the same numbers. Then the
  // record is left invalid (the next call sends all it needs). Call Write next, then copy, apply the updates and
  // score; on any failure of those, Invalidate().
  const ResidentPointLayout& Plan(const PointAdjustProblem& pr, const PointStagingLayout& checked) {
    l_ = ResidentPointLayout{};
    updates_.clear();
    update_features_.clear();
    obs_index_.clear();
    if (checked.num_points == 0) return l_;
    try {
      CheckKeyframes(pr, checked);
      PlanKeyframes(pr, checked);
    } catch (...) {
      Invalidate();
      throw;
    }
    l_.num_points = checked.num_points;
    l_.num_obs = checked.num_obs;
    l_.num_keyframe_updates = static_cast<int>(updates_.size());
    l_.num_update_features = static_cast<int>(update_features_.size());
    l_.block_shift = block_shift_;
    const size_t np = static_cast<size_t>(l_.num_points), no = static_cast<size_t>(l_.num_obs);
    size_t at = 0;
    l_.centres = at;
    at = AlignStaging(at + sizeof(float) * 6 * np);
    l_.obs_begin = at;
    at = AlignStaging(at + sizeof(int) * (np + 1));
    l_.obs_index = at;
    at = AlignStaging(at + sizeof(int) * no);
    l_.keyframe_updates = at;
    at = AlignStaging(at + sizeof(KeyframeUpdate) * updates_.size());
    l_.update_features = at;
    at = AlignStaging(at + sizeof(FeatureUV) * update_features_.size());
    l_.bytes = at;
    return l_;
  }

  // Writes the planned call into dst (layout().bytes bytes).
  void Write(const PointAdjustProblem& pr, const PointStagingLayout& checked, unsigned char* dst) const {
    if (l_.num_points == 0) return;
    StagePointColumns(pr, checked.first_obs, dst + l_.centres, dst + l_.obs_begin);
    if (!obs_index_.empty()) std::memcpy(dst + l_.obs_index, obs_index_.data(), sizeof(int) * obs_index_.size());
    if (!updates_.empty()) std::memcpy(dst + l_.keyframe_updates, updates_.data(), sizeof(KeyframeUpdate) * updates_.size());
    if (!update_features_.empty())
      std::memcpy(dst + l_.update_features, update_features_.data(), sizeof(FeatureUV) * update_features_.size());
  }

  const ResidentPointLayout& layout() const { return l_; }
  // Sizes the device stores must have for this call: pose_capacity() poses and pose_capacity() << block_shift
  // features. They only grow; growing changes generation() (a reallocated store holds nothing valid, and the
  // record knows it).
  size_t pose_capacity() const { return poses_.capacity(); }
  size_t feature_capacity() const { return poses_.capacity() << block_shift_; }
  uint64_t generation() const { return poses_.generation(); }
  // The device copy of this call's updates did not arrive: the next call sends every keyframe it needs.
  void Invalidate() { poses_.Invalidate(); }

 private:
  void CheckKeyframes(const PointAdjustProblem& pr, const PointStagingLayout& checked) const {
    if (pr.keyframe_begin[0] < 0) FailPointProblem("keyframe_begin[0] is negative");
    for (int k = 0; k < checked.num_poses; ++k)
      if (pr.keyframe_begin[k + 1] < pr.keyframe_begin[k])
        FailPointProblem("keyframe_begin decreases at keyframe " + std::to_string(k));
  }

  static uint32_t Bits(float x) {
    uint32_t b;
    std::memcpy(&b, &x, sizeof b);
    return b;
  }

  void PlanKeyframes(const PointAdjustProblem& pr, const PointStagingLayout& checked) {
    // Only the keyframes some observation refers to: a window keyframe nobody sees costs nothing.
    std::vector<int> slot_of(static_cast<size_t>(checked.num_poses), -1);
    for (int o = checked.first_obs; o < checked.first_obs + checked.num_obs; ++o)
      slot_of[static_cast<size_t>(pr.obs_pose[o])] = -2;  // wanted
    // The blocks hold the largest keyframe (a power of two); a larger one means new stores: all is sent again.
    int largest = 0;
    for (int k = 0; k < checked.num_poses; ++k)
      if (slot_of[static_cast<size_t>(k)] == -2) largest = std::max(largest, pr.keyframe_begin[k + 1] - pr.keyframe_begin[k]);
    int shift = block_shift_;
    while ((1 << shift) < largest) ++shift;
    if (shift != block_shift_) {
      block_shift_ = shift;
      poses_.Invalidate();
    }
    poses_.BeginCall();
    for (int k = 0; k < checked.num_poses; ++k)
      if (slot_of[static_cast<size_t>(k)] == -2) poses_.Touch(pr.pose_ids[k]);
    poses_.MakeRoom();
    if (poses_.capacity() > static_cast<size_t>(INT_MAX >> block_shift_))
      FailPointProblem("the keyframe store would exceed 2^31 features (" + std::to_string(poses_.capacity()) +
                       " keyframes of up to " + std::to_string(1 << block_shift_) + ")");
    if (blocks_.size() < poses_.capacity()) blocks_.resize(poses_.capacity());
    for (int k = 0; k < checked.num_poses; ++k) {
      if (slot_of[static_cast<size_t>(k)] != -2) continue;
      bool send = false;
      int slot = -1;
      try {
        slot = poses_.Acquire(pr.pose_ids[k], pr.poses[k], &send);
      } catch (const std::invalid_argument&) {
        FailPointProblem("keyframe id " + std::to_string(pr.pose_ids[k]) + " appears twice in one call");
      }
      slot_of[static_cast<size_t>(k)] = slot;
      // The block goes with the pose whenever the pose goes (a new key, a reused slot, a lost store), and
      // alone never: a changed block is sent with its pose.
      const int b = pr.keyframe_begin[k], count = pr.keyframe_begin[k + 1] - b;
      Block& held = blocks_[static_cast<size_t>(slot)];
      const size_t n = static_cast<size_t>(count);
      const bool block_same = held.u.size() == n &&
                              (n == 0 || (std::memcmp(held.u.data(), pr.keyframe_u + b, n * sizeof(float)) == 0 &&
                                          std::memcmp(held.v.data(), pr.keyframe_v + b, n * sizeof(float)) == 0));
      if (!send && block_same) continue;
      held.u.assign(pr.keyframe_u + b, pr.keyframe_u + b + count);
      held.v.assign(pr.keyframe_v + b, pr.keyframe_v + b + count);
      updates_.push_back(KeyframeUpdate{slot, count, static_cast<int>(update_features_.size()), pr.poses[k]});
      for (int i = 0; i < count; ++i) update_features_.push_back(FeatureUV{pr.keyframe_u[b + i], pr.keyframe_v[b + i]});
    }
    // Each observation's index, and the check that it is the feature it names (a failure here leaves the record
    // invalid, as any failure of Plan does).
    obs_index_.resize(static_cast<size_t>(checked.num_obs));
    for (int o = checked.first_obs, i = 0; i < checked.num_obs; ++o, ++i) {
      const int k = pr.obs_pose[o], f = pr.obs_feature[o];
      const int first = pr.keyframe_begin[k], count = pr.keyframe_begin[k + 1] - first;
      if (f < 0 || f >= count)
        FailPointProblem("observation " + std::to_string(o) + " names feature " + std::to_string(f) + " of keyframe " +
                         std::to_string(k) + ", which has " + std::to_string(count));
      if (Bits(pr.keyframe_u[first + f]) != Bits(pr.obs_u[o]) || Bits(pr.keyframe_v[first + f]) != Bits(pr.obs_v[o]))
        FailPointProblem("observation " + std::to_string(o) + " is not feature " + std::to_string(f) + " of keyframe " +
                         std::to_string(k) + " (its u, v differ)");
      obs_index_[static_cast<size_t>(i)] = (slot_of[static_cast<size_t>(k)] << block_shift_) + f;
    }
  }

  struct Block {  // the features the device holds in a slot (when the slot's pose is valid there)
    std::vector<float> u, v;
  };

  SlotMirror<int64_t, ScaledPose> poses_;
  std::vector<Block> blocks_;  // per slot
  int block_shift_ = 0;
  ResidentPointLayout l_;
  std::vector<int> obs_index_;
  std::vector<KeyframeUpdate> updates_;
  std::vector<FeatureUV> update_features_;
};

}  // namespace mcslam::compute::cuda
