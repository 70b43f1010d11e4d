// The hot path allocates nothing once warm: operator new is replaced in this test binary by a counting one.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

#include "core/random.h"
#include "sim/paper_scenario.h"
#include "slam/pose_tracker.h"

namespace {
std::atomic<long> g_news{0};
}

void* operator new(std::size_t n) {
  g_news.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace mcslam::slam {
namespace {

TEST(PoseTrackerHotPath, TrackAllocatesNothingOnceWarm) {
  const PinholeCamera cam = sim::PaperCamera();
  std::vector<PointObservation> obs;
  CounterRng rng(4, 0);
  for (int i = 0; i < 200; ++i) {
    // z first: the order in which GCC evaluated p(Uniform(), Uniform(), 3 + Uniform()) (unspecified in C++).
    const double z = 3 + rng.Uniform(-0.3, 0.3), y = rng.Uniform(-0.4, 0.4), x = rng.Uniform(-0.5, 0.5);
    const Eigen::Vector3d p(x, y, z);
    Eigen::Vector2d uv;
    cam.ProjectWorld(Pose(), p, &uv);
    obs.push_back({p, uv, true});
  }
  PoseTrackerOptions o;
  o.hypotheses = 1 << 14;
  PoseTracker tracker(cam, o, compute::MakeCpuPoseKernel());
  std::vector<double> res;
  std::vector<uint8_t> inl;
  const long cold = g_news.load();
  ASSERT_TRUE(tracker.Track(Pose(), obs, 1, &res, &inl).tracked);  // warm-up: buffers grow here
  const long before = g_news.load();
  ASSERT_GT(before, cold) << "the counting operator new is not in effect";
  for (int f = 2; f < 6; ++f) ASSERT_TRUE(tracker.Track(Pose(), obs, f, &res, &inl).tracked);
  EXPECT_EQ(g_news.load() - before, 0) << "operator new called in the per-frame path";
}

}  // namespace
}  // namespace mcslam::slam
