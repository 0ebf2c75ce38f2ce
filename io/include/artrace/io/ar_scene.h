// AR scene files (JSON): which glTF models to place in a recording's world, how, and the lights.
//
//   {
//     "models": [
//       { "file": "models/box.gltf", "position": [0, 0.76, 0], "rotation_deg": [0, 30, 0],
//         "scale": 1.0 | [sx, sy, sz], "animation": { "clip": 0 | "name", "speed": 1.0 },
//         "material": { "kind": "diffuse" | "mirror" | "glass", "base_color": [r, g, b], "ior": 1.5,
//                       "metallic": 0.0, "roughness": 0.5 } },
//       { "file": "models/man.glb", "scale": 0.3,
//         "anchor": { "frame": 0, "pixel": [320, 400], "offset": 0.0, "rotation_deg": 30 } }
//     ],
//     "lights": [ { "position": [x, y, z], "color": [r, g, b] } ],
//     "ambient": 0.3,
//     "room": "room.ply"
//   }
//
// An anchor stands a model on the real surface seen at a pixel of a frame of the recording, instead
// of a position: its origin on the plane fitted around that pixel (ar::plane_at_pixel: RANSAC over
// the depths within 12 pixels, in world coordinates, so with or without a trajectory), its +Y along
// the plane's normal (towards the camera that saw it), its +Z towards that camera along the plane,
// then turned by "rotation_deg" about the normal and lifted by "offset" metres along it. Anchored
// models take no "position" or "rotation_deg" of their own; resolve_anchors() places them once the
// recording is open.
//
// Paths are relative to the JSON file. Every key is checked: an unknown key, a wrong type or a
// number beyond +-1e6 is an error naming the file and the key ("scene.json:
// models[1].rotation_deg: expected 3 numbers").
// "room" names a fused model of the recording's room (a mesh `artrace fuse` writes), which the
// compositor then takes as the real scene (ar::CompositeOptions::room).
// Without lights, one light is estimated from the frame's brightness (see ar::Compositor).
#pragma once

#include "artrace/ar/plane_fit.h"
#include "artrace/ar/sensor_frame.h"
#include "artrace/io/gltf_model.h"

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace artrace::io {

enum class SurfaceKind { kDiffuse, kMirror, kGlass };

struct ArModelPlacement {
  std::filesystem::path file;
  glm::vec3 position{0.0f};
  glm::vec3 rotation_deg{0.0f};  ///< applied as Rz · Ry · Rx
  glm::vec3 scale{1.0f};
  int clip = -1;      ///< -1: no animation
  float speed = 1.0f;
  std::optional<SurfaceKind> kind;
  std::optional<glm::vec3> base_color;  ///< replaces the base colour and its texture
  std::optional<float> ior;
  std::optional<float> metallic, roughness;
  struct Anchor {
    int frame = 0;
    int u = 0, v = 0;
    float offset_m = 0.0f;
    float rotation_deg = 0.0f;
  };
  std::optional<Anchor> anchor;
  /// Set by resolve_anchors: world from the anchor's frame (origin on the plane, +Y its normal).
  std::optional<glm::mat4> anchored;
  /// Set by resolve_anchors: the plane the model stands on (world), for contacts.
  std::optional<ar::Plane> support;

  glm::mat4 world_from_model() const;
};

struct ArLightSpec {
  glm::vec3 position{0.0f};
  glm::vec3 color{1.0f};
};

struct ArSceneFile {
  std::filesystem::path file;
  std::vector<ArModelPlacement> models;
  std::vector<GltfModel> loaded;  ///< one per placement
  std::vector<ArLightSpec> lights;
  float ambient = 0.3f;
  /// A fused model of the recording's room (artrace fuse), the real scene for the compositor.
  std::optional<std::filesystem::path> room;
};

/// Loads the JSON and every model it names. Throws ParseError.
ArSceneFile load_ar_scene(const std::filesystem::path& path);

/// Places the anchored models on the surfaces of `recording` (see above); leaves it positioned at
/// frame 0. Throws ParseError naming the scene file and the model when an anchor's frame does not
/// exist or no plane is found at its pixel.
void resolve_anchors(ArSceneFile& scene, ar::FrameSource& recording);

}  // namespace artrace::io

