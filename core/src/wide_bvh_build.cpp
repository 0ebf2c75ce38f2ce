// Build of the 8-wide BVH (see wide_bvh.h): binned SAH, binary splits (object splits, and
// optionally spatial ones) gathered into wide nodes.
#include "artrace/core/wide_bvh.h"
#include "clipping.h"
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
/// 2^28 triangles (2^29 references with the most that spatial splits may add).
constexpr uint32_t kSahDepth = 24;

/// A reference to a triangle: the triangle, or after spatial splits the part of it in `box`.
struct Ref {
  Aabb box;
  uint32_t prim;
};

/// The references below a node, their box and their centroids' box, and how many references
/// spatial splits may still add below it.
struct Range {
  std::vector<Ref> refs;
  Aabb box, centroids;
  uint32_t budget = 0;
  uint32_t size() const { return static_cast<uint32_t>(refs.size()); }
};

/// Spatial splits are tried where the best object split's children overlap by more than this
/// part of the root's surface area (Stich, Friedrich & Dietrich, "Spatial Splits in Bounding
/// Volume Hierarchies", High Performance Graphics 2009).
constexpr float kSpatialOverlap = 1e-4f;

/// Ranges of at least this many references bin their axes as parallel tasks.
constexpr uint32_t kParallelBinning = 4096;

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
    if (!(opt_.spatial_budget >= 0.0f && opt_.spatial_budget <= 1.0f))
      throw std::invalid_argument("wide BVH: spatial_budget must be in 0..1");
    if (tris.size() >= (1u << 28)) throw std::length_error("wide BVH: more than 2^28 triangles");
    for (uint32_t i = 0; i < tris.size(); ++i) {
      if (!finite(tris[i])) continue;  // never hit (the watertight test rejects them)
      all_.refs.push_back(Ref{Aabb::of(tris[i]), i});
    }
  }

  /// Builds into `out`; returns the root reference.
  uint32_t build(Sub& out) {
    if (all_.refs.empty()) return WideNode::kEmpty;
    all_.budget = static_cast<uint32_t>(opt_.spatial_budget * static_cast<float>(all_.size()));
    bounds(all_);
    root_area_ = all_.box.surface_area();
    return subtree(std::move(all_), out);
  }

 private:
  static glm::vec3 centroid(const Ref& r) { return 0.5f * (r.box.lo + r.box.hi); }

  static void bounds(Range& r) {
    r.box = Aabb{};
    r.centroids = Aabb{};
    for (const Ref& ref : r.refs) {
      r.box.extend(ref.box);
      r.centroids.extend(centroid(ref));
    }
  }

  float leaf_cost(uint32_t n) const { return opt_.block_cost * static_cast<float>(blocks_for(n)); }

  /// `r`'s references split into `left` and `right` (their bounds not yet set), whose budgets
  /// share what is left of r's in proportion to their sizes.
  static void hand_down(Range& r, std::vector<Ref>&& left_refs, std::vector<Ref>&& right_refs, uint32_t used,
                        Range& left, Range& right) {
    const uint64_t rest = r.budget - used;
    const uint64_t nl = left_refs.size(), nr = right_refs.size();
    left = Range{std::move(left_refs), {}, {}, static_cast<uint32_t>(rest * nl / (nl + nr))};
    right = Range{std::move(right_refs), {}, {}, 0};
    right.budget = static_cast<uint32_t>(rest) - left.budget;
    std::vector<Ref>().swap(r.refs);  // freed, not kept while the subtrees below are built
  }

  /// The best binary split found on one axis: its cost (area times leaf cost, summed over the two
  /// sides), the bin it starts, the two sides' boxes and reference counts.
  struct AxisSplit {
    float cost = kInfinity;
    int bin = 0;
    Aabb left, right;
    uint32_t nl = 0, nr = 0;
  };

  /// A bin of a split's sweep: the box of what it holds (trivial: only the bins in use are set,
  /// not all 256 at every split), the references that start in it and those that end in it
  /// (for an object split, both its count).
  struct Bin {
    glm::vec3 lo, hi;
    uint32_t enter, exit;
  };

  /// The cheapest split between `bins` bins of `r`: left of it every reference that starts in a
  /// bin before, right of it every one that ends in a bin after; none that would copy more
  /// references than r's budget allows.
  AxisSplit sweep(const std::array<Bin, 256>& bin, int bins, const Range& r) const {
    struct Side {  // trivial, as Bin
      glm::vec3 lo, hi;
      uint32_t count;
    };
    std::array<Side, 256> right;
    Aabb acc;
    uint32_t cnt = 0;
    for (int b = bins - 1; b > 0; --b) {
      acc.extend(Aabb{bin[b].lo, bin[b].hi});
      cnt += bin[b].exit;
      right[b] = Side{acc.lo, acc.hi, cnt};
    }
    AxisSplit best;
    acc = Aabb{};
    cnt = 0;
    for (int b = 1; b < bins; ++b) {  // split between bins b - 1 and b
      acc.extend(Aabb{bin[b - 1].lo, bin[b - 1].hi});
      cnt += bin[b - 1].enter;
      if (cnt == 0 || right[b].count == 0) continue;
      if (cnt + right[b].count - r.size() > r.budget) continue;  // more copies than allowed
      const Aabb right_box{right[b].lo, right[b].hi};
      const float cost = acc.surface_area() * leaf_cost(cnt) + right_box.surface_area() * leaf_cost(right[b].count);
      if (cost < best.cost) best = AxisSplit{cost, b, acc, right_box, cnt, right[b].count};
    }
    return best;
  }

  /// The best object split of `r` on axis a: references binned by their boxes' centroids.
  AxisSplit object_split(const Range& r, int a) const {
    const int bins = opt_.bins;
    const float lo = r.centroids.lo[a], extent = r.centroids.hi[a] - lo;
    if (!(extent > 0.0f)) return AxisSplit{};
    const float scale = static_cast<float>(bins) / extent;
    std::array<Bin, 256> bin;
    for (int b = 0; b < bins; ++b) bin[b] = Bin{glm::vec3(kInfinity), glm::vec3(-kInfinity), 0, 0};
    for (const Ref& ref : r.refs) {
      Bin& in = bin[bin_of(centroid(ref)[a], lo, scale, bins)];
      in.lo = glm::min(in.lo, ref.box.lo);
      in.hi = glm::max(in.hi, ref.box.hi);
      ++in.enter;
    }
    for (int b = 0; b < bins; ++b) bin[b].exit = bin[b].enter;
    return sweep(bin, bins, r);
  }

  /// The best spatial split of `r` on axis a (Stich et al.): equal bins over the node's box, a
  /// reference counted on every bin it reaches, in the bins its box starts and ends in; no more
  /// copies than r's budget allows.
  AxisSplit spatial_split(const Range& r, int a) const {
    const int bins = opt_.bins;
    const float lo = detail::coord(r.box.lo, a), extent = detail::coord(r.box.hi, a) - lo;
    if (!(extent > 0.0f)) return AxisSplit{};
    const float scale = static_cast<float>(bins) / extent;
    std::array<Bin, 256> bin;
    for (int b = 0; b < bins; ++b) bin[b] = Bin{glm::vec3(kInfinity), glm::vec3(-kInfinity), 0, 0};
    const auto add = [&](int b, const Aabb& part) {
      bin[b].lo = glm::min(bin[b].lo, part.lo);
      bin[b].hi = glm::max(bin[b].hi, part.hi);
    };
    for (const Ref& ref : r.refs) {
      const int b0 = bin_of(detail::coord(ref.box.lo, a), lo, scale, bins);
      const int b1 = bin_of(detail::coord(ref.box.hi, a), lo, scale, bins);
      ++bin[b0].enter;
      ++bin[b1].exit;
      if (b0 == b1) {
        add(b0, ref.box);
        continue;
      }
      // the triangle's part in each bin from where its edges cross the bin's planes: an estimate
      // for the costs only (spatial_partition clips exactly)
      const Triangle& t = tris_[ref.prim];
      const glm::vec3 v[3] = {t.v0, t.v1, t.v2};
      for (int b = b0; b <= b1; ++b) {
        const float p0 = b == b0 ? -kInfinity : plane(lo, extent, b, bins);
        const float p1 = b == b1 ? kInfinity : plane(lo, extent, b + 1, bins);
        Aabb part;
        for (int k = 0; k < 3; ++k) {
          const glm::vec3& x = v[k];
          const glm::vec3& y = v[k == 2 ? 0 : k + 1];
          const float xa = detail::coord(x, a), ya = detail::coord(y, a);
          if (xa >= p0 && xa <= p1) part.extend(x);
          for (const float p : {p0, p1}) {
            if ((xa < p && ya > p) || (xa > p && ya < p)) part.extend(x + (p - xa) / (ya - xa) * (y - x));
          }
        }
        add(b, detail::intersect_boxes(part, ref.box));
      }
    }
    return sweep(bin, bins, r);
  }

  /// Plane b of `bins` equal bins over [lo, lo + extent].
  static float plane(float lo, float extent, int b, int bins) {
    return lo + extent * (static_cast<float>(b) / static_cast<float>(bins));
  }

  /// The parts of reference `ref` below and above `pos` on axis a.
  void clip(const Ref& ref, int a, float pos, Aabb& below, Aabb& above) const {
    Aabb box_below = ref.box, box_above = ref.box;
    detail::set_coord(box_below.hi, a, std::min(pos, detail::coord(ref.box.hi, a)));
    detail::set_coord(box_above.lo, a, std::max(pos, detail::coord(ref.box.lo, a)));
    detail::clipped_bounds_split(tris_[ref.prim], box_below, box_above, a, pos, below, above);
  }

  /// `r`'s references on either side of the spatial split `s` on axis a; false when rounding left
  /// a side empty (r untouched).
  bool spatial_partition(Range& r, int a, const AxisSplit& s, Range& left, Range& right) const {
    const int bins = opt_.bins;
    const float lo = detail::coord(r.box.lo, a), extent = detail::coord(r.box.hi, a) - lo;
    const float scale = static_cast<float>(bins) / extent;
    const float pos = plane(lo, extent, s.bin, bins);
    const float c_split = s.left.surface_area() * s.nl + s.right.surface_area() * s.nr;
    std::vector<Ref> below, above;
    uint32_t copies = 0;
    for (const Ref& ref : r.refs) {
      // by the bins of the box's ends, as the costs were counted
      if (bin_of(detail::coord(ref.box.hi, a), lo, scale, bins) < s.bin) {
        below.push_back(ref);
        continue;
      }
      if (bin_of(detail::coord(ref.box.lo, a), lo, scale, bins) >= s.bin) {
        above.push_back(ref);
        continue;
      }
      Aabb b, t;
      clip(ref, a, pos, b, t);
      if (b.empty() || t.empty()) {  // a part that clipping leaves empty holds none of the triangle
        if (!b.empty()) below.push_back(Ref{b, ref.prim});
        if (!t.empty()) above.push_back(Ref{t, ref.prim});
        continue;
      }
      // reference unsplitting (Stich et al.): the whole reference to one side where that costs less
      Aabb whole_left = s.left, whole_right = s.right;
      whole_left.extend(ref.box);
      whole_right.extend(ref.box);
      const float c_left = whole_left.surface_area() * s.nl + s.right.surface_area() * (s.nr - 1);
      const float c_right = s.left.surface_area() * (s.nl - 1) + whole_right.surface_area() * s.nr;
      if (c_left < c_split && c_left <= c_right) {
        below.push_back(ref);
      } else if (c_right < c_split) {
        above.push_back(ref);
      } else {
        below.push_back(Ref{b, ref.prim});
        above.push_back(Ref{t, ref.prim});
        ++copies;
      }
    }
    if (below.empty() || above.empty()) return false;
    hand_down(r, std::move(below), std::move(above), copies, left, right);
    bounds(left);
    bounds(right);
    return true;
  }

  /// The best binary split of `r` by the SAH, its references moved into `left` and `right`; false
  /// (r untouched) when a leaf is cheaper (and allowed).
  bool split(Range& r, Range& left, Range& right, uint32_t depth) {
    const uint32_t n = r.size();
    if (n <= kBlockLanes / 2) return false;  // half a block: no split beats testing it
    if (depth >= kSahDepth) {
      // past this depth (inputs that defeat the SAH, e.g. sizes in geometric progression) the
      // ranges are halved, which bounds the depth and with it the traversal's stack
      halve(r, left, right);
      return true;
    }
    // object splits on the three axes, then spatial ones where the budget allows and the best
    // object split's sides overlap (Stich et al.); large ranges bin the axes side by side (each
    // on its own: the same result for any thread count)
    std::array<AxisSplit, 6> found;  // 0-2 object, 3-5 spatial
    const auto bin_axes = [&](size_t first) {
      const auto bin_axis = [&](size_t a) {
        found[first + a] = first == 0 ? object_split(r, static_cast<int>(a)) : spatial_split(r, static_cast<int>(a));
      };
      if (n >= kParallelBinning) {
        detail::ForkJoin fj;
        tbb::parallel_for(size_t{0}, size_t{3}, fj.task(bin_axis));
        fj.joined();
      } else {
        for (size_t a = 0; a < 3; ++a) bin_axis(a);
      }
    };
    bin_axes(0);
    int object_axis = -1;  // the cheapest object split's, -1 when none
    for (int k = 0; k < 3; ++k) {
      if (found[k].cost < (object_axis < 0 ? kInfinity : found[object_axis].cost)) object_axis = k;
    }
    int axis = object_axis;
    if (r.budget > 0 && axis >= 0 &&
        detail::intersect_boxes(found[axis].left, found[axis].right).surface_area() > kSpatialOverlap * root_area_) {
      bin_axes(3);
      for (int k = 3; k < 6; ++k) {
        if (found[k].cost < found[axis].cost) axis = k;
      }
    }
    const float area = r.box.surface_area();
    const float split_cost = axis >= 0 && area > 0.0f ? opt_.node_cost + found[axis].cost / area : kInfinity;
    if (n <= opt_.max_leaf && !(split_cost < leaf_cost(n))) return false;
    if (axis >= 3) {
      if (spatial_partition(r, axis - 3, found[axis], left, right)) return true;
      axis = object_axis;  // rounding left a side empty (not seen): the best object split instead
    }
    if (axis < 0) {
      // every centroid in one point (or no area): halves in index order
      halve(r, left, right);
      return true;
    }
    const int bins = opt_.bins;
    const float lo = r.centroids.lo[axis];
    const float scale = static_cast<float>(bins) / (r.centroids.hi[axis] - lo);
    std::vector<Ref> below, above;  // in their order in r
    below.reserve(found[axis].nl);
    above.reserve(found[axis].nr);
    Range bounded[2];  // each side's bounds, found on the way
    for (const Ref& ref : r.refs) {
      const glm::vec3 c = centroid(ref);
      const int side = bin_of(c[axis], lo, scale, bins) < found[axis].bin ? 0 : 1;
      (side == 0 ? below : above).push_back(ref);
      bounded[side].box.extend(ref.box);
      bounded[side].centroids.extend(c);
    }
    hand_down(r, std::move(below), std::move(above), 0, left, right);
    left.box = bounded[0].box;
    left.centroids = bounded[0].centroids;
    right.box = bounded[1].box;
    right.centroids = bounded[1].centroids;
    return true;
  }

  /// `r`'s references halved in index order.
  static void halve(Range& r, Range& left, Range& right) {
    const uint32_t n = r.size();
    std::vector<Ref> upper(r.refs.begin() + n / 2, r.refs.end());
    r.refs.resize(n / 2);
    hand_down(r, std::move(r.refs), std::move(upper), 0, left, right);
    bounds(left);
    bounds(right);
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
        const uint32_t i = kBlockLanes * b + static_cast<uint32_t>(l);
        const uint32_t p = i < n ? r.refs[i].prim : kInvalidId;
        block.prim[l] = p;
        // an empty lane repeats the block's first triangle: its hits are that triangle's, and
        // never win (kInvalidId loses every tie), so the kernels need no mask of used lanes
        const Triangle& t = tris_[p == kInvalidId ? r.refs[kBlockLanes * b].prim : p];
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
  uint32_t subtree(Range r, Sub& out, uint32_t depth = 0) {
    // gather up to eight children: split the one of largest area until eight or none splits
    std::vector<Range> child;
    child.push_back(std::move(r));
    std::vector<bool> final_leaf{false};
    Range left, right;
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
      child[pick] = std::move(left);
      final_leaf[pick] = false;
      child.insert(child.begin() + pick + 1, std::move(right));
      final_leaf.insert(final_leaf.begin() + pick + 1, false);
    }
    if (child.size() == 1) return leaf(child[0], out);  // nothing splits (cannot happen above max_leaf)

    const uint32_t index = static_cast<uint32_t>(out.nodes.size());
    out.nodes.emplace_back();
    std::array<uint32_t, 8> ref;
    ref.fill(WideNode::kEmpty);
    std::array<Aabb, 8> box;
    for (size_t c = 0; c < child.size(); ++c) box[c] = child[c].box;
    // children with more references than the threshold: built side by side
    std::vector<size_t> big;
    for (size_t c = 0; c < child.size(); ++c) {
      if (child[c].size() > opt_.parallel_above) big.push_back(c);
    }
    std::vector<Sub> subs(big.size());
    std::vector<uint32_t> sub_root(big.size());
    if (!big.empty()) {
      detail::ForkJoin fj;
      const auto build = [&](size_t k) { sub_root[k] = subtree(std::move(child[big[k]]), subs[k], depth + 1); };
      tbb::parallel_for(size_t{0}, big.size(), fj.task(build));
      fj.joined();
    }
    size_t next_big = 0;
    for (size_t c = 0; c < child.size(); ++c) {
      if (next_big < big.size() && big[next_big] == c) {
        ref[c] = join(subs[next_big], sub_root[next_big], out);
        ++next_big;
      } else {
        ref[c] = subtree(std::move(child[c]), out, depth + 1);
      }
    }
    WideNode& node = out.nodes[index];
    for (int c = 0; c < 8; ++c) {
      const bool used = static_cast<size_t>(c) < child.size();
      for (int a = 0; a < 3; ++a) {
        node.lo[a][c] = used ? box[c].lo[a] : kInfinity;
        node.hi[a][c] = used ? box[c].hi[a] : -kInfinity;
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
  Range all_;
  float root_area_ = 0.0f;
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
