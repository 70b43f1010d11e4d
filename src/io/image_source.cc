#include "io/image_source.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <future>
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>
#include <system_error>

#include "io/text_util.h"

namespace mcslam::io {
namespace fs = std::filesystem;
namespace {

// "frame2" < "frame10": digit runs compare by value (then by length, so "01" and "1" stay distinct).
bool NaturalLess(const std::string& a, const std::string& b) {
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    const bool da = std::isdigit(static_cast<unsigned char>(a[i])) != 0;
    const bool db = std::isdigit(static_cast<unsigned char>(b[j])) != 0;
    if (da && db) {
      size_t ie = i, je = j;
      while (ie < a.size() && std::isdigit(static_cast<unsigned char>(a[ie]))) ++ie;
      while (je < b.size() && std::isdigit(static_cast<unsigned char>(b[je]))) ++je;
      // Compare without leading zeros: longer digit string = bigger number.
      size_t is = i, js = j;
      while (is + 1 < ie && a[is] == '0') ++is;
      while (js + 1 < je && b[js] == '0') ++js;
      if (ie - is != je - js) return ie - is < je - js;
      const int c = a.compare(is, ie - is, b, js, je - js);
      if (c != 0) return c < 0;
      if (ie - i != je - j) return ie - i < je - j;
      i = ie;
      j = je;
      continue;
    }
    if (a[i] != b[j]) return a[i] < b[j];
    ++i;
    ++j;
  }
  return a.size() - i < b.size() - j;
}

// Decodes one image; never throws (OpenCV may throw on some malformed files).
cv::Mat ReadImage(const std::string& path, std::string* error) {
  cv::Mat image;
  try {
    detail::RequireRegularFileIfPresent(path);
  } catch (const std::runtime_error& e) {
    *error = e.what();
    return {};
  }
  try {
    image = cv::imread(path, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    *error = fmt::format("{}: cannot decode image ({})", path, e.what());
    return {};
  }
  if (image.empty()) {
    std::error_code ec;
    *error = fs::exists(path, ec) ? fmt::format("{}: cannot decode image (corrupt or unsupported file)", path)
                                  : fmt::format("{}: image file is missing", path);
    return {};
  }
  if (image.depth() != CV_8U && image.depth() != CV_16U) {
    *error = fmt::format("{}: unsupported pixel depth (OpenCV depth {}); expected 8 or 16 bit", path, image.depth());
    return {};
  }
  return image;
}

}  // namespace

bool IsImageFileName(const std::string& name) {
  const std::string ext = detail::Lower(fs::path(name).extension().string());
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".pgm" || ext == ".ppm" || ext == ".bmp";
}

std::vector<std::string> ListImageFiles(const std::string& dir) {
  std::error_code ec;
  if (!fs::exists(dir, ec)) throw std::runtime_error(fmt::format("{}: folder does not exist", dir));
  if (!fs::is_directory(dir, ec)) throw std::runtime_error(fmt::format("{}: is not a folder", dir));
  std::vector<std::string> names;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (!it->is_regular_file(ec) && !it->is_symlink(ec)) continue;
    const std::string name = it->path().filename().string();
    if (IsImageFileName(name)) names.push_back(name);
  }
  if (ec) throw std::runtime_error(fmt::format("{}: cannot list folder: {}", dir, ec.message()));
  std::sort(names.begin(), names.end(), NaturalLess);
  std::vector<std::string> paths;
  paths.reserve(names.size());
  for (const auto& n : names) paths.push_back((fs::path(dir) / n).string());
  return paths;
}

std::vector<double> ReadTimestampsFile(const std::string& path) {
  detail::LineReader r(path);
  std::vector<double> stamps;
  std::string line;
  while (r.Next(line)) {
    if (detail::IsBlankOrComment(line)) continue;
    const auto tok = detail::SplitWhitespace(line);
    // Some tools add columns after the stamp (e.g. a file name); the first column is the stamp.
    detail::AppendStamp(stamps, detail::ParseFinite(tok[0], r, "timestamp"), tok[0], r);
  }
  return stamps;
}

// ---- ImageListSource -----------------------------------------------------------------------------------

