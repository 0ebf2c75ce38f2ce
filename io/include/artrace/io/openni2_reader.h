// Plays ONI recordings through OpenNI2's own file driver, as the cross-check of the project's own
// reader (oni_reader.h) in the tests, for the files OpenNI2 can play front to back: the project's
// own recordings and finalised OpenNI 1.x ones. Not the reader artrace uses (see oni_file.h for why).
// Depth (DEPTH_1_MM or DEPTH_100_UM, to metres) and colour (RGB888) are read in manual mode (speed -1: one frame per waitForAnyStream, none
// dropped); next() ends after the last frame (the player itself repeats, so that its thread waits
// for a trigger instead of spinning at the end of the file, where closing the device crashed it;
// see open()). The pose comes from an optional sidecar trajectory (TUM format), else the camera is
// fixed at the origin.
//
// Seek: PlaybackControl::seek crashes or hangs in Debian's OpenNI2 2.2 (OpenNI/OpenNI2 issue 51), so
// seek(i) reopens the device and steps to frame i; frame-accurate, O(i).
#pragma once

#include "artrace/ar/sensor_frame.h"
#include "artrace/ar/trajectory.h"

#include <filesystem>
#include <memory>
#include <optional>

namespace artrace::io {

struct OpenNi2Options {
  std::optional<std::filesystem::path> trajectory;  ///< sidecar TUM trajectory (else "<file>.trajectory.txt" if present)
  std::optional<ar::PinholeIntrinsics> intrinsics;  ///< else from the streams' field of view
  double max_pose_gap_s = 0.1;
};

class OpenNi2Reader : public ar::FrameSource {
 public:
  explicit OpenNi2Reader(const std::filesystem::path& path, const OpenNi2Options& options = {});
  ~OpenNi2Reader() override;

  std::optional<int64_t> frame_count() const override { return frames_; }
  bool next(ar::SensorFrame& frame) override;
  void seek(int64_t index) override;
  std::string describe() const override;
  double depth_units_per_metre() const override { return 1000.0; }
  std::string intrinsics_source() const override { return "the streams' field of view"; }
  std::optional<std::pair<double, double>> trajectory_span() const override { return trajectory_.span(); }

 private:
  struct Impl;
  void open();
  std::filesystem::path path_;
  OpenNi2Options options_;
  std::unique_ptr<Impl> impl_;
  ar::Trajectory trajectory_;
  int64_t frames_ = 0;
  int64_t cursor_ = 0;
};

}  // namespace artrace::io
