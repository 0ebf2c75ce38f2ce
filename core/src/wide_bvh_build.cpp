// Build of the 8-wide BVH (see wide_bvh.h): binned SAH, binary splits gathered into wide nodes.
#include "artrace/core/wide_bvh.h"
#include "fork_join.h"
#include "kernels.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

namespace artrace::core {
namespace {

bool finite(const Triangle& t) {
  return std::isfinite(t.v0.x) && std::isfinite(t.v0.y) && std::isfinite(t.v0.z) && std::isfinite(t.v1.x) &&
         std::isfinite(t.v1.y) && std::isfinite(t.v1.z) && std::isfinite(t.v2.x) && std::isfinite(t.v2.y) &&
         std::isfinite(t.v2.z);
}

uint32_t blocks_for(uint32_t n) { return (n + kBlockLanes - 1u) / kBlockLanes; }

/// Wide levels split by the SAH; below, ranges are halved (see Builder::split). Each wide level
/// leaves at most seven entries on the traversal's stack: 7 (kSahDepth + 11) < kWideStack for
/// 2^28 triangles.
constexpr uint32_t kSahDepth = 24;

/// A range of the primitive index array with its box and its centroids' box.
struct Range {
  uint32_t begin = 0, end = 0;
  Aabb box, centroids;
  uint32_t size() const { return end - begin; }
};

/// A subtree built on its own: node and block indices are local until it is joined.
struct Sub {
  std::vector<WideNode> nodes;
  std::vector<TriBlock> blocks;
};

class Builder {
 public:
  Builder(const std::vector<Triangle>& tris, const WideBvhBuildOptions& opt) : tris_(tris), opt_(opt) {
    if (opt_.bins < 2 || opt_.bins > 256) throw std::invalid_argument("wide BVH: bins must be in 2..256");
    if (opt_.max_leaf < 1 || opt_.max_leaf > 32) throw std::invalid_argument("wide BVH: max_leaf must be in 1..32");
    if (tris.size() >= (1u << 28)) throw std::length_error("wide BVH: more than 2^28 triangles");
    box_.resize(tris.size());
    for (uint32_t i = 0; i < tris.size(); ++i) {
      if (!finite(tris[i])) continue;  // never hit (the watertight test rejects them)
      box_[i] = Aabb::of(tris[i]);
      prims_.push_back(i);
    }
  }

  /// Builds into `out`; returns the root reference.
  uint32_t build(Sub& out) {
    if (prims_.empty()) return WideNode::kEmpty;
    Range all{0, static_cast<uint32_t>(prims_.size()), {}, {}};
    bounds(all);
    return subtree(all, out);
  }

 private:
  glm::vec3 centroid(uint32_t prim) const { return 0.5f * (box_[prim].lo + box_[prim].hi); }

  void bounds(Range& r) const {
    r.box = Aabb{};
    r.centroids = Aabb{};
    for (uint32_t i = r.begin; i < r.end; ++i) {
      r.box.extend(box_[prims_[i]]);
      r.centroids.extend(centroid(prims_[i]));
    }
  }

  float leaf_cost(uint32_t n) const { return opt_.block_cost * static_cast<float>(blocks_for(n)); }

