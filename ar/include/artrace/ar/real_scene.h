// The real scene as geometry, as the compositor asks about it: where a ray meets it, with what
// recorded colour and normal. Two kinds:
//   - the per-frame depth mesh (depth_proxy.h), rebuilt from each frame's depth map;
//   - a fused model of the room (FusedRoom): a triangle mesh integrated from every frame (io's
//     `fuse`), static geometry in a kd-tree built once, with the colours fused into its vertices.
//     It knows the room outside the current view and where the sensor had holes or noise.
#pragma once

#include "artrace/ar/sensor_frame.h"
#include "artrace/core/two_level_scene.h"

#include <glm/glm.hpp>

#include <vector>

namespace artrace::ar {

class RealScene {
 public:
  virtual ~RealScene() = default;
  /// Takes the frame (the depth mesh rebuilds; a fused room changes nothing). Returns milliseconds.
  virtual double update(const SensorFrame& frame) = 0;
  /// The geometry, for any-hit queries (a real surface between a point and a light).
  virtual const core::TwoLevelScene& scene() const = 0;
  virtual bool empty() const = 0;
  /// Closest hit of a world-space ray; the recorded colour there (linear RGB) when it hits.
  virtual bool intersect(const core::Ray& ray, float& t, glm::vec3& colour) const = 0;
  /// The same for the lanes of `mask` of a packet, traced together; returns the lanes that hit
  /// (their t and colour set). The same answers as one ray at a time.
  virtual core::LaneMask intersect(const core::RayPacket& rays, core::LaneMask mask, float* t, glm::vec3* colour) const;
};

/// A fused triangle mesh of the real scene (world coordinates), vertex colours in linear RGB.
struct RoomMesh {
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> colours;
  std::vector<glm::uvec3> triangles;
};

class FusedRoom : public RealScene {
 public:
  /// Builds the kd-tree over the mesh's triangles. Throws std::invalid_argument for indices past
  /// the vertices or colours that do not match them.
  explicit FusedRoom(RoomMesh mesh);
  double update(const SensorFrame&) override { return 0.0; }
  const core::TwoLevelScene& scene() const override { return scene_; }
  bool empty() const override { return mesh_.triangles.empty(); }
  bool intersect(const core::Ray& ray, float& t, glm::vec3& colour) const override;
  core::LaneMask intersect(const core::RayPacket& rays, core::LaneMask mask, float* t, glm::vec3* colour) const override;
  /// The room's unit normal at a hit (interpolated vertex normals, facing `dir`'s origin side).
  glm::vec3 normal(const core::Hit& hit, const glm::vec3& dir) const;
  const RoomMesh& mesh() const { return mesh_; }

 private:
  glm::vec3 colour_at(const core::Hit& h) const;

  RoomMesh mesh_;
  std::vector<glm::vec3> normals_;
  core::TwoLevelScene scene_{core::TwoLevelScene::Config::kKdTreeBvh};
};

}  // namespace artrace::ar
