// Plays ONI recordings through OpenNI2's own file driver: depth (DEPTH_1_MM or DEPTH_100_UM, to
// metres) and colour (RGB888) in manual mode (speed -1: one frame per waitForAnyStream, none
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

struct OniOptions {
  std::optional<std::filesystem::path> trajectory;  ///< sidecar TUM trajectory (else "<file>.trajectory.txt" if present)
  std::optional<ar::PinholeIntrinsics> intrinsics;  ///< else from the streams' field of view
  double max_pose_gap_s = 0.1;
};

class OniReader : public ar::FrameSource {
 public:
  explicit OniReader(const std::filesystem::path& path, const OniOptions& options = {});
  ~OniReader() override;

  std::optional<int64_t> frame_count() const override { return frames_; }
  bool next(ar::SensorFrame& frame) override;
  void seek(int64_t index) override;
  std::string describe() const override;

 private:
  struct Impl;
  void open();
  std::filesystem::path path_;
  OniOptions options_;
  std::unique_ptr<Impl> impl_;
  ar::Trajectory trajectory_;
  int64_t frames_ = 0;
  int64_t cursor_ = 0;
};

}  // namespace artrace::io
