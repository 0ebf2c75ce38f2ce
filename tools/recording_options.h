// The options every command that reads a recording takes: the camera's intrinsics file, the depth
// scale and a trajectory; and opening the recording with its warnings printed.
#pragma once

#include <CLI/CLI.hpp>

#include "artrace/io/recording.h"

#include <cstdio>
#include <memory>
#include <string>

namespace artrace::tools {

struct RecordingArgs {
  std::string intrinsics, trajectory;
  double depth_scale = 0.0;  ///< 0: the format's own
};

/// --intrinsics FILE, --depth-scale UNITS, --trajectory FILE.
inline void add_recording_options(CLI::App* cmd, RecordingArgs& a) {
  cmd->add_option("--intrinsics", a.intrinsics,
                  "camera intrinsics: intrinsics.txt (fx fy cx cy [w h]), Open3D JSON or OpenCV/ROS YAML (default: the recording's own)")
      ->check(CLI::ExistingFile);
  cmd->add_option("--depth-scale", a.depth_scale, "stored depth units per metre (default: TUM 5000, image folders and ONI 1000)")
      ->check(CLI::Range(1.0, 1e6));
  cmd->add_option("--trajectory", a.trajectory, "camera poses (TUM format) instead of the recording's own")->check(CLI::ExistingFile);
}

/// Opens the recording and prints its warnings (defaults used, frames skipped) on stderr.
inline std::unique_ptr<ar::FrameSource> open_recording(const std::string& path, const RecordingArgs& a, bool quiet = false) {
  io::RecordingOptions o;
  if (!a.intrinsics.empty()) o.intrinsics = a.intrinsics;
  if (a.depth_scale > 0.0) o.depth_units_per_metre = a.depth_scale;
  if (!a.trajectory.empty()) o.trajectory = a.trajectory;
  auto source = io::open_recording(path, o);
  if (!quiet) {
    for (const std::string& w : source->warnings()) std::fprintf(stderr, "warning: %s\n", w.c_str());
  }
  return source;
}

}  // namespace artrace::tools
