// glTF 2.0 models (.gltf and .glb) through tinygltf, as third-party tools write them:
// - geometry: every primitive mode (strips and fans become triangles; points and lines are
//   skipped with a warning naming the mesh and primitive), indexed or not (8/16/32-bit indices),
//   sparse accessors (applied over the base values or zeros), KHR_mesh_quantization (integer
//   attributes, normalised or not), flat normals where a primitive gives none;
// - materials, metallic-roughness: base colour factor x texture (sRGB) x COLOR_0, metallic and
//   roughness factors and texture, normal, occlusion and emissive textures (with
//   KHR_materials_emissive_strength), alpha modes OPAQUE, MASK (with its cutoff) and BLEND,
//   double-sidedness, KHR_texture_transform, texture coordinate sets 0 and 1, sampler wrap modes
//   and filters; KHR_materials_transmission and KHR_materials_ior;
// - images: PNG and JPEG from bufferViews, data: URIs and files beside the .gltf, decoded by
//   OpenCV; one that is missing or does not decode is an error naming the file and the image;
// - the node hierarchy; node animation (translation, rotation, scale, morph weights; LINEAR, STEP
//   and CUBICSPLINE samplers); skinning with any number of JOINTS_n / WEIGHTS_n sets (linear blend,
//   weights renormalised); morph targets (POSITION and NORMAL deltas, the mesh's or node's default
//   weights, animated weights);
// - extensions: a required one this reader does not support (Draco, meshopt, BasisU, ...) is an
//   error naming it; optional ones it ignores give one warning listing them.
#pragma once

#include "artrace/ar/texture.h"
#include "artrace/core/geometry.h"

#include <glm/gtc/quaternion.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace artrace::io {

/// An image as decoded: 8-bit RGBA, top row first.
struct GltfImage {
  std::string name;  ///< its name, URI or "image N", for messages
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;
};

/// A material's use of a texture.
struct GltfTextureRef {
  int image = -1;  ///< into GltfModel::images; -1: none
  int tex_coord = 0;
  ar::TextureSampler sampler;
  glm::mat3 transform{1.0f};  ///< KHR_texture_transform: uv' = transform * (u, v, 1)
  float scale = 1.0f;         ///< normalTexture.scale or occlusionTexture.strength
  bool valid() const { return image >= 0; }
};

enum class AlphaMode { kOpaque, kMask, kBlend };

struct GltfMaterial {
  std::string name;
  glm::vec3 base_color{0.8f};
  float alpha = 1.0f;
  GltfTextureRef base_color_texture;
  float metallic = 0.0f;
  float roughness = 1.0f;
  GltfTextureRef metallic_roughness_texture;  ///< roughness in G, metallic in B
  GltfTextureRef normal_texture;
  GltfTextureRef occlusion_texture;  ///< R
  glm::vec3 emissive{0.0f};          ///< factor times KHR_materials_emissive_strength
  GltfTextureRef emissive_texture;
  AlphaMode alpha_mode = AlphaMode::kOpaque;
  float alpha_cutoff = 0.5f;
  bool double_sided = false;
  float transmission = 0.0f;  ///< KHR_materials_transmission
  float ior = 1.5f;
  /// Whether this material came from a file's metallic-roughness definition (shaded with GGX) or is
  /// the default material (plain Lambert).
  bool pbr = false;
};

struct GltfMorphTarget {
  std::vector<glm::vec3> position;  ///< deltas, one per vertex (zeros where the target gives none)
  std::vector<glm::vec3> normal;    ///< empty when no primitive gives NORMAL deltas
};

