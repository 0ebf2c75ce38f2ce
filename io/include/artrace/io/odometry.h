// Camera trajectories for recordings that have none: frame-to-frame RGB-D odometry from OpenCV's
// rgbd module (opencv_contrib; photometric + geometric alignment, F. Steinbruecker, J. Sturm and
// D. Cremers, "Real-Time Visual Odometry from Dense RGB-D Images", ICCV Workshops 2011), chained
// into world-from-camera poses with the first frame as the world.
#pragma once

#include "artrace/ar/sensor_frame.h"
#include "artrace/ar/trajectory.h"

#include <string>

namespace artrace::io {

struct OdometryOptions {
  std::string method = "RgbdICPOdometry";  ///< or "RgbdOdometry", "ICPOdometry"
  int max_frames = 0;                      ///< 0 = all
};

struct OdometryResult {
  ar::Trajectory trajectory;
  int failures = 0;  ///< frames where odometry failed and the previous motion was kept
  ar::Trajectory reference;  ///< the poses the frames carried, when every frame had one
};

/// Runs odometry over the source from its current position.
OdometryResult estimate_trajectory(ar::FrameSource& source, const OdometryOptions& options = {});

/// Drift against a reference trajectory (both aligned at their first pose): RMS and final
/// translation error in metres, and the final rotation error in degrees.
struct DriftReport {
  double rms_m = 0.0, final_m = 0.0, final_deg = 0.0;
  int compared = 0;
};
DriftReport compare_trajectories(const ar::Trajectory& estimate, const ar::Trajectory& reference);

}  // namespace artrace::io