ImageListSource::ImageListSource(std::vector<std::string> paths, std::vector<double> stamps_s, std::string description)
    : paths_(std::move(paths)), stamps_s_(std::move(stamps_s)), description_(std::move(description)) {
  if (paths_.size() != stamps_s_.size())
    throw std::invalid_argument(fmt::format("{}: {} images but {} timestamps; they must match one to one", description_,
                                            paths_.size(), stamps_s_.size()));
  for (size_t i = 0; i < stamps_s_.size(); ++i)
    if (!std::isfinite(stamps_s_[i]))
      throw std::invalid_argument(
          fmt::format("{}: timestamp of image {} ({}) is not finite", description_, i, paths_[i]));
}

std::optional<cv::Size> ImageListSource::ImageSize() {
  if (!size_probed_) {
    size_probed_ = true;
    // The first few files: a corrupt first frame must not hide the size of the sequence.
    constexpr size_t kProbe = 5;
    for (size_t i = 0; i < std::min(kProbe, paths_.size()) && !size_; ++i) {
      std::string error;
      const cv::Mat image = ReadImage(paths_[i], &error);
      if (!image.empty()) size_ = image.size();
    }
  }
  return size_;
}

bool ImageListSource::Next(Frame* frame) {
  if (next_ >= paths_.size()) return false;
  const size_t i = next_++;
  *frame = Frame{};
  frame->index = static_cast<int64_t>(i);
  frame->stamp_s = stamps_s_[i];
  frame->name = paths_[i];
  frame->image = ReadImage(paths_[i], &frame->error);
  if (frame->image.empty()) return true;
  if (!size_) {
    size_ = frame->image.size();
    size_probed_ = true;
  } else if (frame->image.size() != *size_) {
    frame->error = fmt::format("{}: image is {}x{} but the sequence's frames are {}x{}", paths_[i], frame->image.cols,
                               frame->image.rows, size_->width, size_->height);
    frame->image.release();
  }
  return true;
}

void ImageFolderOptions::Check() const {
  if (!(fps > 0) || !std::isfinite(fps))
    throw std::invalid_argument(fmt::format("ImageFolderOptions.fps must be positive and finite (got {})", fps));
}

std::unique_ptr<ImageListSource> OpenImageFolder(const std::string& dir, const ImageFolderOptions& options) {
  options.Check();
  std::vector<std::string> paths = ListImageFiles(dir);
  if (paths.empty())
    throw std::runtime_error(
        fmt::format("{}: no images in the folder (looked for .png .jpg .jpeg .pgm .ppm .bmp files)", dir));
  std::string times_path = options.timestamps_path;
  if (times_path.empty()) {
    for (const char* name : {"times.txt", "timestamps.txt"}) {
      std::error_code ec;
      if (fs::is_regular_file(fs::path(dir) / name, ec)) {
        times_path = (fs::path(dir) / name).string();
        break;
      }
    }
  }
  std::vector<double> stamps;
  if (!times_path.empty()) {
    stamps = ReadTimestampsFile(times_path);
    if (stamps.size() != paths.size())
      throw std::runtime_error(fmt::format("{}: {} timestamps, but {} holds {} images; they must match one to one",
                                           times_path, stamps.size(), dir, paths.size()));
  } else {
    stamps.resize(paths.size());
    for (size_t i = 0; i < paths.size(); ++i) stamps[i] = static_cast<double>(i) / options.fps;
  }
  const size_t n = paths.size();
  return std::make_unique<ImageListSource>(std::move(paths), std::move(stamps),
                                           fmt::format("image folder {} ({} images)", dir, n));
}

// ---- VideoSource --------------------------------------------------------------------------------------

std::unique_ptr<VideoSource> VideoSource::OpenFile(const std::string& path, double fps_override) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw std::runtime_error(fmt::format("{}: video file does not exist", path));
  if (fs::is_directory(path, ec)) throw std::runtime_error(fmt::format("{}: is a folder, not a video file", path));
  if (!fs::is_regular_file(path, ec))
    throw std::runtime_error(fmt::format(
        "{}: is not a regular file (a pipe, device or socket): give a video file, an image folder or a webcam index",
        path));
  if (!(fps_override >= 0) || !std::isfinite(fps_override))
    throw std::invalid_argument(fmt::format("{}: fps override must be >= 0 (got {})", path, fps_override));
  std::unique_ptr<VideoSource> src(new VideoSource());
  bool opened = false;
  try {
    opened = src->capture_.open(path, cv::CAP_ANY);
  } catch (const cv::Exception& e) {
    throw std::runtime_error(fmt::format("{}: cannot open video ({})", path, e.what()));
  }
  if (!opened || !src->capture_.isOpened())
    throw std::runtime_error(fmt::format("{}: cannot open video (not a video file, or no decoder for it)", path));
  src->name_ = path;
  src->description_ = fmt::format("video {}", path);
  const double fps = src->capture_.get(cv::CAP_PROP_FPS);
  src->fps_ = fps_override > 0 ? fps_override : (fps > 0 && std::isfinite(fps) ? fps : 30.0);
  const double count = src->capture_.get(cv::CAP_PROP_FRAME_COUNT);
  if (count > 0 && std::isfinite(count)) src->count_ = static_cast<int64_t>(std::llround(count));
  const int w = static_cast<int>(src->capture_.get(cv::CAP_PROP_FRAME_WIDTH));
  const int h = static_cast<int>(src->capture_.get(cv::CAP_PROP_FRAME_HEIGHT));
  if (w > 0 && h > 0) src->size_ = cv::Size(w, h);
  return src;
}