  /// The best binary split of `r` by the SAH, in place; false when a leaf is cheaper (and allowed).
  bool split(const Range& r, Range& left, Range& right, uint32_t depth) {
    const uint32_t n = r.size();
    if (n <= kBlockLanes / 2) return false;  // half a block: no split beats testing it
    if (depth >= kSahDepth) {
      // past this depth (inputs that defeat the SAH, e.g. sizes in geometric progression) the
      // ranges are halved, which bounds the depth and with it the traversal's stack
      left = Range{r.begin, r.begin + n / 2, {}, {}};
      right = Range{r.begin + n / 2, r.end, {}, {}};
      bounds(left);
      bounds(right);
      return true;
    }
    const int bins = opt_.bins;
    const float area = r.box.surface_area();
    float best_cost = kInfinity;
    int best_axis = -1, best_bin = 0;
    struct Bin {  // trivial: only the first `bins` are set, not all 256 at every split
      glm::vec3 lo, hi;
      uint32_t count;
    };
    std::array<Bin, 256> bin;
    std::array<float, 256> right_area;
    std::array<uint32_t, 256> right_count;
    for (int a = 0; a < 3; ++a) {
      const float lo = r.centroids.lo[a], extent = r.centroids.hi[a] - lo;
      if (!(extent > 0.0f)) continue;
      const float scale = static_cast<float>(bins) / extent;
      for (int b = 0; b < bins; ++b) bin[b] = Bin{glm::vec3(kInfinity), glm::vec3(-kInfinity), 0};
      for (uint32_t i = r.begin; i < r.end; ++i) {
        const uint32_t p = prims_[i];
        const int b = bin_of(centroid(p)[a], lo, scale, bins);
        bin[b].lo = glm::min(bin[b].lo, box_[p].lo);
        bin[b].hi = glm::max(bin[b].hi, box_[p].hi);
        ++bin[b].count;
      }
      Aabb acc;
      uint32_t cnt = 0;
      for (int b = bins - 1; b > 0; --b) {
        acc.extend(Aabb{bin[b].lo, bin[b].hi});
        cnt += bin[b].count;
        right_area[b] = acc.surface_area();
        right_count[b] = cnt;
      }
      acc = Aabb{};
      cnt = 0;
      for (int b = 1; b < bins; ++b) {  // split between bins b - 1 and b
        acc.extend(Aabb{bin[b - 1].lo, bin[b - 1].hi});
        cnt += bin[b - 1].count;
        if (cnt == 0 || right_count[b] == 0) continue;
        const float cost = acc.surface_area() * leaf_cost(cnt) + right_area[b] * leaf_cost(right_count[b]);
        if (cost < best_cost) {
          best_cost = cost;
          best_axis = a;
          best_bin = b;
        }
      }
    }
    const float split_cost = area > 0.0f ? opt_.node_cost + best_cost / area : kInfinity;
    if (n <= opt_.max_leaf && !(split_cost < leaf_cost(n))) return false;
    uint32_t mid;
    if (best_axis < 0) {
      // every centroid in one point (or no area): halves in index order
      mid = r.begin + n / 2;
    } else {
      const float lo = r.centroids.lo[best_axis];
      const float scale = static_cast<float>(bins) / (r.centroids.hi[best_axis] - lo);
      auto first = prims_.begin() + r.begin, last = prims_.begin() + r.end;
      mid = static_cast<uint32_t>(std::stable_partition(first, last, [&](uint32_t p) {
                                    return bin_of(centroid(p)[best_axis], lo, scale, bins) < best_bin;
                                  }) - prims_.begin());
    }
    left = Range{r.begin, mid, {}, {}};
    right = Range{mid, r.end, {}, {}};
    bounds(left);
    bounds(right);
    return true;
  }

  static int bin_of(float c, float lo, float scale, int bins) {
    const float f = (c - lo) * scale;
    // clamped while a float: a NaN goes to bin 0, anything at or past the top to the last bin
    if (!(f > 0.0f)) return 0;
    if (f >= static_cast<float>(bins - 1)) return bins - 1;
    return static_cast<int>(f);
  }

  /// The leaf of `r`: its triangles in blocks of kBlockLanes.
  uint32_t leaf(const Range& r, Sub& out) const {
    const uint32_t first = static_cast<uint32_t>(out.blocks.size());
    const uint32_t n = r.size();
    const uint32_t blocks = blocks_for(n);
    for (uint32_t b = 0; b < blocks; ++b) {
      TriBlock block{};
      for (int l = 0; l < kBlockLanes; ++l) {
        const uint32_t i = r.begin + kBlockLanes * b + static_cast<uint32_t>(l);
        const uint32_t p = i < r.end ? prims_[i] : kInvalidId;
        block.prim[l] = p;
        // an empty lane repeats the block's first triangle: its hits are that triangle's, and
        // never win (kInvalidId loses every tie), so the kernels need no mask of used lanes
        const Triangle& t = tris_[p == kInvalidId ? prims_[r.begin + kBlockLanes * b] : p];
        const glm::vec3* v[3] = {&t.v0, &t.v1, &t.v2};
        for (int k = 0; k < 3; ++k)
          for (int a = 0; a < 3; ++a) block.v[k][a][l] = (*v[k])[a];
      }
      out.blocks.push_back(block);
    }
    return WideNode::make_leaf(first, blocks);
  }

