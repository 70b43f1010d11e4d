#pragma once
// A source read ahead on a thread of its own: the next frames are decoded while the caller processes the
// current one (JPEG/PNG decoding or a video's decoder is 5-10 % of a frame's time on the shared sequences),
// in the same order and with the same content as the wrapped source gives them.
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <exception>
#include <memory>
#include <mutex>
#include <thread>

#include "io/image_source.h"

namespace mcslam::io {

class PrefetchingSource : public ImageSource {
 public:
  // Reads at most `depth` (>= 1) frames ahead of the caller; the thread starts at the first Next. Throws
  // std::invalid_argument for a null source or a depth below 1.
  PrefetchingSource(std::unique_ptr<ImageSource> source, size_t depth = 2);
  ~PrefetchingSource() override;  // stops the reader after the frame it is decoding
  PrefetchingSource(const PrefetchingSource&) = delete;
  PrefetchingSource& operator=(const PrefetchingSource&) = delete;

  // The wrapped source's next frame, with Frame::read_ms its decoding time on the reader thread. An exception
  // the wrapped source threw comes out here, after the frames read before it.
  bool Next(Frame* frame) override;
  std::optional<cv::Size> ImageSize() override;
  std::optional<int64_t> FrameCount() const override;
  std::string Description() const override;

 private:
  void ReadAhead();

  std::unique_ptr<ImageSource> source_;
  size_t depth_;
  mutable std::mutex source_mutex_;  // the wrapped source: the reader's Next, the caller's queries
  std::mutex mutex_;                 // what follows
  std::condition_variable changed_;
  std::deque<Frame> ready_;
  bool ended_ = false;  // the wrapped source ended or threw (error_)
  bool stop_ = false;
  std::exception_ptr error_;
  std::thread reader_;
};

}  // namespace mcslam::io
