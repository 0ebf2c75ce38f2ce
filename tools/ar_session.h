// What export, replay and bench-ar share: an AR scene placed in a recording (anchors resolved on it,
// the fused room loaded), the compositor's options, and a reader that decodes the next frame on a
// thread of its own while the current one is composited.
#pragma once

#include "bench_util.h"
#include "commands.h"
#include "frame_reader.h"
#include "outputs.h"
#include "recording_options.h"

#include "artrace/ar/compositor.h"
#include "artrace/io/ar_scene.h"
#include "artrace/io/fusion.h"

#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>

namespace artrace::tools {

struct ArArgs {
  std::string scene, room;
  RecordingArgs rec;
  int threads = 0;
};

/// The files an AR command reads: the recording's (outputs.h) and the scene and room.
inline std::vector<std::string> ar_inputs(const std::string& recording, const ArArgs& a) {
  std::vector<std::string> in = recording_inputs(recording, a.rec.intrinsics, a.rec.trajectory);
  in.insert(in.end(), {a.scene, a.room});
  return in;
}

/// --scene (required), --room, the recording options, --depth-shift, --threads.
inline void add_ar_options(CLI::App* cmd, ArArgs& a) {
  cmd->add_option("--scene", a.scene, "AR scene (JSON)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--room", a.room, "a fused model of the recording's room (artrace fuse), the real scene instead of the per-frame depth mesh")
      ->check(CLI::ExistingFile);
  add_recording_options(cmd, a.rec);
  add_depth_shift_option(cmd, a.rec.depth_shift);
  add_threads_option(cmd, a.threads);
}

class ArSession {
 public:
  ArSession(const std::string& recording, const ArArgs& args, bool quiet = false) : recording_(recording), scene_file_(io::load_ar_scene(args.scene)) {
    if (!quiet) {
      for (const io::GltfModel& m : scene_file_.loaded) {
        for (const std::string& w : m.warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
      }
    }
    source_ = open_recording(recording, args.rec, quiet);
    frame_span_ = frame_time_span(*source_);
    require_poses_in_time(args.rec.trajectory.empty() ? recording + "'s trajectory" : args.rec.trajectory);
    io::resolve_anchors(scene_file_, *source_);
    runtime_ = std::make_unique<io::ArRuntime>(scene_file_);
    const std::string room = !args.room.empty() ? args.room : scene_file_.room ? scene_file_.room->string() : std::string();
    if (!room.empty()) room_ = std::make_unique<ar::FusedRoom>(io::read_room_ply(room));
    options_.lights = runtime_->lights();
    options_.ambient = runtime_->ambient();
    options_.alpha_tested = runtime_->alpha_tested();
    options_.threads = args.threads;
    options_.proxy = &proxy_;
    options_.room = room_.get();
    for (const io::ArModelPlacement& p : scene_file_.models) {
      if (p.support) options_.support_planes.push_back(*p.support);
    }
  }

  ar::FrameSource& source() { return *source_; }
  /// The colour times of the recording's first and last frames (frame_time_span).
  const std::optional<std::pair<double, double>>& frame_span() const { return frame_span_; }
  io::ArRuntime& runtime() { return *runtime_; }
  ar::CompositeOptions& options() { return options_; }
  const ar::FusedRoom* room() const { return room_.get(); }
  /// Frames composite() gave back as recorded, for want of a pose.
  int64_t frames_without_pose() const { return frames_without_pose_; }
  /// Frames composited with a camera in which a virtual object's bounds came into view.
  int64_t frames_in_view() const { return frames_in_view_; }

  /// The models moved to the frame's time, and the frame composited. `update_ms` (optional): the
  /// time the models took to move. A frame that the recording's trajectory gives no pose (it lies
  /// outside the trajectory, or in a gap of it) has no camera to place the models with: it comes
  /// back as recorded, and the first such frame is warned about on stderr. A recording without any
  /// trajectory (a TUM or image folder without one) is composited with a fixed camera at the
  /// world's origin, as an .oni file's is, with a warning the first time. A frame whose depth is
  /// not of its colour's size is refused (the compositor reads a pixel's depth at that pixel).
  ar::ColorImage composite(const ar::SensorFrame& f, ar::CompositeStats* st, double* update_ms = nullptr) {
    ar::require_depth_at_colour_size(f, recording_, "occlusion needs a depth at every colour pixel");
    if (!f.world_from_camera) {
      if (const auto span = source_->trajectory_span()) {
        ++frames_without_pose_;
        if (frames_without_pose_ == 1) {
          std::fprintf(stderr,
                       "warning: frame %lld (t = %.6f s) has no camera pose: the trajectory runs from %.6f to %.6f s and "
                       "gives poses only between samples at most 0.1 s apart; such frames are shown as recorded, "
                       "without the virtual objects\n",
                       static_cast<long long>(f.index), f.color_time_s, span->first, span->second);
        }
        if (st) *st = ar::CompositeStats{};
        if (update_ms) *update_ms = 0.0;
        return f.color;
      }
      if (!warned_fixed_camera_) {
        warned_fixed_camera_ = true;
        std::fprintf(stderr,
                     "warning: %s has no trajectory: the camera is taken as fixed, the AR scene's world being the camera's "
                     "frame (x right, y down, z forward, metres); give one with --trajectory, or estimate one with artrace track\n",
                     recording_.c_str());
      }
    }
    const double u = runtime_->update(f.color_time_s);
    if (update_ms) *update_ms = u;
    options_.object_bounds = runtime_->object_bounds();
    const io::ArRuntime& rt = *runtime_;
    ar::CompositeStats local;
    ar::CompositeStats& stats = st ? *st : local;
    ar::ColorImage out = ar::composite(f, rt.scene(), [&rt](const ar::SurfaceQuery& q) { return rt.material(q); }, options_, &stats);
    if (stats.traced_pixels > 0) ++frames_in_view_;
    return out;
  }

 private:
  /// Refuses a trajectory that covers none of the frames' times: its clock is not theirs, and every
  /// frame would come out as recorded.
  void require_poses_in_time(const std::string& trajectory) const {
    const auto span = source_->trajectory_span();
    if (!span || !frame_span_) return;
    const auto [first, last] = *frame_span_;
    if (last >= span->first && first <= span->second) return;
    auto seconds = [](double t) {
      char s[40];
      std::snprintf(s, sizeof s, "%.6f", t);
      return std::string(s);
    };
    throw std::runtime_error(trajectory + ": its poses run from " + seconds(span->first) + " to " + seconds(span->second) + " s, the frames of " +
                             recording_ + " from " + seconds(first) + " to " + seconds(last) +
                             " s: no frame has a camera pose (are their times on different clocks?)");
  }

  std::string recording_;
  io::ArSceneFile scene_file_;
  std::unique_ptr<ar::FrameSource> source_;
  std::unique_ptr<io::ArRuntime> runtime_;
  std::unique_ptr<ar::FusedRoom> room_;
  ar::DepthProxy proxy_;
  std::optional<std::pair<double, double>> frame_span_;
  int64_t frames_without_pose_ = 0, frames_in_view_ = 0;
  bool warned_fixed_camera_ = false;
  ar::CompositeOptions options_;
};

}  // namespace artrace::tools
