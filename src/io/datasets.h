#pragma once
// Datasets: a folder (or file) opened as a frame source, with the camera and the ground truth it carries.
// Layouts read (kind detected from the folder content, or named):
//   images     any folder of .png/.jpg/.jpeg/.pgm/.ppm/.bmp, sorted by name; stamps from times.txt /
//              timestamps.txt / DatasetOptions::timestamps_path, else index / fps; camera.yaml or
//              camera.txt in the folder when present
//   video      a video file (cv::VideoCapture); webcam: the path "webcam:N" (or kind webcam, path "N")
//   kitti      KITTI odometry sequence: image_0/*.png, calib.txt (P0 line, with or without "P0:"),
//              times.txt, ground truth poses.txt in the folder or ../../poses/<sequence>.txt
//   tum        TUM RGB-D: rgb.txt ("timestamp filename"), groundtruth.txt (interpolated at the frames);
//              camera from camera.yaml / camera.txt in the folder, else TUM's fr1/fr2/fr3 colour camera
//              chosen by the folder name ("freiburg3", "fr3")
//   euroc      EuRoC MAV: mav0/cam0/data.csv + data/*.png, mav0/cam0/sensor.yaml (intrinsics,
//              distortion, resolution, T_BS), ground truth mav0/state_groundtruth_estimate0/data.csv
//              (body poses, turned into camera poses with T_BS and interpolated at the frames)
//   7scenes    Microsoft 7-Scenes style: color/frame-NNNNNN.color.(jpg|png) + pose/frame-NNNNNN.pose.txt
//              (or both beside each other, as in the original seq-NN folders), 4x4 camera-to-world;
//              camera-intrinsics.txt (3x3 K); stamps index / fps (30 Hz)
//   synthetic  a folder written by `mcslam synth`: camera.yaml, groundtruth.txt (TUM), images/ if present
// Ground truth is always world_from_cam with the stamps of the frames it belongs to.
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/camera.h"
#include "io/image_source.h"
#include "io/trajectory_io.h"

namespace mcslam::io {

enum class DatasetKind { kAuto, kImageFolder, kVideo, kWebcam, kKitti, kTum, kEuroc, kSevenScenes, kSynthetic };

// "auto" | "images" | "video" | "webcam" | "kitti" | "tum" | "euroc" | "7scenes" | "synthetic";
// throws std::invalid_argument naming the value.
DatasetKind ParseDatasetKind(const std::string& name);
std::string ToString(DatasetKind kind);
// From the folder content (see the list at the top). Throws std::runtime_error naming the path when it
// does not exist or nothing in it says what it is.
DatasetKind DetectDatasetKind(const std::string& path);

struct DatasetOptions {
  DatasetKind kind = DatasetKind::kAuto;
  // Replaces the dataset's own camera (e.g. 7-Scenes, whose camera-intrinsics.txt holds the depth
  // camera's K). Its image size must match the frames.
  std::optional<PinholeCamera> camera;
  // A camera file replacing the dataset's own (used when `camera` is not set): YAML (ReadCameraYaml) when
  // it ends in .yaml/.yml, else text (ReadCameraText; the image size then comes from the frames).
  std::string camera_path;
  // Frame rate for the stamps of datasets without stamps (index / fps); 0: the kind's own (KITTI 10,
  // others 30; a video's container rate).
  double fps = 0.0;
  // Image folders: a timestamps file, one a line, one per image (see ImageFolderOptions).
  std::string timestamps_path;
  // TUM / EuRoC: the ground truth is interpolated at a frame only when a ground-truth sample lies within
  // this many seconds of it (TUM's associate.py uses 0.02 s).
  double gt_max_dt_s = 0.02;
  // Check that the camera's image size is that of the frames (OpenDataset throws otherwise).
  bool check_image_size = true;
  // Throws std::invalid_argument naming the bad field.
  void Check() const;
};

struct Dataset {
  DatasetKind kind = DatasetKind::kAuto;
  std::string path;
  std::unique_ptr<ImageSource> source;  // never null; may hold no frame (a synthetic folder without images)
  std::optional<PinholeCamera> camera;  // when the dataset (or the options) define one
  std::string camera_origin;            // where the camera came from, for messages ("calib.txt P0", ...)
  std::optional<cv::Size> image_size;   // of the frames, when known before reading them
  // world_from_cam at the frames that have one, with the frames' stamps; absent when the dataset has none.
  std::optional<Trajectory> ground_truth;
  // For each ground-truth pose, the index of its frame in `source` (same length as ground_truth).
  std::vector<int64_t> ground_truth_frames;
  // Caveats worth telling the user (an uncalibrated camera, frames without ground truth, ...).
  std::vector<std::string> notes;
};

// Opens the dataset at `path`. Throws std::runtime_error naming the file and the value for a missing or
// malformed file, an unknown layout, a camera whose size differs from the frames (before any frame is
// processed), or ground truth that cannot be paired with the frames.
Dataset OpenDataset(const std::string& path, const DatasetOptions& options = {});

// Throws std::runtime_error when camera.width/height differ from `size`, saying both and `what` (where
// the frames come from); when the aspect ratio matches, it names the scale that would fit.
void CheckCameraMatchesImageSize(const PinholeCamera& camera, const cv::Size& size, const std::string& what);

// A one-line camera text file: "fx fy cx cy", "fx fy cx cy k1 k2 p1 p2" or "fx fy cx cy k1 k2 p1 p2 k3"
// ('#' lines skipped), with the given image size. Throws "<path>:<line>: <what>".
PinholeCamera ReadCameraText(const std::string& path, int width, int height);
// A 3x3 intrinsics matrix, 3 lines of 3 numbers (7-Scenes camera-intrinsics.txt), with the given size.
PinholeCamera ReadIntrinsicsMatrix(const std::string& path, int width, int height);
// TUM RGB-D colour camera of Freiburg 1, 2 or 3 (640x480), as published by TUM. Throws for another number.
PinholeCamera TumColorCamera(int freiburg);

// The trajectory `samples` at `stamps_s`: at each stamp with a sample within max_dt_s, the pose
// interpolated (position linearly, rotation by slerp) between the samples around it, or the nearest
// sample when the stamp lies outside them or they are more than 2 max_dt_s apart. Stamps with no sample
// that near are skipped; `used` (optional) receives the index into stamps_s of each output pose.
// `samples` must be sorted by stamp.
Trajectory SampleTrajectoryAt(const Trajectory& samples, const std::vector<double>& stamps_s, double max_dt_s,
                              std::vector<int64_t>* used = nullptr);

}  // namespace mcslam::io
