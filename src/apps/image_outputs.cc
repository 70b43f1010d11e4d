#include "apps/image_outputs.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <Eigen/Eigenvalues>
#include <opencv2/imgcodecs.hpp>

namespace mcslam::apps {

void WriteTopView(const std::string& path, const std::vector<Eigen::Vector3d>& reference,
                  const std::vector<Eigen::Vector3d>& estimate, const std::vector<std::string>& caption) {
  const std::vector<Eigen::Vector3d>& basis_points = reference.size() >= 2 ? reference : estimate;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : basis_points) mean += p;
  mean /= std::max<double>(1.0, static_cast<double>(basis_points.size()));
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& p : basis_points) cov += (p - mean) * (p - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  // Eigenvalues ascending: the two largest span the view.
  const Eigen::Vector3d e1 = eig.eigenvectors().col(2), e2 = eig.eigenvectors().col(1);
  auto to2d = [&](const Eigen::Vector3d& p) { return Eigen::Vector2d((p - mean).dot(e1), (p - mean).dot(e2)); };
  Eigen::Vector2d lo(std::numeric_limits<double>::max(), std::numeric_limits<double>::max()), hi = -lo;
  for (const auto* set : {&reference, &estimate})
    for (const Eigen::Vector3d& p : *set) {
      const Eigen::Vector2d q = to2d(p);
      lo = lo.cwiseMin(q), hi = hi.cwiseMax(q);
    }
  const int W = 900, H = 900, margin = 70;
  cv::Mat canvas(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  if (!(hi.array() >= lo.array()).all()) lo = hi = Eigen::Vector2d::Zero();
  const Eigen::Vector2d span = (hi - lo).cwiseMax(1e-9);
  const double scale = std::min((W - 2.0 * margin) / span.x(), (H - 2.0 * margin - 60) / span.y());
  const Eigen::Vector2d centre = 0.5 * (lo + hi);
  auto px = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector2d q = to2d(p) - centre;
    return cv::Point2d(W / 2.0 + scale * q.x(), (H + 60) / 2.0 - scale * q.y());
  };
  auto polyline = [&](const std::vector<Eigen::Vector3d>& pts, const cv::Scalar& colour) {
    for (size_t i = 1; i < pts.size(); ++i) cv::line(canvas, px(pts[i - 1]), px(pts[i]), colour, 2, cv::LINE_AA);
    for (const Eigen::Vector3d& p : pts) cv::circle(canvas, px(p), 2, colour, cv::FILLED, cv::LINE_AA);
    if (!pts.empty()) cv::circle(canvas, px(pts.front()), 7, colour, 2, cv::LINE_AA);
  };
  polyline(reference, cv::Scalar(60, 160, 0));
  polyline(estimate, cv::Scalar(0, 0, 220));
  // Scale bar: the largest power of ten (times 1, 2 or 5) that fits in a fifth of the width.
  const double target = (W - 2.0 * margin) / 5.0 / scale;
  double bar = std::pow(10.0, std::floor(std::log10(std::max(target, 1e-9))));
  for (double m : {5.0, 2.0})
    if (bar * m <= target) {
      bar *= m;
      break;
    }
  const cv::Point2d b0(margin, H - 25.0), b1(margin + bar * scale, H - 25.0);
  cv::line(canvas, b0, b1, cv::Scalar(0, 0, 0), 2);
  cv::putText(canvas, fmt::format("{:g} m", bar), b1 + cv::Point2d(10, 5), cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  int y = 24;
  for (const std::string& line : caption) {
    cv::putText(canvas, line, cv::Point(12, y), cv::FONT_HERSHEY_SIMPLEX, 0.55, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    y += 22;
  }
  if (!reference.empty())
    cv::putText(canvas, "ground truth", cv::Point(W - 260, H - 42), cv::FONT_HERSHEY_SIMPLEX, 0.55,
                cv::Scalar(60, 160, 0), 2, cv::LINE_AA);
  cv::putText(canvas, reference.empty() ? "estimate" : "estimate (Sim(3)-aligned)", cv::Point(W - 260, H - 20),
              cv::FONT_HERSHEY_SIMPLEX, 0.55, cv::Scalar(0, 0, 220), 2, cv::LINE_AA);
  if (!cv::imwrite(path, canvas)) throw std::runtime_error(fmt::format("--plot {}: cannot write the image", path));
}

}  // namespace mcslam::apps