  /// The subtree of `r`, into `out`; returns its reference. Large children go to parallel tasks,
  /// each into its own Sub, joined after in child order.
  uint32_t subtree(const Range& r, Sub& out, uint32_t depth = 0) {
    Range left, right;
    if (r.size() <= opt_.max_leaf) {
      if (!split(r, left, right, depth)) return leaf(r, out);
      // a split chosen: fall through to a node
    }
    // gather up to eight children: split the one of largest area until eight or none splits
    std::vector<Range> child{r};
    std::vector<bool> final_leaf{false};
    while (child.size() < 8) {
      int pick = -1;
      float pick_area = -1.0f;
      for (size_t c = 0; c < child.size(); ++c) {
        if (final_leaf[c]) continue;
        const float a = child[c].box.surface_area();
        if (a > pick_area) {
          pick_area = a;
          pick = static_cast<int>(c);
        }
      }
      if (pick < 0) break;
      if (!split(child[pick], left, right, depth)) {
        final_leaf[pick] = true;
        continue;
      }
      child[pick] = left;
      final_leaf[pick] = false;
      child.insert(child.begin() + pick + 1, right);
      final_leaf.insert(final_leaf.begin() + pick + 1, false);
    }
    if (child.size() == 1) return leaf(r, out);  // nothing splits (cannot happen above max_leaf)

    const uint32_t index = static_cast<uint32_t>(out.nodes.size());
    out.nodes.emplace_back();
    std::array<uint32_t, 8> ref;
    ref.fill(WideNode::kEmpty);
    // children with more triangles than the threshold: built side by side
    std::vector<size_t> big;
    for (size_t c = 0; c < child.size(); ++c) {
      if (child[c].size() > opt_.parallel_above) big.push_back(c);
    }
    std::vector<Sub> subs(big.size());
    std::vector<uint32_t> sub_root(big.size());
    if (!big.empty()) {
      detail::ForkJoin fj;
      const auto build = [&](size_t k) { sub_root[k] = subtree(child[big[k]], subs[k], depth + 1); };
      tbb::parallel_for(size_t{0}, big.size(), fj.task(build));
      fj.joined();
    }
    size_t next_big = 0;
    for (size_t c = 0; c < child.size(); ++c) {
      if (next_big < big.size() && big[next_big] == c) {
        ref[c] = join(subs[next_big], sub_root[next_big], out);
        ++next_big;
      } else {
        ref[c] = subtree(child[c], out, depth + 1);
      }
    }
    WideNode& node = out.nodes[index];
    for (int c = 0; c < 8; ++c) {
      const bool used = static_cast<size_t>(c) < child.size();
      for (int a = 0; a < 3; ++a) {
        node.lo[a][c] = used ? child[c].box.lo[a] : kInfinity;
        node.hi[a][c] = used ? child[c].box.hi[a] : -kInfinity;
      }
      node.child[c] = ref[c];
    }
    return index;
  }

  /// Appends `sub` to `out`, moving its references by the offsets; returns its root's reference.
  static uint32_t join(Sub& sub, uint32_t root, Sub& out) {
    const uint32_t node_offset = static_cast<uint32_t>(out.nodes.size());
    const uint32_t block_offset = static_cast<uint32_t>(out.blocks.size());
    auto move = [&](uint32_t ref) {
      if (ref == WideNode::kEmpty) return ref;
      if (WideNode::is_leaf(ref)) {
        return WideNode::make_leaf(WideNode::first_block(ref) + block_offset, WideNode::block_count(ref));
      }
      return ref + node_offset;
    };
    for (WideNode& n : sub.nodes) {
      for (uint32_t& c : n.child) c = move(c);
    }
    out.nodes.insert(out.nodes.end(), sub.nodes.begin(), sub.nodes.end());
    out.blocks.insert(out.blocks.end(), sub.blocks.begin(), sub.blocks.end());
    return move(root);
  }

