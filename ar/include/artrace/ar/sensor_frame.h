// One frame of an RGBD recording, as every reader delivers it, and the interface of the readers.
#pragma once

#include "artrace/ar/pinhole_intrinsics.h"

#include <Eigen/Geometry>

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace artrace::ar {

/// 8-bit RGB, row-major, top row first, no padding.
struct ColorImage {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> rgb;  ///< 3 bytes a pixel: R, G, B

  bool empty() const { return width == 0 || height == 0; }
  const uint8_t* at(int x, int y) const { return rgb.data() + 3 * (static_cast<size_t>(y) * width + x); }
};

/// Depth in metres along the optical axis; 0 marks a pixel without a reading (the sensor saw
/// nothing there, or the value was invalid): never a made-up value.
/// Metres of a stored depth value: value / units_per_metre, divided in double and rounded once to
/// float, so that one depth stored in any unit is the same float (1201 mm and 6005 TUM units both
/// give 1.201f): recordings converted between formats keep their depths bit for bit.
inline float depth_metres(uint32_t value, double units_per_metre) { return static_cast<float>(value / units_per_metre); }

struct DepthImage {
  int width = 0;
  int height = 0;
  std::vector<float> depth_m;

  bool empty() const { return width == 0 || height == 0; }
  float at(int x, int y) const { return depth_m[static_cast<size_t>(y) * width + x]; }
  static bool valid(float d) { return d > 0.0f; }
};

struct SensorFrame {
  ColorImage color;
  DepthImage depth;
  double color_time_s = 0.0;
  double depth_time_s = 0.0;
  PinholeIntrinsics color_intrinsics;
  PinholeIntrinsics depth_intrinsics;
  /// world-from-camera of the colour camera, when the recording (or a sidecar trajectory) has one
  std::optional<Eigen::Isometry3d> world_from_camera;
  int64_t index = 0;
};

/// Throws std::runtime_error "WHERE: frame N: depth is WxH, colour wxh: NEED" unless the frame's
/// depth is of its colour's size, as everything that reads a colour pixel's depth at the same
/// pixel (the compositor, odometry, fusion, a TUM folder) needs.
inline void require_depth_at_colour_size(const SensorFrame& f, const std::string& where, const std::string& need) {
  if (f.depth.width == f.color.width && f.depth.height == f.color.height) return;
  throw std::runtime_error(where + ": frame " + std::to_string(f.index) + ": depth is " + std::to_string(f.depth.width) + "x" +
                           std::to_string(f.depth.height) + ", colour " + std::to_string(f.color.width) + "x" +
                           std::to_string(f.color.height) + ": " + need);
}

/// Every reader: open in the constructor (throwing io::ParseError naming the file on bad input),
/// then next / seek / rewind.
class FrameSource {
 public:
  virtual ~FrameSource() = default;
  /// Number of frames when known up front.
  virtual std::optional<int64_t> frame_count() const = 0;
  /// The next frame; false at the end.
  virtual bool next(SensorFrame& frame) = 0;
  /// Positions the source so that next() returns frame `index` (0-based). Throws std::out_of_range.
  virtual void seek(int64_t index) = 0;
  void rewind() { seek(0); }
  /// What the source reads, for messages and `artrace info`.
  virtual std::string describe() const = 0;
  /// Stored depth units per metre (5000 in TUM folders, 1000 for millimetres).
  virtual double depth_units_per_metre() const = 0;
  /// Where the intrinsics come from (a file, the recording's own metadata, or defaults).
  virtual std::string intrinsics_source() const = 0;
  /// What the reader had to decide for the user at open (defaults used, frames skipped or
  /// dropped, depth not registered): the tools print these.
  virtual std::vector<std::string> warnings() const { return {}; }
  /// The trajectory the frames take their poses from, when there is one: (first, last) sample
  /// times in seconds. A frame outside it, or in a gap of it, comes without a pose (where a
  /// recording without a trajectory gives each frame a fixed camera, or none).
  virtual std::optional<std::pair<double, double>> trajectory_span() const { return std::nullopt; }
};

/// Frames held in memory as a recording (synthetic frames, tests).
class FrameList : public FrameSource {
 public:
  explicit FrameList(std::vector<SensorFrame> frames, std::string what = "frames in memory")
      : frames_(std::move(frames)), what_(std::move(what)) {}
  std::optional<int64_t> frame_count() const override { return static_cast<int64_t>(frames_.size()); }
  bool next(SensorFrame& frame) override {
    if (cursor_ >= frames_.size()) return false;
    frame = frames_[cursor_++];
    return true;
  }
  void seek(int64_t index) override {
    if (index < 0 || static_cast<size_t>(index) > frames_.size()) throw std::out_of_range(what_ + ": no frame " + std::to_string(index));
    cursor_ = static_cast<size_t>(index);
  }
  std::string describe() const override { return what_; }
  double depth_units_per_metre() const override { return 1000.0; }
  std::string intrinsics_source() const override { return "given"; }

 private:
  std::vector<SensorFrame> frames_;
  std::string what_;
  size_t cursor_ = 0;
};

}  // namespace artrace::ar
