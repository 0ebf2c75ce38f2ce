// Pinhole camera in the computer-vision convention: camera x right, y down, z forward; pixel
// (u, v) has its centre at (u + 0.5, v + 0.5). The same model serves the BART views and the
// intrinsics of RGBD recordings.
#pragma once

#include "artrace/core/geometry.h"

#include <glm/mat3x3.hpp>

namespace artrace::core {

struct Camera {
  int width = 512;
  int height = 400;
  float fx = 1.0f, fy = 1.0f;  ///< focal lengths in pixels
  float cx = 0.0f, cy = 0.0f;  ///< principal point in pixels
  glm::vec3 position{0.0f};
  glm::mat3 rotation{1.0f};    ///< world-from-camera; columns are the camera's x, y, z axes

  /// Whether look_at can make a camera of these: `at` apart from `from`, `up` not parallel to the
  /// view direction. (Readers check their files with it, to name the file and line.)
  static bool valid_view(const glm::vec3& from, const glm::vec3& at, const glm::vec3& up) {
    return glm::length(at - from) > 0.0f && glm::length(glm::cross(at - from, up)) > 0.0f;
  }
  /// Whether a full vertical field of view is usable: strictly between 0 and 180 degrees.
  static bool valid_fov(float fov_y_deg) { return fov_y_deg > 0.0f && fov_y_deg < 180.0f; }

  /// A camera at `from` looking at `at`, `up` pointing up in the picture, `fov_y_deg` the full
  /// vertical field of view. Throws std::invalid_argument on a degenerate view (valid_view,
  /// valid_fov).
  static Camera look_at(const glm::vec3& from, const glm::vec3& at, const glm::vec3& up, float fov_y_deg,
                        int width, int height);
  /// A camera with pose (position, world-from-camera rotation of a camera that looks down -z with
  /// +y up, as in OpenGL and BART) and a vertical field of view.
  static Camera from_gl_pose(const glm::vec3& position, const glm::mat3& gl_rotation, float fov_y_deg,
                             int width, int height);

  /// Unnormalised direction of the ray through the pixel position (u, v) (pixel centres at +0.5).
  glm::vec3 direction(float u, float v) const {
    return rotation * glm::vec3((u - cx) / fx, (v - cy) / fy, 1.0f);
  }
  Ray ray(float u, float v) const { return Ray{position, direction(u, v), 0.0f, kInfinity}; }
};

}  // namespace artrace::core
