// SAH kd-tree for static geometry.
//
// Build: I. Wald and V. Havran, "On building fast kd-Trees for Ray Tracing, and on doing that in
// O(N log N)", IEEE Symposium on Interactive Ray Tracing 2006: sorted event lists per axis, a sweep
// that evaluates the SAH at every event, triangles straddling the chosen plane clipped to each child
// ("perfect splits"), an empty-space bonus, and leaves made where the SAH says splitting does not
// pay. Departures: three per-axis event lists instead of one interleaved list (same O(N log N)),
// each event one 64-bit integer key (position bits, type, triangle); the subtrees of large nodes
// are built in parallel with oneTBB into their own arrays and copied into the tree once, at the
// end, in a fixed order, so the node array is identical whatever the thread count (the top
// levels' binning and partitioning, too, run in fixed pieces side by side); nodes of at most 128
// triangles (most of the tree) run the same steps on arrays on the stack with node-local triangle
// numbers, and nodes of at most 6 take every bound as a candidate without events (the same
// splits); event lists are sorted by a stable radix sort (the same order). By default nodes of
// more than 1024 triangles choose their split from binned counts instead
// (KdTreeBuildOptions::binned_above: O(n) a node, no events; 0 restores the sweep everywhere),
// which on the BART kitchen gives a lower SAH cost and 5% fewer build instructions; the sweep
// still makes every node below.
//
// Traversal: the recursive ray segment algorithm (Havran's TA_B^rec), for single rays and for
// SIMD packets (I. Wald, "Realtime Ray Tracing and Interactive Global Illumination", PhD thesis,
// Saarland University 2004, section 7). Rays of a packet are grouped by direction octant, so a packet
// whose rays disagree in sign is split and stays correct. Any-hit traversal visits the far child
// first: the light's end of a shadow ray, where occluders tend to be, before the lit point's own
// clutter (the answer does not depend on the order).
#pragma once

#include "artrace/core/geometry.h"
#include "artrace/core/ray_packet.h"

#include <cstdint>
#include <vector>

namespace artrace::core {

/// One kd-tree node in 8 bytes; inner nodes and leaves share the layout.
///
///   word 0 (32 bits)               word 1 (32 bits)
///   +---------------------------+  +------------------------------+------+
///   | inner: split (float)      |  | inner: index of left child   | axis |
///   | leaf:  first prim offset  |  | leaf:  primitive count       |  3   |
///   +---------------------------+  +------------------------------+------+
///                                   bits 31..2                     1..0
///
/// Children are adjacent: the right child is at left + 1. Leaf primitives are
/// `prim_refs()[offset .. offset + count)`, indices into the triangle array.
struct KdNode {
  union {
    float split;
    uint32_t prim_offset;
  };
  uint32_t bits;

  static constexpr uint32_t kLeafTag = 3u;

  bool is_leaf() const { return (bits & 3u) == kLeafTag; }
  int axis() const { return static_cast<int>(bits & 3u); }
  uint32_t left_child() const { return bits >> 2; }
  uint32_t prim_count() const { return bits >> 2; }
  bool is_empty_leaf() const { return bits == kLeafTag; }

