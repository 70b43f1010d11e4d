#include "sim/scene.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include <fmt/format.h>

#include "core/random.h"
#include "sim/paper_scenario.h"

namespace mcslam::sim {
namespace {

// The index of the only non-zero coordinate of v, or -1 when v does not lie along a world axis.
int AxisOf(const Eigen::Vector3d& v) {
  int axis = -1;
  for (int k = 0; k < 3; ++k) {
    if (v[k] == 0.0) continue;
    if (axis >= 0) return -1;
    axis = k;
  }
  return axis;
}

}  // namespace

Quad MakeQuad(const Eigen::Vector3d& corner, const Eigen::Vector3d& edge_u, const Eigen::Vector3d& edge_v,
              const Eigen::Vector3d& normal, TextureStyle style, double texels_per_m, float brightness,
              double point_weight) {
  const auto texels = [&](double length_m) {
    return static_cast<int>(std::clamp(std::lround(length_m * texels_per_m), 16L, 2048L));
  };
  Quad q;
  q.corner_in_world = corner;
  q.edge_u_in_world = edge_u;
  q.edge_v_in_world = edge_v;
  q.normal_in_world = normal;
  q.style = style;
  q.brightness = brightness;
  q.texture_cols = texels(edge_u.norm());
  q.texture_rows = texels(edge_v.norm());
  q.point_weight = point_weight;
  return q;
}

void Scene::Check() const {
  if (!(background >= 0 && background <= 1))
    throw std::invalid_argument(fmt::format("scene: background must be in [0, 1], got {}", background));
  for (size_t i = 0; i < quads.size(); ++i) {
    const Quad& q = quads[i];
    const auto fail = [i](const std::string& what) {
      throw std::invalid_argument(fmt::format("scene: quad {} {}", i, what));
    };
    const double lu = q.edge_u_in_world.norm(), lv = q.edge_v_in_world.norm();
    if (!q.corner_in_world.allFinite() || !(std::isfinite(lu) && lu > 0) || !(std::isfinite(lv) && lv > 0))
      fail("has a non-finite corner or an empty edge");
    if (std::abs(q.edge_u_in_world.dot(q.edge_v_in_world)) > 1e-9 * lu * lv) fail("is not a rectangle");
    if (!(std::abs(q.normal_in_world.norm() - 1.0) < 1e-9) ||
        std::abs(q.normal_in_world.dot(q.edge_u_in_world)) > 1e-9 * lu ||
        std::abs(q.normal_in_world.dot(q.edge_v_in_world)) > 1e-9 * lv)
      fail("has a normal that is not a unit vector perpendicular to its edges");
    if (q.texture_cols < 2 || q.texture_rows < 2) fail("has a texture smaller than 2x2 texels");
    if (!(q.brightness >= 0)) fail("has a negative brightness");
    if (!(std::isfinite(q.point_weight) && q.point_weight >= 0)) fail("has a point_weight that is not >= 0");
  }
}

Scene PaperScene(double floor_half_size_m) {
  // Brightness per face (-x, +x, -y, +y, -z, +z) and the floor: faces differ, so the box's edges are visible.
  static constexpr float kLight[7] = {0.75f, 0.9f, 0.8f, 0.95f, 0.6f, 1.0f, 0.7f};
  const Eigen::Vector3d size(kPaperBoxSizeM[0], kPaperBoxSizeM[1], kPaperBoxSizeM[2]);
  const Eigen::Vector3d half = size / 2;
  Scene scene;
  for (int axis = 0; axis < 3; ++axis) {
    for (const double sign : {-1.0, 1.0}) {
      // Texture coordinates run along the next two axes, (axis+1) and (axis+2), on both faces of a pair.
      const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
      Quad q;
      q.corner_in_world = -half;
      q.corner_in_world[axis] = sign * half[axis];
      q.edge_u_in_world = Eigen::Vector3d::Zero();
      q.edge_u_in_world[a1] = size[a1];
      q.edge_v_in_world = Eigen::Vector3d::Zero();
      q.edge_v_in_world[a2] = size[a2];
      q.normal_in_world = Eigen::Vector3d::Zero();
      q.normal_in_world[axis] = sign;
      q.brightness = kLight[scene.quads.size()];
      scene.quads.push_back(q);
    }
  }
  const double s = floor_half_size_m;
  Quad floor;
  floor.corner_in_world = Eigen::Vector3d(-s, -s, -half.z());
  floor.edge_u_in_world = Eigen::Vector3d(2 * s, 0, 0);
  floor.edge_v_in_world = Eigen::Vector3d(0, 2 * s, 0);
  floor.normal_in_world = Eigen::Vector3d::UnitZ();
  floor.brightness = kLight[6];
  floor.point_weight = 0.0;  // the paper's points are on the box only
  scene.quads.push_back(floor);
  return scene;
}

QuadIntersector::QuadIntersector(const Scene& scene) {
  scene.Check();
  prepared_.reserve(scene.quads.size());
  for (const Quad& q : scene.quads) {
    Prepared p;
    p.corner = q.corner_in_world;
    p.edge_u = q.edge_u_in_world;
    p.edge_v = q.edge_v_in_world;
    p.normal = q.normal_in_world;
    p.inv_u2 = 1.0 / p.edge_u.squaredNorm();
    p.inv_v2 = 1.0 / p.edge_v.squaredNorm();
    p.normal_axis = AxisOf(p.normal);
    p.u_axis = AxisOf(p.edge_u);
    p.v_axis = AxisOf(p.edge_v);
    prepared_.push_back(p);
  }
}

std::optional<QuadHit> QuadIntersector::Nearest(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir,
                                                double t_min, double t_max) const {
  std::optional<QuadHit> best;
  QuadHit hit;
  for (int q = 0; q < static_cast<int>(prepared_.size()); ++q) {
    if (Hits(q, origin, dir, t_min, t_max, &hit)) {
      best = hit;
      t_max = hit.t;
    }
  }
  return best;
}

bool IsPointVisibleInScene(const PinholeCamera& camera, const Pose& cam_from_world, const QuadIntersector& scene,
                           const Eigen::Vector3d& point_in_world, const Eigen::Vector3d& normal_in_world,
                           Eigen::Vector2d* uv_px) {
  // Facing the camera, in front of it and in its image (sim/paper_scenario.h), then not hidden.
  Eigen::Vector2d uv;
  if (!IsPointVisible(camera, cam_from_world, point_in_world, normal_in_world, &uv)) return false;
  const Eigen::Vector3d center_in_world = cam_from_world.OriginOfTargetInSource();
  // The ray from the centre reaches the point at t = 1; its own quad is met there, not before. The margin
  // keeps a quad sharing the point's edge (a coplanar neighbour) from hiding it by rounding.
  const Eigen::Vector3d dir = point_in_world - center_in_world;
  for (int q = 0; q < static_cast<int>(scene.size()); ++q) {
    if (scene.Hits(q, center_in_world, dir, 0.0, 1.0 - 1e-9)) return false;
  }
  if (uv_px) *uv_px = uv;
  return true;
}

std::vector<int> LargestRemainderCounts(const std::vector<double>& weights, int total) {
  double total_weight = 0;
  for (const double w : weights) total_weight += w;
  if (!(total_weight > 0)) throw std::invalid_argument("LargestRemainderCounts: the weights add up to 0");
  std::vector<int> count(weights.size(), 0);
  std::vector<double> remainder(weights.size(), 0.0);
  int assigned = 0;
  for (size_t i = 0; i < weights.size(); ++i) {
    const double exact = total * weights[i] / total_weight;
    count[i] = static_cast<int>(std::floor(exact));
    remainder[i] = exact - count[i];
    assigned += count[i];
  }
  while (assigned < total) {
    const size_t i = static_cast<size_t>(std::max_element(remainder.begin(), remainder.end()) - remainder.begin());
    ++count[i];
    remainder[i] = -1.0;
    ++assigned;
  }
  return count;
}

void SamplePointsOnQuads(const Scene& scene, int num_points, uint64_t seed, uint32_t stream,
                         std::vector<Eigen::Vector3d>* points_in_world,
                         std::vector<Eigen::Vector3d>* normals_in_world) {
  std::vector<double> weights;
  weights.reserve(scene.quads.size());
  for (const Quad& q : scene.quads) weights.push_back(q.AreaM2() * q.point_weight);
  const std::vector<int> count = LargestRemainderCounts(weights, num_points);
  CounterRng rng(seed, stream);
  points_in_world->clear();
  normals_in_world->clear();
  points_in_world->reserve(static_cast<size_t>(num_points));
  normals_in_world->reserve(static_cast<size_t>(num_points));
  for (size_t i = 0; i < scene.quads.size(); ++i) {
    for (int k = 0; k < count[i]; ++k) {
      const double a = rng.Uniform(), b = rng.Uniform();
      points_in_world->push_back(scene.quads[i].At(a, b));
      normals_in_world->push_back(scene.quads[i].normal_in_world);
    }
  }
}

}  // namespace mcslam::sim
