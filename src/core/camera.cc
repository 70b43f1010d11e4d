#include "core/camera.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include <fmt/format.h>

namespace mcslam {

PinholeCamera::PinholeCamera(double fx_, double fy_, double cx_, double cy_, int width_, int height_, Distortion d)
    : fx(fx_), fy(fy_), cx(cx_), cy(cy_), width(width_), height(height_), dist(d) {}

void PinholeCamera::Check() const {
  auto finite = [](double v) { return std::isfinite(v); };
  if (!finite(fx) || fx <= 0) throw std::invalid_argument(fmt::format("camera: fx must be positive, got {}", fx));
  if (!finite(fy) || fy <= 0) throw std::invalid_argument(fmt::format("camera: fy must be positive, got {}", fy));
  if (!finite(cx) || !finite(cy)) throw std::invalid_argument(fmt::format("camera: cx, cy must be finite, got {}, {}", cx, cy));
  if (width <= 0 || height <= 0)
    throw std::invalid_argument(fmt::format("camera: image size must be positive, got {}x{}", width, height));
  for (double v : {dist.k1, dist.k2, dist.p1, dist.p2, dist.k3, dist.k4})
    if (!finite(v)) throw std::invalid_argument("camera: distortion coefficients must be finite");
  if (dist.IsFisheye() && (dist.p1 != 0 || dist.p2 != 0))
    throw std::invalid_argument(fmt::format("camera: the equidistant (fisheye) model has no tangential terms, got p1 = {}, "
                                            "p2 = {}", dist.p1, dist.p2));
  if (!dist.IsFisheye() && dist.k4 != 0)
    throw std::invalid_argument(fmt::format("camera: k4 = {} belongs to the equidistant (fisheye) model only", dist.k4));
  // A focal length that leaves almost no field of view is a unit mistake (millimetres or metres for pixels is
  // the other way round; a typo of a few digits this way): the features could never show parallax. The
  // narrowest real lenses (astronomy, 2000 mm on a small sensor) see ~0.3 deg; refuse below a tenth of that.
  constexpr double kMinFovDeg = 0.03;
  const double fov_x_deg = 2.0 * std::atan(0.5 * width / fx) * 180.0 / M_PI;
  const double fov_y_deg = 2.0 * std::atan(0.5 * height / fy) * 180.0 / M_PI;
  if (fov_x_deg < kMinFovDeg || fov_y_deg < kMinFovDeg)
    throw std::invalid_argument(fmt::format(
        "camera: fx = {:g}, fy = {:g} px leave a field of view of {:.3g} x {:.3g} deg on a {}x{} image (at least "
        "{} deg expected): are the focal lengths in pixels?",
        fx, fy, fov_x_deg, fov_y_deg, width, height, kMinFovDeg));
}

Eigen::Matrix3d PinholeCamera::K() const {
  Eigen::Matrix3d k;
  k << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  return k;
}

Eigen::Vector2d PinholeCamera::NormalizedToPixel(const Eigen::Vector2d& n) const {
  return {fx * n.x() + cx, fy * n.y() + cy};
}

const char* ToString(LensModel model) {
  return model == LensModel::kEquidistant ? "equidistant" : "radial-tangential";
}

namespace {

// Kannala-Brandt: theta_d(theta) and its derivative.
double ThetaD(const Distortion& d, double theta, double* derivative = nullptr) {
  const double t2 = theta * theta;
  const double poly = 1.0 + t2 * (d.k1 + t2 * (d.k2 + t2 * (d.k3 + t2 * d.k4)));
  if (derivative) *derivative = 1.0 + t2 * (3.0 * d.k1 + t2 * (5.0 * d.k2 + t2 * (7.0 * d.k3 + t2 * 9.0 * d.k4)));
  return theta * poly;
}

// n -> n / r * theta_d(atan r), with its Jacobian: J = s I + (ds/dr) / r n n^T, s = theta_d / r.
Eigen::Vector2d DistortEquidistant(const Distortion& d, const Eigen::Vector2d& n, Eigen::Matrix2d* J) {
  const double r = n.norm();
  if (r < 1e-12) {  // theta_d = theta + O(theta^3) = r + O(r^3): the identity to first order
    if (J) J->setIdentity();
    return n;
  }
  const double theta = std::atan(r);
  double dtd_dtheta = 0;
  const double td = ThetaD(d, theta, J ? &dtd_dtheta : nullptr);
  const double s = td / r;
  if (J) {
    const double ds_dr = (dtd_dtheta / (1.0 + r * r) - s) / r;
    *J = s * Eigen::Matrix2d::Identity() + (ds_dr / r) * n * n.transpose();
  }
  return s * n;
}

// The inverse: theta from theta_d = |n_d| by Newton (theta_d grows with theta for any lens that maps its image one to
// one), then r = tan(theta). Angles are capped just under 90 degrees, where the pinhole's r is unbounded.
Eigen::Vector2d UndistortEquidistant(const Distortion& d, const Eigen::Vector2d& nd) {
  const double td = nd.norm();
  if (td < 1e-12) return nd;
  constexpr double kMaxTheta = M_PI / 2 - 1e-6;
  double theta = std::min(td, kMaxTheta);
  for (int it = 0; it < 30; ++it) {
    double dtd = 0;
    const double f = ThetaD(d, theta, &dtd) - td;
    if (std::abs(f) < 1e-15 || !(dtd > 0)) break;
    theta = std::clamp(theta - f / dtd, 0.0, kMaxTheta);
  }
  return nd * (std::tan(theta) / td);
}

}  // namespace

Eigen::Vector2d PinholeCamera::Distort(const Eigen::Vector2d& n, Eigen::Matrix2d* J) const {
  if (dist.IsFisheye()) return DistortEquidistant(dist, n, J);
  const double x = n.x(), y = n.y();
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (dist.k1 + r2 * (dist.k2 + r2 * dist.k3));
  const double xd = x * radial + 2.0 * dist.p1 * x * y + dist.p2 * (r2 + 2.0 * x * x);
  const double yd = y * radial + dist.p1 * (r2 + 2.0 * y * y) + 2.0 * dist.p2 * x * y;
  if (J) {
    const double dradial_dr2 = dist.k1 + r2 * (2.0 * dist.k2 + 3.0 * dist.k3 * r2);
    const double dr_dx = 2.0 * x * dradial_dr2, dr_dy = 2.0 * y * dradial_dr2;
    (*J)(0, 0) = radial + x * dr_dx + 2.0 * dist.p1 * y + 6.0 * dist.p2 * x;
    (*J)(0, 1) = x * dr_dy + 2.0 * dist.p1 * x + 2.0 * dist.p2 * y;
    (*J)(1, 0) = y * dr_dx + 2.0 * dist.p1 * x + 2.0 * dist.p2 * y;
    (*J)(1, 1) = radial + y * dr_dy + 6.0 * dist.p1 * y + 2.0 * dist.p2 * x;
  }
  return {xd, yd};
}

Eigen::Vector2d PinholeCamera::Undistort(const Eigen::Vector2d& d) const {
  if (!HasDistortion()) return d;
  if (dist.IsFisheye()) return UndistortEquidistant(dist, d);
  Eigen::Vector2d n = d;  // the distortion is small near the centre: start from the distorted point
  for (int it = 0; it < 30; ++it) {
    Eigen::Matrix2d J;
    const Eigen::Vector2d r = Distort(n, &J) - d;
    if (r.squaredNorm() < 1e-28) break;
    n -= J.inverse() * r;
  }
  return n;
}

bool PinholeCamera::Project(const Eigen::Vector3d& p, Eigen::Vector2d* uv_px, Eigen::Matrix<double, 2, 3>* J_point,
                            double min_depth) const {
  if (!(p.z() > min_depth)) return false;
  const double iz = 1.0 / p.z();
  const Eigen::Vector2d n(p.x() * iz, p.y() * iz);
  Eigen::Matrix2d Jd = Eigen::Matrix2d::Identity();
  const Eigen::Vector2d nd = HasDistortion() ? Distort(n, J_point ? &Jd : nullptr) : n;
  if (uv_px) *uv_px = NormalizedToPixel(nd);
  if (J_point) {
    Eigen::Matrix<double, 2, 3> Jn;
    Jn << iz, 0, -n.x() * iz, 0, iz, -n.y() * iz;
    Eigen::Matrix2d F;
    F << fx, 0, 0, fy;
    *J_point = F * Jd * Jn;
  }
  return true;
}

bool PinholeCamera::ProjectWorld(const Pose& cam_from_world, const Eigen::Vector3d& point_in_world,
                                 Eigen::Vector2d* uv_px, Eigen::Matrix<double, 2, 3>* J_world,
                                 Eigen::Matrix<double, 2, 3>* J_translation) const {
  Eigen::Matrix<double, 2, 3> J_cam;
  const bool want_j = J_world || J_translation;
  if (!Project(cam_from_world * point_in_world, uv_px, want_j ? &J_cam : nullptr)) return false;
  if (J_translation) *J_translation = J_cam;  // d(Rz + t)/dt = I
  if (J_world) *J_world = J_cam * cam_from_world.R();
  return true;
}

Eigen::Vector2d PinholeCamera::UndistortPixel(const Eigen::Vector2d& uv_px) const {
  const Eigen::Vector2d n = Undistort(PixelToNormalized(uv_px));
  static const double max_r2 = std::pow(std::tan(kMaxPinholeRayAngleDeg * M_PI / 180.0), 2);
  if (dist.IsFisheye() && n.squaredNorm() > max_r2) return Eigen::Vector2d::Constant(std::nan(""));
  return NormalizedToPixel(n);
}

PinholeCamera PinholeCamera::Scaled(double f) const {
  // Pixel centres: u' + 0.5 = f (u + 0.5)
  PinholeCamera c = *this;
  c.fx *= f;
  c.fy *= f;
  c.cx = f * (cx + 0.5) - 0.5;
  c.cy = f * (cy + 0.5) - 0.5;
  c.width = static_cast<int>(std::lround(width * f));
  c.height = static_cast<int>(std::lround(height * f));
  return c;
}

std::string PinholeCamera::ToString() const {
  if (dist.IsFisheye())
    return fmt::format("fisheye (equidistant) {}x{} fx={} fy={} cx={} cy={} k1={} k2={} k3={} k4={}", width, height, fx,
                       fy, cx, cy, dist.k1, dist.k2, dist.k3, dist.k4);
  return fmt::format("pinhole {}x{} fx={} fy={} cx={} cy={} k1={} k2={} p1={} p2={} k3={}", width, height, fx, fy, cx,
                     cy, dist.k1, dist.k2, dist.p1, dist.p2, dist.k3);
}

}  // namespace mcslam
