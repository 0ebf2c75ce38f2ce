// ClipWriter: video clips through FFmpeg's libraries (libavformat, libavcodec, libswscale), for
// export and join. OpenCV's VideoWriter offers no choice of the encoder's speed: it runs x264 at
// its default `medium` preset (an export to .mp4 took 1.3x the time of one to Motion JPEG .avi on
// two cores, 2026-12-04), and its OPENCV_FFMPEG_WRITER_OPTIONS reaches only hardware encoders
// (OpenCV 4.6).
#pragma once

#include <opencv2/core.hpp>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

namespace CLI {
class App;
}

namespace artrace::tools {

struct ClipOptions {
  double fps = 30.0;
  /// x264's speed preset (ultrafast ... veryslow); other encoders ignore it
  std::string preset = "veryfast";
  /// x264's constant rate factor (0 lossless ... 51; 23 is x264's default)
  int crf = 23;
};

/// --preset and --crf on a command that writes clips (the frame rate is each command's own).
void add_clip_options(CLI::App* cmd, ClipOptions& clip);

/// Writes BGR frames (8-bit, 3 channels, all of one size) to `file`, the container chosen by its
/// extension: H.264 (libx264) in .mp4, .mkv and .mov, MPEG-4 part 2 where FFmpeg has no x264, and
/// Motion JPEG in .avi. A frame of odd width or height is padded by repeating its last column
/// or row (4:2:0 needs even sizes). finish() completes the file; a writer destroyed without it
/// leaves an incomplete file, which the caller removes. Errors name `shown_name`.
class ClipWriter {
 public:
  ClipWriter(const std::filesystem::path& file, const std::string& shown_name, cv::Size size, const ClipOptions& options);
  ~ClipWriter();
  ClipWriter(const ClipWriter&) = delete;
  ClipWriter& operator=(const ClipWriter&) = delete;

  void write(const cv::Mat& bgr);
  void finish();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace artrace::tools
