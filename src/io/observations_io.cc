#include "io/observations_io.h"

#include <cmath>
#include <optional>
#include <utility>
#include <stdexcept>
#include <unordered_set>

#include <fmt/format.h>

#include "io/text_util.h"

namespace mcslam::io {

std::vector<ObservationFrame> ReadObservations(const std::string& path) {
  detail::LineReader r(path);
  std::vector<ObservationFrame> frames;
  std::unordered_set<int64_t> ids_in_frame;  // of frames.back()
  std::string line;
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    const auto tok = detail::SplitWhitespace(line);
    if (tok.size() != 5 && tok.size() != 2)
      r.Fail(fmt::format("expected 5 columns (frame_index timestamp_s feature_id u_px v_px) or 2 (frame_index "
                         "timestamp_s), found {}",
                         tok.size()));
    const int64_t index = detail::ParseInteger(tok[0], r, "frame_index");
    if (index < 0) r.Fail(fmt::format("frame_index {} is negative", index));
    const double stamp_s = detail::ParseFinite(tok[1], r, "timestamp_s");

    if (frames.empty() || index > frames.back().index) {
      if (!frames.empty() && stamp_s < frames.back().stamp_s)
        r.Fail(fmt::format("timestamp {} of frame {} goes back in time (frame {} has {})", tok[1], index,
                           frames.back().index, detail::FormatStamp(frames.back().stamp_s)));
      frames.push_back(ObservationFrame{index, stamp_s, {}});
      ids_in_frame.clear();
    } else if (index < frames.back().index) {
      r.Fail(fmt::format("frame_index {} after {}: frame indices must not decrease", index, frames.back().index));
    } else if (stamp_s != frames.back().stamp_s) {
      r.Fail(fmt::format("frame {} has timestamp {} here but {} on an earlier line", index, tok[1],
                         detail::FormatStamp(frames.back().stamp_s)));
    }
    if (tok.size() == 2) continue;

    Observation obs;
    obs.feature_id = detail::ParseInteger(tok[2], r, "feature_id");
    obs.u_px = detail::ParseFinite(tok[3], r, "u_px");
    obs.v_px = detail::ParseFinite(tok[4], r, "v_px");
    if (!ids_in_frame.insert(obs.feature_id).second)
      r.Fail(fmt::format("feature {} is observed twice in frame {}", obs.feature_id, index));
    frames.back().observations.push_back(obs);
  }
  return frames;
}

namespace {

// What ReadObservations would refuse in frame f after a frame (index, stamp) when `after` holds one: throws
// std::invalid_argument naming the file and the frame.
void CheckFrame(const std::string& path, const ObservationFrame& f, const std::optional<std::pair<int64_t, double>>& after) {
  if (f.index < 0 || (after && f.index <= after->first))
    throw std::invalid_argument(
        fmt::format("{}: frame indices must be non-negative and increasing (frame index {} after {})", path, f.index,
                    after ? fmt::format("{}", after->first) : std::string("none")));
  if (!std::isfinite(f.stamp_s))
    throw std::invalid_argument(fmt::format("{}: frame {} has a non-finite timestamp", path, f.index));
  if (after && f.stamp_s < after->second)
    throw std::invalid_argument(fmt::format("{}: the timestamp of frame {} goes back in time", path, f.index));
  std::unordered_set<int64_t> ids;
  for (const Observation& o : f.observations) {
    if (!std::isfinite(o.u_px) || !std::isfinite(o.v_px))
      throw std::invalid_argument(
          fmt::format("{}: feature {} in frame {} has a non-finite position", path, o.feature_id, f.index));
    if (!ids.insert(o.feature_id).second)
      throw std::invalid_argument(fmt::format("{}: feature {} is observed twice in frame {}", path, o.feature_id, f.index));
  }
}

constexpr char kHeader[] =
    "# frame_index timestamp_s feature_id u_px v_px (distorted pixels); 2 columns: a frame with no observation\n";

// One frame's lines (a frame with no observation: its index and stamp only); the frame was checked.
void WriteFrame(std::ostream& out, const ObservationFrame& f) {
  const std::string stamp = detail::FormatStamp(f.stamp_s);
  if (f.observations.empty()) out << fmt::format("{} {}\n", f.index, stamp);
  for (const Observation& o : f.observations)
    out << fmt::format("{} {} {} {:.17g} {:.17g}\n", f.index, stamp, o.feature_id, o.u_px, o.v_px);
}

}  // namespace

void WriteObservations(const std::string& path, const std::vector<ObservationFrame>& frames) {
  // Everything is checked before the file is touched: a refused write leaves an existing file as it was.
  for (size_t i = 0; i < frames.size(); ++i)
    CheckFrame(path, frames[i], i == 0 ? std::nullopt
                                       : std::optional<std::pair<int64_t, double>>({frames[i - 1].index, frames[i - 1].stamp_s}));
  std::ofstream out = detail::OpenForWrite(path);
  out << kHeader;
  for (const ObservationFrame& f : frames) WriteFrame(out, f);
  detail::FinishWrite(out, path);
}

ObservationWriter::ObservationWriter(std::string path) : path_(std::move(path)), out_(detail::OpenForWrite(path_)) {
  out_ << kHeader;
}

void ObservationWriter::Append(const ObservationFrame& f) {
  CheckFrame(path_, f, last_);
  WriteFrame(out_, f);
  last_ = {f.index, f.stamp_s};
}

void ObservationWriter::Close() { detail::FinishWrite(out_, path_); }

}  // namespace mcslam::io
