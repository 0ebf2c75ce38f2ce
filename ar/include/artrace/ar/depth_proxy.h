// The real scene as geometry, from the sensor's depth map, for the effects virtual objects have on
// it and it has on them:
//   - receivers: every pixel's depth point, with a normal from the depth gradient, receives the
//     virtual objects' shadows (differential rendering in compositor.cpp);
//   - a depth mesh: the depth map sampled every `step` pixels as a triangle grid in world space, a
//     deformable mesh in its own two-level scene, rebuilt each frame (lazily: only the parts rays
//     reach are built). Triangles across depth discontinuities (a jump of more than
//     `max_jump` x depth) or with a hole at a corner are left out. Reflection and refraction rays
//     leaving the virtual objects meet it and take the recorded colour where they hit.
#pragma once

#include "artrace/ar/real_scene.h"
#include "artrace/ar/sensor_frame.h"
#include "artrace/core/two_level_scene.h"

#include <memory>

namespace artrace::ar {

class DepthProxy : public RealScene {
 public:
  explicit DepthProxy(int step = 4, float max_jump = 0.05f);

  /// Takes the frame's depth (registered to the colour camera) and pose. Returns milliseconds.
  double update(const SensorFrame& frame) override;

  /// The depth mesh (empty when the frame has no depth).
  const core::TwoLevelScene& scene() const override { return scene_; }
  bool empty() const override { return triangles_ == 0; }
  size_t triangles() const { return triangles_; }

  /// Closest hit of a world-space ray with the depth mesh; the recorded colour there (linear RGB)
  /// when it hits.
  bool intersect(const core::Ray& ray, float& t, glm::vec3& colour) const override;
  core::LaneMask intersect(const core::RayPacket& rays, core::LaneMask mask, float* t, glm::vec3* colour) const override;

 private:
  /// The recorded colour where world point p projects (false behind the camera).
  bool colour_at(const glm::vec3& p, glm::vec3& colour) const;

  int step_;
  float max_jump_;
  const SensorFrame* frame_ = nullptr;  ///< the frame of the last update (colour look-ups)
  Eigen::Isometry3d camera_from_world_ = Eigen::Isometry3d::Identity();
  core::TwoLevelScene scene_{core::TwoLevelScene::Config::kBvh};
  core::DeformableHandle mesh_;
  bool has_mesh_ = false;
  size_t triangles_ = 0;
};

}  // namespace artrace::ar
