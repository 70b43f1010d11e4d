#include "geometry/pnp.h"

#include <stdexcept>
#include <string>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

namespace mcslam::geometry {

std::optional<Pose> SolvePnp(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector2d>& uv,
                             const PnpOptions& o, int* num_inliers) {
  if (num_inliers) *num_inliers = 0;
  if (points.size() != uv.size())
    throw std::invalid_argument("SolvePnp: " + std::to_string(points.size()) + " points but " +
                                std::to_string(uv.size()) + " observations");
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
  cv::Mat R;
  cv::Rodrigues(rvec, R);
  Eigen::Matrix3d Re;
  Eigen::Vector3d te;
  cv::cv2eigen(R, Re);
  cv::cv2eigen(tvec, te);
  if (!Re.allFinite() || !te.allFinite()) return std::nullopt;
  if (num_inliers) *num_inliers = inliers.rows;
  return Pose::FromRotationTranslation(Re, te);
}

}  // namespace mcslam::geometry
