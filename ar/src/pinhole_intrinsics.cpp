#include "artrace/ar/pinhole_intrinsics.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace artrace::ar {

void PinholeIntrinsics::validate() const {
  auto bad = [](double x) { return !(std::isfinite(x) && x > 0.0); };
  if (width <= 0 || height <= 0) {
    throw std::invalid_argument("intrinsics: image size " + std::to_string(width) + "x" +
                                std::to_string(height) + " is not positive");
  }
  if (bad(fx) || bad(fy)) throw std::invalid_argument("intrinsics: focal lengths must be positive and finite");
  if (!std::isfinite(cx) || !std::isfinite(cy)) throw std::invalid_argument("intrinsics: principal point is not finite");
}

Eigen::Vector2d PinholeIntrinsics::project(const Eigen::Vector3d& p) const {
  return {fx * p.x() / p.z() + cx, fy * p.y() / p.z() + cy};
}

Eigen::Vector3d PinholeIntrinsics::unproject(double u, double v, double z) const {
  return {(u - cx) / fx * z, (v - cy) / fy * z, z};
}

core::Camera make_camera(const PinholeIntrinsics& k, const Eigen::Isometry3d& world_from_camera) {
  k.validate();
  core::Camera c;
  c.width = k.width;
  c.height = k.height;
  c.fx = static_cast<float>(k.fx);
  c.fy = static_cast<float>(k.fy);
  // OpenCV puts the centre of pixel x at x; the renderer at x + 0.5.
  c.cx = static_cast<float>(k.cx + 0.5);
  c.cy = static_cast<float>(k.cy + 0.5);
  const Eigen::Vector3d t = world_from_camera.translation();
  const Eigen::Matrix3d r = world_from_camera.rotation();
  c.position = glm::vec3(t.x(), t.y(), t.z());
  for (int col = 0; col < 3; ++col) {
    for (int row = 0; row < 3; ++row) c.rotation[col][row] = static_cast<float>(r(row, col));
  }
  return c;
}

}  // namespace artrace::ar