  static KdNode make_inner(int axis, float split_pos, uint32_t left) {
    KdNode n;
    n.split = split_pos;
    n.bits = (left << 2) | static_cast<uint32_t>(axis);
    return n;
  }
  static KdNode make_leaf(uint32_t offset, uint32_t count) {
    KdNode n;
    n.prim_offset = offset;
    n.bits = (count << 2) | kLeafTag;
    return n;
  }
};
static_assert(sizeof(KdNode) == 8, "kd-tree nodes are 8 bytes");

struct KdTreeBuildOptions {
  float traversal_cost = 2.0f;     ///< K_T of the SAH
  float intersection_cost = 1.5f;  ///< K_I of the SAH
  float empty_bonus = 0.8f;        ///< cost factor lambda for splits with one empty side
  /// Depth cap; 0 = 6 + 1.3 log2(N), at most 60. (Havran's 8 + 1.3 log2 N made the kitchen's
  /// tree 317K nodes deep into its clutter; 6 makes it 250K and builds 14% faster for 0.35% more
  /// render work over four all-effects frames, none on robots: docs/benchmarks.md.)
  int max_depth = 0;
  /// Nodes with at least this many triangles build their two subtrees as parallel tasks.
  uint32_t parallel_threshold = 4096;
  /// Nodes with more triangles than this choose their split from binned counts (the SAH at
  /// the boundaries of up to 512 equal bins an axis: O(n) a node, no sorting) instead of Wald &
  /// Havran's sweep over sorted events; the nodes below, where most of the tree's nodes are, take
  /// the exact sweep. 0 means the sweep everywhere. Either way triangles are clipped to the
  /// child voxels ("perfect splits") and leaves are chosen by the exact SAH.
  uint32_t binned_above = 1024;
};

struct KdTreeStats {
  uint32_t nodes = 0;
  uint32_t leaves = 0;
  uint32_t empty_leaves = 0;
  uint32_t prim_refs = 0;
  uint32_t max_depth = 0;
  double sah_cost = 0.0;  ///< expected cost of a random ray, in units of K_T, from the built tree
  size_t node_bytes = 0;
};

/// Shadow-ray coherence (a "last occluder" cache): the kd-tree triangle that blocked the previous
/// packet towards the same light is tested before the traversal, and lanes it blocks skip it. A
/// hint that blocks none of a packet's lanes is replaced by that packet's blocker, or dropped
/// when it has none (a stale hint is tried once, not on every packet).
/// Keep one per light and per thread, for one tree; a fresh one is empty. It changes the work,
/// never the answer (the triangle is tested exactly as the traversal would test it).
struct ShadowHint {
  uint32_t prim = kInvalidId;
};

/// Read-only view of a built tree, as the traversal kernels see it.
struct KdTreeView {
  const KdNode* nodes;
  const uint32_t* prim_refs;
  const Triangle* tris;
  Aabb bounds;
  /// Transmittance queries: light passing each triangle (0 or null: opaque).
  const float* pass = nullptr;
  /// Any-hit and transmittance packets: an opaque triangle worth testing first (the last packet's
  /// blocker, see ShadowHint); the kernels update it. Null: none. It changes the work, never the
  /// answer: a lane it blocks is blocked by a triangle the traversal would also have found.
  uint32_t* hint = nullptr;
};

class KdTree {
 public:
  KdTree() = default;
  /// Builds over `tris` (copied). Uses the current oneTBB arena's threads; the result does not
  /// depend on how many there are. Throws std::length_error beyond 2^30 triangles.
  explicit KdTree(std::vector<Triangle> tris, const KdTreeBuildOptions& opt = {});

  /// Closest hit along `ray` in (ray.tmin, ray.tmax]; an invalid Hit when there is none.
  Hit intersect(const Ray& ray) const;
  /// True when anything lies in (ray.tmin, ray.tmax].
  bool occluded(const Ray& ray) const;

  /// Closest hits for the lanes in `mask`; other lanes of `hits` are left untouched.
  void intersect(const RayPacket& rays, LaneMask mask, HitPacket& hits) const;
  /// Returns the subset of `mask` whose rays are blocked; `hint` (optional) is tried first and updated.
  LaneMask occluded(const RayPacket& rays, LaneMask mask, ShadowHint* hint = nullptr) const;

  const std::vector<KdNode>& nodes() const { return nodes_; }
  const std::vector<uint32_t>& prim_refs() const { return prim_refs_; }
  const std::vector<Triangle>& triangles() const { return tris_; }
  const Aabb& bounds() const { return bounds_; }
  /// The arrays the kernels read, with the root box slightly widened for robust clipping, and
  /// `hint` (emptied when it names no triangle of this tree).
  KdTreeView view(ShadowHint* hint = nullptr) const;
  /// Walks the tree and computes its statistics (including the SAH cost).
  KdTreeStats stats(const KdTreeBuildOptions& opt = {}) const;

 private:
  std::vector<Triangle> tris_;
  std::vector<KdNode> nodes_;
  std::vector<uint32_t> prim_refs_;
  Aabb bounds_;
  Aabb view_bounds_;  ///< bounds_ widened for the kernels, worked out once (view() is per packet)
};

}  // namespace artrace::core
