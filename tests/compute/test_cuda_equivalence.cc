// The CUDA backend against the CPU backend (DESIGN.md: both call the same per-element math, so they agree
// to float tolerance), and the host side of the CUDA backend, which runs without a GPU: the reduction
// order, when the normal table is uploaded again, the checks and staging of the point problem, and the
// --backend selection. Tests that need a device skip with a visible message when there is none. The whole
// SLAM run on both: test_cuda_whole_run.cc.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iostream>
#include <limits>
#include <memory>
#include <random>
#include <utility>
#include <stdexcept>
#include <string>
#include <vector>

#include "apps/options.h"
#include "apps/slam_job.h"
#include "compute/backend.h"
#include "compute/cuda/candidate.h"
#include "compute/cuda/cuda_kernels.h"
#include "compute/cuda/point_staging.h"
#include "compute/cuda/pose_staging.h"
#include "compute/cuda/table_key.h"
#include "compute/kernel_tolerance.h"
#include "cuda_test_util.h"
#include "compute/point_kernel.h"
#include "compute/pose_fixture.h"
#include "compute/pose_kernel.h"
#include "eval/trajectory_eval.h"
#include "sim/paper_scenario.h"

namespace mcslam::compute {
namespace {

using cuda::Candidate;

// Tolerance of CPU vs CUDA scores. Each per-point distance of the CPU uses the hardware rsqrt estimate
// (|rel err| < 2^-14 = 6.1e-5 with AVX-512, 1.5 * 2^-12 = 3.7e-4 with AVX), the GPU's rsqrtf is within 2
// ulp, and every distance is positive, so the sum keeps that relative bound; float summation in the same
// order on both adds < 2e-5 relative for a few hundred points: kKernelRel. The hypotheses themselves differ by
// a few ulp (the CPU normalises the quaternion with rsqrt + a Newton step, the GPU with rsqrtf), which
// moves each projection by ~5e-5 px whatever its distance: kAbsPerTerm per point (or observation).
constexpr double kAbsPerTerm = 1e-4;

double Tolerance(double score, int terms) { return kKernelRel * std::abs(score) + kAbsPerTerm * std::max(terms, 1); }

std::unique_ptr<PoseKernel> CudaPose() {
#ifdef MCSLAM_WITH_CUDA
  return MakeCudaPoseKernel();
#else
  throw std::logic_error("no CUDA backend in this build");
#endif
}

std::unique_ptr<PointKernel> CudaPoint() {
#ifdef MCSLAM_WITH_CUDA
  return MakeCudaPointKernel();
#else
  throw std::logic_error("no CUDA backend in this build");
#endif
}

cuda::CudaKernelStats Stats(const PoseKernel& k) {
#ifdef MCSLAM_WITH_CUDA
  return cuda::StatsOf(k);
#else
  (void)k;
  return {};
#endif
}

cuda::CudaKernelStats Stats(const PointKernel& k) {
#ifdef MCSLAM_WITH_CUDA
  return cuda::StatsOf(k);
#else
  (void)k;
  return {};
#endif
}

// ---- Host side: no GPU needed ----------------------------------------------------------------------

TEST(CudaHost, CandidateOrderIsTotalWithTiesToTheLowestIndexAndNanLast) {
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  EXPECT_TRUE(cuda::Better({1.0f, 9}, {2.0f, 0}));
  EXPECT_TRUE(cuda::Better({1.0f, 3}, {1.0f, 4}));   // a tie goes to the lower index
  EXPECT_FALSE(cuda::Better({1.0f, 4}, {1.0f, 3}));
  EXPECT_FALSE(cuda::Better({1.0f, 3}, {1.0f, 3}));  // strict
  EXPECT_TRUE(cuda::Better({1e30f, 5}, {nan, 1}));   // a NaN ranks as +infinity: after every finite score ...
  EXPECT_TRUE(cuda::Better({nan, 1}, {inf, 5}));     // ... level with +infinity, where the lower index wins
  EXPECT_TRUE(cuda::Better({nan, 1}, {nan, 2}));
  EXPECT_TRUE(cuda::Better({nan, 7}, cuda::NoCandidate()));  // the identity loses to anything real
  EXPECT_TRUE(cuda::Better({inf, 7}, cuda::NoCandidate()));
  // What enters the reductions: an infinite or NaN score is no candidate (the CPU never picks one), so a
  // reduction over nothing but those returns the identity, which the host reads as "no winner" (-1).
  EXPECT_EQ(cuda::Scored(3.5f, 7).index, 7);
  EXPECT_EQ(cuda::Scored(3.5f, 7).score, 3.5f);
  EXPECT_EQ(cuda::Scored(-1e30f, 2).index, 2);
  EXPECT_TRUE(cuda::IsNoCandidate(cuda::Scored(inf, 7)));
  EXPECT_TRUE(cuda::IsNoCandidate(cuda::Scored(nan, 7)));
  EXPECT_TRUE(cuda::IsNoCandidate(cuda::BestOf(cuda::Scored(nan, 1), cuda::Scored(inf, 0))));
  EXPECT_EQ(cuda::BestOf(cuda::Scored(nan, 0), cuda::Scored(1e30f, 9)).index, 9);
  EXPECT_FALSE(cuda::IsNoCandidate(cuda::Scored(1e30f, 9)));
  const Candidate a{2.0f, 5}, b{2.0f, 3};
  EXPECT_EQ(cuda::BestOf(a, b).index, 3);
  EXPECT_EQ(cuda::BestOf(b, a).index, 3);

  // Any reduction order gives the lowest score at the lowest index: folds over shuffles, and pairwise trees
  // of several widths (the device's blocks and warps), all agree with a plain scan.
  std::vector<Candidate> v;
  std::mt19937 rng(7);
  for (int i = 0; i < 3000; ++i) v.push_back({static_cast<float>(rng() % 50), i});  // many ties
  v[1234].score = -1.0f;
  v[2345].score = -1.0f;
  v[17].score = nan;
  const auto fold = [](const std::vector<Candidate>& c) {
    Candidate best = cuda::NoCandidate();
    for (const Candidate& x : c) best = cuda::BestOf(best, x);
    return best;
  };
  for (int trial = 0; trial < 5; ++trial) {
    std::vector<Candidate> w = v;
    std::shuffle(w.begin(), w.end(), rng);
    const Candidate r = fold(w);
    EXPECT_EQ(r.index, 1234);
    EXPECT_EQ(r.score, -1.0f);
    for (int width : {2, 32, 256}) {
      std::vector<Candidate> level = w;
      while (level.size() > 1) {
        std::vector<Candidate> next;
        for (size_t i = 0; i < level.size(); i += width) {
          Candidate best = cuda::NoCandidate();
          for (size_t j = i; j < std::min(level.size(), i + width); ++j) best = cuda::BestOf(best, level[j]);
          next.push_back(best);
        }
        level.swap(next);
      }
      EXPECT_EQ(level[0].index, 1234) << "width " << width;
    }
  }
}

TEST(CudaHost, TableKeyChangesWhenTheTableChangesAndOnlyThen) {
  for (int rows : {100, cuda::kFingerprintFullRows, cuda::kFingerprintFullRows + 1, 1 << 18}) {
    NormalTable t(rows, 5);
    const cuda::NormalTableKey k0 = cuda::MakeNormalTableKey(t);
    EXPECT_EQ(k0, cuda::MakeNormalTableKey(t)) << rows;  // unchanged: no upload
    t.Fill(5, 0, 1);                                      // "fresh" random numbers: same object, new contents
    const cuda::NormalTableKey k1 = cuda::MakeNormalTableKey(t);
    EXPECT_NE(k0, k1) << rows;
    EXPECT_EQ(k0.object, k1.object);
    t.Fill(5, 0, 0);  // back to the first contents
    EXPECT_EQ(k0.fingerprint, cuda::MakeNormalTableKey(t).fingerprint) << rows;
    const NormalTable other(rows, 6);  // another table
    EXPECT_NE(k0, cuda::MakeNormalTableKey(other));
  }
  // Same seed, fewer rows: the first rows are equal, the key is not.
  const NormalTable small(1000, 5), large(2000, 5);
  EXPECT_NE(cuda::MakeNormalTableKey(small).fingerprint, cuda::MakeNormalTableKey(large).fingerprint);
  // A small table is hashed whole: one changed entry anywhere is seen.
  NormalTable t(4096, 5);
  const uint64_t before = cuda::MakeNormalTableKey(t).fingerprint;
  t.column(6)[2777] += 1.0f;
  EXPECT_NE(before, cuda::MakeNormalTableKey(t).fingerprint);
  EXPECT_EQ(cuda::MakeNormalTableKey(NormalTable()).count, 0);
}

// The pose kernel keeps the points of its last call on the device and sends a call's points only when they
// differ from those: the comparison must see any change, in any column, and nothing else.
TEST(CudaHost, PosePointsAreSentAgainWhenAnyValueChangesAndOnlyThen) {
  const PoseFixture fx(37);
  std::vector<float> staged(cuda::StagedPosePointFloats(37));
  cuda::StagePosePoints(fx.View(), staged.data());
  const int n = 37;
  for (int c = 0; c < 5; ++c) {  // column c of the staging holds the points' column c
    const float* column[5] = {fx.x.data(), fx.y.data(), fx.z.data(), fx.u.data(), fx.v.data()};
    EXPECT_EQ(0, std::memcmp(staged.data() + c * n, column[c], sizeof(float) * n)) << "column " << c;
  }
  EXPECT_TRUE(cuda::SameAsStaged(fx.View(), staged.data(), n));
  // The same values at other addresses are the same points.
  const PoseFixture copy = fx;
  EXPECT_TRUE(cuda::SameAsStaged(copy.View(), staged.data(), n));
  // One value of one column, by the smallest step a float can take, in the first, a middle and the last point.
  for (int c = 0; c < 5; ++c)
    for (int i : {0, n / 2, n - 1}) {
      PoseFixture changed = fx;
      std::vector<float>* column[5] = {&changed.x, &changed.y, &changed.z, &changed.u, &changed.v};
      float& value = (*column[c])[i];
      value = std::nextafter(value, std::numeric_limits<float>::infinity());
      EXPECT_FALSE(cuda::SameAsStaged(changed.View(), staged.data(), n)) << "column " << c << ", point " << i;
    }
  // Fewer points (a prefix of the same columns), none, and nothing staged yet.
  PoseScoringPoints prefix = fx.View();
  prefix.count = n - 1;
  EXPECT_FALSE(cuda::SameAsStaged(prefix, staged.data(), n));
  EXPECT_FALSE(cuda::SameAsStaged(fx.View(), nullptr, n));
  PoseScoringPoints none;
  EXPECT_TRUE(cuda::SameAsStaged(none, nullptr, 0));
  EXPECT_FALSE(cuda::SameAsStaged(none, staged.data(), n));
}

// Point problems: PointFixture (compute/pose_fixture.h): five cameras on an arc, point p seen by p % 6 of them
// (some by none).

TEST(CudaHost, PointStagingRebasesAndRejectsWhatWouldReadOutOfBounds) {
  const PointFixture sc(20, 5, PointFixture::Views::kVarying, /*first_obs=*/3);
  const PointAdjustProblem pr = sc.Problem();
  const cuda::PointStagingLayout l = cuda::PlanPointStaging(pr);
  EXPECT_EQ(l.first_obs, 3);
  EXPECT_EQ(l.num_obs, sc.begin.back() - 3);
  for (size_t off : {l.poses, l.centres, l.obs_begin, l.obs_pose, l.obs_u, l.obs_v, l.bytes}) EXPECT_EQ(off % 256, 0u);
  EXPECT_GE(l.centres, l.poses + sizeof(ScaledPose) * 5);
  EXPECT_GE(l.bytes, l.obs_v + sizeof(float) * l.num_obs);
  std::vector<unsigned char> buf(l.bytes);
  cuda::StagePointProblem(pr, l, buf.data());
  const int* begin = reinterpret_cast<const int*>(buf.data() + l.obs_begin);
  const int* pose = reinterpret_cast<const int*>(buf.data() + l.obs_pose);
  const float* u = reinterpret_cast<const float*>(buf.data() + l.obs_u);
  const float* sz = reinterpret_cast<const float*>(buf.data() + l.centres) + 5 * 20;
  EXPECT_EQ(begin[0], 0);
  for (int p = 0; p <= 20; ++p) EXPECT_EQ(begin[p], sc.begin[p] - 3);
  for (int o = 0; o < l.num_obs; ++o) {
    EXPECT_EQ(pose[o], sc.pose_idx[o + 3]);
    EXPECT_EQ(u[o], sc.ou[o + 3]);
  }
  for (int p = 0; p < 20; ++p) EXPECT_EQ(sz[p], sc.sz[p]);
  EXPECT_EQ(std::memcmp(buf.data() + l.poses, sc.poses.data(), sizeof(ScaledPose) * 5), 0);

  const auto throws_saying = [](const PointAdjustProblem& bad, const std::string& what) {
    try {
      cuda::PlanPointStaging(bad);
      ADD_FAILURE() << "no exception, expected one saying " << what;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  PointFixture bad_pose(20);
  bad_pose.pose_idx[4] = 5;  // only poses 0..4
  throws_saying(bad_pose.Problem(), "refers to keyframe pose 5 of 5");
  PointFixture decreasing(20);
  decreasing.begin[7] = decreasing.begin[8] + 1;
  throws_saying(decreasing.Problem(), "obs_begin decreases");
  PointAdjustProblem null_obs = sc.Problem();
  null_obs.obs_u = nullptr;
  throws_saying(null_obs, "observation array");
  EXPECT_EQ(cuda::PlanPointStaging(PointAdjustProblem{}).bytes, 0u);  // no points: nothing to stage
}

TEST(CudaHost, BackendSelectionIsExplicitAndNeverFallsBackSilently) {
  EXPECT_EQ(apps::MakePoseKernelFor("cpu")->kind(), BackendKind::kCpu);
  EXPECT_EQ(apps::MakePointKernelFor("cpu")->kind(), BackendKind::kCpu);
  EXPECT_THROW(apps::MakePoseKernelFor("gpu"), std::invalid_argument);
  if (CudaDeviceCount() == 0) {
    for (const auto& make : {+[] { apps::MakePoseKernelFor("cuda"); }, +[] { apps::MakePointKernelFor("cuda"); }}) {
      try {
        make();
        ADD_FAILURE() << "--backend cuda without a device must throw";
      } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("--backend cuda"), std::string::npos) << e.what();
      }
    }
    EXPECT_EQ(apps::MakePoseKernelFor("auto")->kind(), BackendKind::kCpu);
    EXPECT_EQ(apps::MakePointKernelFor("auto")->kind(), BackendKind::kCpu);
  } else {
    EXPECT_EQ(apps::MakePoseKernelFor("cuda")->kind(), BackendKind::kCuda);
    EXPECT_EQ(apps::MakePointKernelFor("cuda")->kind(), BackendKind::kCuda);
    EXPECT_EQ(apps::MakePoseKernelFor("auto")->kind(), BackendKind::kCuda);
  }
}

TEST(CudaHost, KernelsWithoutADeviceThrowRuntimeErrorNotCrash) {
  if (!CudaCompiled()) GTEST_SKIP() << "no CUDA backend in this build: " << CudaDeviceDescription();
  if (CudaDeviceCount() == 0) {
    EXPECT_THROW(CudaPose(), std::runtime_error);
    EXPECT_THROW(CudaPoint(), std::runtime_error);
  }
#ifdef MCSLAM_WITH_CUDA
  EXPECT_THROW(MakeCudaPoseKernel(CudaDeviceCount()), std::runtime_error);  // one past the last device
  EXPECT_THROW(MakeCudaPointKernel(-1), std::runtime_error);
#endif
}

// ---- CPU vs CUDA: need a device --------------------------------------------------------------------

// Checks CUDA's result against the CPU's on one problem: every score within tolerance, and the same best
// hypothesis, or one whose CPU score ties the CPU's best within tolerance.
void ExpectPoseEquivalent(PoseKernel& gpu, const PoseFixture& fx, const NormalTable& table, int count,
                          const std::string& what) {
  const int n = std::min(count, table.count());
  std::vector<float> cpu_scores(n), gpu_scores(n, -1.0f);
  const BestHypothesis cpu = MakeCpuPoseKernel()->Score(fx.sampling, fx.View(), fx.params, table, count, cpu_scores.data());
  const BestHypothesis got = gpu.Score(fx.sampling, fx.View(), fx.params, table, count, gpu_scores.data());
  const int terms = static_cast<int>(fx.x.size());
  for (int i = 0; i < n; ++i)
    ASSERT_NEAR(gpu_scores[i], cpu_scores[i], Tolerance(cpu_scores[i], terms)) << what << ", hypothesis " << i;
  ASSERT_GE(got.index, 0) << what;
  ASSERT_LT(got.index, n) << what;
  EXPECT_EQ(got.score, gpu_scores[got.index]) << what;  // the winner's score is its score
  // The winner is the lowest GPU score at the lowest index.
  const int gpu_min = static_cast<int>(std::min_element(gpu_scores.begin(), gpu_scores.end()) - gpu_scores.begin());
  EXPECT_EQ(got.index, gpu_min) << what;
  if (got.index != cpu.index) {
    EXPECT_NEAR(cpu_scores[got.index], cpu.score, 2 * Tolerance(cpu.score, terms))
        << what << ": CUDA picked " << got.index << ", the CPU " << cpu.index;
  }
  // The pose comes from the winner's row, by the host's PerturbPose, as on the CPU.
  float q[4], t[3];
  const int w = got.index;
  PerturbPose(fx.sampling, table.column(0)[w], table.column(1)[w], table.column(2)[w], table.column(3)[w],
              table.column(4)[w], table.column(5)[w], table.column(6)[w], q, t);
  for (int j = 0; j < 4; ++j) EXPECT_NEAR(got.q[j], q[j], 1e-6f) << what;
  for (int j = 0; j < 3; ++j) EXPECT_NEAR(got.t[j], t[j], 1e-6f) << what;
}

TEST(CudaEquivalence, PoseKernelMatchesCpu) {
  REQUIRE_CUDA_DEVICE();
  auto gpu = CudaPose();
  EXPECT_EQ(gpu->kind(), BackendKind::kCuda);
  const NormalTable table(5000, 11);
  // Points through shared tiles of 256: none, part of one tile, exactly one and eight, and partial last
  // tiles. 5000 hypotheses: a partial last block.
  for (int points : {0, 1, 17, 200, 256, 2048, 2049, 3000}) {
    PoseFixture fx(points);
    fx.params.max_distance_px = 25.0f;  // exercise the cap too
    ExpectPoseEquivalent(*gpu, fx, table, 5000, "points " + std::to_string(points));
  }
  // count below the table's rows, a single hypothesis, and above the rows (clamped, as on the CPU).
  const PoseFixture fx(100);
  ExpectPoseEquivalent(*gpu, fx, table, 777, "count 777");
  ExpectPoseEquivalent(*gpu, fx, table, 1, "count 1");
  ExpectPoseEquivalent(*gpu, fx, table, 9000, "count 9000 > rows");
  EXPECT_EQ(gpu->Score(fx.sampling, fx.View(), fx.params, table, 0).index, -1);
}

TEST(CudaEquivalence, PoseKernelPaperSizeAndExactFeatures) {
  REQUIRE_CUDA_DEVICE();
  auto gpu = CudaPose();
  // The paper's 2^18 hypotheses.
  const NormalTable big(1 << 18, 2);
  PoseFixture shifted(200);
  for (size_t j = 0; j < shifted.x.size(); ++j) shifted.u[j] = 500.0f * (shifted.x[j] + 0.02f) / shifted.z[j];
  ExpectPoseEquivalent(*gpu, shifted, big, big.count(), "2^18 hypotheses, shifted camera");
  // Features at the exact projections of the centre: row 0 (all zeros) wins on both backends.
  const PoseFixture exact(150);
  const BestHypothesis b = gpu->Score(exact.sampling, exact.View(), exact.params, big, big.count());
  EXPECT_EQ(b.index, 0);
  EXPECT_LT(b.score, 1e-2f);
  EXPECT_NEAR(b.q[0], 1.0f, 1e-6f);
  // Every point behind the camera costs the cap.
  PoseFixture behind(3);
  for (float& z : behind.z) z = -3.0f;
  behind.params.max_distance_px = 7.0f;
  std::vector<float> scores(64);
  gpu->Score(behind.sampling, behind.View(), behind.params, big, 64, scores.data());
  for (float s : scores) EXPECT_FLOAT_EQ(s, 21.0f);
}

TEST(CudaEquivalence, NoFiniteScoreMeansNoWinnerOnBothBackends) {
  const NormalTable table(4096, 5);
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  // The cap keeps every score finite (a point behind the camera, or a NaN distance, costs the cap), so only an
  // infinite cap gives non-finite scores: points behind the camera, or a NaN feature, then make every
  // hypothesis's score infinite (or NaN). The CPU returns no winner (index -1, the tracker's "no finite
  // hypothesis score"), and so must the device.
  PoseFixture with_nan(50);
  with_nan.params.max_distance_px = inf;
  with_nan.u[17] = nan;
  PoseFixture behind(20);
  for (float& z : behind.z) z = -3.0f;
  behind.params.max_distance_px = inf;
  const std::vector<const PoseFixture*> poses{&with_nan, &behind};
  for (const PoseFixture* fx : poses)
    EXPECT_EQ(MakeCpuPoseKernel()->Score(fx->sampling, fx->View(), fx->params, table, 3000).index, -1);
  // Points, under an infinite cap: a NaN centre makes every sample of that point score infinite: no winner
  // for it; the others have one.
  PointFixture sc(30);
  sc.params.max_distance_px = inf;
  sc.cx[10] = nan;
  ASSERT_GT(sc.begin[11], sc.begin[10]);  // point 10 is seen (by 10 % 6 = 4 cameras)
  std::vector<PointBest> cpu(30), got(30);
  MakeCpuPointKernel()->Score(sc.Problem(), table, 4096, cpu.data());
  for (int p = 0; p < 30; ++p) EXPECT_EQ(cpu[p].index < 0, p == 10) << "point " << p;

  REQUIRE_CUDA_DEVICE();
  auto gpu = CudaPose();
  for (const PoseFixture* fx : poses) {
    const BestHypothesis g = gpu->Score(fx->sampling, fx->View(), fx->params, table, 3000);
    EXPECT_EQ(g.index, -1);
    EXPECT_EQ(g.score, inf);
  }
  CudaPoint()->Score(sc.Problem(), table, 4096, got.data());
  for (int p = 0; p < 30; ++p) {
    if (p == 10) {
      EXPECT_EQ(got[p].index, -1);
      EXPECT_EQ(got[p].score, inf);
    } else {
      EXPECT_GE(got[p].index, 0) << "point " << p;
      EXPECT_NEAR(got[p].score, cpu[p].score, Tolerance(cpu[p].score, sc.begin[p + 1] - sc.begin[p])) << "point " << p;
    }
  }
}

TEST(CudaEquivalence, PoseKernelReusesBuffersAndFollowsTableChanges) {
  REQUIRE_CUDA_DEVICE();
  auto gpu = CudaPose();
  const PoseFixture fx(200);
  NormalTable table(1 << 16, 4);
  std::vector<float> first(table.count()), again(table.count());
  const BestHypothesis a = gpu->Score(fx.sampling, fx.View(), fx.params, table, table.count(), first.data());
  const cuda::CudaKernelStats warm = Stats(*gpu);
  EXPECT_EQ(warm.table_uploads, 1);
  EXPECT_EQ(warm.point_uploads, 1);
  for (int r = 0; r < 5; ++r) {
    const BestHypothesis b = gpu->Score(fx.sampling, fx.View(), fx.params, table, table.count(), again.data());
    EXPECT_EQ(b.index, a.index);  // deterministic: same problem, same answer, bit for bit
    EXPECT_EQ(b.score, a.score);
    EXPECT_EQ(again, first);
  }
  EXPECT_EQ(Stats(*gpu).point_uploads, 1);  // the same points (a frame's later rounds): found on the device
  // Smaller problems (fewer hypotheses, fewer points, no all_scores): no new allocation, no new upload.
  const PoseFixture small(50);
  gpu->Score(small.sampling, small.View(), small.params, table, 1000);
  const cuda::CudaKernelStats steady = Stats(*gpu);
  EXPECT_EQ(steady.table_uploads, 1);
  EXPECT_EQ(steady.device_allocations, warm.device_allocations);
  EXPECT_EQ(steady.pinned_allocations, warm.pinned_allocations);
  EXPECT_EQ(steady.calls, 7);
  // The table refilled in place ("fresh" random numbers): uploaded again, and the results follow it.
  table.Fill(4, 0, 1);
  ExpectPoseEquivalent(*gpu, fx, table, table.count(), "refilled table");
  EXPECT_EQ(Stats(*gpu).table_uploads, 2);
  // Another table object, then the first again: one upload each.
  const NormalTable other(1 << 16, 9);
  ExpectPoseEquivalent(*gpu, fx, other, other.count(), "other table");
  ExpectPoseEquivalent(*gpu, fx, table, table.count(), "first table again");
  EXPECT_EQ(Stats(*gpu).table_uploads, 4);
  // Two kernels in turn: each scores its own points.
  auto second = CudaPose();
  const PoseFixture other_points(300, /*seed=*/8);
  const BestHypothesis x = second->Score(other_points.sampling, other_points.View(), other_points.params, table, 4096);
  const BestHypothesis y = gpu->Score(fx.sampling, fx.View(), fx.params, table, table.count());
  const BestHypothesis x2 = second->Score(other_points.sampling, other_points.View(), other_points.params, table, 4096);
  EXPECT_EQ(x.index, x2.index);
  EXPECT_EQ(x.score, x2.score);
  EXPECT_EQ(y.score, gpu->Score(fx.sampling, fx.View(), fx.params, table, table.count()).score);
}

// Points kept on the device between calls: a call whose points changed, even by one ulp in one feature,
// scores the new points; the same points again score as before (one tile and several); another kernel's calls
// in between change nothing of it.
TEST(CudaEquivalence, PoseKernelScoresTheCallsOwnPointsWhenTheyChange) {
  REQUIRE_CUDA_DEVICE();
  const NormalTable table(1 << 14, 12);
  for (int np : {200, 3000}) {
    auto gpu = CudaPose();
    PoseFixture fx(np, /*seed=*/5);
    std::vector<float> before(table.count()), after(table.count());
    gpu->Score(fx.sampling, fx.View(), fx.params, table, table.count(), before.data());
    gpu->Score(fx.sampling, fx.View(), fx.params, table, table.count(), after.data());
    EXPECT_EQ(after, before) << np << " points, the same again";
    EXPECT_EQ(Stats(*gpu).point_uploads, 1) << np;
    // One feature moved 5 px, in place (same arrays): hypotheses' scores move with it, as on the CPU.
    fx.u[np / 2] += 5.0f;
    ExpectPoseEquivalent(*gpu, fx, table, table.count(), std::to_string(np) + " points, one feature moved");
    EXPECT_EQ(Stats(*gpu).point_uploads, 2) << np;
    // One ulp in the last point's depth.
    fx.z[np - 1] = std::nextafter(fx.z[np - 1], 100.0f);
    ExpectPoseEquivalent(*gpu, fx, table, table.count(), std::to_string(np) + " points, one ulp");
    EXPECT_EQ(Stats(*gpu).point_uploads, 3) << np;
    // Another kernel scores its own points: ours stay on the device, not sent again.
    auto other = CudaPose();
    const PoseFixture others(150, /*seed=*/6);
    ExpectPoseEquivalent(*other, others, table, table.count(), "the other kernel");
    ExpectPoseEquivalent(*gpu, fx, table, table.count(), std::to_string(np) + " points after another kernel");
    EXPECT_EQ(Stats(*gpu).point_uploads, 3) << np;
  }
}

void ExpectPointEquivalent(PointKernel& gpu, const PointFixture& sc, const NormalTable& table, int samples,
                           const std::string& what) {
  const PointAdjustProblem pr = sc.Problem();
  std::vector<PointBest> cpu(pr.num_points), got(pr.num_points);
  MakeCpuPointKernel()->Score(pr, table, samples, cpu.data());
  gpu.Score(pr, table, samples, got.data());
  const int n = std::min(samples, table.count());
  for (int p = 0; p < pr.num_points; ++p) {
    const int terms = sc.begin[p + 1] - sc.begin[p];
    ASSERT_GE(got[p].index, 0) << what << ", point " << p;
    ASSERT_LT(got[p].index, n) << what << ", point " << p;
    EXPECT_NEAR(got[p].score, cpu[p].score, Tolerance(cpu[p].score, terms)) << what << ", point " << p;
    if (terms == 0) {
      EXPECT_EQ(got[p].index, 0) << what << ": all samples tie at 0, the lowest index wins";
    }
    // The winner's position comes from its row by the same PerturbPointT as on the CPU.
    float z[3];
    const float c[3] = {sc.cx[p], sc.cy[p], sc.cz[p]}, s[3] = {sc.sx[p], sc.sy[p], sc.sz[p]};
    const int w = got[p].index;
    PerturbPointT<float>(c, s, table.column(0)[w], table.column(1)[w], table.column(2)[w], z);
    // To float rounding of c + s n, which may or may not be one fused multiply-add on either side (a host
    // built for AVX2/FMA contracts it, the device may): a few ulps of the larger term, not of the result,
    // which cancellation can make far smaller (measured 9e-10 apart on 1e-3 positions, sm_90 vs x86-64-v3).
    for (int k = 0; k < 3; ++k) {
      const float scale = std::abs(c[k]) + std::abs(s[k] * table.column(k)[w]);
      EXPECT_NEAR(got[p].position[k], z[k], 4 * std::numeric_limits<float>::epsilon() * scale)
          << what << ", point " << p;
    }
    if (got[p].index != cpu[p].index) {
      // A different sample only where the two tie within tolerance: the CPU's score of CUDA's sample.
      double ref = 0;
      for (int o = sc.begin[p]; o < sc.begin[p + 1]; ++o)
        ref += ReprojectionDistance(sc.poses[sc.pose_idx[o]], z[0], z[1], z[2], sc.ou[o], sc.ov[o], sc.params);
      EXPECT_NEAR(ref, cpu[p].score, 2 * Tolerance(cpu[p].score, terms))
          << what << ", point " << p << ": CUDA picked " << got[p].index << ", the CPU " << cpu[p].index;
    }
  }
}

TEST(CudaEquivalence, PointKernelMatchesCpu) {
  REQUIRE_CUDA_DEVICE();
  auto gpu = CudaPoint();
  EXPECT_EQ(gpu->kind(), BackendKind::kCuda);
  const NormalTable table(4096, 3);
  ExpectPointEquivalent(*gpu, PointFixture(300), table, 4000, "300 points, 4000 samples");  // partial last round
  ExpectPointEquivalent(*gpu, PointFixture(7, 5, PointFixture::Views::kVarying, /*first_obs=*/5), table, 4096, "obs_begin[0] = 5");
  ExpectPointEquivalent(*gpu, PointFixture(40), table, 100, "fewer samples than threads");
  ExpectPointEquivalent(*gpu, PointFixture(40), table, 9999, "samples > rows (clamped)");
  // No samples: as the CPU, index -1 and an infinite score.
  const PointFixture sc(3);
  std::vector<PointBest> best(3);
  gpu->Score(sc.Problem(), table, 0, best.data());
  for (const PointBest& b : best) {
    EXPECT_EQ(b.index, -1);
    EXPECT_EQ(b.score, std::numeric_limits<float>::infinity());
  }
  // An inconsistent problem is refused before anything reaches the device.
  PointFixture bad(5);
  bad.pose_idx[0] = 42;
  EXPECT_THROW(gpu->Score(bad.Problem(), table, 100, best.data()), std::invalid_argument);
}

TEST(CudaEquivalence, PointKernelReusesBuffersAndFollowsTableChanges) {
  REQUIRE_CUDA_DEVICE();
  auto gpu = CudaPoint();
  const PointFixture sc(200);
  NormalTable table(4096, 3);
  std::vector<PointBest> first(200), again(200);
  gpu->Score(sc.Problem(), table, 4096, first.data());
  const cuda::CudaKernelStats warm = Stats(*gpu);
  for (int r = 0; r < 3; ++r) {
    gpu->Score(sc.Problem(), table, 4096, again.data());
    for (int p = 0; p < 200; ++p) {
      EXPECT_EQ(again[p].index, first[p].index);
      EXPECT_EQ(again[p].score, first[p].score);
    }
  }
  const PointFixture fewer(50);
  gpu->Score(fewer.Problem(), table, 2048, again.data());
  const cuda::CudaKernelStats steady = Stats(*gpu);
  EXPECT_EQ(steady.table_uploads, 1);
  EXPECT_EQ(steady.device_allocations, warm.device_allocations);
  EXPECT_EQ(steady.pinned_allocations, warm.pinned_allocations);
  table.Fill(3, 0, 7);
  ExpectPointEquivalent(*gpu, sc, table, 4096, "refilled table");
  EXPECT_EQ(Stats(*gpu).table_uploads, 2);
}

// Successive keyframes' adjustments as the System makes them (windows one keyframe on, each keyframe seeing a
// twentieth of the points fewer than the next; observations that do not start at index 0 of their arrays
// after the first point): the device agrees with the CPU within tolerance on every point of every call, and a
// refused call (a keyframe index out of range) leaves the next call right.
TEST(CudaEquivalence, PointKernelMatchesCpuOnSuccessiveKeyframeWindows) {
  REQUIRE_CUDA_DEVICE();
  auto gpu = CudaPoint(), cpu = MakeCpuPointKernel();
  const NormalTable table(4096, 3);
  const auto expect_agree = [&](const KeyframeWindowFixture& f, const std::string& what) {
    const int n = f.Problem().num_points;
    std::vector<PointBest> got(n), ref(n);
    gpu->Score(f.Problem(), table, 4096, got.data());
    cpu->Score(f.Problem(), table, 4096, ref.data());
    for (int p = 0; p < n; ++p) {
      ASSERT_GE(got[p].index, 0) << what << ", point " << p;
      EXPECT_NEAR(got[p].score, ref[p].score, 2 * Tolerance(ref[p].score, f.begin[p + 1] - f.begin[p]))
          << what << ", point " << p;
    }
  };
  for (int c = 0; c < 12; ++c)
    expect_agree(KeyframeWindowFixture(c, /*window=*/12, /*per_keyframe=*/400, /*shift=*/20), "call " + std::to_string(c));
  KeyframeWindowFixture bad(12, 12, 400, 20);
  bad.pose_idx[5] = 12;  // one past the window's 12 keyframes
  std::vector<PointBest> out(400);
  EXPECT_THROW(gpu->Score(bad.Problem(), table, 4096, out.data()), std::invalid_argument);
  expect_agree(KeyframeWindowFixture(13, 12, 400, 20), "after a refused call");
}

}  // namespace
}  // namespace mcslam::compute
