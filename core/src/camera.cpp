#include "artrace/core/camera.h"

#include <cmath>
#include <stdexcept>

namespace artrace::core {
namespace {

void set_fov(Camera& c, float fov_y_deg, int width, int height) {
  if (width <= 0 || height <= 0) throw std::invalid_argument("camera: image size must be positive");
  if (!Camera::valid_fov(fov_y_deg)) {
    throw std::invalid_argument("camera: field of view must lie in (0, 180) degrees");
  }
  c.width = width;
  c.height = height;
  const float f = 0.5f * static_cast<float>(height) / std::tan(glm::radians(fov_y_deg) * 0.5f);
  c.fx = c.fy = f;
  c.cx = 0.5f * static_cast<float>(width);
  c.cy = 0.5f * static_cast<float>(height);
}

}  // namespace

Camera Camera::look_at(const glm::vec3& from, const glm::vec3& at, const glm::vec3& up, float fov_y_deg,
                       int width, int height) {
  if (!valid_view(from, at, up)) {
    throw std::invalid_argument("camera: 'at' must differ from 'from' and 'up' must not be parallel to the view");
  }
  const glm::vec3 forward = at - from;
  const glm::vec3 right = glm::cross(forward, up);
  Camera c;
  set_fov(c, fov_y_deg, width, height);
  const glm::vec3 z = glm::normalize(forward);
  const glm::vec3 x = glm::normalize(right);
  const glm::vec3 y = glm::cross(z, x);  // points down in the picture
  c.position = from;
  c.rotation = glm::mat3(x, y, z);
  return c;
}

Camera Camera::from_gl_pose(const glm::vec3& position, const glm::mat3& gl_rotation, float fov_y_deg,
                            int width, int height) {
  Camera c;
  set_fov(c, fov_y_deg, width, height);
  c.position = position;
  // GL camera axes (x right, y up, z backwards) to vision axes (x right, y down, z forward).
  c.rotation = glm::mat3(gl_rotation[0], -gl_rotation[1], -gl_rotation[2]);
  return c;
}

}  // namespace artrace::core
