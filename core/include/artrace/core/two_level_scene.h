// Two-level scene after I. Wald, "Realtime Ray Tracing and Interactive Global Illumination" (PhD
// thesis, 2004, chapter 9), with BVHs instead of BSPs for the objects: a top level over the objects'
// world bounds (SAH splits, one object a leaf), rebuilt at every commit (it holds tens to hundreds
// of objects, so this costs well under a millisecond), above
//   - the static geometry: a kd-tree (`kKdTreeBvh`) or one more BVH instance (`kBvh`);
//   - rigid meshes: a BVH built once in object space, shared by any number of instances, each with
//     its own transform (rays are taken to object space; mirroring and non-uniform scale are fine);
//   - deforming meshes: vertex and index buffers the application writes, then refits, restructures
//     or rebuilds (DeformableMesh).
// The application edits, then calls commit(); tracing between commits sees a consistent scene.
#pragma once

#include "artrace/core/bvh.h"
#include "artrace/core/kd_tree.h"
#include "artrace/core/wide_bvh.h"

#include <memory>
#include <string>
#include <vector>

namespace artrace::core {

/// `Hit::inst` of hits on the static geometry.
inline constexpr uint32_t kStaticObject = 0xfffffffeu;

struct TopNode {
  Aabb bounds;
  uint32_t first = 0;  ///< inner: left child (right = first + 1); leaf: first entry of `order`
  uint16_t count = 0;  ///< 0 for inner nodes
  uint16_t axis = 0;
};

struct InstanceData {
  BvhView bvh;
  float object_from_world[12];  ///< 3x4, row-major
  Aabb world_bounds;
  uint32_t id;
};

struct TwoLevelView {
  const TopNode* nodes;
  const uint32_t* order;
  const InstanceData* instances;
  uint32_t node_count;
};

/// A mesh whose vertices (and, with rebuild(), triangles) change from frame to frame.
class DeformableMesh {
 public:
  explicit DeformableMesh(TriangleMesh mesh);

  /// The buffers the application writes between frames.
  std::vector<glm::vec3>& positions() { return mesh_.positions; }
  std::vector<glm::uvec3>& indices() { return mesh_.indices; }
  const TriangleMesh& mesh() const { return mesh_; }

  /// Same triangles, moved vertices: refits the BVH. Throws std::logic_error when the index buffer
  /// changed since the last rebuild (call rebuild), std::out_of_range for an index past the vertices.
  void refit();
  /// refit, then rebuilds the degenerate subtrees (Bvh::restructure); returns how many.
  uint32_t restructure();
  /// Triangles added, removed or re-indexed: a new BVH over the current buffers.
  void rebuild();

  const Bvh& bvh() const { return bvh_; }

 private:
  uint64_t index_fingerprint() const;
  void flatten();

  TriangleMesh mesh_;
  std::vector<Triangle> tris_;
  Bvh bvh_;
  uint64_t fingerprint_ = 0;
};

/// Handles: slot index plus a generation, so a handle to a removed object is detected.
struct MeshHandle {
  uint32_t index = kInvalidId;
  uint32_t generation = 0;
};
struct InstanceHandle {
  uint32_t index = kInvalidId;
  uint32_t generation = 0;
};
struct DeformableHandle {
  uint32_t index = kInvalidId;
  uint32_t generation = 0;
};

/// What a packet's rays are like, as the flags of Embree's intersect context: neighbouring
/// pixels' camera rays are coherent; reflection and refraction rays gathered from many pixels are
/// not. It chooses how a packet is traced, never what it hits.
enum class Coherence { kCoherent, kIncoherent };

class TwoLevelScene {
 public:
  enum class Config { kBvh, kKdTreeBvh };
  static Config parse_config(const std::string& name);  ///< "bvh" or "kdtree+bvh"

  explicit TwoLevelScene(Config config = Config::kKdTreeBvh) : config_(config) {}

  /// The geometry that never moves (kd-tree or lazy BVH, by configuration). With the kd-tree,
  /// `single_ray_bvh` also builds a WideBvh over it, which serves the single-ray queries
  /// (reflection and refraction rays are incoherent: it traces them about twice as fast as the
  /// kd-tree, bench-core) and, where its frustums pay (WideBvh::frustums_pay),
  /// coherent packets' closest hits; other packets keep the kd-tree. Hits are the same either
  /// way, to the bit.
  void set_static(std::vector<Triangle> tris, bool single_ray_bvh = true);
  /// A rigid mesh in object space; its BVH is built lazily and shared by its instances.
  MeshHandle add_rigid_mesh(std::vector<Triangle> object_space);
  InstanceHandle add_instance(MeshHandle mesh, const glm::mat4& world_from_object);
  void set_transform(InstanceHandle inst, const glm::mat4& world_from_object);
  void remove_instance(InstanceHandle inst);
  DeformableHandle add_deformable(TriangleMesh world_space);
  DeformableMesh& deformable(DeformableHandle h);
  void remove_deformable(DeformableHandle h);

  /// Takes the edits since the last commit: world bounds of every object, a new top level.
  void commit();
  /// Levels of the committed top level (0 without objects, 1 for a single leaf).
  uint32_t top_depth() const;

