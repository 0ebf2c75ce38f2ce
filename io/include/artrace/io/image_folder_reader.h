// Plain OpenCV sources: a folder holding depth/ (16-bit PNGs, `depth_per_metre` units, 1000 = mm by
// default, with a warning) and either color/ (images, any format OpenCV reads) or one colour video color.<ext>
// (mp4, avi, mkv, mov). Frames pair by file names in natural order (numbers as numbers: 9.png
// before 10.png) / video order, with a warning where a pair's names carry different numbers; frame
// k is at k / fps seconds.
// Optional: trajectory.txt (TUM format, poses at those times) and an intrinsics file (intrinsics_file.h;
// without one, defaults with a warning).
#pragma once

#include "artrace/ar/sensor_frame.h"
#include "artrace/ar/trajectory.h"

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace artrace::io {

struct ImageFolderOptions {
  double fps = 30.0;  ///< for image folders; a video's own rate wins
  /// stored depth units per metre; empty: 1000 (millimetres), with a warning
  std::optional<double> depth_per_metre;
  std::optional<ar::PinholeIntrinsics> intrinsics;
  std::optional<std::filesystem::path> trajectory;  ///< else trajectory.txt when present
};

class ImageFolderReader : public ar::FrameSource {
 public:
  explicit ImageFolderReader(const std::filesystem::path& folder, const ImageFolderOptions& options = {});
  ~ImageFolderReader() override;

  std::optional<int64_t> frame_count() const override { return static_cast<int64_t>(depth_files_.size()); }
  bool next(ar::SensorFrame& frame) override;
  void seek(int64_t index) override;
  std::string describe() const override;
  double depth_units_per_metre() const override { return *options_.depth_per_metre; }
  std::string intrinsics_source() const override { return intrinsics_source_; }
  std::optional<std::pair<double, double>> trajectory_span() const override { return trajectory_.span(); }
  std::vector<std::string> warnings() const override { return warnings_; }

  /// True when `folder` looks like this layout.
  static bool accepts(const std::filesystem::path& folder);

 private:
  struct Video;
  std::filesystem::path folder_;
  ImageFolderOptions options_;
  std::vector<std::filesystem::path> color_files_, depth_files_;
  std::filesystem::path video_path_;
  std::unique_ptr<Video> video_;
  ar::Trajectory trajectory_;
  std::optional<ar::PinholeIntrinsics> intrinsics_;
  std::string intrinsics_source_;
  std::vector<std::string> warnings_;
  int64_t cursor_ = 0;
};

}  // namespace artrace::io