std::unique_ptr<VideoSource> VideoSource::OpenCamera(int camera_index) {
  if (camera_index < 0) throw std::invalid_argument(fmt::format("webcam index must be >= 0 (got {})", camera_index));
  std::unique_ptr<VideoSource> src(new VideoSource());
  bool opened = false;
  try {
    opened = src->capture_.open(camera_index, cv::CAP_ANY);
  } catch (const cv::Exception& e) {
    throw std::runtime_error(fmt::format("webcam {}: cannot open ({})", camera_index, e.what()));
  }
  if (!opened || !src->capture_.isOpened())
    throw std::runtime_error(
        fmt::format("webcam {}: cannot open (no camera at that index, or it is busy)", camera_index));
  src->is_camera_ = true;
  src->name_ = fmt::format("webcam{}", camera_index);
  src->description_ = fmt::format("webcam {}", camera_index);
  const double fps = src->capture_.get(cv::CAP_PROP_FPS);
  src->fps_ = fps > 0 && std::isfinite(fps) ? fps : 30.0;
  const int w = static_cast<int>(src->capture_.get(cv::CAP_PROP_FRAME_WIDTH));
  const int h = static_cast<int>(src->capture_.get(cv::CAP_PROP_FRAME_HEIGHT));
  if (w > 0 && h > 0) src->size_ = cv::Size(w, h);
  src->start_ticks_ = std::chrono::steady_clock::now().time_since_epoch().count();
  return src;
}

bool VideoSource::Next(Frame* frame) {
  cv::Mat image;
  bool got = false;
  try {
    got = capture_.read(image);
  } catch (const cv::Exception&) {
    got = false;
  }
  if (!got || image.empty()) return false;
  *frame = Frame{};
  frame->index = next_index_++;
  frame->name = fmt::format("{}#{}", name_, frame->index);
  if (is_camera_) {
    const auto now = std::chrono::steady_clock::now().time_since_epoch();
    const auto start = std::chrono::steady_clock::duration(start_ticks_);
    frame->stamp_s = std::chrono::duration<double>(now - start).count();
  } else {
    frame->stamp_s = static_cast<double>(frame->index) / fps_;
  }
  if (!size_) size_ = image.size();
  if (image.size() != *size_) {
    frame->error = fmt::format("{}: frame is {}x{} but the video's frames are {}x{}", frame->name, image.cols,
                               image.rows, size_->width, size_->height);
    return true;
  }
  frame->image = std::move(image);
  return true;
}

std::optional<cv::Size> VideoSource::ImageSize() { return size_; }

std::optional<int64_t> VideoSource::FrameCount() const { return count_; }

PrefetchingSource::~PrefetchingSource() {
  if (next_.valid()) next_.wait();  // an exception it holds is dropped with it
}

void PrefetchingSource::Launch() {
  next_ = std::async(std::launch::async, [source = source_] {
    Read r;
    const auto t0 = std::chrono::steady_clock::now();
    r.more = source->Next(&r.frame);
    r.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return r;
  });
}

bool PrefetchingSource::Next(Frame* frame, double* read_ms) {
  if (ended_) return false;
  if (!next_.valid()) Launch();
  Read r;
  try {
    r = next_.get();
  } catch (...) {
    ended_ = true;  // the source's state after a throw is its own: nothing more is read from it here
    throw;
  }
  if (!r.more) {
    ended_ = true;
    return false;
  }
  Launch();  // the next frame, while the caller works on this one
  *frame = std::move(r.frame);
  if (read_ms) *read_ms = r.ms;
  return true;
}

}  // namespace mcslam::io
