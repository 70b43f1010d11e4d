#pragma once
// The synthetic worlds, as textured planar rectangles ("quads"): the paper's box is six of them and its floor
// a seventh; a street, a room or a poster on a wall are more of the same. One description serves both uses:
// the observation-only sequences (points sampled on the quads, seen when nothing nearer is on the ray) and
// the rendered images (the same quads ray-cast, textures made from the seed), so the two never disagree.
//
// A quad is one-sided: it is seen only from the side its normal points to (a wall's inside is never looked
// at), which also halves the work of the ray-caster.
#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/camera.h"
#include "core/pose.h"

namespace mcslam::sim {

// How a quad's texture is drawn (sim/render.cc makes it from the render seed).
enum class TextureStyle {
  kBlobs,   // the paper's: high-contrast random discs and bars, corners at several scales (a printed poster)
  kFacade,  // mostly rectangles of varied size and grey (windows, signs, bricks), fewer discs
  kGround,  // many small low-contrast speckles (asphalt, pavement), a few bright marks
  kSmooth,  // low texture: a smooth low-contrast shading with a handful of distinct blobs (few corners)
};

struct Quad {
  // The rectangle corner + a * edge_u + b * edge_v, a and b in [0, 1]; (a, b) are its texture coordinates.
  Eigen::Vector3d corner_in_world = Eigen::Vector3d::Zero();
  Eigen::Vector3d edge_u_in_world = Eigen::Vector3d::UnitX();
  Eigen::Vector3d edge_v_in_world = Eigen::Vector3d::UnitY();
  // Unit normal of the side that is seen, +-(edge_u x edge_v) normalised (explicit, so that the box's six
  // faces keep one texture orientation whatever side faces out).
  Eigen::Vector3d normal_in_world = Eigen::Vector3d::UnitZ();
  TextureStyle style = TextureStyle::kBlobs;
  float brightness = 1.0f;  // fixed light: neighbouring quads differ, so their common edge is visible
  int texture_cols = 512;   // texture size in texels along edge_u and edge_v
  int texture_rows = 512;
  double point_weight = 1.0;  // observation points per square metre, relative to the other quads; 0: none

  double AreaM2() const { return edge_u_in_world.norm() * edge_v_in_world.norm(); }
  Eigen::Vector3d At(double a, double b) const { return corner_in_world + a * edge_u_in_world + b * edge_v_in_world; }
};

// A quad facing `normal`, texture sized to texels_per_m along each edge (at least 16 texels, at most 2048).
Quad MakeQuad(const Eigen::Vector3d& corner, const Eigen::Vector3d& edge_u, const Eigen::Vector3d& edge_v,
              const Eigen::Vector3d& normal, TextureStyle style, double texels_per_m, float brightness = 1.0f,
              double point_weight = 1.0);

struct Scene {
  std::vector<Quad> quads;
  float background = 0.35f;  // grey level (0-1) where a ray meets nothing

  // Throws std::invalid_argument naming the bad quad and what is wrong (not a rectangle, normal not unit or
  // not perpendicular, texture smaller than 2x2, negative weight).
  void Check() const;
};

// The paper's world (§8.1): the box kPaperBoxSizeM centred at the origin, faces in the order -x, +x, -y, +y,
// -z, +z (quads 0-5, points on them), on a floor square of floor_half_size_m at the box's bottom (quad 6, no
// points): the layout the renderer had before scenes were made of quads.
Scene PaperScene(double floor_half_size_m = 4.0);

// The nearest quad on a ray: quad index, the ray parameter t (point = origin + t * dir) and texture
// coordinates (a, b) in [0, 1].
struct QuadHit {
  int quad = -1;
  double t = 0;
  double a = 0, b = 0;
};

// Quads laid out for ray casting: per quad the axis of its normal and edges when they lie along world axes
// (then the intersection is one division per coordinate, the arithmetic of a box's slab test, so the
// paper's images stay what they were), else the general plane intersection.
class QuadIntersector {
 public:
  explicit QuadIntersector(const Scene& scene);
  // The nearest front-facing quad met by origin + t * dir with t in (t_min, t_max).
  std::optional<QuadHit> Nearest(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double t_min,
                                 double t_max) const;
  // True when the ray meets quad q (front side) with t in (t_min, t_max); *hit filled when given. Inline:
  // the renderer calls it for every sample.
  bool Hits(int q, const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, double t_min, double t_max,
            QuadHit* hit = nullptr) const {
    const Prepared& p = prepared_[static_cast<size_t>(q)];
    double t;
    if (p.normal_axis >= 0) {
      const int k = p.normal_axis;
      if (!(p.normal[k] * dir[k] < 0)) return false;  // parallel, or seen from behind
      t = (p.corner[k] - origin[k]) / dir[k];
    } else {
      const double facing = p.normal.dot(dir);
      if (!(facing < 0)) return false;
      t = p.normal.dot(p.corner - origin) / facing;
    }
    if (!(t > t_min && t < t_max)) return false;
    const Eigen::Vector3d x = origin + t * dir;
    const double a = p.u_axis >= 0 ? (x[p.u_axis] - p.corner[p.u_axis]) / p.edge_u[p.u_axis]
                                   : (x - p.corner).dot(p.edge_u) * p.inv_u2;
    if (!(a >= 0 && a <= 1)) return false;
    const double b = p.v_axis >= 0 ? (x[p.v_axis] - p.corner[p.v_axis]) / p.edge_v[p.v_axis]
                                   : (x - p.corner).dot(p.edge_v) * p.inv_v2;
    if (!(b >= 0 && b <= 1)) return false;
    if (hit) *hit = QuadHit{q, t, a, b};
    return true;
  }
  size_t size() const { return prepared_.size(); }

 private:
  struct Prepared {
    Eigen::Vector3d corner, edge_u, edge_v, normal;
    double inv_u2 = 0, inv_v2 = 0;  // 1 / |edge|^2, for edges not along an axis
    int normal_axis = -1, u_axis = -1, v_axis = -1;  // >= 0 when along a world axis
  };
  std::vector<Prepared> prepared_;
};

// True when point_in_world, on a quad with outward normal normal_in_world, is seen by the camera: it faces
// the camera centre, its depth exceeds kMinDepthM, its exact projection is in the image, and no quad of the
// scene meets the ray from the camera centre to it before it (exact occlusion, any scene). On true, *uv_px
// (when given) holds the exact projection.
bool IsPointVisibleInScene(const PinholeCamera& camera, const Pose& cam_from_world, const QuadIntersector& scene,
                           const Eigen::Vector3d& point_in_world, const Eigen::Vector3d& normal_in_world,
                           Eigen::Vector2d* uv_px = nullptr);

// Splits `total` into integer counts proportional to `weights` (>= 0, not all 0) by largest remainder, so
// that they add up to total exactly; ties go to the lower index (deterministic).
std::vector<int> LargestRemainderCounts(const std::vector<double>& weights, int total);

// num_points points uniform on the quads, counts proportional to area * point_weight (LargestRemainderCounts),
// quad by quad in scene order; normals are the quads' normals. Deterministic in (seed, stream).
void SamplePointsOnQuads(const Scene& scene, int num_points, uint64_t seed, uint32_t stream,
                         std::vector<Eigen::Vector3d>* points_in_world, std::vector<Eigen::Vector3d>* normals_in_world);

}  // namespace mcslam::sim
