// The front end's remapping (paper §6.4): a lost feature found again by its descriptor near where the map
// projects it, and what remapping refuses.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <opencv2/imgproc.hpp>

#include "frontend/frontend.h"
#include "frontend_test_util.h"
#include "synthetic_images.h"

namespace mcslam::frontend {
namespace {

using mcslam::testing::MovingTexture;
using namespace test;  // kSize, ById, Find, Lost

// ---- remapping --------------------------------------------------------------------------------------------

// Tracks for two frames, loses feature `A` under an occluder in frame 2, and returns the frame-3 image with
// A's true position there.
struct RemapScene {
  MovingTexture tex{kSize, 11};
  Eigen::Vector2d step{1.0, 0.5};
  int64_t a_id = -1;
  int64_t b_id = -1;  // another feature, far from A
  Descriptor a_desc{}, b_desc{};
  Eigen::Vector2d a_at_frame3;
  int occluder_half_px = 20;  // the occluder in frame 2 is a square of 2 * this + 1 px around A

  void Run(Frontend& fe) {
    const FrameResult r0 = fe.Process(tex.Frame(0, 0), 0, 0.0);
    const FrameResult r1 = fe.Process(tex.Frame(step.x(), step.y()), 1, 0.1);
    for (const auto& f : r1.features) {
      const double du = f.uv_px.x() - 160, dv = f.uv_px.y() - 120;
      if (f.age_frames > 0 && std::abs(du) < 40 && std::abs(dv) < 40 && a_id < 0) a_id = f.feature_id;
      if (f.age_frames > 0 && f.uv_px.x() > 250 && b_id < 0) b_id = f.feature_id;
    }
    ASSERT_GE(a_id, 0);
    ASSERT_GE(b_id, 0);
    a_desc = *fe.GetDescriptor(a_id);
    b_desc = *fe.GetDescriptor(b_id);
    const Eigen::Vector2d a1 = ById(r1).at(a_id);
    cv::Mat f2 = tex.Frame(2 * step.x(), 2 * step.y());
    const cv::Point c(static_cast<int>(a1.x() + step.x()), static_cast<int>(a1.y() + step.y()));
    const int h = occluder_half_px;
    f2(cv::Rect(c.x - h, c.y - h, 2 * h + 1, 2 * h + 1)).setTo(128);
    const FrameResult r2 = fe.Process(f2, 2, 0.2);
    ASSERT_TRUE(Lost(r2, a_id));
    for (const auto& l : r2.lost)
      if (l.feature_id == a_id) {
        ASSERT_TRUE(l.descriptor.has_value());
        EXPECT_EQ(*l.descriptor, a_desc);
      }
    a_at_frame3 = a1 + 2 * step;
  }
  cv::Mat Frame3() const { return tex.Frame(3 * step.x(), 3 * step.y()); }
};

TEST(Frontend, RemapReattachesALostFeatureByDescriptorNearItsProjection) {
  RemapScene scene;
  Frontend fe;
  ASSERT_NO_FATAL_FAILURE(scene.Run(fe));
  // The back end's projection is a few pixels off, as it would be.
  const RemapRequest req{scene.a_id, scene.a_desc, scene.a_at_frame3 + Eigen::Vector2d(4, -3)};
  const FrameResult r3 = fe.Process(scene.Frame3(), 3, 0.3, std::span<const RemapRequest>(&req, 1));
  ASSERT_EQ(r3.remapped_ids, std::vector<int64_t>{scene.a_id})
      << "no_candidate " << r3.stats.remap_no_candidate << " no_match " << r3.stats.remap_no_match;
  const TrackedFeature* f = Find(r3, scene.a_id);
  ASSERT_NE(f, nullptr);
  EXPECT_TRUE(f->remapped);
  EXPECT_EQ(f->age_frames, 0);
  // Corners are found on whole pixels while the texture moved by fractions: within a pixel and a half.
  EXPECT_LT((f->uv_px - scene.a_at_frame3).norm(), 1.5);
  // Ids are still unique and the re-attached track goes on being tracked.
  std::set<int64_t> ids;
  for (const auto& g : r3.features) EXPECT_TRUE(ids.insert(g.feature_id).second);
  const FrameResult r4 = fe.Process(scene.tex.Frame(4 * scene.step.x(), 4 * scene.step.y()), 4, 0.4);
  const TrackedFeature* g = Find(r4, scene.a_id);
  ASSERT_NE(g, nullptr);
  EXPECT_FALSE(g->remapped);
  EXPECT_LT((g->uv_px - f->uv_px - scene.step).norm(), 0.3);
  EXPECT_EQ(*fe.GetDescriptor(scene.a_id), scene.a_desc);
}

TEST(Frontend, RemapRefusesAWrongDescriptor) {
  RemapScene scene;
  Frontend fe;
  ASSERT_NO_FATAL_FAILURE(scene.Run(fe));
  // A's id and projection, but the look of another feature: no corner in the window matches it.
  const RemapRequest req{scene.a_id, scene.b_desc, scene.a_at_frame3};
  const FrameResult r3 = fe.Process(scene.Frame3(), 3, 0.3, std::span<const RemapRequest>(&req, 1));
  EXPECT_TRUE(r3.remapped_ids.empty());
  EXPECT_EQ(Find(r3, scene.a_id), nullptr);
  EXPECT_EQ(r3.stats.remap_no_match, 1);
}

// A new track born at a corner that a remapping window had described takes that descriptor instead of being
// described again: the same descriptors as a front end that was asked for no remapping, and fewer descriptions.
TEST(Frontend, ANewTrackKeepsTheDescriptorItsRemappingWindowGaveIt) {
  for (const bool async : {false, true}) {
    FrontendOptions o;
    o.describe_async = async;
    RemapScene with_scene, without_scene;
    // An occluder wide enough to empty A's detection cell: frame 3 starts new tracks there, in A's window.
    with_scene.occluder_half_px = without_scene.occluder_half_px = 40;
    Frontend with(o), without(o);
    ASSERT_NO_FATAL_FAILURE(with_scene.Run(with));
    ASSERT_NO_FATAL_FAILURE(without_scene.Run(without));
    // Another feature's look: the window's corners are described and none matches, so they all become new tracks.
    const RemapRequest req{with_scene.a_id, with_scene.b_desc, with_scene.a_at_frame3};
    const FrameResult r = with.Process(with_scene.Frame3(), 3, 0.3, std::span<const RemapRequest>(&req, 1));
    const FrameResult q = without.Process(without_scene.Frame3(), 3, 0.3);
    EXPECT_TRUE(r.remapped_ids.empty());
    EXPECT_GT(r.stats.described_for_remap, 0) << "async " << async << ", new tracks " << r.stats.detected;
    EXPECT_EQ(q.stats.described_for_remap, 0);
    ASSERT_EQ(r.features.size(), q.features.size());
    for (size_t i = 0; i < r.features.size(); ++i) {
      ASSERT_EQ(r.features[i].feature_id, q.features[i].feature_id);
      EXPECT_EQ(r.features[i].uv_px, q.features[i].uv_px);
      const auto dr = with.GetDescriptor(r.features[i].feature_id), dq = without.GetDescriptor(q.features[i].feature_id);
      ASSERT_TRUE(dr && dq) << "id " << r.features[i].feature_id << " async " << async;
      EXPECT_EQ(*dr, *dq) << "id " << r.features[i].feature_id << " async " << async;
    }
  }
}

// A point whose last look no longer matches (here: another feature's) is still re-attached by the look it had
// when its track began, when the caller gives that too (RemapRequest::first_look); with neither matching, none.
TEST(Frontend, RemapMatchesTheFirstLookWhereTheLastOneFails) {
  for (const bool right_first_look : {true, false}) {
    RemapScene scene;
    Frontend fe;
    ASSERT_NO_FATAL_FAILURE(scene.Run(fe));
    RemapRequest req{scene.a_id, scene.b_desc, scene.a_at_frame3};
    req.first_look = right_first_look ? scene.a_desc : scene.b_desc;
    const FrameResult r3 = fe.Process(scene.Frame3(), 3, 0.3, std::span<const RemapRequest>(&req, 1));
    if (right_first_look) {
      ASSERT_EQ(r3.remapped_ids, std::vector<int64_t>{scene.a_id});
      EXPECT_LT((Find(r3, scene.a_id)->uv_px - scene.a_at_frame3).norm(), 1.5);  // as in the test above
    } else {
      EXPECT_TRUE(r3.remapped_ids.empty());
      EXPECT_EQ(r3.stats.remap_no_match, 1);
    }
  }
}

TEST(Frontend, RemapRefusesOutsideTheWindowTheImageOrForALiveId) {
  RemapScene scene;
  Frontend fe;
  ASSERT_NO_FATAL_FAILURE(scene.Run(fe));
  // Live id: B is tracked.
  const std::vector<RemapRequest> reqs{
      {scene.a_id, scene.a_desc, scene.a_at_frame3 + Eigen::Vector2d(45, 0)},  // A's corner is 45 px away: outside
      {scene.a_id + 100000, scene.a_desc, scene.a_at_frame3},                  // never issued
      {scene.b_id, scene.b_desc, scene.a_at_frame3},                           // live
  };
  const FrameResult r3 = fe.Process(scene.Frame3(), 3, 0.3, reqs);
  EXPECT_TRUE(r3.remapped_ids.empty());
  EXPECT_EQ(Find(r3, scene.a_id), nullptr);
  EXPECT_EQ(r3.stats.remap_requests, 3);
  EXPECT_EQ(r3.stats.remap_refused_id, 2);
  EXPECT_EQ(r3.stats.remap_no_match + r3.stats.remap_no_candidate, 1);

  // A projection outside the image is not searched.
  Frontend fe2;
  RemapScene scene2;
  ASSERT_NO_FATAL_FAILURE(scene2.Run(fe2));
  const RemapRequest out{scene2.a_id, scene2.a_desc, Eigen::Vector2d(-5, 50)};
  const FrameResult r = fe2.Process(scene2.Frame3(), 3, 0.3, std::span<const RemapRequest>(&out, 1));
  EXPECT_EQ(r.stats.remap_outside, 1);
  EXPECT_TRUE(r.remapped_ids.empty());
}

// A backed-off request (RemapRequest::only_near_new_corner) costs nothing while nothing new appears where it
// should be, and is tried as any request when a corner that would start a new track appears in its window.
TEST(Frontend, ABackedOffRequestIsTriedOnlyWhereANewCornerAppears) {
  {  // the occluder stays: the window holds no new corner
    RemapScene scene;
    Frontend fe;
    ASSERT_NO_FATAL_FAILURE(scene.Run(fe));
    cv::Mat f3 = scene.Frame3();
    const cv::Point c(static_cast<int>(scene.a_at_frame3.x()), static_cast<int>(scene.a_at_frame3.y()));
    f3(cv::Rect(c.x - 20, c.y - 20, 41, 41)).setTo(128);
    RemapRequest req{scene.a_id, scene.a_desc, scene.a_at_frame3, true};
    const FrameResult deferred = fe.Process(f3, 3, 0.3, std::span<const RemapRequest>(&req, 1));
    EXPECT_EQ(deferred.stats.remap_requests, 1);
    EXPECT_EQ(deferred.stats.remap_deferred, 1);
    EXPECT_EQ(deferred.stats.remap_no_candidate + deferred.stats.remap_no_match, 0);
    EXPECT_TRUE(deferred.remapped_ids.empty());
    // The same request not backed off is tried (and fails: nothing to find under the occluder).
    req.only_near_new_corner = false;
    const FrameResult tried = fe.Process(f3, 4, 0.4, std::span<const RemapRequest>(&req, 1));
    EXPECT_EQ(tried.stats.remap_deferred, 0);
    EXPECT_EQ(tried.stats.remap_no_candidate + tried.stats.remap_no_match, 1);
  }
  {  // the occluder (larger: every track of A's cell went) went: A's corner is new in an empty cell, and A
     // takes it instead of a new track
    RemapScene scene;
    scene.occluder_half_px = 60;
    Frontend fe;
    ASSERT_NO_FATAL_FAILURE(scene.Run(fe));
    const RemapRequest req{scene.a_id, scene.a_desc, scene.a_at_frame3 + Eigen::Vector2d(4, -3), true};
    const FrameResult r3 = fe.Process(scene.Frame3(), 3, 0.3, std::span<const RemapRequest>(&req, 1));
    EXPECT_EQ(r3.stats.remap_deferred, 0);
    ASSERT_EQ(r3.remapped_ids, std::vector<int64_t>{scene.a_id});
    const TrackedFeature* f = Find(r3, scene.a_id);
    ASSERT_NE(f, nullptr);
    EXPECT_LT((f->uv_px - scene.a_at_frame3).norm(), 1.5);  // as for a request not backed off
  }
}

}  // namespace
}  // namespace mcslam::frontend