#include "artrace/ar/compositor.h"
#include "artrace/core/two_level_scene.h"

namespace artrace::io {

/// The virtual objects of an AR scene file in a two-level scene, as the paper's three kinds:
/// models without animation go into the static kd-tree (in world space, built once); meshes under
/// animated nodes are rigid instances whose transforms the node animation drives (hierarchically
/// transformed objects); skinned meshes, and meshes whose morph weights are animated, are
/// deformable meshes whose vertices are recomputed and refit every update.
///
/// Materials are looked up per hit (material()): base colour, metallic, roughness, occlusion and
/// emissive textures sampled at the interpolated texture coordinates with a ray-cone level of
/// detail, vertex colours, interpolated normals and normal maps (tangents from TANGENT, or from the
/// texture coordinates), alpha MASK as cut-outs and BLEND as coverage; the placement's material
/// override on top. Single-sided surfaces are seen from both sides: a ray tracer meets back faces
/// only inside closed models or at open ones, where culling them would show holes.
class ArRuntime {
 public:
  explicit ArRuntime(const ArSceneFile& scene);
  /// Moves the animated models to recording time t (seconds) and commits. Returns milliseconds.
  double update(double time_s);
  const core::TwoLevelScene& scene() const { return scene_; }
  ar::VirtualMaterial material(const ar::SurfaceQuery& hit) const;
  std::vector<ar::VirtualLight> lights() const;
  float ambient() const { return file_.ambient; }
  /// Whether some material cuts out or blends (ar::CompositeOptions::alpha_tested).
  bool alpha_tested() const { return alpha_tested_; }
  /// How many triangles went into each kind.
  size_t static_triangles() const { return static_parts_.size(); }
  size_t instance_count() const { return parts_.size(); }
  size_t skinned_meshes() const { return deforming_.size(); }
  /// World box of every placed model at the last update (for ar::CompositeOptions::object_bounds).
  const std::vector<core::Aabb>& object_bounds() const { return bounds_; }

 private:
  struct Part {
    size_t placement = 0;
    int node = -1;
    int mesh = -1;
    core::InstanceHandle instance;
    core::Aabb object_box;  ///< of the mesh, in its own space
  };
  struct StaticTriangle {
    uint32_t placement, mesh, triangle, xform;  ///< xform: into static_xforms_
  };
  struct Deforming {
    size_t placement;
    int node, mesh, skin;  ///< skin -1: morph targets only
    core::DeformableHandle handle;
    std::vector<glm::vec3> normals;  ///< world space, at the last update (empty: flat)
  };
  /// The part of a hit's material that does not depend on where in the triangle it is: the
  /// placement's overrides applied to the glTF material's factors.
  ar::VirtualMaterial triangle_material(size_t placement, int mesh, uint32_t triangle) const;
  /// Each triangle's share of light let through to shadow rays (ar::shadow_transmittance); empty
  /// when none of the mesh is glass.
  std::vector<float> glass_pass(size_t placement, int mesh) const;

  const ArSceneFile& file_;
  core::TwoLevelScene scene_{core::TwoLevelScene::Config::kKdTreeBvh};
  std::vector<Part> parts_;  ///< indexed by instance slot
  std::vector<StaticTriangle> static_parts_;  ///< indexed by static triangle
  std::vector<glm::mat4> static_xforms_;      ///< world from mesh of the static parts
  std::vector<Deforming> deforming_;          ///< indexed by deformable slot
  std::vector<core::Aabb> static_bounds_;  ///< per placement: its static triangles
  std::vector<core::Aabb> bounds_;         ///< per placement, at the last update
  std::vector<std::vector<ar::Texture>> textures_;  ///< per placement, per image: [2 i] linear, [2 i + 1] sRGB
  bool alpha_tested_ = false;
};

}  // namespace artrace::io
