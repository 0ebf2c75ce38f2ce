// Writes recordings: a TUM RGB-D folder (rgb/, depth/ PNGs at 5000 per metre, rgb.txt, depth.txt,
// groundtruth.txt, intrinsics.txt) or an ONI file (depth in mm, RGB888) with its poses in a
// sidecar "<file>.trajectory.txt". Output appears under its final name only after close().
#pragma once

#include "artrace/ar/sensor_frame.h"

#include <filesystem>
#include <memory>

namespace artrace::io {

class RecordingWriter {
 public:
  virtual ~RecordingWriter() = default;
  /// Frames in order, all of the first frame's size; depth in metres (0 = no reading).
  virtual void write(const ar::SensorFrame& frame) = 0;
  /// Finishes the recording and moves it into place.
  virtual void close() = 0;
};

/// ".oni" (in any case) gives an ONI writer, anything else a TUM folder. `fps` is stored where the format has it.
std::unique_ptr<RecordingWriter> make_recording_writer(const std::filesystem::path& path, int fps = 30);

}  // namespace artrace::io
