// Opens any supported recording by what it is: a folder in the TUM RGB-D layout, a colour/depth
// image folder, or an ONI file; with the user's intrinsics file and depth scale where given.
#pragma once

#include "artrace/ar/sensor_frame.h"

#include <filesystem>
#include <memory>
#include <optional>

namespace artrace::io {

struct RecordingOptions {
  /// A camera file (intrinsics_file.h) to use instead of the recording's own intrinsics. Without it,
  /// a folder's own file (find_camera_file) is used. Non-zero distortion coefficients make the
  /// frames undistorted (colour bilinear, depth nearest) to the same camera matrix.
  std::optional<std::filesystem::path> intrinsics;
  /// Stored depth units per metre, instead of the format's (TUM 5000, image folders and ONI 1000).
  std::optional<double> depth_units_per_metre;
  /// A TUM trajectory to use instead of the recording's own (groundtruth.txt, trajectory.txt, the
  /// ONI sidecar).
  std::optional<std::filesystem::path> trajectory;
};

/// Throws ParseError naming the path when it is none of them, or when the reader refuses it.
std::unique_ptr<ar::FrameSource> open_recording(const std::filesystem::path& path, const RecordingOptions& options = {});

}  // namespace artrace::io
