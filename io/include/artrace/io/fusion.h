// A fused model of the room: every frame of a recording integrated with its pose into a truncated
// signed distance field (B. Curless and M. Levoy, "A Volumetric Method for Building Complex Models
// from Range Images", SIGGRAPH 1996; R. A. Newcombe et al., "KinectFusion", ISMAR 2011), and a
// triangle mesh with vertex colours extracted from it by marching cubes. The TSDF is Open3D's
// (0.16, Debian's libopen3d-dev): ScalableTSDFVolume, a hashed voxel volume integrated on the CPU.
// The mesh is written and read as PLY through Open3D too.
#pragma once

#include "artrace/ar/real_scene.h"
#include "artrace/ar/sensor_frame.h"

#include <filesystem>
#include <functional>

namespace artrace::io {

struct FusionOptions {
  double voxel_m = 0.01;        ///< voxel edge
  double truncation_m = 0.04;   ///< signed distances are cut off beyond this
  double max_depth_m = 4.0;     ///< depths beyond are left out (the sensor's noise grows as z^2)
  int every = 1;                ///< integrate every n-th frame
};

struct FusionStats {
  int frames = 0;          ///< integrated
  int without_pose = 0;    ///< skipped: no pose
  double seconds = 0.0;
};

/// Integrates the recording from its current position to its end. Frames without a pose are
/// skipped (a recording without a trajectory has a fixed camera at the origin: its frames are all
/// integrated there). `progress(frame, total)` is called after each frame. Throws
/// std::runtime_error when no frame has a pose.
ar::RoomMesh fuse_recording(ar::FrameSource& recording, const FusionOptions& options, FusionStats* stats = nullptr,
                            const std::function<void(int, int)>& progress = {});

/// PLY (binary) through a temporary name renamed into place.
void write_room_ply(const ar::RoomMesh& mesh, const std::filesystem::path& path);
/// Throws ParseError naming the file when it is not a readable triangle mesh.
ar::RoomMesh read_room_ply(const std::filesystem::path& path);

}  // namespace artrace::io
