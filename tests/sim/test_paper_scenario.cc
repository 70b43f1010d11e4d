#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "test_util.h"
#include "core/pose.h"
#include "sim/paper_scenario.h"

namespace mcslam::sim {
namespace {

using mcslam::testing::LookAt;


// Independent occlusion check: where the segment from the camera centre c to p first enters the box
// (slab method), as a fraction of the segment; 1 means p itself is the first surface point on the ray.
double BoxEntryFraction(const Eigen::Vector3d& c, const Eigen::Vector3d& p) {
  const Eigen::Vector3d half(kPaperBoxSizeM[0] / 2, kPaperBoxSizeM[1] / 2, kPaperBoxSizeM[2] / 2);
  const Eigen::Vector3d d = p - c;
  double enter = -1e300;
  for (int k = 0; k < 3; ++k) {
    if (d[k] == 0) continue;  // parallel to this slab; c is outside the box, p on it, so other slabs decide
    const double s1 = (-half[k] - c[k]) / d[k], s2 = (half[k] - c[k]) / d[k];
    enter = std::max(enter, std::min(s1, s2));
  }
  return enter;
}

// Which of the 6 faces (+x, -x, +y, -y, +z, -z) a normal belongs to.
int FaceOf(const Eigen::Vector3d& n) {
  for (int axis = 0; axis < 3; ++axis) {
    if (n[axis] > 0.5) return 2 * axis;
    if (n[axis] < -0.5) return 2 * axis + 1;
  }
  return -1;
}

bool SameObservation(const SyntheticObservation& a, const SyntheticObservation& b) {
  return a.feature_id == b.feature_id && a.uv_px == b.uv_px && a.uv_true_px == b.uv_true_px &&
         a.is_outlier == b.is_outlier;
}

bool SameSequence(const SyntheticSequence& a, const SyntheticSequence& b) {
  if (a.points_in_world != b.points_in_world || a.normals_in_world != b.normals_in_world) return false;
  if (a.stamps_s != b.stamps_s || a.frames.size() != b.frames.size()) return false;
  for (size_t i = 0; i < a.cam_from_world.size(); ++i) {
    if (a.cam_from_world[i].q.coeffs() != b.cam_from_world[i].q.coeffs() ||
        a.cam_from_world[i].t != b.cam_from_world[i].t)
      return false;
  }
  for (size_t i = 0; i < a.frames.size(); ++i) {
    const auto& oa = a.frames[i].observations;
    const auto& ob = b.frames[i].observations;
    if (oa.size() != ob.size()) return false;
    for (size_t j = 0; j < oa.size(); ++j)
      if (!SameObservation(oa[j], ob[j])) return false;
  }
  return true;
}

void ExpectRejected(const PaperScenarioOptions& o, const std::string& field) {
  try {
    o.Check();
    ADD_FAILURE() << "Check() accepted bad " << field;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
  }
  EXPECT_THROW(MakePaperScenario(o), std::invalid_argument);
}

TEST(PaperScenario, CheckRejectsBadOptionsNamingTheField) {
  EXPECT_NO_THROW(PaperScenarioOptions{}.Check());
  PaperScenarioOptions o;
  o.frames = 0;
  ExpectRejected(o, "frames");
  o = {};
  o.fps = 0;
  ExpectRejected(o, "fps");
  o = {};
  o.noise_px = -1;
  ExpectRejected(o, "noise_px");
  o = {};
  o.noise_px = std::nan("");
  ExpectRejected(o, "noise_px");
  o = {};
  o.outlier_fraction = 1.5;
  ExpectRejected(o, "outlier_fraction");
  o = {};
  o.outlier_fraction = -0.1;
  ExpectRejected(o, "outlier_fraction");
  o = {};
  o.speed = 0;
  ExpectRejected(o, "speed");
  o = {};
  o.speed = -2;
  ExpectRejected(o, "speed");
  o = {};
  o.num_points = 0;
  ExpectRejected(o, "num_points");
  try {
    PaperScenarioOptions bad;
    bad.noise_px = -1;
    bad.Check();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("got -1"), std::string::npos) << e.what();
  }
}

TEST(PaperScenario, CameraIsThePapers) {
  const PinholeCamera cam = PaperCamera();
  EXPECT_EQ(cam.fx, 500.0);
  EXPECT_EQ(cam.fy, 500.0);
  EXPECT_EQ(cam.cx, 159.5);
  EXPECT_EQ(cam.cy, 119.5);
  EXPECT_EQ(cam.width, 320);
  EXPECT_EQ(cam.height, 240);
  EXPECT_FALSE(cam.HasDistortion());
  EXPECT_NO_THROW(cam.Check());
}

TEST(PaperScenario, PointsLieOnTheBoxFacesInProportionToArea) {
  PaperScenarioOptions o;
  o.frames = 1;
  const SyntheticSequence seq = MakePaperScenario(o);
  ASSERT_EQ(seq.points_in_world.size(), 400u);
  ASSERT_EQ(seq.normals_in_world.size(), 400u);
  const Eigen::Vector3d half(kPaperBoxSizeM[0] / 2, kPaperBoxSizeM[1] / 2, kPaperBoxSizeM[2] / 2);
  std::map<int, int> per_face;
  for (size_t i = 0; i < seq.points_in_world.size(); ++i) {
    const Eigen::Vector3d& p = seq.points_in_world[i];
    const Eigen::Vector3d& n = seq.normals_in_world[i];
    const int face = FaceOf(n);
    ASSERT_GE(face, 0);
    EXPECT_DOUBLE_EQ(n.norm(), 1.0);
    ++per_face[face];
    const int axis = face / 2;
    // On its face plane exactly (the coordinate is set, not computed), inside the face's extent.
    EXPECT_EQ(p[axis], n[axis] * half[axis]);
    EXPECT_TRUE((p.cwiseAbs().array() <= half.array()).all());
  }
  const double total = 2 * (half[0] * half[1] + half[1] * half[2] + half[0] * half[2]) * 4;
  for (int face = 0; face < 6; ++face) {
    const int axis = face / 2;
    const double area = 4 * half[(axis + 1) % 3] * half[(axis + 2) % 3];
    // Largest-remainder rounding: each face is within one point of its exact share.
    EXPECT_NEAR(per_face[face], 400 * area / total, 1.0) << "face " << face;
  }
}

TEST(PaperScenario, IsPointVisibleHandMadeCases) {
  const PinholeCamera cam = PaperCamera();
  const Pose cam_from_world = LookAt({0, -3, 0}, {0, 0, 0});
  Eigen::Vector2d uv;
  // Centre of the front face: seen at the principal point.
  ASSERT_TRUE(IsPointVisible(cam, cam_from_world, {0, -0.35, 0}, {0, -1, 0}, &uv));
  // Exact up to rounding of the look-at rotation.
  EXPECT_NEAR(uv.x(), 159.5, 1e-9);
  EXPECT_NEAR(uv.y(), 119.5, 1e-9);
  // Centre of the back face: straight behind the front face, hidden by the box.
  EXPECT_FALSE(IsPointVisible(cam, cam_from_world, {0, 0.35, 0}, {0, 1, 0}));
  // The +x side face faces away from a camera straight in front of the box, and towards one off to +x.
  EXPECT_FALSE(IsPointVisible(cam, cam_from_world, {0.5, 0, 0}, {1, 0, 0}));
  EXPECT_TRUE(IsPointVisible(cam, LookAt({2, -3, 0}, {0, 0, 0}), {0.5, 0, 0}, {1, 0, 0}));
  // Facing the camera but behind it, or too close to it.
  EXPECT_FALSE(IsPointVisible(cam, cam_from_world, {0, -4, 0}, {0, 1, 0}));
  EXPECT_FALSE(IsPointVisible(cam, cam_from_world, {0, -2.95, 0}, {0, -1, 0}));
  // Facing the camera, in front, but outside the field of view (x/z = 1 -> 500 px off centre).
  EXPECT_FALSE(IsPointVisible(cam, cam_from_world, {1, -2, 0}, {0, -1, 0}));
}

TEST(PaperScenario, EveryObservationIsGeometricallyValidAndEveryVisiblePointIsObserved) {
  PaperScenarioOptions o;  // noise 0, no outliers: nothing is dropped, so observed == visible
  const SyntheticSequence seq = MakePaperScenario(o);
  ASSERT_EQ(seq.frames.size(), 300u);
  ASSERT_EQ(seq.cam_from_world.size(), 300u);
  ASSERT_EQ(seq.stamps_s.size(), 300u);
  const PinholeCamera& cam = seq.camera;
  int64_t checked = 0;
  for (size_t i = 0; i < seq.frames.size(); ++i) {
    EXPECT_DOUBLE_EQ(seq.stamps_s[i], i / 30.0);
    const Pose& cam_from_world = seq.cam_from_world[i];
    const Eigen::Vector3d c = cam_from_world.OriginOfTargetInSource();
    std::set<int64_t> observed;
    int64_t last_id = -1;
    for (const SyntheticObservation& ob : seq.frames[i].observations) {
      ASSERT_GE(ob.feature_id, 0);
      ASSERT_LT(ob.feature_id, static_cast<int64_t>(seq.points_in_world.size()));
      EXPECT_GT(ob.feature_id, last_id) << "ids increase within a frame, so none repeats";
      last_id = ob.feature_id;
      observed.insert(ob.feature_id);
      const Eigen::Vector3d& p = seq.points_in_world[ob.feature_id];
      const Eigen::Vector3d& n = seq.normals_in_world[ob.feature_id];
      const Eigen::Vector3d p_cam = cam_from_world * p;
      EXPECT_GT(p_cam.z(), kMinDepthM);
      EXPECT_GT(n.dot(c - p), 0.0);
      EXPECT_TRUE(cam.InImage(ob.uv_true_px));
      Eigen::Vector2d uv;
      ASSERT_TRUE(cam.ProjectWorld(cam_from_world, p, &uv));
      // ProjectWorld rotates by a matrix, the scenario by the quaternion: equal to rounding (~1e-13 px).
      EXPECT_LT((uv - ob.uv_true_px).norm(), 1e-9);
      EXPECT_EQ(ob.uv_px, ob.uv_true_px);  // noise 0
      EXPECT_FALSE(ob.is_outlier);
      // Nothing of the box lies between the camera and the point. 1e-9: rounding of the slab division.
      EXPECT_GT(BoxEntryFraction(c, p), 1.0 - 1e-9);
      ++checked;
    }
    // Conversely, every unoccluded point in front of the camera and inside the image is observed.
    for (size_t j = 0; j < seq.points_in_world.size(); ++j) {
      const Eigen::Vector3d& p = seq.points_in_world[j];
      Eigen::Vector2d uv;
      const bool in_view = cam.Project(cam_from_world * p, &uv, nullptr, kMinDepthM) && cam.InImage(uv);
      const bool unoccluded = BoxEntryFraction(c, p) > 1.0 - 1e-9;
      EXPECT_EQ(observed.count(static_cast<int64_t>(j)) == 1, in_view && unoccluded) << "frame " << i << " point " << j;
    }
  }
  EXPECT_GT(checked, 0);
}

TEST(PaperScenario, BackFaceIsNeverObserved) {
  // The camera stays on the -y side: points on the +y face are always behind the box.
  for (uint64_t seed : {1, 2, 3}) {
    PaperScenarioOptions o;
    o.seed = seed;
    const SyntheticSequence seq = MakePaperScenario(o);
    for (const SyntheticFrame& f : seq.frames)
      for (const SyntheticObservation& ob : f.observations) ASSERT_NE(FaceOf(seq.normals_in_world[ob.feature_id]), 2);
  }
}

TEST(PaperScenario, EnoughPointsVisibleInEveryFrame) {
  constexpr int kMinVisible = 100;  // the promise of the header, for the default 400 points
  for (uint64_t seed = 1; seed <= 8; ++seed) {
    PaperScenarioOptions o;
    o.seed = seed;
    const SequenceSummary s = Summarize(MakePaperScenario(o));
    EXPECT_GE(s.min_visible, kMinVisible) << "seed " << seed;
    EXPECT_LE(s.max_visible, 400);
  }
}

TEST(PaperScenario, PointsAndFacesComeIntoAndOutOfView) {
  for (uint64_t seed = 1; seed <= 5; ++seed) {
    PaperScenarioOptions o;
    o.seed = seed;
    const SyntheticSequence seq = MakePaperScenario(o);
    std::vector<std::set<int64_t>> visible(seq.frames.size());
    for (size_t i = 0; i < seq.frames.size(); ++i)
      for (const auto& ob : seq.frames[i].observations) visible[i].insert(ob.feature_id);
    int appeared = 0, disappeared = 0;
    for (size_t i = 1; i < visible.size(); ++i) {
      for (int64_t id : visible[i]) appeared += !visible[i - 1].count(id);
      for (int64_t id : visible[i - 1]) disappeared += !visible[i].count(id);
    }
    EXPECT_GT(appeared, 0) << "seed " << seed;
    EXPECT_GT(disappeared, 0) << "seed " << seed;
    // Faces whose visibility (any point seen) changes along the sequence: at least the two side faces.
    std::set<int> faces_changing;
    std::vector<bool> prev(6, false);
    for (size_t i = 0; i < seq.frames.size(); ++i) {
      std::vector<bool> now(6, false);
      for (const auto& ob : seq.frames[i].observations) now[FaceOf(seq.normals_in_world[ob.feature_id])] = true;
      if (i > 0)
        for (int f = 0; f < 6; ++f)
          if (now[f] != prev[f]) faces_changing.insert(f);
      prev = now;
    }
    EXPECT_GE(faces_changing.size(), 2u) << "seed " << seed;
    EXPECT_TRUE(faces_changing.count(0) && faces_changing.count(1)) << "seed " << seed;
  }
  // With seed 1 the box's edge also leaves the image in some frames: a front-facing point in front of the
  // camera is then not observed because it projects outside the image.
  const SyntheticSequence seq = MakePaperScenario(PaperScenarioOptions{});
  int lost_at_border = 0;
  for (size_t i = 0; i < seq.frames.size(); ++i) {
    const Eigen::Vector3d c = seq.cam_from_world[i].OriginOfTargetInSource();
    for (size_t j = 0; j < seq.points_in_world.size(); ++j) {
      Eigen::Vector2d uv;
      if (seq.normals_in_world[j].dot(c - seq.points_in_world[j]) > 0 &&
          seq.camera.Project(seq.cam_from_world[i] * seq.points_in_world[j], &uv, nullptr, kMinDepthM) &&
          !seq.camera.InImage(uv))
        ++lost_at_border;
    }
  }
  EXPECT_GT(lost_at_border, 0);
}

TEST(PaperScenario, NoiseIsZeroMeanWithTheRequestedSigma) {
  PaperScenarioOptions o;
  o.noise_px = 1.5;
  o.outlier_fraction = 0.2;
  o.seed = 7;
  const SyntheticSequence seq = MakePaperScenario(o);
  double sum = 0, sum2 = 0;
  int64_t n = 0;
  for (const SyntheticFrame& f : seq.frames) {
    for (const SyntheticObservation& ob : f.observations) {
      EXPECT_TRUE(seq.camera.InImage(ob.uv_px));  // noisy pixels outside the image are dropped
      if (ob.is_outlier) continue;
      const Eigen::Vector2d r = ob.uv_px - ob.uv_true_px;
      sum += r.x() + r.y();
      sum2 += r.squaredNorm();
      n += 2;
    }
  }
  ASSERT_GT(n, 50000);
  const double mean = sum / n;
  const double stddev = std::sqrt(sum2 / n - mean * mean);
  // 5 standard errors: of the mean sigma/sqrt(n), of the sample std sigma/sqrt(2n) (Gaussian). Dropping the
  // few noisy pixels that leave the image truncates the tails of border points only, far below this.
  EXPECT_NEAR(mean, 0.0, 5 * o.noise_px / std::sqrt(double(n)));
  EXPECT_NEAR(stddev, o.noise_px, 5 * o.noise_px / std::sqrt(2.0 * n));
}

TEST(PaperScenario, OutlierFractionAndPlacement) {
  PaperScenarioOptions o;
  o.outlier_fraction = 0.3;  // noise 0: no observation is dropped, so the denominator is every visible point
  const SyntheticSequence seq = MakePaperScenario(o);
  int64_t n = 0, outliers = 0;
  for (const SyntheticFrame& f : seq.frames) {
    for (const SyntheticObservation& ob : f.observations) {
      ++n;
      if (!ob.is_outlier) {
        EXPECT_EQ(ob.uv_px, ob.uv_true_px);
        continue;
      }
      ++outliers;
      EXPECT_GE((ob.uv_px - ob.uv_true_px).norm(), kMinOutlierDistancePx);
      EXPECT_TRUE(seq.camera.InImage(ob.uv_px));
    }
  }
  EXPECT_EQ(Summarize(seq).outliers, outliers);
  // Binomial(n, 0.3): 5 standard deviations.
  const double sd = std::sqrt(n * 0.3 * 0.7);
  EXPECT_NEAR(static_cast<double>(outliers), 0.3 * n, 5 * sd);

  o.outlier_fraction = 1.0;
  EXPECT_EQ(Summarize(MakePaperScenario(o)).outliers, Summarize(MakePaperScenario(o)).observations);
  o.outlier_fraction = 0.0;
  EXPECT_EQ(Summarize(MakePaperScenario(o)).outliers, 0);
}

TEST(PaperScenario, DeterministicAndSeeded) {
  PaperScenarioOptions o;
  o.noise_px = 1.0;
  o.outlier_fraction = 0.1;
  const SyntheticSequence a = MakePaperScenario(o), b = MakePaperScenario(o);
  EXPECT_TRUE(SameSequence(a, b));
  o.seed = 2;
  const SyntheticSequence c = MakePaperScenario(o);
  EXPECT_FALSE(SameSequence(a, c));
  EXPECT_NE(a.points_in_world, c.points_in_world);
  EXPECT_NE(a.cam_from_world[0].t, c.cam_from_world[0].t);  // the path's phases are seeded too

  // A short sequence is the start of a long one.
  o.seed = 1;
  o.frames = 20;
  const SyntheticSequence shorter = MakePaperScenario(o);
  SyntheticSequence prefix = a;
  prefix.frames.resize(20);
  prefix.cam_from_world.resize(20);
  prefix.stamps_s.resize(20);
  EXPECT_TRUE(SameSequence(shorter, prefix));
}

TEST(PaperScenario, OutlierFractionDoesNotChangeTheNoiseOfInliers) {
  PaperScenarioOptions o;
  o.noise_px = 1.0;
  const SyntheticSequence clean = MakePaperScenario(o);
  o.outlier_fraction = 0.3;
  const SyntheticSequence dirty = MakePaperScenario(o);
  int64_t compared = 0;
  for (size_t i = 0; i < clean.frames.size(); ++i) {
    std::map<int64_t, Eigen::Vector2d> uv;
    for (const auto& ob : clean.frames[i].observations) uv[ob.feature_id] = ob.uv_px;
    for (const auto& ob : dirty.frames[i].observations) {
      if (ob.is_outlier) continue;
      ASSERT_TRUE(uv.count(ob.feature_id));
      EXPECT_EQ(uv[ob.feature_id], ob.uv_px);
      ++compared;
    }
  }
  EXPECT_GT(compared, 0);
}

TEST(PaperScenario, MotionPerFrameIsHandHeld) {
  for (uint64_t seed = 1; seed <= 5; ++seed) {
    PaperScenarioOptions o;
    o.seed = seed;
    const SyntheticSequence seq = MakePaperScenario(o);
    double sum_cm = 0, max_cm = 0, sum_deg = 0, max_deg = 0;
    double min_dist = 1e9, max_dist = 0;
    for (size_t i = 0; i < seq.cam_from_world.size(); ++i) {
      const Pose world_from_cam = seq.cam_from_world[i].Inverse();
      min_dist = std::min(min_dist, world_from_cam.t.norm());
      max_dist = std::max(max_dist, world_from_cam.t.norm());
      if (i == 0) continue;
      const Pose prev = seq.cam_from_world[i - 1].Inverse();
      const double cm = 100 * (world_from_cam.t - prev.t).norm();
      const double deg = AngularDistanceDeg(world_from_cam.q, prev.q);
      sum_cm += cm;
      sum_deg += deg;
      max_cm = std::max(max_cm, cm);
      max_deg = std::max(max_deg, deg);
    }
    const double n = seq.cam_from_world.size() - 1.0;
    // The ranges promised in the header (a person moving a webcam at 30 Hz).
    EXPECT_GE(sum_cm / n, 1.0) << "seed " << seed;
    EXPECT_LE(sum_cm / n, 3.0) << "seed " << seed;
    EXPECT_LE(max_cm, 5.0) << "seed " << seed;
    EXPECT_GE(sum_deg / n, 0.3) << "seed " << seed;
    EXPECT_LE(sum_deg / n, 1.0) << "seed " << seed;
    EXPECT_LE(max_deg, 1.5) << "seed " << seed;
    // About 3 m from the box centre.
    EXPECT_GT(min_dist, 2.7);
    EXPECT_LT(max_dist, 3.3);
  }
}

TEST(PaperScenario, SpeedScalesPathTime) {
  PaperScenarioOptions slow, fast;
  slow.frames = 61;
  fast.frames = 31;
  fast.speed = 2.0;
  const SyntheticSequence a = MakePaperScenario(slow), b = MakePaperScenario(fast);
  for (int k = 0; k < 31; ++k) {
    // The same path time is computed as 2 * (k / 30) and (2k) / 30: equal up to rounding.
    EXPECT_LT((a.cam_from_world[2 * k].t - b.cam_from_world[k].t).norm(), 1e-12);
    EXPECT_LT(AngularDistanceRad(a.cam_from_world[2 * k].q, b.cam_from_world[k].q), 1e-12);
    EXPECT_DOUBLE_EQ(b.stamps_s[k], k / 30.0);
  }
}

TEST(PaperScenario, ConversionsToIoTypes) {
  PaperScenarioOptions o;
  o.frames = 5;
  o.noise_px = 0.5;
  SyntheticSequence seq = MakePaperScenario(o);
  seq.frames[2].observations.clear();  // a frame with nothing seen must still be listed

  const std::vector<io::ObservationFrame> frames = ToObservationFrames(seq);
  ASSERT_EQ(frames.size(), 5u);
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(frames[i].index, static_cast<int64_t>(i));
    EXPECT_EQ(frames[i].stamp_s, seq.stamps_s[i]);
    ASSERT_EQ(frames[i].observations.size(), seq.frames[i].observations.size());
    for (size_t j = 0; j < frames[i].observations.size(); ++j) {
      EXPECT_EQ(frames[i].observations[j].feature_id, seq.frames[i].observations[j].feature_id);
      EXPECT_EQ(frames[i].observations[j].u_px, seq.frames[i].observations[j].uv_px.x());
      EXPECT_EQ(frames[i].observations[j].v_px, seq.frames[i].observations[j].uv_px.y());
    }
  }
  EXPECT_TRUE(frames[2].observations.empty());

