#pragma once
// PLY point clouds (ASCII, readable by MeshLab, CloudCompare, Open3D). Each vertex has x y z (float64),
// optional red green blue (uchar) and an optional integer id (the feature / map point id).
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace mcslam::io {

struct PointCloud {
  std::vector<Eigen::Vector3d> points;
  std::vector<int64_t> ids;                       // empty, or one per point
  std::vector<Eigen::Matrix<uint8_t, 3, 1>> rgb;  // empty, or one per point
};

void WritePly(const std::string& path, const PointCloud& cloud);
// Reads ASCII PLY vertex elements with at least x y z; throws std::runtime_error naming the file (and line).
PointCloud ReadPly(const std::string& path);

}  // namespace mcslam::io
