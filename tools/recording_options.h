// The options every command that reads a recording takes: the camera's intrinsics file, the depth
// scale and a trajectory; and opening the recording with its warnings printed.
#pragma once

#include <CLI/CLI.hpp>

#include "artrace/ar/depth_registration.h"
#include "artrace/io/recording.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>

namespace artrace::tools {

struct RecordingArgs {
  std::string intrinsics, trajectory;
  double depth_scale = 0.0;  ///< 0: the format's own
  std::string depth_shift;   ///< --depth-shift, for the commands that offer it ("" leaves the depth as read)
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

/// --depth-shift auto|DX,DY: the depth's residual shift from the colour (depth_registration.h).
inline void add_depth_shift_option(CLI::App* cmd, std::string& value) {
  value = "auto";
  cmd->add_option("--depth-shift", value,
                  "depth lined up with the colour: 'auto' estimates the shift from the depth's edges against the colour's, "
                  "'DX,DY' takes the colour pixel (x,y)'s depth from (x+DX,y+DY), '0,0' leaves it")
      ->capture_default_str()
      ->check([](const std::string& v) -> std::string {
        int dx = 0, dy = 0;
        char end = 0;
        if (v == "auto" || std::sscanf(v.c_str(), "%d,%d%c", &dx, &dy, &end) == 2) return "";
        return "expected 'auto' or 'DX,DY' (whole pixels), got '" + v + "'";
      });
}

/// The shift --depth-shift names; `estimate` runs for 'auto', and its finding is printed on stderr.
inline ar::DepthShift resolve_depth_shift(const std::string& value, const std::function<ar::DepthShiftEstimate()>& estimate,
                                          bool quiet = false) {
  ar::DepthShift s;
  if (value == "auto") {
    const ar::DepthShiftEstimate e = estimate();
    if (!quiet) std::fprintf(stderr, "note: %s\n", e.describe().c_str());
    return e.shift;
  }
  std::sscanf(value.c_str(), "%d,%d", &s.dx, &s.dy);
  return s;
}

/// The colour times of a recording's first and last frames (both read, then the source rewound);
/// empty when it holds none or does not say how many.
inline std::optional<std::pair<double, double>> frame_time_span(ar::FrameSource& source) {
  const int64_t count = source.frame_count().value_or(0);
  ar::SensorFrame first, last;
  source.seek(0);
  if (count <= 0 || !source.next(first)) return std::nullopt;
  source.seek(count - 1);
  if (!source.next(last)) last = first;
  source.seek(0);
  return std::make_pair(first.color_time_s, last.color_time_s);
}

/// A recording's frame rate from `count` frames over their time span, to a thousandth (30 for one
/// frame, or none).
inline double recording_rate(int64_t count, const std::optional<std::pair<double, double>>& span) {
  const double seconds = span ? span->second - span->first : 0.0;
  if (count < 2 || !(seconds > 0.0)) return 30.0;
  return std::clamp(std::round(1000.0 * static_cast<double>(count - 1) / seconds) / 1000.0, 1.0, 1000.0);
}

/// Opens the recording and prints its warnings (defaults used, frames skipped) on stderr; with
/// --depth-shift, the depth lined up with the colour.
inline std::unique_ptr<ar::FrameSource> open_recording(const std::string& path, const RecordingArgs& a, bool quiet = false) {
  io::RecordingOptions o;
  if (!a.intrinsics.empty()) o.intrinsics = a.intrinsics;
  if (a.depth_scale > 0.0) o.depth_units_per_metre = a.depth_scale;
  if (!a.trajectory.empty()) o.trajectory = a.trajectory;
  std::unique_ptr<ar::FrameSource> source = io::open_recording(path, o);
  if (!quiet) {
    for (const std::string& w : source->warnings()) std::fprintf(stderr, "warning: %s\n", w.c_str());
  }
  if (!a.depth_shift.empty()) {
    const ar::DepthShift shift = resolve_depth_shift(a.depth_shift, [&] { return ar::estimate_depth_shift(*source); }, quiet);
    if (!shift.zero()) source = std::make_unique<ar::DepthShiftedSource>(std::move(source), shift);
  }
  return source;
}

}  // namespace artrace::tools
