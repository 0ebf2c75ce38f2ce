// Camera intrinsics from the files people have:
//   - `.txt`: 'fx fy cx cy [width height]', as TUM sequences and the project's writer keep them
//     (read_intrinsics in tum_reader.h);
//   - `.json`: Open3D's PinholeCameraIntrinsic ("intrinsic_matrix": 9 numbers, column-major,
//     "width", "height"), what Open3D's and RealSense's tools write;
//   - `.yaml` / `.yml`: OpenCV calibration files ("camera_matrix" as an OpenCV matrix,
//     "distortion_coefficients", "image_width"/"image_height") and ROS camera_info files
//     ("camera_matrix" as {rows, cols, data}, or "K"; "distortion_coefficients" or "D").
// Values are checked as read_intrinsics checks them; a file without the keys, or with numbers out
// of range, is a ParseError naming the file and the key.
#pragma once

#include "artrace/ar/pinhole_intrinsics.h"

#include <filesystem>
#include <optional>
#include <vector>

namespace artrace::io {

struct CameraFile {
  ar::PinholeIntrinsics intrinsics;  ///< width and height 0 where the file does not give them
  std::vector<double> distortion;    ///< OpenCV order (k1 k2 p1 p2 [k3 ...]); empty when not given
  std::filesystem::path file;
};

/// Reads one, choosing the format by the extension.
CameraFile read_camera_file(const std::filesystem::path& path);

/// The intrinsics file a recording folder holds, looked for in this order: intrinsics.txt,
/// intrinsics.json, camera_intrinsic.json, camera.yaml, camera_info.yaml, calibration.yaml.
std::optional<std::filesystem::path> find_camera_file(const std::filesystem::path& folder);

}  // namespace artrace::io
