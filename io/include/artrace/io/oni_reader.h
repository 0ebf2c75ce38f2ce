// Plays ONI recordings (OpenNI 1.x and OpenNI2, as recorded in the field and as the project writes
// them) with the project's own container reader and decoders (oni_file.h, oni_codecs.h): depth as
// uncompressed, 16zP or 16zT; colour as JPEG or uncompressed RGB24, YUV422 or GRAY8.
//
// - Frames: each depth frame paired with the colour frame nearest in time (within half a frame
//   period, each used once; in OpenNI's recordings this pairs equal frame numbers). Seeking is
//   frame-accurate and O(1): the records are indexed at open.
// - Depth unit: millimetres (OpenNI 1.x has no other), or 0.1 mm where an OpenNI2 file says
//   oniPixelFormat 101 (DEPTH_100_UM); OniOptions::depth_units_per_metre overrides it.
// - Intrinsics: from the colour stream's xnFOV (radians), principal point at the image centre; else
//   525 px at 640 wide (scaled), with a warning naming them. OniOptions::intrinsics overrides.
// - Registration: the depth stream's AlternativeViewPoint (1: registered to the colour camera);
//   depth that is not registered is read as it is, with a warning.
// - Dropped frames: timestamp gaps of more than 1.5 frame periods, listed by gaps().
// - Poses: a sidecar TUM trajectory ("<file>.trajectory.txt" or OniOptions::trajectory), else the
//   camera stays at the origin (camera frame, y down).
#pragma once

#include "artrace/ar/sensor_frame.h"
#include "artrace/ar/trajectory.h"
#include "artrace/io/oni_file.h"

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace artrace::io {

struct OniOptions {
  std::optional<std::filesystem::path> trajectory;  ///< sidecar TUM trajectory (else "<file>.trajectory.txt" if present)
  std::optional<ar::PinholeIntrinsics> intrinsics;  ///< else from the colour stream's field of view
  std::optional<double> depth_units_per_metre;      ///< else from the file (1000, or 10000 for DEPTH_100_UM)
  double max_pose_gap_s = 0.1;
};

/// A gap in a stream's timestamps: frames the sensor or recorder dropped.
struct OniGap {
  std::string stream;  ///< "depth" or "colour"
  size_t after = 0;    ///< the index (in that stream) of the frame before the gap
  double gap_ms = 0.0;
  int missing = 0;     ///< frames the gap would hold at the stream's rate
};

class OniReader : public ar::FrameSource {
 public:
  explicit OniReader(const std::filesystem::path& path, const OniOptions& options = {});

  std::optional<int64_t> frame_count() const override { return static_cast<int64_t>(pairs_.size()); }
  bool next(ar::SensorFrame& frame) override;
  void seek(int64_t index) override;
  std::string describe() const override;
  double depth_units_per_metre() const override { return depth_units_; }
  std::string intrinsics_source() const override { return intrinsics_source_; }
  std::optional<std::pair<double, double>> trajectory_span() const override { return trajectory_.span(); }
  std::vector<std::string> warnings() const override { return warnings_; }

  const OniContainer& container() const { return file_; }
  const std::vector<OniGap>& gaps() const { return gaps_; }
  /// Whether the depth is registered to the colour camera (AlternativeViewPoint), when recorded.
  std::optional<bool> registered() const { return registered_; }
  /// Reads frame i without moving the cursor.
  ar::SensorFrame read(int64_t i) const;
  /// The same into `frame`, reusing its buffers.
  void read_into(int64_t i, ar::SensorFrame& frame) const;

 private:
  std::filesystem::path path_;
  OniOptions options_;
  OniContainer file_;
  const OniNode* depth_ = nullptr;
  const OniNode* color_ = nullptr;
  std::vector<std::pair<size_t, size_t>> pairs_;  ///< (depth frame, colour frame)
  std::vector<OniGap> gaps_;
  std::vector<std::string> warnings_;
  ar::Trajectory trajectory_;
  ar::PinholeIntrinsics color_k_, depth_k_;
  std::string intrinsics_source_;
  double depth_units_ = 1000.0;
  std::vector<float> metres_;  ///< metres of every stored value (ar::depth_metres)
  std::optional<bool> registered_;
  int64_t cursor_ = 0;
};

}  // namespace artrace::io
