#pragma once
// Camera calibration files. Written in the ORB-SLAM2 style (%YAML:1.0, Camera.fx ... Camera.width), which
// ORB-SLAM2/3 and OpenCV FileStorage read too. Read: that style, the ORB-SLAM3 style (Camera1.fx ...,
// Camera.type: "PinHole"), and mcslam's own small YAML (fx fy cx cy width height [k1 k2 p1 p2 k3]).
#include <string>

#include "core/camera.h"

namespace mcslam::io {

// Throws std::runtime_error naming the file and the missing or bad key; the result passes Check().
PinholeCamera ReadCameraYaml(const std::string& path);
// fps <= 0 leaves Camera.fps out.
void WriteCameraYaml(const std::string& path, const PinholeCamera& camera, double fps = 0.0);

}  // namespace mcslam::io