  const io::Trajectory traj = ToTrajectory(seq);
  ASSERT_EQ(traj.size(), 5u);
  EXPECT_TRUE(traj.has_stamps);
  for (size_t i = 0; i < traj.size(); ++i) {
    EXPECT_EQ(traj.stamps_s[i], seq.stamps_s[i]);
    const Pose identity = traj.world_from_cam[i] * seq.cam_from_world[i];
    // Composition of a pose with its inverse: identity up to rounding.
    EXPECT_LT(identity.t.norm(), 1e-12);
    EXPECT_LT(AngularDistanceRad(identity.q, Eigen::Quaterniond::Identity()), 1e-12);
  }

  const io::PointCloud cloud = ToPointCloud(seq);
  ASSERT_EQ(cloud.points.size(), 400u);
  ASSERT_EQ(cloud.ids.size(), 400u);
  EXPECT_TRUE(cloud.rgb.empty());
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    EXPECT_EQ(cloud.ids[i], static_cast<int64_t>(i));
    EXPECT_EQ(cloud.points[i], seq.points_in_world[i]);
  }

  const SequenceSummary s = Summarize(seq);
  EXPECT_EQ(s.frames, 5);
  EXPECT_EQ(s.points, 400);
  EXPECT_EQ(s.min_visible, 0);
  EXPECT_NE(s.ToString().find("5 frames"), std::string::npos) << s.ToString();
}

}  // namespace
}  // namespace mcslam::sim
