// glTF 2.0 models (.gltf and .glb) through tinygltf: triangle meshes with their materials, the node
// hierarchy, node animation (translation, rotation, scale; LINEAR, STEP and CUBICSPLINE samplers)
// and skinning (JOINTS_0 / WEIGHTS_0, linear blend skinning with the skin's inverse bind matrices).
#pragma once

#include "artrace/core/geometry.h"

#include <glm/gtc/quaternion.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace artrace::io {

struct GltfMaterial {
  std::string name;
  glm::vec3 base_color{0.8f};
  float metallic = 0.0f;
  float roughness = 1.0f;
  float transmission = 0.0f;  ///< KHR_materials_transmission, or 1 - alpha for blended materials
  float ior = 1.5f;
};

struct GltfMesh {
  std::vector<core::Triangle> tris;  ///< in the mesh's own space (bind pose for skinned meshes)
  std::vector<uint32_t> material;    ///< per triangle
  // the same triangles, indexed (tris[i] = positions[indices[i]])
  std::vector<glm::vec3> positions;
  std::vector<glm::uvec3> indices;
  // skinning, per vertex (empty when the mesh has no JOINTS_0 / WEIGHTS_0)
  std::vector<glm::uvec4> joints;  ///< indices into the skin's joint list
  std::vector<glm::vec4> weights;
  bool skinned() const { return !joints.empty(); }
};

struct GltfSkin {
  std::string name;
  std::vector<int> joints;                ///< node indices
  std::vector<glm::mat4> inverse_bind;    ///< one per joint (identity when the file gives none)
};

struct GltfNode {
  std::string name;
  int parent = -1;
  int mesh = -1;
  int skin = -1;
  glm::vec3 translation{0.0f};
  glm::quat rotation{1.0f, 0.0f, 0.0f, 0.0f};
  glm::vec3 scale{1.0f};
  glm::mat4 matrix{1.0f};  ///< used when the node gives a matrix instead of TRS
  bool has_matrix = false;
};

struct GltfChannel {
  int node = 0;
  enum Path { kTranslation, kRotation, kScale } path = kTranslation;
  enum Interp { kLinear, kStep, kCubic } interpolation = kLinear;
  std::vector<float> times;
  std::vector<glm::vec4> values;  ///< xyz (w unused) or quaternion xyzw; cubic: in-tangent, value, out-tangent per key
};

struct GltfAnimation {
  std::string name;
  std::vector<GltfChannel> channels;
  float duration_s = 0.0f;
};

struct GltfModel {
  std::filesystem::path file;
  std::vector<GltfMaterial> materials;  ///< index 0 is the default material
  std::vector<GltfMesh> meshes;
  std::vector<GltfNode> nodes;          ///< parents before children
  std::vector<GltfSkin> skins;
  std::vector<GltfAnimation> animations;

  /// Object-space transform of every node at time t of animation `clip` (-1: rest pose); the
  /// clip loops.
  std::vector<glm::mat4> node_transforms(int clip, float t) const;
  /// Model-space vertices of a skinned mesh for the given node transforms (from node_transforms):
  /// v' = sum_i w_i (joint_i · inverse_bind_i) v, weights normalised. As the glTF specification
  /// says, the transform of the node holding the mesh does not apply.
  std::vector<glm::vec3> skinned_positions(int mesh, int skin, const std::vector<glm::mat4>& node_world) const;
  size_t triangle_count() const;
};

/// Throws ParseError naming the file and what is wrong.
GltfModel load_gltf(const std::filesystem::path& path);

}  // namespace artrace::io

namespace artrace::io {

/// Writes a model as glTF 2.0 (.gltf with the buffer embedded, or .glb) through tinygltf: meshes,
/// materials (index 0, the default, is not written), nodes and node animations. Output appears
/// under its final name only when complete.
void write_gltf(const GltfModel& model, const std::filesystem::path& path);

/// The models the project ships in data/models: a box that turns about y (node animation, 4 s),
/// and a glass sphere. `radius`/`size` in metres.
GltfModel make_spinning_box(float size, const glm::vec3& color);
GltfModel make_glass_sphere(float radius);
/// A skinned square tube of `length` along +y on two joints (root at the origin, elbow half way up),
/// weights blending over the middle third; animation "bend" turns the elbow about z to 90 degrees
/// and back in 2 s.
GltfModel make_bending_tube(float length, float width, const glm::vec3& color);

}  // namespace artrace::io
