// BART scenes in the AFF format (shared/docs/aff-format.md): loading, and the scene at any time t
// as static geometry plus animated objects with their transforms.
#pragma once

#include "artrace/core/camera.h"
#include "artrace/core/geometry.h"
#include "artrace/io/keyframe_animation.h"

#include <array>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace artrace::io {

/// `f` and `fm` materials. For `f r g b Kd Ks shine T ior`: diffuse = Kd·colour, specular = Ks·colour.
struct AffMaterial {
  glm::vec3 ambient{0.0f};
  glm::vec3 diffuse{0.8f};
  glm::vec3 specular{0.0f};
  float shine = 0.0f;
  float transmittance = 0.0f;
  float ior = 1.0f;
};

struct AffLight {
  glm::vec3 position{0.0f};
  glm::vec3 color{1.0f};
};

struct AffView {
  glm::vec3 from{0.0f}, at{0.0f, 0.0f, -1.0f}, up{0.0f, 1.0f, 0.0f};
  float fov_y_deg = 45.0f;
  float hither = 0.0f;
  int width = 512, height = 400;
};

/// Triangles with shading attributes, in the local frame of the node that holds them.
struct TriangleBatch {
  std::vector<core::Triangle> tris;
  std::vector<std::array<glm::vec3, 3>> normals;  ///< vertex normals (geometric when the file gives none)
  std::vector<std::array<glm::vec2, 3>> uvs;      ///< texture coordinates (zero when none)
  std::vector<uint32_t> material;                 ///< index into AffScene::materials
  std::vector<int32_t> texture;                   ///< index into AffScene::textures, -1 for none

  size_t size() const { return tris.size(); }
};

/// A node of the transform tree: node 0 is the world (static); every `x name { }` makes one node.
/// world(node, t) = world(parent, t) · offset · animation(t).
struct AffNode {
  int parent = -1;
  glm::dmat4 offset{1.0};
  std::string animation;  ///< empty for the root; an `x` without a `k` record stays at identity
  TriangleBatch geometry;
};

/// An animated triangle (`tpa`): vertex positions at key times, linear in between.
struct AffAnimatedTriangle {
  int node = 0;
  uint32_t material = 0;
  std::vector<double> times;
  std::vector<core::Triangle> keys;
};

struct AffScene {
  std::filesystem::path file;
  glm::vec3 background{0.0f};
  glm::vec3 ambient{0.0f};
  std::vector<AffLight> lights;
  std::vector<AffMaterial> materials;
  std::vector<std::filesystem::path> textures;  ///< resolved paths of the referenced PPM files
  std::optional<AffView> view;
  double anim_start = 0.0, anim_end = 0.0;
  int anim_frames = 1;
  std::map<std::string, KeyframeAnimation> animations;
  std::vector<AffNode> nodes;  ///< nodes[0] is the static world
  std::vector<AffAnimatedTriangle> animated_triangles;

  /// Time of frame f of the `a` record: start + f (end - start) / (frames - 1).
  double frame_time(int frame) const;
  /// World transform of a node at time t.
  glm::dmat4 node_transform(int node, double t) const;
  /// Every triangle of the scene in world space at time t: static nodes first, then the dynamic
  /// nodes in order, then the animated triangles.
  std::vector<core::Triangle> triangles_at(double t) const;
  size_t triangle_count() const;
  /// Triangles that never move (in nodes with no animated ancestor).
  size_t static_triangle_count() const;
  /// The light material `material` lets through, in [0, 1] (0 for an index out of range).
  float transmittance(uint32_t material) const;
  /// Whether an animated (deforming) triangle is transmissive.
  bool deforming_transmissive() const;
  /// The camera at time t: the `camera` animation when there is one (a camera looking down -z
  /// with +y up, moved by it), else the `v` view. Field of view from `v` (45 degrees without).
  core::Camera camera_at(double t, int width, int height) const;
};

/// Loads an AFF file and its includes. Throws ParseError naming file, line and column.
AffScene load_aff(const std::filesystem::path& file);

}  // namespace artrace::io
