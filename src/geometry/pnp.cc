#include "geometry/pnp.h"

#include <random>
#include <stdexcept>
#include <string>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

namespace mcslam::geometry {

namespace {

// cam_from_world from OpenCV's rotation vector and translation; nothing when not finite.
std::optional<Pose> FromCv(const cv::Mat& rvec, const cv::Mat& tvec) {
  cv::Mat R;
  cv::Rodrigues(rvec, R);
  Eigen::Matrix3d Re;
  Eigen::Vector3d te;
  cv::cv2eigen(R, Re);
  cv::cv2eigen(tvec, te);
  if (!Re.allFinite() || !te.allFinite()) return std::nullopt;
  return Pose::FromRotationTranslation(Re, te);
}

void CheckSizes(const char* who, size_t points, size_t observations) {
  if (points != observations)
    throw std::invalid_argument(std::string(who) + ": " + std::to_string(points) + " points but " +
                                std::to_string(observations) + " observations");
}

}  // namespace

std::optional<Pose> SolvePnp(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector2d>& uv,
                             const PnpOptions& o, int* num_inliers) {
  if (num_inliers) *num_inliers = 0;
  CheckSizes("SolvePnp", points.size(), uv.size());
  const size_t n = points.size();
  if (n < 4 || static_cast<int>(n) < o.min_inliers) return std::nullopt;
  std::vector<cv::Point3d> obj(n);
  std::vector<cv::Point2d> img(n);
  for (size_t i = 0; i < n; ++i) {
    obj[i] = {points[i].x(), points[i].y(), points[i].z()};
    img[i] = {uv[i].x(), uv[i].y()};
  }
  cv::Mat rvec, tvec, inliers;
  const cv::Mat K = cv::Mat::eye(3, 3, CV_64F);  // normalised coordinates
  const bool ok = cv::solvePnPRansac(obj, img, K, cv::noArray(), rvec, tvec, false, o.iterations,
                                     o.threshold_px / o.focal_px, 0.999, inliers, cv::SOLVEPNP_EPNP);
  if (!ok || inliers.rows < std::max(4, o.min_inliers)) return std::nullopt;
  // Refine on the inliers (Levenberg-Marquardt).
  std::vector<cv::Point3d> obj_in;
  std::vector<cv::Point2d> img_in;
  for (int i = 0; i < inliers.rows; ++i) obj_in.push_back(obj[inliers.at<int>(i)]), img_in.push_back(img[inliers.at<int>(i)]);
  cv::solvePnPRefineLM(obj_in, img_in, K, cv::noArray(), rvec, tvec);
  const std::optional<Pose> pose = FromCv(rvec, tvec);
  if (pose && num_inliers) *num_inliers = inliers.rows;
  return pose;
}

std::optional<Pose> SolvePnpNearRotation(const std::vector<Eigen::Vector3d>& points,
                                         const std::vector<Eigen::Vector2d>& uv, const PnpOptions& o,
                                         const Eigen::Quaterniond& prior, double max_deg, uint64_t seed,
                                         int* num_inliers) {
  if (num_inliers) *num_inliers = 0;
  CheckSizes("SolvePnpNearRotation", points.size(), uv.size());
  const size_t n = points.size();
  if (n < 4 || static_cast<int>(n) < o.min_inliers) return std::nullopt;
  const double threshold = o.threshold_px / o.focal_px;
  auto inliers_of = [&](const Pose& pose, std::vector<int>* which) {
    which->clear();
    for (size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d x = pose * points[i];
      if (x.z() > 0 && (x.head<2>() / x.z() - uv[i]).norm() < threshold) which->push_back(static_cast<int>(i));
    }
    return static_cast<int>(which->size());
  };
  const cv::Mat K = cv::Mat::eye(3, 3, CV_64F);
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<size_t> pick(0, n - 1);
  std::vector<int> best, which;
  for (int it = 0; it < o.iterations; ++it) {
    size_t s[3] = {pick(rng), pick(rng), pick(rng)};
    if (s[0] == s[1] || s[0] == s[2] || s[1] == s[2]) continue;
    std::vector<cv::Point3d> obj;
    std::vector<cv::Point2d> img;
    for (size_t k : s) obj.emplace_back(points[k].x(), points[k].y(), points[k].z()), img.emplace_back(uv[k].x(), uv[k].y());
    std::vector<cv::Mat> rvecs, tvecs;
    if (cv::solveP3P(obj, img, K, cv::noArray(), rvecs, tvecs, cv::SOLVEPNP_P3P) <= 0) continue;
    for (size_t k = 0; k < rvecs.size(); ++k) {
      const std::optional<Pose> pose = FromCv(rvecs[k], tvecs[k]);
      if (!pose || AngularDistanceDeg(pose->q, prior) > max_deg) continue;
      if (inliers_of(*pose, &which) > static_cast<int>(best.size())) best = which;
    }
  }
  if (static_cast<int>(best.size()) < std::max(4, o.min_inliers)) return std::nullopt;
  std::vector<cv::Point3d> obj_in;
  std::vector<cv::Point2d> img_in;
  for (int i : best) obj_in.emplace_back(points[i].x(), points[i].y(), points[i].z()), img_in.emplace_back(uv[i].x(), uv[i].y());
  cv::Mat rvec, tvec;
  if (!cv::solvePnP(obj_in, img_in, K, cv::noArray(), rvec, tvec, false, cv::SOLVEPNP_EPNP)) return std::nullopt;
  cv::solvePnPRefineLM(obj_in, img_in, K, cv::noArray(), rvec, tvec);
  const std::optional<Pose> pose = FromCv(rvec, tvec);
  if (!pose || AngularDistanceDeg(pose->q, prior) > max_deg) return std::nullopt;
  const int count = inliers_of(*pose, &which);
  if (count < std::max(4, o.min_inliers)) return std::nullopt;
  if (num_inliers) *num_inliers = count;
  return pose;
}

}  // namespace mcslam::geometry
