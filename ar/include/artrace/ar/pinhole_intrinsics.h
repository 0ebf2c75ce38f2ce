// Sensor geometry of an RGBD camera (Eigen) and its hand-over to the renderer's camera (GLM).
#pragma once

#include "artrace/core/camera.h"

#include <Eigen/Geometry>

namespace artrace::ar {

/// Pinhole intrinsics in pixels, OpenCV convention (x right, y down, z forward; the centre of pixel
/// (x, y) is at (x, y), whereas core::Camera puts it at (x + 0.5, y + 0.5)).
struct PinholeIntrinsics {
  int width = 0;
  int height = 0;
  double fx = 0.0, fy = 0.0, cx = 0.0, cy = 0.0;

  /// Throws std::invalid_argument when a size or focal length is not positive or not finite.
  void validate() const;
  /// Pixel coordinates of a camera-space point (z > 0).
  Eigen::Vector2d project(const Eigen::Vector3d& p_cam) const;
  /// Camera-space point at pixel (u, v) and depth z (metres along the optical axis).
  Eigen::Vector3d unproject(double u, double v, double z) const;
};

/// The renderer's camera for a sensor with these intrinsics at pose `world_from_camera`.
core::Camera make_camera(const PinholeIntrinsics& k, const Eigen::Isometry3d& world_from_camera);

}  // namespace artrace::ar
