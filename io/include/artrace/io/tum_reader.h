// TUM RGB-D benchmark layout (Sturm et al., IROS 2012): rgb.txt, depth.txt, groundtruth.txt and the
// rgb/ and depth/ PNG folders, read through OpenCV.
//
// What the reader does with messy recordings (decided here, tested in tum_reader_test.cpp):
// - a listed image that does not exist: the frame is skipped with a warning (warnings());
// - an image that exists but does not decode, or a depth PNG that is not 16-bit one-channel:
//   io::ParseError naming the file when that frame is read;
// - depth 0 and 65535 (saturated): no reading (0 in the frame);
// - a timestamp list out of order, an unparsable line, a trajectory with a non-unit quaternion, a
//   translation beyond +-1e6 m or out-of-order times, intrinsics out of range (read_intrinsics):
//   io::ParseError naming file and line, at open;
// - colour frames without a depth frame within `max_dt_s`: skipped with a warning;
// - no groundtruth.txt: frames have no pose; poses more than `max_pose_gap_s` from a trajectory
//   sample on either side: that frame has no pose.
#pragma once

#include "artrace/ar/sensor_frame.h"
#include "artrace/ar/trajectory.h"

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace artrace::io {

struct TimedFile {
  double time_s = 0.0;
  std::string file;  ///< relative to the sequence folder
};

/// Reads an associations/list file ("timestamp filename" lines, '#' comments); ParseError on bad lines.
std::vector<TimedFile> read_tum_list(const std::filesystem::path& path);
/// Reads a TUM trajectory ("timestamp tx ty tz qx qy qz qw"); ParseError naming file and line.
ar::Trajectory read_tum_trajectory(const std::filesystem::path& path);

/// An intrinsics.txt: 'fx fy cx cy [width height]' on its first line that is not blank or a '#'
/// comment. Focal lengths above 0 and at most 1e6 pixels, the principal point within +-1e6, the
/// size (when given) 1 to 100000 pixels; io::ParseError naming the file and line otherwise. The
/// size stays 0 when not given (the readers take it from the images).
ar::PinholeIntrinsics read_intrinsics(const std::filesystem::path& path);
/// Throws ParseError "WHERE: SUBJECT for WxH images, the recording's are wxh" when `k` names an
/// image size (a width or height not 0) other than the images' `width` x `height`: intrinsics are
/// not scaled to other images on a guess.
void check_intrinsics_size(const ar::PinholeIntrinsics& k, int width, int height, const std::string& where,
                           const std::string& subject = "is");
/// Writes one (write-then-rename).
void write_tum_trajectory(const std::filesystem::path& path, const ar::Trajectory& trajectory);

/// Pairs colour and depth frames by nearest timestamp within max_dt_s, each used at most once
/// (greedy by smallest difference, as the benchmark's associate.py). Returns index pairs sorted by
/// colour time.
std::vector<std::pair<size_t, size_t>> associate(const std::vector<TimedFile>& color,
                                                 const std::vector<TimedFile>& depth, double max_dt_s);

/// Intrinsics of the Freiburg sequences by name ("freiburg1"/"fr1", 2, 3), else the ROS default
/// (525, 525, 319.5, 239.5), for 640x480. The reader refuses the Freiburg ones on images of another
/// size, and scales the default with the width.
ar::PinholeIntrinsics freiburg_intrinsics(const std::string& sequence_name);

struct TumOptions {
  double max_dt_s = 0.02;
  double max_pose_gap_s = 0.1;
  double depth_scale = 5000.0;  ///< PNG units per metre
  std::optional<ar::PinholeIntrinsics> intrinsics;  ///< else intrinsics.txt in the folder, else by name
  std::optional<std::filesystem::path> trajectory;   ///< else groundtruth.txt when present
};

class TumReader : public ar::FrameSource {
 public:
  explicit TumReader(const std::filesystem::path& folder, const TumOptions& options = {});

  std::optional<int64_t> frame_count() const override { return static_cast<int64_t>(frames_.size()); }
  bool next(ar::SensorFrame& frame) override;
  void seek(int64_t index) override;
  std::string describe() const override;
  double depth_units_per_metre() const override { return options_.depth_scale; }
  std::string intrinsics_source() const override { return intrinsics_source_; }
  std::optional<std::pair<double, double>> trajectory_span() const override { return trajectory_.span(); }
  std::vector<std::string> warnings() const override { return warnings_; }

  const ar::PinholeIntrinsics& intrinsics() const { return intrinsics_; }
  const ar::Trajectory& trajectory() const { return trajectory_; }
  /// Reads frame i without moving the cursor.
  ar::SensorFrame read(int64_t i) const;

 private:
  struct Entry {
    TimedFile color, depth;
  };
  std::filesystem::path folder_;
  TumOptions options_;
  ar::PinholeIntrinsics intrinsics_;
  std::string intrinsics_source_;
  std::string intrinsics_subject_ = "is";  ///< for check_intrinsics_size
  std::filesystem::path intrinsics_where_;
  bool default_intrinsics_ = false;  ///< the ROS default, scaled with each frame's width
  std::vector<std::string> warnings_;
  ar::Trajectory trajectory_;
  std::vector<Entry> frames_;
  int64_t cursor_ = 0;
};

}  // namespace artrace::io