  const std::vector<Triangle>& tris_;
  WideBvhBuildOptions opt_;
  std::vector<Aabb> box_;
  std::vector<uint32_t> prims_;
};

void walk(const WideBvh& bvh, uint32_t ref, double area, double inv_root, uint32_t depth, const WideBvhBuildOptions& opt,
          WideBvhStats& s) {
  s.max_depth = std::max(s.max_depth, depth);
  if (WideNode::is_leaf(ref)) {
    ++s.leaves;
    const uint32_t count = WideNode::block_count(ref);
    s.blocks += count;
    for (uint32_t b = 0; b < count; ++b)
      for (uint32_t p : bvh.blocks()[WideNode::first_block(ref) + b].prim) s.triangles_in_blocks += p != kInvalidId;
    s.sah_cost += area * inv_root * opt.block_cost * count;
    return;
  }
  ++s.nodes;
  s.sah_cost += area * inv_root * opt.node_cost;
  const WideNode& n = bvh.nodes()[wide_node_index(ref)];
  for (int c = 0; c < 8; ++c) {
    if (n.child[c] == WideNode::kEmpty) continue;
    Aabb b;
    b.lo = glm::vec3(n.lo[0][c], n.lo[1][c], n.lo[2][c]);
    b.hi = glm::vec3(n.hi[0][c], n.hi[1][c], n.hi[2][c]);
    walk(bvh, n.child[c], b.surface_area(), inv_root, depth + 1, opt, s);
  }
}

}  // namespace

WideBvh::WideBvh(const std::vector<Triangle>& tris, const WideBvhBuildOptions& opt) {
  Builder builder(tris, opt);
  Sub sub;
  root_ = builder.build(sub);
  nodes_ = std::move(sub.nodes);
  blocks_ = std::move(sub.blocks);
  // inner children by byte offset (see WideNode)
  if (nodes_.size() > kMaxWideNodes) throw std::length_error("wide BVH: more nodes than references can address");
  const auto to_offset = [](uint32_t& ref) {
    if (ref != WideNode::kEmpty && !WideNode::is_leaf(ref)) ref = wide_node_ref(ref);
  };
  for (WideNode& n : nodes_) {
    for (uint32_t& c : n.child) to_offset(c);
  }
  to_offset(root_);
}

Hit WideBvh::intersect(const Ray& ray) const {
  if (empty()) return Hit{};
  return single_ray_kernels().intersect(view(), ray);
}

void WideBvh::intersect(const RayPacket& rays, LaneMask mask, HitPacket& hits) const {
  mask &= kAllLanes;
  const SingleRayKernels& k = single_ray_kernels();
  if (!empty() && k.intersect_packet) return k.intersect_packet(view(), rays, mask, hits);
  for (LaneMask m = mask; m; m &= m - 1) {  // a ray at a time
    const int i = __builtin_ctz(m);
    const Hit h = intersect(rays.get(i));
    hits.t[i] = h.valid() ? h.t : rays.tmax[i];
    hits.u[i] = h.u;
    hits.v[i] = h.v;
    hits.prim[i] = h.prim;
    hits.inst[i] = kInvalidId;
  }
}

bool WideBvh::frustums_pay(LaneMask mask) {
  mask &= kAllLanes;
  return single_ray_kernels().intersect_packet != nullptr && (mask & 0xffu) != 0 && (mask >> 8) != 0;
}

bool WideBvh::occluded(const Ray& ray) const {
  if (empty()) return false;
  return single_ray_kernels().occluded(view(), ray);
}

WideBvhStats WideBvh::stats(const WideBvhBuildOptions& opt) const {
  WideBvhStats s;
  if (empty()) return s;
  if (WideNode::is_leaf(root_)) {
    walk(*this, root_, 1.0, 1.0, 0, opt, s);
    return s;
  }
  Aabb root;
  const WideNode& n = nodes_[wide_node_index(root_)];
  for (int c = 0; c < 8; ++c) {
    if (n.child[c] == WideNode::kEmpty) continue;
    root.extend(glm::vec3(n.lo[0][c], n.lo[1][c], n.lo[2][c]));
    root.extend(glm::vec3(n.hi[0][c], n.hi[1][c], n.hi[2][c]));
  }
  const double area = root.surface_area();
  walk(*this, root_, area, area > 0.0 ? 1.0 / area : 0.0, 0, opt, s);
  return s;
}

}  // namespace artrace::core
