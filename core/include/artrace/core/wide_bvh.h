// An 8-wide BVH for single and incoherent rays over static triangles.
//
// The kd-tree is the paper's structure for static geometry, and its packet traversal is what
// coherent rays (camera, shadow) want. A single ray through it takes one dependent load and two
// unpredictable branches a level, some 25 levels on the BART kitchen, which caps single and
// incoherent rays far below what a wide BVH gives: one node test there answers eight boxes in one
// pass of SIMD arithmetic (8-wide with AVX2, two 4-wide halves on the baseline), and a leaf tests
// up to eight triangles at once. This structure serves those rays; the kd-tree keeps the packets.
//
// Build: a binned SAH (I. Wald, "On fast Construction of SAH-based Bounding Volume Hierarchies",
// IEEE Symposium on Interactive Ray Tracing 2007) splitting binary, with leaves costed by the
// eight-triangle blocks they take; a wide node gathers up to eight children by splitting the
// child of largest surface area again and again (as in Wald, Benthin & Boulos, "Getting Rid of
// Packets", IEEE Symposium on Interactive Ray Tracing 2008). Large subtrees are built in
// parallel and joined in a fixed order: the arrays do not depend on the thread count.
// Optionally with spatial splits (Stich, Friedrich & Dietrich, "Spatial Splits in Bounding Volume
// Hierarchies", HPG 2009): where a node's object split leaves overlapping sides, a plane may cut
// the triangles that cross it, each side keeping a reference with a box of its part (clipped
// exactly, then widened past the rounding). A triangle may then sit in several leaves; every
// point of it lies in the boxes down to one of them, and the leaves test whole triangles, so the
// hits stay the kd-tree's.
//
// Traversal: children tested with precomputed near/far planes by the ray's octant, visited
// nearest first; the triangles with the same watertight test, the same operations in the same
// order, as the kd-tree's kernels: a ray gets bit-identical hits from either structure (equal
// distances go to the smaller primitive whatever the order of the visit).
#pragma once

#include "artrace/core/geometry.h"
#include "artrace/core/ray_packet.h"

#include <cstdint>
#include <vector>

namespace artrace::core {

/// Eight children: their boxes as structure of arrays (an unused slot has lo = +inf, hi = -inf,
/// which no ray meets) and their references. An inner child's reference is its byte offset in the
/// node array (index * sizeof(WideNode)): the kernels add it to the array's address, with no
/// multiplication between loading a reference and loading its node.
struct alignas(32) WideNode {
  float lo[3][8];
  float hi[3][8];
  uint32_t child[8];