  /// Closest hit; `Hit::inst` is the instance index, `kStaticObject`, or for deformable meshes
  /// `deformable_object_id(handle)`.
  Hit intersect(const Ray& ray) const;
  bool occluded(const Ray& ray) const;
  /// Closest hits of the lanes in `mask`; the other lanes of `hits` keep what they hold. Packets
  /// are coherent unless said otherwise (see Coherence); the answer does not depend on it.
  void intersect(const RayPacket& rays, LaneMask mask, HitPacket& hits,
                 Coherence coherence = Coherence::kCoherent) const;
  /// `hint` (optional, see ShadowHint) serves the static kd-tree of the kdtree+bvh configuration.
  LaneMask occluded(const RayPacket& rays, LaneMask mask, ShadowHint* hint = nullptr) const;

  /// Light passing each triangle, for shadow rays through glass: pass[i] in (0, 1] for a
  /// transmissive triangle, 0 for an opaque one. For the static geometry (call after set_static,
  /// which clears it), a rigid mesh or a deformable mesh (by its triangle index in the index
  /// buffer; a rebuild with another triangle count needs a new one: commit() throws
  /// std::logic_error until then). Throws std::invalid_argument when the size differs from the
  /// triangle count or a value is not in [0, 1].
  void set_static_transmittance(std::vector<float> pass);
  void set_mesh_transmittance(MeshHandle mesh, std::vector<float> pass);
  void set_deformable_transmittance(DeformableHandle mesh, std::vector<float> pass);
  /// Whether any transmittance was given; then every triangle without one counts as opaque.
  bool has_transmittance() const { return has_transmittance_; }
  /// In one traversal per level, for the lanes in `mask`: trans[i] = the product of the
  /// transmittance of every transmissive triangle the segment (tmin, tmax] crosses, each once, or
  /// 0 when it crosses an opaque one. Returns the lanes whose answer is unsure (a packet crossing
  /// more than 16 distinct transmissive triangles of the static kd-tree; walk those instead).
  /// The other lanes of `trans` keep what they hold.
  LaneMask transmittance(const RayPacket& rays, LaneMask mask, float* trans, ShadowHint* hint = nullptr) const;

  /// The triangle a hit names, in world space (inline: the shader asks for every hit's).
  Triangle world_triangle(const Hit& hit) const;
  /// The transform of the object a hit names (identity for static and deformable geometry).
  glm::mat4 world_from_object(const Hit& hit) const;
  /// Its inverse transpose (3x3), kept with the transform: takes object-space normals to world space.
  glm::mat3 normal_to_world(const Hit& hit) const;
  static uint32_t deformable_object_id(DeformableHandle h) { return 0x80000000u | h.index; }

  Config config() const { return config_; }
  /// World bounds of everything committed (empty box for an empty scene).
  Aabb bounds() const;
  size_t instance_count() const;
  /// Nodes of all object BVHs built so far (lazily) and still waiting.
  BvhStats bvh_stats() const;
  /// The same BVHs built in full (copies are built; for reports): what lazy building saves.
  BvhStats bvh_stats_full() const;
  const KdTree* static_kd_tree() const { return config_ == Config::kKdTreeBvh ? &kd_ : nullptr; }

 private:
  struct Instance {
    uint32_t mesh = kInvalidId;
    uint32_t generation = 0;
    bool alive = false;
    glm::mat4 world_from_object{1.0f};
    glm::mat3 normal_to_world{1.0f};
  };
  struct RigidMesh {
    std::unique_ptr<Bvh> bvh;
    std::vector<float> pass;
    uint32_t generation = 0;
  };
  struct Deformable {
    std::unique_ptr<DeformableMesh> mesh;
    std::vector<float> pass;
    uint32_t generation = 0;
  };

  Instance& checked(InstanceHandle h);
  template <class Fn>
  void for_each_bvh(const Fn& fn) const;

  Config config_;
  KdTree kd_;
  WideBvh wide_;  ///< empty unless set_static built it
  std::unique_ptr<Bvh> static_bvh_;
  std::vector<float> static_pass_;
  bool has_transmittance_ = false;
  std::vector<RigidMesh> meshes_;
  std::vector<Instance> instances_;
  std::vector<Deformable> deformables_;
  // committed state
  std::vector<InstanceData> data_;
  std::vector<uint32_t> order_;
  std::vector<TopNode> top_;
  bool dirty_ = true;
};

inline Triangle TwoLevelScene::world_triangle(const Hit& hit) const {
  if (hit.inst == kStaticObject) {
    return config_ == Config::kKdTreeBvh ? kd_.triangles().at(hit.prim) : static_bvh_->triangles().at(hit.prim);
  }
  if (hit.inst & 0x80000000u) return deformables_.at(hit.inst & 0x7fffffffu).mesh->bvh().triangles().at(hit.prim);
  const Instance& inst = instances_.at(hit.inst);
  const Triangle& t = meshes_[inst.mesh].bvh->triangles().at(hit.prim);
  const glm::mat4& m = inst.world_from_object;
  return {glm::vec3(m * glm::vec4(t.v0, 1.0f)), glm::vec3(m * glm::vec4(t.v1, 1.0f)), glm::vec3(m * glm::vec4(t.v2, 1.0f))};
}

}  // namespace artrace::core