struct GltfMesh {
  std::vector<core::Triangle> tris;  ///< in the mesh's own space (bind pose, default morph weights)
  std::vector<uint32_t> material;    ///< per triangle
  // the same triangles, indexed (tris[i] = positions[indices[i]]), and per-vertex attributes
  std::vector<glm::vec3> positions;  ///< without morph targets applied
  std::vector<glm::uvec3> indices;
  std::vector<glm::vec3> normals;   ///< empty: flat (geometric) normals everywhere
  std::vector<glm::vec4> tangents;  ///< xyz and the bitangent's sign; empty: from the texture coordinates
  std::vector<glm::vec2> uv[2];     ///< TEXCOORD_0 and _1; empty when no primitive gives them
  std::vector<glm::vec4> colors;    ///< COLOR_0 (linear RGBA); empty: white
  // skinning: influence_sets groups of four (joint, weight) a vertex, joints[v * sets + s]
  int influence_sets = 0;
  std::vector<glm::uvec4> joints;  ///< indices into the skin's joint list
  std::vector<glm::vec4> weights;
  std::vector<GltfMorphTarget> targets;
  std::vector<float> default_weights;  ///< the mesh's "weights" (zeros where not given)
  bool skinned() const { return influence_sets > 0; }
  bool morphed() const { return !targets.empty(); }
};

struct GltfSkin {
  std::string name;
  std::vector<int> joints;              ///< node indices
  std::vector<glm::mat4> inverse_bind;  ///< one per joint (identity when the file gives none)
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
  std::vector<float> weights;  ///< morph weights overriding the mesh's; empty: the mesh's
};

struct GltfChannel {
  int node = 0;
  enum Path { kTranslation, kRotation, kScale, kWeights } path = kTranslation;
  enum Interp { kLinear, kStep, kCubic } interpolation = kLinear;
  std::vector<float> times;
  std::vector<glm::vec4> values;  ///< xyz (w unused) or quaternion xyzw; cubic: in-tangent, value, out-tangent per key
  int weight_count = 0;           ///< kWeights: morph weights a key (values unused; weights holds them)
  std::vector<float> weights;     ///< kWeights: weight_count a key (times 3 for cubic, as values)
};

struct GltfAnimation {
  std::string name;
  std::vector<GltfChannel> channels;
  float duration_s = 0.0f;
};

struct GltfModel {
  std::filesystem::path file;
  std::vector<GltfMaterial> materials;  ///< index 0 is the default material
  std::vector<GltfImage> images;
  std::vector<GltfMesh> meshes;
  std::vector<GltfNode> nodes;  ///< parents before children
  std::vector<GltfSkin> skins;
  std::vector<GltfAnimation> animations;
  std::vector<std::string> extensions_used, extensions_required;
  std::vector<std::string> warnings;  ///< what was skipped or ignored (the tools print them)

  /// Object-space transform of every node at time t of animation `clip` (-1: rest pose); the
  /// clip loops.
  std::vector<glm::mat4> node_transforms(int clip, float t) const;
  /// Morph weights of every node with a morphed mesh at time t of `clip` (empty for the others):
  /// the animation's, else the node's default, else the mesh's.
  std::vector<std::vector<float>> node_weights(int clip, float t) const;
  /// Vertices (and normals, when `normals` is given and the mesh has them) of a mesh with morph
  /// weights applied: base + sum_i w_i delta_i.
  std::vector<glm::vec3> morphed_positions(int mesh, const std::vector<float>& weights, std::vector<glm::vec3>* normals = nullptr) const;
  /// Model-space vertices of a skinned mesh for the given node transforms (from node_transforms):
  /// v' = sum_i w_i (joint_i · inverse_bind_i) v over every influence set, the weights divided by
  /// their sum. As the glTF specification says, the transform of the node holding the mesh does
  /// not apply. `base` (optional) replaces the mesh's own positions (morphed ones); `normals`
  /// (optional, in: base normals, out: skinned ones).
  std::vector<glm::vec3> skinned_positions(int mesh, int skin, const std::vector<glm::mat4>& node_world,
                                           const std::vector<glm::vec3>* base = nullptr, std::vector<glm::vec3>* normals = nullptr) const;
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
/// and a glass sphere with its vertex normals (smooth, not faceted). `radius`/`size` in metres.
GltfModel make_spinning_box(float size, const glm::vec3& color);
GltfModel make_glass_sphere(float radius);
/// The radius of data/models/glass_sphere.gltf, as make-models writes it.
inline constexpr float kShippedGlassSphereRadius = 0.12f;
/// A skinned square tube of `length` along +y on two joints (root at the origin, elbow half way up),
/// weights blending over the middle third; animation "bend" turns the elbow about z to 90 degrees
/// and back in 2 s.
GltfModel make_bending_tube(float length, float width, const glm::vec3& color);

}  // namespace artrace::io
