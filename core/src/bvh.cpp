#include "artrace/core/bvh.h"
#include "fork_join.h"
#include "kernels.h"

#include <tbb/task_group.h>

#include <algorithm>
#include <stdexcept>
#include <thread>

namespace artrace::core {
namespace {

constexpr uint8_t kUnbuilt = kBvhUnbuilt, kBuilding = kBvhBuilding, kBuilt = kBvhBuilt;

constexpr int kBins = 16;
constexpr uint32_t kMaxLeafSize = 4;
constexpr uint16_t kMaxDepth = 60;  // below the traversal stack of 64
constexpr float kTraversalCost = 1.0f;
constexpr uint32_t kParallelThreshold = 4096;

Aabb bounds_of(const std::vector<Aabb>& boxes, const uint32_t* refs, uint32_t b, uint32_t e) {
  Aabb box;
  for (uint32_t i = b; i < e; ++i) box.extend(boxes[refs[i]]);
  return box;
}

}  // namespace

Bvh::Bvh(std::vector<Triangle> tris, bool eager) {
  rebuild(std::move(tris));
  if (eager) build_all();
}

Bvh::Bvh(Bvh&&) noexcept = default;
Bvh& Bvh::operator=(Bvh&&) noexcept = default;

void Bvh::rebuild(std::vector<Triangle> tris) {
  if (tris.size() >= (1u << 30)) throw std::length_error("BVH: at most 2^30 triangles");
  tris_ = std::move(tris);
  const uint32_t n = static_cast<uint32_t>(tris_.size());
  centroids_.resize(n);
  boxes_.resize(n);
  set_boxes_and_centroids();
  prim_refs_.resize(n);
  for (uint32_t i = 0; i < n; ++i) prim_refs_[i] = i;
  const size_t slots = std::max<size_t>(2, 2 * static_cast<size_t>(n));
  nodes_.assign(slots, BvhNode{});
  build_area_.assign(slots, 0.0f);
  state_.reset(new std::atomic<uint8_t>[slots]);
  for (size_t i = 0; i < slots; ++i) state_[i].store(kUnbuilt, std::memory_order_relaxed);
  reset_root();
}

void Bvh::set_boxes_and_centroids() {
  // the splits bin every triangle of a node by its box again at each level: boxes worked out once
  for (size_t i = 0; i < tris_.size(); ++i) {
    centroids_[i] = (tris_[i].v0 + tris_[i].v1 + tris_[i].v2) * (1.0f / 3.0f);
    boxes_[i] = Aabb::of(tris_[i]);
  }
}

void Bvh::reset_root() {
  BvhNode& root = nodes_[0];
  root = BvhNode{};
  root.begin = 0;
  root.end = static_cast<uint32_t>(tris_.size());
  root.bounds = bounds_of(boxes_, prim_refs_.data(), root.begin, root.end);
  state_[0].store(kUnbuilt, std::memory_order_release);
}

const Aabb& Bvh::bounds() const { return nodes_[0].bounds; }

void Bvh::ensure_built(uint32_t node) const {
  if (state_[node].load(std::memory_order_acquire) == kBuilt) return;
  uint8_t expected = kUnbuilt;
  if (state_[node].compare_exchange_strong(expected, kBuilding, std::memory_order_acq_rel)) {
    split_node(node);
    state_[node].store(kBuilt, std::memory_order_release);
    return;
  }
  // Another thread is splitting this node; splitting one node is O(its primitives), so wait.
  for (int spin = 0; state_[node].load(std::memory_order_acquire) != kBuilt; ++spin) {
    if (spin > 64) std::this_thread::yield();
  }
}

void Bvh::split_node(uint32_t index) const {
  BvhNode& node = nodes_[index];
  node.split = 0;
  const uint32_t b = node.begin, e = node.end, count = e - b;
  if (count <= 2 || node.depth >= kMaxDepth) return;  // leaf
  uint32_t* refs = prim_refs_.data();

  Aabb cb;
  for (uint32_t i = b; i < e; ++i) cb.extend(centroids_[refs[i]]);
  const glm::vec3 ext = cb.extent();
  const int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : (ext.y >= ext.z ? 1 : 2);
  uint32_t m = b;
  if (ext[axis] > 0.0f) {
    // Binned SAH over centroids along the widest axis.
    const float scale = static_cast<float>(kBins) * (1.0f - 1e-6f) / ext[axis];
    const float lo = cb.lo[axis];
    auto bin_of = [&](uint32_t prim) {
      const int k = static_cast<int>((centroids_[prim][axis] - lo) * scale);
      return std::min(std::max(k, 0), kBins - 1);
    };
    Aabb bin_box[kBins];
    uint32_t bin_count[kBins] = {};
    for (uint32_t i = b; i < e; ++i) {
      const int k = bin_of(refs[i]);
      ++bin_count[k];
      bin_box[k].extend(boxes_[refs[i]]);
    }
    float right_area[kBins];
    Aabb acc;
    for (int k = kBins - 1; k > 0; --k) {
      acc.extend(bin_box[k]);
      right_area[k] = acc.surface_area();
    }
    acc = Aabb{};
    uint32_t left_n = 0;
    float best_cost = kInfinity;
    int best_bin = -1;
    for (int k = 0; k < kBins - 1; ++k) {
      acc.extend(bin_box[k]);
      left_n += bin_count[k];
      const uint32_t right_n = count - left_n;
      if (left_n == 0 || right_n == 0) continue;
      const float cost = acc.surface_area() * left_n + right_area[k + 1] * right_n;
      if (cost < best_cost) {
        best_cost = cost;
        best_bin = k;
      }
    }
    const float area = node.bounds.surface_area();
    const float split_cost = kTraversalCost + (area > 0.0f ? best_cost / area : 0.0f);
    if (count <= kMaxLeafSize && split_cost >= static_cast<float>(count)) return;  // leaf pays
    if (best_bin >= 0) {
      m = static_cast<uint32_t>(std::partition(refs + b, refs + e, [&](uint32_t p) { return bin_of(p) <= best_bin; }) - refs);
    }
  } else if (count <= kMaxLeafSize * 4) {
    return;  // all centroids coincide: a leaf, unless it is large
  }
  if (m <= b || m >= e) {
    // No useful SAH split: median by centroid, ties broken by primitive index.
    m = b + count / 2;
    std::nth_element(refs + b, refs + m, refs + e, [&](uint32_t p, uint32_t q) {
      const float cp = centroids_[p][axis], cq = centroids_[q][axis];
      return cp < cq || (cp == cq && p < q);
    });
  }
  for (int side = 0; side < 2; ++side) {
    const uint32_t slot = 2 * m + static_cast<uint32_t>(side);
    BvhNode& child = nodes_[slot];
    child = BvhNode{};
    child.begin = side == 0 ? b : m;
    child.end = side == 0 ? m : e;
    child.depth = static_cast<uint16_t>(node.depth + 1);
    child.bounds = bounds_of(boxes_, refs, child.begin, child.end);
    state_[slot].store(kUnbuilt, std::memory_order_relaxed);
  }
  build_area_[index] = node.bounds.surface_area();
  node.axis = static_cast<uint16_t>(axis);
  node.split = m;
}

void Bvh::build_subtree(uint32_t index) const {
  ensure_built(index);
  const BvhNode& n = nodes_[index];
  if (n.split == 0) return;
  const uint32_t l = 2 * n.split, r = l + 1;
  if (n.end - n.begin >= kParallelThreshold) {
    detail::ForkJoin fj;
    tbb::task_group tasks;
    const auto left = [&] { build_subtree(l); };
    tasks.run(fj.task(left));
    build_subtree(r);
    tasks.wait();
    fj.joined();
  } else {
    build_subtree(l);
    build_subtree(r);
  }
}

void Bvh::build_all() {
  if (!tris_.empty()) build_subtree(0);
}

Aabb Bvh::refit_node(uint32_t index) {
  BvhNode& n = nodes_[index];
  if (state_[index].load(std::memory_order_relaxed) == kBuilt && n.split != 0) {
    Aabb box = refit_node(2 * n.split);
    box.extend(refit_node(2 * n.split + 1));
    n.bounds = box;
  } else {
    n.bounds = bounds_of(boxes_, prim_refs_.data(), n.begin, n.end);
  }
  return n.bounds;
}

void Bvh::refit(const std::vector<Triangle>& tris) {
  if (tris.size() != tris_.size()) {
    throw std::invalid_argument("BVH refit: " + std::to_string(tris.size()) + " triangles given, the tree has " +
                                std::to_string(tris_.size()) + " (adding or removing triangles needs rebuild)");
  }
  tris_ = tris;
  set_boxes_and_centroids();
  if (!tris_.empty()) refit_node(0);
}

uint32_t Bvh::mark_degenerate(uint32_t index, uint32_t& inner_nodes) {
  const BvhNode& n = nodes_[index];
  if (state_[index].load(std::memory_order_relaxed) != kBuilt || n.split == 0) return 0;
  ++inner_nodes;
  if (n.bounds.surface_area() > kDegenerationRatio * build_area_[index]) {
    state_[index].store(kUnbuilt, std::memory_order_relaxed);  // split again when a ray arrives
    return 1;
  }
  return mark_degenerate(2 * n.split, inner_nodes) + mark_degenerate(2 * n.split + 1, inner_nodes);
}

uint32_t Bvh::restructure(const std::vector<Triangle>& tris) {
  refit(tris);
  if (tris_.empty()) return 0;
  uint32_t inner = 0;
  const uint32_t reset = mark_degenerate(0, inner);
  if (inner > 0 && static_cast<float>(reset) >= kFullRebuildShare * static_cast<float>(inner)) {
    state_[0].store(kUnbuilt, std::memory_order_release);
  }
  return reset;
}

BvhStats Bvh::stats() const {
  BvhStats s;
  if (tris_.empty()) return s;
  std::vector<uint32_t> stack{0};
  while (!stack.empty()) {
    const uint32_t i = stack.back();
    stack.pop_back();
    const BvhNode& n = nodes_[i];
    s.max_depth = std::max<uint32_t>(s.max_depth, n.depth);
    if (state_[i].load(std::memory_order_acquire) != kBuilt) {
      ++s.nodes_unbuilt;
      continue;
    }
    ++s.nodes_built;
    if (n.split == 0) {
      ++s.leaves;
    } else {
      stack.push_back(2 * n.split);
      stack.push_back(2 * n.split + 1);
    }
  }
  return s;
}

BvhView Bvh::view() const {
  return {nodes_.data(), prim_refs_.data(), tris_.data(), state_.get(), this,
          [](const Bvh* b, uint32_t node) { b->ensure_built(node); }};
}

Hit Bvh::intersect(const Ray& ray) const {
  if (tris_.empty()) return Hit{};
  return sse::bvh_intersect_single(view(), ray);
}

bool Bvh::occluded(const Ray& ray) const {
  if (tris_.empty()) return false;
  return sse::bvh_occluded_single(view(), ray);
}

void Bvh::intersect(const RayPacket& rays, LaneMask mask, HitPacket& hits) const {
  mask &= kAllLanes;
  for (int i = 0; i < kPacketSize; ++i) {
    if ((mask >> i) & 1u) {
      hits.t[i] = rays.tmax[i];
      hits.prim[i] = kInvalidId;
      hits.u[i] = hits.v[i] = 0.0f;
    }
  }
  if (tris_.empty()) return;
  packet_kernels().bvh_intersect(view(), rays, mask, hits);
}

LaneMask Bvh::occluded(const RayPacket& rays, LaneMask mask) const {
  mask &= kAllLanes;
  if (tris_.empty() || mask == 0) return 0;
  return packet_kernels().bvh_occluded(view(), rays, mask);
}

}  // namespace artrace::core