  static constexpr uint32_t kEmpty = 0xffffffffu;
  static constexpr uint32_t kLeafBit = 0x80000000u;
  /// A leaf: its first block and block count (1 to 8).
  static uint32_t make_leaf(uint32_t first_block, uint32_t blocks) {
    return kLeafBit | (first_block << 3) | (blocks - 1u);
  }
  static bool is_leaf(uint32_t ref) { return (ref & kLeafBit) != 0; }
  static uint32_t first_block(uint32_t ref) { return (ref & ~kLeafBit) >> 3; }
  static uint32_t block_count(uint32_t ref) { return (ref & 7u) + 1u; }
};
static_assert(sizeof(WideNode) == 224, "a wide node is seven 32-byte lines");

/// Nodes a hierarchy can hold: their byte offsets stay below WideNode::kLeafBit.
inline constexpr uint32_t kMaxWideNodes = WideNode::kLeafBit / sizeof(WideNode);
/// An inner child's reference from its node's index, and back.
inline uint32_t wide_node_ref(uint32_t index) { return index * static_cast<uint32_t>(sizeof(WideNode)); }
inline uint32_t wide_node_index(uint32_t ref) { return ref / static_cast<uint32_t>(sizeof(WideNode)); }

/// Triangles a leaf block holds: one 8-wide test (an AVX register, two SSE halves).
inline constexpr int kBlockLanes = 8;

/// Up to kBlockLanes triangles, structure of arrays: v[vertex][axis][lane]; a lane without a
/// triangle has prim = kInvalidId and repeats lane 0's vertices.
struct alignas(32) TriBlock {
  float v[3][3][kBlockLanes];
  uint32_t prim[kBlockLanes];
};

struct WideBvhBuildOptions {
  int bins = 32;              ///< SAH bins per axis
  float node_cost = 1.0f;     ///< cost of a node test, relative to
  float block_cost = 1.0f;    ///< the cost of testing a block of kBlockLanes triangles
  uint32_t max_leaf = 8;      ///< triangles a leaf at most (up to 32)
  uint32_t parallel_above = 2048;  ///< subtrees with more references are built as parallel tasks
  /// Spatial splits (see wide_bvh_build.cpp) may add up to this many references per triangle, 0
  /// to 1; 0, the default, builds with object splits only. They pay where objects stand in open
  /// space and the rays come from outside them (the BART robots at 0.5: single rays 1.19x and
  /// incoherent 1.07x the speed without), and cost where the camera stands inside a room of large
  /// triangles (the BART kitchen: 0.99x, 0.94x); the build takes about twice as long. See
  /// docs/benchmarks.md.
  float spatial_budget = 0.0f;
};

struct WideBvhStats {
  uint32_t nodes = 0;
  uint32_t leaves = 0;
  uint32_t blocks = 0;
  uint32_t triangles_in_blocks = 0;  ///< lanes holding a triangle (after spatial splits, a triangle may fill several)
  uint32_t max_depth = 0;
  double sah_cost = 0.0;  ///< expected cost of a random ray meeting the root box, in node-test units
};

/// What the kernels read.
struct WideBvhView {
  const WideNode* nodes;
  const TriBlock* blocks;
  uint32_t root;  ///< a node, a leaf, or WideNode::kEmpty for an empty hierarchy
};

class WideBvh {
 public:
  WideBvh() = default;
  /// Builds over `tris` (primitive i is tris[i]); uses the current oneTBB arena's threads, with a
  /// result that does not depend on how many there are.
  explicit WideBvh(const std::vector<Triangle>& tris, const WideBvhBuildOptions& opt = {});

  /// Closest hit in (ray.tmin, ray.tmax]; an invalid Hit when there is none. Ties in distance go to
  /// the smaller primitive, as in the kd-tree: both give the same Hit for the same ray.
  Hit intersect(const Ray& ray) const;
  /// True when anything lies in (ray.tmin, ray.tmax].
  bool occluded(const Ray& ray) const;
  /// Closest hits of the lanes of `rays` in `mask`, written to `hits` (the other lanes untouched),
  /// as the single-ray query gives them. For coherent packets (neighbouring pixels' camera rays)
  /// with the AVX-512 kernels: the lanes of a direction octant descend as one frustum, a node test
  /// for all of them, and each leaf's triangles are tested against the lanes that reach its box.
  /// Otherwise a ray at a time.
  void intersect(const RayPacket& rays, LaneMask mask, HitPacket& hits) const;
  /// Whether intersect(rays, mask, ...)'s frustums beat the kd-tree's packets on camera rays: with
  /// the AVX-512 kernels, and lanes in both halves of the packet. (intersect traces frustums
  /// whenever the kernels have them, whatever the mask. Frustums of 8 rays lost to the kd-tree:
  /// with the AVX2 kernels 0.76-0.87x its speed on the kitchen, about 0.5x on the robots; 8-ray
  /// packets through the AVX-512 kernel likewise.)
  static bool frustums_pay(LaneMask mask);

  bool empty() const { return root_ == WideNode::kEmpty; }
  WideBvhView view() const { return {nodes_.data(), blocks_.data(), root_}; }
  const std::vector<WideNode>& nodes() const { return nodes_; }
  const std::vector<TriBlock>& blocks() const { return blocks_; }
  WideBvhStats stats(const WideBvhBuildOptions& opt = {}) const;

 private:
  std::vector<WideNode> nodes_;
  std::vector<TriBlock> blocks_;
  uint32_t root_ = WideNode::kEmpty;
};

}  // namespace artrace::core
