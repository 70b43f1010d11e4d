#pragma once
// Feature observations: the seam between a front end and the SLAM back end. Text format, one observation
// a line, whitespace separated:
//   frame_index timestamp_s feature_id u_px v_px
// frame_index counts from 0 and does not decrease; a frame with no observation may be absent, and frames
// with no observation but a timestamp may be declared by a line "frame_index timestamp_s" (2 columns).
// Lines starting with '#' are comments. u, v are distorted pixel coordinates, as a camera would see them.
#include <cstdint>
#include <fstream>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace mcslam::io {

struct Observation {
  int64_t feature_id = 0;
  double u_px = 0, v_px = 0;
};

struct ObservationFrame {
  int64_t index = 0;
  double stamp_s = 0;
  std::vector<Observation> observations;
};

// Frames in file order, one per distinct frame_index. Throws std::runtime_error "<path>:<line>: <what>"
// for a missing file, a malformed line, a non-finite value, a decreasing frame index, a timestamp that
// differs within one frame, or a feature id seen twice in one frame.
std::vector<ObservationFrame> ReadObservations(const std::string& path);
void WriteObservations(const std::string& path, const std::vector<ObservationFrame>& frames);

// The same file written a frame at a time, as a run produces them (what was appended survives a run that stops
// early). Append refuses what ReadObservations would refuse (std::invalid_argument naming the file and frame);
// Close flushes and checks the write (std::runtime_error naming the file).
class ObservationWriter {
 public:
  explicit ObservationWriter(std::string path);  // creates or truncates the file, writes the header
  void Append(const ObservationFrame& frame);
  void Close();

 private:
  std::string path_;
  std::ofstream out_;
  std::optional<std::pair<int64_t, double>> last_;  // the last frame appended: index, stamp
};

}  // namespace mcslam::io
