#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "compute/kernel_tolerance.h"
#include "compute/point_kernel.h"
#include "compute/pose_fixture.h"

namespace mcslam::compute {
namespace {

TEST(PointKernelCpu, FindsTheTruePointAndMatchesTheScalarReference) {
  const ArcCameras sc;  // five cameras on an arc, points near the origin
  const float truth[2][3] = {{0.1f, -0.05f, 0.2f}, {-0.2f, 0.1f, -0.1f}};
  // Start 3 cm off along each axis; spread 3 cm.
  std::vector<float> cx, cy, cz, sx(2, 0.03f), sy(2, 0.03f), sz(2, 0.03f), ou, ov;
  std::vector<int> begin{0}, pose_idx;
  for (const auto& t : truth) {
    cx.push_back(t[0] + 0.03f), cy.push_back(t[1] - 0.03f), cz.push_back(t[2] + 0.03f);
    for (int k = 0; k < 5; ++k) {
      float u, v;
      sc.Observe(k, t, &u, &v);
      pose_idx.push_back(k), ou.push_back(u), ov.push_back(v);
    }
    begin.push_back(static_cast<int>(pose_idx.size()));
  }
  PointAdjustProblem pr;
  pr.poses = sc.poses.data();
  pr.num_poses = 5;
  pr.cx = cx.data(), pr.cy = cy.data(), pr.cz = cz.data(), pr.sx = sx.data(), pr.sy = sy.data(), pr.sz = sz.data();
  pr.obs_begin = begin.data();
  pr.num_points = 2;
  pr.obs_pose = pose_idx.data(), pr.obs_u = ou.data(), pr.obs_v = ov.data();
  pr.params = sc.params;
  const NormalTable table(4096, 3);
  std::vector<PointBest> best(2);
  MakeCpuPointKernel()->Score(pr, table, 4000, best.data());
  for (int p = 0; p < 2; ++p) {
    ASSERT_GT(best[p].index, 0);
    // The cameras look along z from a 7-degree arc: x and y are seen sharply (1 cm is 1.7 px), depth barely
    // (3 cm of depth moves the projections ~0.3 px). 4000 samples at sigma 3 cm resolve x and y to a few mm.
    const double lateral = std::hypot(best[p].position[0] - truth[p][0], best[p].position[1] - truth[p][1]);
    EXPECT_LT(lateral, 0.01) << "point " << p;
    // The reported score is the scalar reference's score of the reported sample.
    double ref = 0;
    for (int o = begin[p]; o < begin[p + 1]; ++o)
      ref += ReprojectionDistance(sc.poses[pose_idx[o]], best[p].position[0], best[p].position[1], best[p].position[2],
                                  ou[o], ov[o], sc.params);
    EXPECT_NEAR(best[p].score, ref, kKernelRel * ref + 1e-3);
    // ... and it beats the centre (sample 0).
    double centre = 0;
    for (int o = begin[p]; o < begin[p + 1]; ++o)
      centre += ReprojectionDistance(sc.poses[pose_idx[o]], cx[p], cy[p], cz[p], ou[o], ov[o], sc.params);
    EXPECT_LT(best[p].score, 0.2 * centre);  // the centre is ~5 px off in every view
  }
}

TEST(PointKernelCpu, CentreWinsWhenItIsExact) {
  const ArcCameras sc;  // five cameras on an arc, points near the origin
  const float X[3] = {0.05f, 0.02f, -0.1f};
  std::vector<float> cx{X[0]}, cy{X[1]}, cz{X[2]}, s{0.02f}, ou, ov;
  std::vector<int> begin{0, 5}, pose_idx;
  for (int k = 0; k < 5; ++k) {
    float u, v;
    sc.Observe(k, X, &u, &v);
    pose_idx.push_back(k), ou.push_back(u), ov.push_back(v);
  }
  PointAdjustProblem pr;
  pr.poses = sc.poses.data();
  pr.num_poses = 5;
  pr.cx = cx.data(), pr.cy = cy.data(), pr.cz = cz.data(), pr.sx = s.data(), pr.sy = s.data(), pr.sz = s.data();
  pr.obs_begin = begin.data();
  pr.num_points = 1;
  pr.obs_pose = pose_idx.data(), pr.obs_u = ou.data(), pr.obs_v = ov.data();
  pr.params = sc.params;
  const NormalTable table(1024, 3);
  PointBest best;
  MakeCpuPointKernel(1)->Score(pr, table, 1024, &best);
  EXPECT_EQ(best.index, 0);
  EXPECT_LT(best.score, 1e-2f);  // five float round-offs
}

}  // namespace
}  // namespace mcslam::compute
