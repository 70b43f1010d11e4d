// io::PrefetchingSource: the frames of the wrapped source, in its order and with its content, whatever the
// depth; an error of the wrapped source after the frames before it; a reader stopped mid-source.
#include <gtest/gtest.h>

#include <atomic>
#include <memory>
#include <stdexcept>
#include <string>

#include "io/prefetch_source.h"

namespace mcslam::io {
namespace {

// `count` frames, frame i an 8x6 image filled with i, every third one unreadable; throws at `throw_at`.
class CountingSource : public ImageSource {
 public:
  CountingSource(int count, int throw_at, std::atomic<int>* reads) : count_(count), throw_at_(throw_at), reads_(reads) {}
  bool Next(Frame* frame) override {
    if (next_ == throw_at_) throw std::runtime_error("the disk went away at frame " + std::to_string(next_));
    if (next_ >= count_) return false;
    ++*reads_;
    *frame = Frame{};
    frame->index = next_;
    frame->stamp_s = 0.5 * next_;
    frame->name = "f" + std::to_string(next_);
    if (next_ % 3 == 2)
      frame->error = "corrupt";
    else
      frame->image = cv::Mat(6, 8, CV_8UC1, cv::Scalar(next_ % 256));
    ++next_;
    return true;
  }
  std::optional<cv::Size> ImageSize() override { return cv::Size(8, 6); }
  std::optional<int64_t> FrameCount() const override { return count_; }
  std::string Description() const override { return "counting source"; }

 private:
  int count_, throw_at_, next_ = 0;
  std::atomic<int>* reads_;
};

TEST(PrefetchingSource, GivesTheWrappedSourcesFramesInOrder) {
  for (size_t depth : {1, 2, 5}) {
    SCOPED_TRACE(testing::Message() << "depth " << depth);
    std::atomic<int> reads{0};
    PrefetchingSource src(std::make_unique<CountingSource>(50, -1, &reads), depth);
    EXPECT_EQ(src.FrameCount(), 50);
    EXPECT_EQ(src.Description(), "counting source");
    EXPECT_EQ(src.ImageSize(), cv::Size(8, 6));
    Frame f;
    int n = 0;
    while (src.Next(&f)) {
      EXPECT_EQ(f.index, n);
      EXPECT_EQ(f.stamp_s, 0.5 * n);
      EXPECT_EQ(f.name, "f" + std::to_string(n));
      if (n % 3 == 2) {
        EXPECT_FALSE(f.ok());
        EXPECT_EQ(f.error, "corrupt");
      } else {
        ASSERT_TRUE(f.ok());
        EXPECT_EQ(f.image.at<uchar>(5, 7), n);
      }
      EXPECT_GE(f.read_ms, 0.0);
      ++n;
      // Never more than `depth` frames ahead of the caller (plus the one being read).
      EXPECT_LE(reads.load(), n + static_cast<int>(depth) + 1);
    }
    EXPECT_EQ(n, 50);
    EXPECT_FALSE(src.Next(&f));  // and stays at the end
  }
}

TEST(PrefetchingSource, AnErrorOfTheSourceComesAfterTheFramesBeforeIt) {
  std::atomic<int> reads{0};
  PrefetchingSource src(std::make_unique<CountingSource>(50, 7, &reads), 3);
  Frame f;
  for (int i = 0; i < 7; ++i) {
    ASSERT_TRUE(src.Next(&f));
    EXPECT_EQ(f.index, i);
  }
  try {
    src.Next(&f);
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("frame 7"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(src.Next(&f));  // reported once, then the end
}

TEST(PrefetchingSource, StopsMidSourceAndRefusesBadArguments) {
  std::atomic<int> reads{0};
  {
    PrefetchingSource src(std::make_unique<CountingSource>(100000, -1, &reads), 2);
    Frame f;
    ASSERT_TRUE(src.Next(&f));
  }  // destroyed while the reader is ahead: it stops after the frame it reads
  EXPECT_LE(reads.load(), 4);
  EXPECT_THROW(PrefetchingSource(nullptr, 2), std::invalid_argument);
  EXPECT_THROW(PrefetchingSource(std::make_unique<CountingSource>(1, -1, &reads), 0), std::invalid_argument);
}

}  // namespace
}  // namespace mcslam::io
