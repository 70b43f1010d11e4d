#pragma once
// Where frames come from: a folder of images, an explicit list of image files, a video file or a webcam.
// Every source hands out frames in order with an index and a timestamp; a frame that cannot be decoded is
// handed out too, with an empty image and the reason, so that the caller can skip it and count it (a
// corrupt file in the middle of a sequence never ends the run and never crashes it).
#include <cstdint>
#include <future>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>
#include <optional>
#include <string>
#include <vector>

namespace mcslam::io {

struct Frame {
  cv::Mat image;       // as decoded (8-bit gray or BGR, or 16-bit); empty when the frame is unreadable
  int64_t index = 0;   // position in the source, from 0, counting unreadable frames too
  double stamp_s = 0;  // seconds (from the dataset's stamps, else index / fps)
  std::string name;    // the file it came from, or "<video>#<index>"
  std::string error;   // why the image is empty; empty when the frame is fine
  bool ok() const { return !image.empty(); }
};

class ImageSource {
 public:
  virtual ~ImageSource() = default;
  // The next frame, or false at the end of the source. A frame that cannot be read comes back with
  // `ok() == false` and `error` set; the source then goes on with the next one.
  virtual bool Next(Frame* frame) = 0;
  // Size of the frames (width, height) when known without reading the whole source (from the first
  // readable image, or the video's properties).
  virtual std::optional<cv::Size> ImageSize() = 0;
  // Number of frames when known (image lists: exact; video files: as the container says, may be off).
  virtual std::optional<int64_t> FrameCount() const = 0;
  // Words for messages: "image folder /data/x (120 images)", "video /data/a.mp4", "webcam 0".
  virtual std::string Description() const = 0;
};

// ---- image files -------------------------------------------------------------------------------------

// True for the image extensions the folder readers take: .png .jpg .jpeg .pgm .ppm .bmp (any case).
bool IsImageFileName(const std::string& name);
// The image files directly in `dir`, sorted by name (numbers in names compare as numbers, so "img2.png"
// comes before "img10.png"). Throws std::runtime_error naming `dir` when it is missing or not a folder.
std::vector<std::string> ListImageFiles(const std::string& dir);
// One timestamp (seconds) a line; blank and '#' lines skipped. Throws "<path>:<line>: <what>".
std::vector<double> ReadTimestampsFile(const std::string& path);

// Frames from a list of files with their stamps (same length). Frames whose size differs from the first
// readable frame are reported as unreadable (the pipeline needs one image size).
class ImageListSource : public ImageSource {
 public:
  // Throws std::invalid_argument when the lengths differ or a stamp is not finite.
  ImageListSource(std::vector<std::string> paths, std::vector<double> stamps_s, std::string description);
  bool Next(Frame* frame) override;
  std::optional<cv::Size> ImageSize() override;
  std::optional<int64_t> FrameCount() const override { return static_cast<int64_t>(paths_.size()); }
  std::string Description() const override { return description_; }
  const std::vector<std::string>& paths() const { return paths_; }
  const std::vector<double>& stamps_s() const { return stamps_s_; }

 private:
  std::vector<std::string> paths_;
  std::vector<double> stamps_s_;
  std::string description_;
  size_t next_ = 0;
  std::optional<cv::Size> size_;
  bool size_probed_ = false;
};

struct ImageFolderOptions {
  // Stamps when there is no timestamps file: index / fps seconds.
  double fps = 30.0;
  // A file of timestamps, one a line, one per image. Empty: use "times.txt" or "timestamps.txt" in the
  // folder when there is one, else index / fps.
  std::string timestamps_path;
  // Throws std::invalid_argument naming the bad field.
  void Check() const;
};

// All images in `dir` (ListImageFiles). Throws std::runtime_error naming the folder when it is missing or
// holds no image, or naming the timestamps file when its length differs from the number of images.
std::unique_ptr<ImageListSource> OpenImageFolder(const std::string& dir, const ImageFolderOptions& options = {});

// ---- video -------------------------------------------------------------------------------------------

// A video file or a camera through cv::VideoCapture. A video file's stamps are index / fps (the
// container's rate, or fps_override); a camera's come from the steady clock since it was opened. The end
// of a video and a frame the decoder gives up on look the same to cv::VideoCapture: both end the source.
class VideoSource : public ImageSource {
 public:
  // Throws std::runtime_error naming the file when it does not exist or cannot be opened.
  // fps_override > 0 replaces the container's frame rate for the stamps.
  static std::unique_ptr<VideoSource> OpenFile(const std::string& path, double fps_override = 0.0);
  // Throws std::runtime_error naming the index when no camera opens there.
  static std::unique_ptr<VideoSource> OpenCamera(int camera_index);

  bool Next(Frame* frame) override;
  std::optional<cv::Size> ImageSize() override;
  std::optional<int64_t> FrameCount() const override;
  std::string Description() const override { return description_; }
  double fps() const { return fps_; }

 private:
  VideoSource() = default;
  cv::VideoCapture capture_;
  std::string description_;
  std::string name_;
  bool is_camera_ = false;
  double fps_ = 30.0;
  int64_t next_index_ = 0;
  std::optional<int64_t> count_;
  std::optional<cv::Size> size_;
  int64_t start_ticks_ = 0;
};

// ---- reading ahead -----------------------------------------------------------------------------------

// Reads a source one frame ahead on a thread of its own: the next frame is decoded while the caller works on the
// one it has (a PNG of 1920x1440 took 21 ms a frame to decode, a fifth of a frame's work: docs/tuning.md). The same
// frames in the same order as the source's own Next, errors included; an exception the source throws comes out of
// the Next that would have returned that frame.
class PrefetchingSource {
 public:
  // Does not own `source`, which must outlive this reader and must not be read from elsewhere meanwhile.
  explicit PrefetchingSource(ImageSource* source) : source_(source) {}
  ~PrefetchingSource();  // waits for the frame being read, if any
  PrefetchingSource(const PrefetchingSource&) = delete;
  PrefetchingSource& operator=(const PrefetchingSource&) = delete;
  // As ImageSource::Next. `read_ms`, when given: how long the source took to read and decode the frame (on the
  // reading thread, mostly while the caller worked on the frame before).
  bool Next(Frame* frame, double* read_ms = nullptr);

 private:
  struct Read {
    bool more = false;
    Frame frame;
    double ms = 0;
  };
  void Launch();
  ImageSource* source_;
  std::future<Read> next_;
  bool ended_ = false;
};

}  // namespace mcslam::io
