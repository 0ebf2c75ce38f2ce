// Synthetic RGBD recordings rendered by the project's own ray tracer: colour, exact depth, exact
// poses and intrinsics, optionally through the Kinect-like depth model. The ground truth of the
// occlusion tests and the source of the recording in data/.
#pragma once

#include "artrace/ar/depth_model.h"
#include "artrace/io/aff_scene.h"
#include "artrace/io/recording_writer.h"

#include <optional>

namespace artrace::io {

struct SynthOptions {
  int frames = 60;
  int fps = 30;
  int width = 640;
  int height = 480;
  double fov_y_deg = 45.0;  ///< 45 deg at 640x480: fx = fy ~ 579, close to a Kinect
  double start_time_s = 1.0;
  /// Camera path: the scene's `camera` track when it has one, else an orbit of `orbit_deg` around
  /// the view's 'at' point, starting at 'from'.
  double orbit_deg = 30.0;
  std::optional<ar::DepthModel> depth_model;  ///< none: exact depth
  uint64_t seed = 1;
  int threads = 0;
};

/// Renders frame k of a synthetic recording of `scene` (exact depth unless a model is given).
class Synthesizer {
 public:
  Synthesizer(const AffScene& scene, const SynthOptions& options);
  ~Synthesizer();
  ar::SensorFrame render(int k);
  /// All frames into a writer; returns the number written.
  int write(RecordingWriter& out);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace artrace::io
