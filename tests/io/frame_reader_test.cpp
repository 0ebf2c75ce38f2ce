// The reader thread of export, replay and bench-ar (tools/frame_reader.h).
#include "../../tools/frame_reader.h"

#include <gtest/gtest.h>

#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

namespace artrace::tools {
namespace {

/// Frames 0..n-1 (their index only), noting the thread that reads each; throws at frame `bad`.
class ThreadNotingSource : public ar::FrameSource {
 public:
  ThreadNotingSource(int64_t n, int64_t bad = -1) : n_(n), bad_(bad) {}
  std::optional<int64_t> frame_count() const override { return n_; }
  bool next(ar::SensorFrame& f) override {
    readers.insert(std::this_thread::get_id());
    if (at_ == bad_) throw std::runtime_error("frame " + std::to_string(at_) + " is corrupt");
    if (at_ >= n_) return false;
    f.index = at_++;
    return true;
  }
  void seek(int64_t index) override { at_ = index; }
  std::string describe() const override { return "test frames"; }
  double depth_units_per_metre() const override { return 1000.0; }
  std::string intrinsics_source() const override { return "none"; }
  std::set<std::thread::id> readers;

 private:
  int64_t n_, at_ = 0, bad_;
};

TEST(FrameReader, OneThreadReadsEveryFrameInOrderAcrossSeeks) {
  ThreadNotingSource source(5);
  std::vector<int64_t> got;
  {
    FrameReader reader(source);
    ar::SensorFrame f;
    for (int loop = 0; loop < 200; ++loop) {  // the recording looped, as bench-ar and replay do
      while (reader.next(f)) got.push_back(f.index);
      reader.seek(0);
    }
    reader.seek(3);
    ASSERT_TRUE(reader.next(f));
    EXPECT_EQ(f.index, 3);
  }
  ASSERT_EQ(got.size(), 1000u);
  for (size_t k = 0; k < got.size(); ++k) ASSERT_EQ(got[k], static_cast<int64_t>(k % 5)) << k;
  // one thread for the whole recording, not one a frame (a thread a frame left OpenCV's
  // per-thread storage behind each time), and never the caller's
  EXPECT_EQ(source.readers.size(), 1u);
  EXPECT_EQ(source.readers.count(std::this_thread::get_id()), 0u);
}

TEST(FrameReader, AReadersErrorComesOutOfNext) {
  ThreadNotingSource source(5, 2);
  FrameReader reader(source);
  ar::SensorFrame f;
  ASSERT_TRUE(reader.next(f));
  ASSERT_TRUE(reader.next(f));
  EXPECT_THROW(
      {
        try {
          reader.next(f);
        } catch (const std::runtime_error& e) {
          EXPECT_STREQ(e.what(), "frame 2 is corrupt");
          throw;
        }
      },
      std::runtime_error);
}

}  // namespace
}  // namespace artrace::tools
