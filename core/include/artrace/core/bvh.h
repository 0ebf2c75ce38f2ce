// Bounding volume hierarchy for animated geometry, built lazily.
//
// Binned SAH (I. Wald, "On fast Construction of SAH-based Bounding Volume Hierarchies", IEEE
// Symposium on Interactive Ray Tracing 2007) with 16 bins over triangle centroids. A node is split
// only when a ray first reaches it; until then it is an unbuilt leaf over its primitive range
// (the lazy construction of Wald et al., "Ray Tracing Animated Scenes using Coherent Grid
// Traversal" and Embree's lazy_geometry tutorial, here for a BVH). Frame to frame the tree is refit
// bottom-up; subtrees whose surface area grew beyond `kDegenerationRatio` times their area at build
// time are reset to unbuilt and rebuilt lazily (selective restructuring, after Lauterbach et al.,
// "RT-DEFORM: Interactive Ray Tracing of Dynamic Scenes using BVHs", IEEE RT 2006).
//
// Determinism: every internal node splits its primitive range [b, e) at a position m with
// b < m < e, and distinct internal nodes split at distinct positions, so the children of the node
// that splits at m live in slots 2m and 2m + 1 whatever order nodes are built in. Splits depend on
// the node's primitives only; the tree, and hence every hit, is the same for any thread count and
// any order in which rays reach nodes.
#pragma once

#include "artrace/core/geometry.h"
#include "artrace/core/ray_packet.h"

#include <atomic>
#include <cstdint>
#include <memory>
#include <vector>

namespace artrace::core {

class Bvh;

/// 40 bytes: bounds, the primitive range and, for inner nodes, the split position (children in
/// slots 2 split and 2 split + 1) and axis. `split == 0` marks a leaf (or a node not built yet).
struct BvhNode {
  Aabb bounds;
  uint32_t begin = 0, end = 0;
  uint32_t split = 0;
  uint16_t axis = 0;
  uint16_t depth = 0;
};
static_assert(sizeof(BvhNode) == 40, "BVH node layout");

/// A node slot's state in BvhView::state: not split yet, being split by one thread, split (its
/// children, or its being a leaf, may be read).
enum BvhNodeState : uint8_t { kBvhUnbuilt = 0, kBvhBuilding = 1, kBvhBuilt = 2 };

/// What the traversal kernels read. `ensure_built` splits node i if no ray reached it before
/// (state[i] is not kBvhBuilt).
struct BvhView {
  BvhNode* nodes;
  const uint32_t* prim_refs;
  const Triangle* tris;
  const std::atomic<uint8_t>* state;
  const Bvh* owner;
  void (*ensure_built)(const Bvh* owner, uint32_t node);
  /// Transmittance queries: light passing each triangle (0 or null: opaque).
  const float* pass = nullptr;
};

struct BvhStats {
  uint32_t nodes_built = 0;    ///< inner nodes and leaves reached so far (built)
  uint32_t nodes_unbuilt = 0;  ///< nodes still waiting for a ray
  uint32_t leaves = 0;
  uint32_t max_depth = 0;
};

class Bvh {
 public:
  /// A surface-area growth above this factor (against the area at build time) marks a subtree as
  /// degenerate for restructure().
  static constexpr float kDegenerationRatio = 2.0f;
  /// restructure() rebuilds everything when at least this share of the built inner nodes degenerated.
  static constexpr float kFullRebuildShare = 0.5f;

  Bvh() = default;
  /// Takes the triangles; builds nothing yet (lazy) unless `eager`.
  explicit Bvh(std::vector<Triangle> tris, bool eager = false);
  Bvh(const Bvh&) = delete;
  Bvh& operator=(const Bvh&) = delete;
  Bvh(Bvh&&) noexcept;
  Bvh& operator=(Bvh&&) noexcept;

  /// Builds every node now (in parallel with oneTBB); the same tree lazy traversal would build.
  void build_all();
  /// Replaces the triangle positions (same count, same order) and refits the bounds bottom-up.
  /// Throws std::invalid_argument when the count differs: that needs rebuild().
  void refit(const std::vector<Triangle>& tris);
  /// refit, then resets degenerate subtrees to be rebuilt lazily; everything when most degenerated.
  /// Returns the number of subtrees reset.
  uint32_t restructure(const std::vector<Triangle>& tris);
  /// New triangles (any count): the tree starts over, lazily.
  void rebuild(std::vector<Triangle> tris);

  Hit intersect(const Ray& ray) const;
  bool occluded(const Ray& ray) const;
  void intersect(const RayPacket& rays, LaneMask mask, HitPacket& hits) const;
  LaneMask occluded(const RayPacket& rays, LaneMask mask) const;

  const Aabb& bounds() const;
  const std::vector<Triangle>& triangles() const { return tris_; }
  BvhStats stats() const;
  BvhView view() const;
  /// Splits node i if it is not built yet (thread safe; the first caller builds, others wait).
  void ensure_built(uint32_t node) const;

 private:
  void reset_root();
  void set_boxes_and_centroids();
  void split_node(uint32_t node) const;
  void build_subtree(uint32_t node) const;
  Aabb refit_node(uint32_t node);
  uint32_t mark_degenerate(uint32_t node, uint32_t& inner_nodes);

  std::vector<Triangle> tris_;
  std::vector<glm::vec3> centroids_;
  std::vector<Aabb> boxes_;  ///< each triangle's box
  mutable std::vector<uint32_t> prim_refs_;
  mutable std::vector<BvhNode> nodes_;       ///< 2N slots; slot 0 is the root, slot 1 unused
  mutable std::vector<float> build_area_;    ///< surface area when the node was split
  mutable std::unique_ptr<std::atomic<uint8_t>[]> state_;
};

}  // namespace artrace::core
