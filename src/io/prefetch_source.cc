#include "io/prefetch_source.h"

#include <chrono>
#include <stdexcept>
#include <utility>

namespace mcslam::io {

PrefetchingSource::PrefetchingSource(std::unique_ptr<ImageSource> source, size_t depth)
    : source_(std::move(source)), depth_(depth) {
  if (!source_) throw std::invalid_argument("PrefetchingSource: no source");
  if (depth_ < 1) throw std::invalid_argument("PrefetchingSource: depth must be >= 1");
}

PrefetchingSource::~PrefetchingSource() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  changed_.notify_all();
  if (reader_.joinable()) reader_.join();
}

void PrefetchingSource::ReadAhead() {
  for (;;) {
    {
      std::unique_lock lock(mutex_);
      changed_.wait(lock, [&] { return stop_ || ready_.size() < depth_; });
      if (stop_) return;
    }
    Frame frame;
    bool more = false;
    std::exception_ptr error;
    const auto t0 = std::chrono::steady_clock::now();
    try {
      std::lock_guard source_lock(source_mutex_);
      more = source_->Next(&frame);
    } catch (...) {
      error = std::current_exception();
    }
    frame.read_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    {
      std::lock_guard lock(mutex_);
      if (more) {
        ready_.push_back(std::move(frame));
      } else {
        ended_ = true;
        error_ = error;
      }
    }
    changed_.notify_all();
    if (!more) return;
  }
}

bool PrefetchingSource::Next(Frame* frame) {
  if (!reader_.joinable()) reader_ = std::thread([this] { ReadAhead(); });
  std::unique_lock lock(mutex_);
  changed_.wait(lock, [&] { return !ready_.empty() || ended_; });
  if (ready_.empty()) {
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
    return false;
  }
  *frame = std::move(ready_.front());
  ready_.pop_front();
  lock.unlock();
  changed_.notify_all();
  return true;
}

std::optional<cv::Size> PrefetchingSource::ImageSize() {
  std::lock_guard lock(source_mutex_);
  return source_->ImageSize();
}

std::optional<int64_t> PrefetchingSource::FrameCount() const {
  std::lock_guard lock(source_mutex_);
  return source_->FrameCount();
}

std::string PrefetchingSource::Description() const {
  std::lock_guard lock(source_mutex_);
  return source_->Description();
}

}  // namespace mcslam::io
