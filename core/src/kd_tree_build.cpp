// SAH kd-tree construction in O(N log N) after Wald & Havran 2006 (see kd_tree.h).
#include "artrace/core/kd_tree.h"
#include "clipping.h"
#include "fork_join.h"
#include "kernels.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <bitset>
#include <cmath>
#include <cstring>
#include <memory>
#include <stdexcept>

namespace artrace::core {
namespace {

using detail::clipped_bounds_split;
using detail::coord;
using detail::set_coord;

enum EventType : uint32_t { kEnd = 0, kPlanar = 1, kStart = 2 };

/// Float bits mapped to unsigned integers in the same order (finite values; -0.0 is made +0.0
/// first, so that equal positions have equal bits).
inline uint32_t ordered_bits(float f) {
  f += 0.0f;
  uint32_t u;
  std::memcpy(&u, &f, sizeof(u));
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

inline float from_ordered_bits(uint32_t u) {
  u = (u & 0x80000000u) ? (u & 0x7fffffffu) : ~u;
  float f;
  std::memcpy(&f, &u, sizeof(f));
  return f;
}

/// A triangle's clipped extent entering (start), leaving (end) or lying in (planar) a plane, as
/// one 64-bit key: the position's ordered bits, the type (end < planar < start, as the sweep
/// needs) and the triangle (30 bits). Keys sort by position, then type, then triangle, and
/// compare as integers.
struct Event {
  uint64_t key;

  Event() = default;
  Event(float p, uint32_t tri, uint32_t type)
      : key(uint64_t{ordered_bits(p)} << 32 | uint64_t{type} << 30 | tri) {}
  float pos() const { return from_ordered_bits(static_cast<uint32_t>(key >> 32)); }
  uint32_t pos_bits() const { return static_cast<uint32_t>(key >> 32); }
  uint32_t tri() const { return static_cast<uint32_t>(key) & 0x3fffffffu; }
  uint32_t type() const { return static_cast<uint32_t>(key >> 30) & 3u; }
  /// The same event for triangle number `tri`.
  Event renumbered(uint32_t tri) const {
    Event e;
    e.key = (key & ~uint64_t{0x3fffffffu}) | tri;
    return e;
  }
};

inline bool operator<(const Event& a, const Event& b) { return a.key < b.key; }

/// std::allocator that leaves resized elements uninitialised (the event lists are sized, then
/// written through pointers).
template <class T>
struct UninitAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = UninitAllocator<U>;
  };
  UninitAllocator() = default;
  template <class U>
  UninitAllocator(const UninitAllocator<U>&) noexcept {}
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

using EventList = std::vector<Event, UninitAllocator<Event>>;

enum Side : uint8_t { kBoth = 0, kLeftOnly = 1, kRightOnly = 2 };

struct Split {
  int axis = -1;
  float pos = 0.0f;
  bool planar_left = false;
  float cost = kInfinity;
};

/// Nodes and leaf references built by one task. Subtrees built by tasks of their own hang off
/// their parent's slots (`pending`) and are copied into the tree once, at the end (flatten).
struct Subtree {
  std::vector<KdNode> nodes;
  std::vector<uint32_t> prims;
  struct Pending {
    uint32_t slot;  ///< the subtree's root node in `nodes`
    std::unique_ptr<Subtree> sub;
  };
  std::vector<Pending> pending;
};

/// Runs f(begin, end, chunk) on `chunks` equal pieces of [0, n) as parallel tasks. The pieces
/// depend on n and `chunks` only, so results combined in chunk order do not depend on the
/// thread count.
template <class F>
void for_chunks(size_t n, size_t chunks, const F& f) {
  detail::ForkJoin fj;
  const auto body = [&](size_t c) { f(n * c / chunks, n * (c + 1) / chunks, c); };
  tbb::parallel_for(size_t{0}, chunks, fj.task(body));
  fj.joined();
}

/// Sorts events made in triangle order by (position, type), triangles in order among equals:
/// the order of operator<, by a stable least-significant-digit radix sort (the type, then the
/// position's bits kBits at a time; a pass whose digit is the same for all events is skipped)
/// instead of a comparison sort, whose mispredicted branches cost more than its instructions.
template <unsigned kBits>
void radix_sort(EventList& ev) {
  constexpr uint32_t kBuckets = 1u << kBits;
  EventList tmp(ev.size());
  uint32_t count[kBuckets];
  auto pass = [&](auto digit, uint32_t buckets) {
    std::fill(count, count + buckets, 0u);
    for (const Event& e : ev) ++count[digit(e)];
    if (count[digit(ev.front())] == ev.size()) return;  // one digit: already in order
    uint32_t sum = 0;
    for (uint32_t b = 0; b < buckets; ++b) {
      const uint32_t c = count[b];
      count[b] = sum;
      sum += c;
    }
    for (const Event& e : ev) tmp[count[digit(e)]++] = e;
    ev.swap(tmp);
  };
  if (ev.empty()) return;
  pass([](const Event& e) { return e.type(); }, 3);
  for (unsigned shift = 0; shift < 32; shift += kBits) {
    pass([shift](const Event& e) { return (e.pos_bits() >> shift) & (kBuckets - 1); },
         std::min<uint32_t>(kBuckets, uint32_t{1} << std::min(31u, 32u - shift)));
  }
}

/// The events of a triangle's box on each axis: `emit(axis, event)`.
template <class Emit>
void box_events(const Aabb& box, uint32_t tri, const Emit& emit) {
  for (int a = 0; a < 3; ++a) {
    const float lo = coord(box.lo, a), hi = coord(box.hi, a);
    if (lo == hi) {
      emit(a, Event(lo, tri, kPlanar));
    } else {
      emit(a, Event(lo, tri, kStart));
      emit(a, Event(hi, tri, kEnd));
    }
  }
}

void add_events(EventList ev[3], const Aabb& box, uint32_t tri) {
  box_events(box, tri, [&](int a, const Event& e) { ev[a].push_back(e); });
}

/// The voxels on either side of a split.
void child_voxels(const Aabb& voxel, const Split& split, Aabb& left, Aabb& right) {
  left = right = voxel;
  set_coord(left.hi, split.axis, split.pos);
  set_coord(right.lo, split.axis, split.pos);
}

class Builder {
 public:
  Builder(const std::vector<Triangle>& tris, const KdTreeBuildOptions& opt, int max_depth)
      : tris_(tris), opt_(opt), max_depth_(max_depth),
        sides_([n = tris.size()] { return std::vector<uint8_t>(n, kBoth); }) {}

  /// Builds the subtree of the node stored at `out.nodes[index]`. Consumes `ev`.
  void build(Subtree& out, uint32_t index, const Aabb& voxel, EventList ev[3], uint32_t n, int depth) {
    if (n <= kSmall) {
      // Small nodes (most of the tree's nodes): the same algorithm on arrays on the stack, with
      // node-local triangle numbers, instead of a dozen heap vectors per node.
      Item items[kSmall];
      Event local[3][2 * kSmall];
      size_t sizes[3];
      to_local(ev, items, local, sizes);
      for (int a = 0; a < 3; ++a) EventList().swap(ev[a]);
      const Event* lists[3] = {local[0], local[1], local[2]};
      if (n <= kTiny) {
        build_tiny(out, index, voxel, items, n, depth);
      } else {
        build_small(out, index, voxel, items, n, lists, sizes, depth);
      }
      return;
    }
    const Split split = may_split(n, depth) ? find_split(voxel, ev, n) : Split{};
    if (is_leaf(split, n, depth)) {
      make_leaf(out, index, ev[0]);
      return;
    }
    Aabb voxel_left, voxel_right;
    child_voxels(voxel, split, voxel_left, voxel_right);
    EventList left[3], right[3];
    uint32_t n_left = 0, n_right = 0;
    distribute(voxel_left, voxel_right, split, ev, left, right, n_left, n_right);
    for (int a = 0; a < 3; ++a) EventList().swap(ev[a]);

    children(out, index, split, n, [&](Subtree& o, uint32_t i) { build(o, i, voxel_left, left, n_left, depth + 1); },
             [&](Subtree& o, uint32_t i) { build(o, i, voxel_right, right, n_right, depth + 1); });
  }

  /// A triangle of a binned node with its bounds clipped to the node.
  struct Ref {
    uint32_t tri;
    Aabb box;
  };
  using RefList = std::vector<Ref>;

  /// build() from references in triangle order: their events, sorted.
  void build_swept(Subtree& out, uint32_t index, const Aabb& voxel, RefList refs, int depth) {
    const uint32_t n = static_cast<uint32_t>(refs.size());
    EventList ev[3];
    for (auto& list : ev) list.reserve(2 * static_cast<size_t>(n));
    for (const Ref& r : refs) add_events(ev, r.box, r.tri);
    RefList().swap(refs);
    // Radix sorts keep triangle order among equal keys: the order of operator<.
    if (n >= opt_.parallel_threshold) {
      detail::ForkJoin fj;
      const auto x = [&] { radix_sort<11>(ev[0]); };
      const auto y = [&] { radix_sort<11>(ev[1]); };
      const auto z = [&] { radix_sort<11>(ev[2]); };
      tbb::parallel_invoke(fj.task(x), fj.task(y), fj.task(z));
      fj.joined();
    } else {
      for (auto& list : ev) radix_sort<8>(list);
    }
    build(out, index, voxel, ev, n, depth);
  }

  /// build() for nodes of more than opt_.binned_above triangles: the split from binned counts,
  /// the triangles handed down as references with clipped boxes. Smaller nodes, and nodes where
  /// no binned split pays, continue with sorted events and the exact sweep.
  void build_binned(Subtree& out, uint32_t index, const Aabb& voxel, RefList refs, int depth) {
    const uint32_t n = static_cast<uint32_t>(refs.size());
    const Split split = n > opt_.binned_above ? binned_split(voxel, refs) : Split{};
    if (n <= opt_.binned_above || is_leaf(split, n, depth)) {
      build_swept(out, index, voxel, std::move(refs), depth);
      return;
    }
    Aabb voxel_left, voxel_right;
    child_voxels(voxel, split, voxel_left, voxel_right);
    // The references partitioned (and straddlers clipped) in pieces side by side, joined in order.
    const size_t pieces = this->pieces(n);
    std::vector<RefList> lefts(pieces), rights(pieces);
    for_chunks(n, pieces, [&](size_t begin, size_t end, size_t c) {
      partition_refs(refs.data() + begin, refs.data() + end, split, voxel_left, voxel_right, lefts[c], rights[c]);
    });
    RefList().swap(refs);
    RefList left = join(lefts), right = join(rights);
    children(out, index, split, n, [&](Subtree& o, uint32_t i) { build_binned(o, i, voxel_left, std::move(left), depth + 1); },
             [&](Subtree& o, uint32_t i) { build_binned(o, i, voxel_right, std::move(right), depth + 1); });
  }

 private:
  /// Pieces a node's binning and partition are cut into for tasks: 16 for nodes of at least
  /// opt_.parallel_threshold triangles, else one (the same for any thread count).
  size_t pieces(uint32_t n) const { return n >= opt_.parallel_threshold ? 16 : 1; }

  /// Hands the references [begin, end) to the sides of `split`, in order; those straddling it
  /// are clipped to each child's voxel.
  void partition_refs(const Ref* begin, const Ref* end, const Split& split, const Aabb& voxel_left,
                      const Aabb& voxel_right, RefList& left, RefList& right) const {
    const size_t n = static_cast<size_t>(end - begin);
    left.reserve(n / 2 + n / 8);
    right.reserve(n / 2 + n / 8);
    const int a = split.axis;
    for (const Ref* r = begin; r != end; ++r) {
      bool go_left, go_right;
      classify(coord(r->box.lo, a), coord(r->box.hi, a), split, go_left, go_right);
      if (go_left && go_right) {
        Aabb bl, br;
        clipped_bounds_split(tris_[r->tri], voxel_left, voxel_right, a, split.pos, bl, br);
        if (!bl.empty()) left.push_back(Ref{r->tri, bl});
        if (!br.empty()) right.push_back(Ref{r->tri, br});
      } else if (go_left) {
        left.push_back(*r);
      } else {
        right.push_back(*r);
      }
    }
  }

  /// The pieces' lists, one after the other.
  static RefList join(std::vector<RefList>& pieces) {
    if (pieces.size() == 1) return std::move(pieces[0]);
    size_t size = 0;
    for (const RefList& p : pieces) size += p.size();
    RefList out;
    out.reserve(size);
    for (const RefList& p : pieces) out.insert(out.end(), p.begin(), p.end());
    return out;
  }

  /// Makes `out.nodes[index]` an inner node splitting at `split` and builds its children with
  /// `build_left(subtree, slot)` and `build_right`: side by side as two tasks for nodes of at
  /// least opt_.parallel_threshold triangles (each into a subtree of its own, left pending on
  /// `out` and copied in once at the end), else in place. Which nodes take tasks depends on
  /// their size only, so the layout is the same whatever the thread count.
  template <class Left, class Right>
  void children(Subtree& out, uint32_t index, const Split& split, uint32_t n, const Left& build_left,
                const Right& build_right) {
    if (n >= opt_.parallel_threshold) {
      auto sub_left = std::make_unique<Subtree>(), sub_right = std::make_unique<Subtree>();
      sub_left->nodes.resize(1);
      sub_right->nodes.resize(1);
      detail::ForkJoin fj;
      tbb::task_group tasks;
      const auto left = [&] { build_left(*sub_left, 0); };
      tasks.run(fj.task(left));
      build_right(*sub_right, 0);
      tasks.wait();
      fj.joined();
      const uint32_t child = add_inner(out, index, split);
      out.pending.push_back({child, std::move(sub_left)});
      out.pending.push_back({child + 1, std::move(sub_right)});
    } else {
      const uint32_t child = add_inner(out, index, split);
      build_left(out, child);
      build_right(out, child + 1);
    }
  }

  /// Makes `out.nodes[index]` an inner node splitting at `split`; returns the slot of its first
  /// child (the two children's slots are appended, adjacent).
  static uint32_t add_inner(Subtree& out, uint32_t index, const Split& split) {
    const uint32_t child = static_cast<uint32_t>(out.nodes.size());
    out.nodes.resize(child + 2);
    out.nodes[index] = KdNode::make_inner(split.axis, split.pos, child);
    return child;
  }

  /// The sides of a triangle whose clipped extent on the split axis is [lo, hi]: one side if it
  /// ends at or before (starts at or after) the plane, both if it crosses; a triangle lying in
  /// the plane goes to the side the split chose for it.
  static void classify(float lo, float hi, const Split& split, bool& go_left, bool& go_right) {
    if (lo == hi) {
      go_left = lo < split.pos || (lo == split.pos && split.planar_left);
      go_right = !go_left;
    } else {
      go_left = !(lo >= split.pos);
      go_right = !(hi <= split.pos);
    }
  }

  /// The SAH at the inner boundaries of equal bins over each axis of the voxel, from counts of
  /// the triangles' (clipped) lower and upper bounds per bin: a triangle counts to the left of
  /// a boundary when its lower bound's bin lies below it, to the right when its upper bound's
  /// bin lies at or above it. Integer counts: the same split whatever the thread count.
  Split binned_split(const Aabb& voxel, const RefList& refs) const {
    constexpr int kMaxBins = 512;
    const uint32_t n = static_cast<uint32_t>(refs.size());
    const int bins = static_cast<int>(std::clamp<uint32_t>(n / 2, 32, kMaxBins));
    Split best;
    const Planes pl(opt_, voxel);
    // Counts per axis, taken in pieces side by side for large nodes and added up (integers: the
    // same sums in any order).
    struct Counts {
      uint32_t lower[3][kMaxBins], upper[3][kMaxBins];
    };
    // One pass over the references for the three axes. A bin is the position's offset times
    // bins / extent, clamped to [0, bins - 1] before it is truncated: an infinite product (a
    // denormal extent) goes to the last bin, a NaN one (0 times that infinite scale) to bin 0.
    // An unusable axis has scale 0: everything in bin 0, counts never read.
    auto count = [&](const Ref* begin, const Ref* end, Counts& c) {
      float lo[3], scale[3];
      for (int k = 0; k < 3; ++k) {
        std::fill(c.lower[k], c.lower[k] + bins, 0u);
        std::fill(c.upper[k], c.upper[k] + bins, 0u);
        lo[k] = pl.lo(k);
        scale[k] = pl.usable(k) ? static_cast<float>(bins) / (pl.hi(k) - lo[k]) : 0.0f;
      }
      const float top = static_cast<float>(bins - 1);
      auto bin = [&](float x, int k) {
        const float f = (x - lo[k]) * scale[k];
        return f > 0.0f ? static_cast<int>(std::min(f, top)) : 0;
      };
      for (const Ref* r = begin; r != end; ++r) {
        for (int k = 0; k < 3; ++k) {
          ++c.lower[k][bin(coord(r->box.lo, k), k)];
          ++c.upper[k][bin(coord(r->box.hi, k), k)];
        }
      }
    };
    std::vector<Counts> counts(pieces(n));
    for_chunks(n, counts.size(), [&](size_t begin, size_t end, size_t c) {
      count(refs.data() + begin, refs.data() + end, counts[c]);
    });
    for (size_t c = 1; c < counts.size(); ++c) {
      for (int k = 0; k < 3; ++k) {
        for (int j = 0; j < bins; ++j) {
          counts[0].lower[k][j] += counts[c].lower[k][j];
          counts[0].upper[k][j] += counts[c].upper[k][j];
        }
      }
    }
    for (int k = 0; k < 3; ++k) {
      if (!pl.usable(k)) continue;
      const float lo = pl.lo(k), hi = pl.hi(k);
      const uint32_t* lower = counts[0].lower[k];
      const uint32_t* upper = counts[0].upper[k];
      const float width = (hi - lo) / static_cast<float>(bins);
      uint32_t n_left = 0, n_right = n;
      for (int j = 1; j < bins; ++j) {
        n_left += lower[j - 1];
        n_right -= upper[j - 1];
        const float p = lo + width * static_cast<float>(j);
        if (!pl.inside(k, p)) continue;
        // a triangle lying in p was counted on the right (its bin is j): it goes there
        Split s = pl.at(k, p, n_left, n_right, 0);
        s.planar_left = false;
        if (s.cost < best.cost) best = s;
      }
    }
    return best;
  }

  /// Nodes of at most this many triangles take build_small (its arrays live on the stack:
  /// about 20 KB a level, and 17 KB in child_events() while it runs; 64 was 1.6% slower).
  static constexpr uint32_t kSmall = 128;

  /// A triangle of a small node with its bounds clipped to the node (what its events encode).
  struct Item {
    uint32_t tri;
    glm::vec3 lo, hi;  // not an Aabb: arrays of these stay uninitialised until filled
  };

  /// A small node's events with node-local triangle numbers (items[i] is triangle i), in the
  /// same (position, type) order; the items' boxes read off the events.
  void to_local(const EventList ev[3], Item* items, Event local[3][2 * kSmall], size_t sizes[3]) {
    std::vector<uint8_t>& slot = sides_.local();  // reused as triangle -> local number
    uint32_t count = 0;
    for (const Event& e : ev[0]) {
      if (e.type() == kEnd) continue;
      slot[e.tri()] = static_cast<uint8_t>(count);
      items[count++].tri = e.tri();
    }
    for (int a = 0; a < 3; ++a) {
      sizes[a] = ev[a].size();
      for (size_t k = 0; k < ev[a].size(); ++k) {
        const Event& e = ev[a][k];
        const uint32_t i = slot[e.tri()];
        Item& it = items[i];
        if (e.type() != kEnd) set_coord(it.lo, a, e.pos());
        if (e.type() != kStart) set_coord(it.hi, a, e.pos());
        local[a][k] = e.renumbered(i);
      }
    }
    for (uint32_t i = 0; i < count; ++i) slot[items[i].tri] = kBoth;  // leave the array as found
  }

  /// add_events into fixed arrays.
  static void add_local_events(Event out[3][2 * kSmall], size_t sizes[3], const Aabb& box, uint32_t i) {
    box_events(box, i, [&](int a, const Event& e) { out[a][sizes[a]++] = e; });
  }

  /// Whether a split could pay at all: below the depth cap, and more triangles than the least a
  /// split can cost (lambda K_T, its intersection term being at least 0) pays for as a leaf.
  /// Where not, the node is a leaf without a sweep: the same tree, less work.
  bool may_split(uint32_t n, int depth) const {
    return depth < max_depth_ &&
           opt_.intersection_cost * static_cast<float>(n) > std::min(1.0f, opt_.empty_bonus) * opt_.traversal_cost;
  }

  /// The SAH termination: no split pays, or the depth cap is reached.
  bool is_leaf(const Split& split, uint32_t n, int depth) const {
    return split.axis < 0 || split.cost >= opt_.intersection_cost * static_cast<float>(n) || depth >= max_depth_;
  }

  /// build() for a node of at most kSmall triangles: the same sweep, the same classification,
  /// clipping and merge as distribute(), on arrays on the stack.
  void build_small(Subtree& out, uint32_t index, const Aabb& voxel, const Item* items, uint32_t n,
                   const Event* const ev[3], const size_t sizes[3], int depth) {
    const Split split = may_split(n, depth) ? find_split(voxel, ev, sizes, n) : Split{};
    Children c;
    uint32_t child;
    if (!split_items(out, index, voxel, split, items, n, depth, c, child)) return;
    if (c.n_left <= kTiny && c.n_right <= kTiny) {  // no events needed below
      build_tiny(out, child, c.voxel_left, c.left, c.n_left, depth + 1);
      build_tiny(out, child + 1, c.voxel_right, c.right, c.n_right, depth + 1);
      return;
    }
    Event ev_left[3][2 * kSmall], ev_right[3][2 * kSmall];
    size_t size_left[3], size_right[3];
    child_events(c, ev, sizes, ev_left, size_left, ev_right, size_right);
    const Event* lists_left[3] = {ev_left[0], ev_left[1], ev_left[2]};
    const Event* lists_right[3] = {ev_right[0], ev_right[1], ev_right[2]};
    build_small(out, child, c.voxel_left, c.left, c.n_left, lists_left, size_left, depth + 1);
    build_small(out, child + 1, c.voxel_right, c.right, c.n_right, lists_right, size_right, depth + 1);
  }

  /// Nodes of at most this many triangles find their split without events: every bound of every
  /// triangle is a candidate, its counts taken over all the triangles (O(n^2), on arrays of
  /// positions the compiler vectorises). The same candidates, counts, costs and tie-breaks as
  /// the sweep, so the same tree.
  static constexpr uint32_t kTiny = 6;

  /// build_small() for a node of at most kTiny triangles, without events.
  void build_tiny(Subtree& out, uint32_t index, const Aabb& voxel, const Item* items, uint32_t n, int depth) {
    const Split split = may_split(n, depth) ? tiny_split(voxel, items, n) : Split{};
    Children c;
    uint32_t child;
    if (!split_items(out, index, voxel, split, items, n, depth, c, child)) return;
    build_tiny(out, child, c.voxel_left, c.left, c.n_left, depth + 1);
    build_tiny(out, child + 1, c.voxel_right, c.right, c.n_right, depth + 1);
  }

  /// find_split() for at most kTiny items, from their boxes. The sweep visits positions in
  /// increasing order, axis by axis, and keeps the first least cost; here candidates come in any
  /// order, so an equal cost wins when it comes at a smaller position on the same axis.
  Split tiny_split(const Aabb& voxel, const Item* items, uint32_t n) const {
    Split best;
    const Planes pl(opt_, voxel);
    float lows[kTiny], highs[kTiny];
    for (int k = 0; k < 3; ++k) {
      if (!pl.usable(k)) continue;
      for (uint32_t i = 0; i < n; ++i) {
        lows[i] = coord(items[i].lo, k);
        highs[i] = coord(items[i].hi, k);
      }
      for (uint32_t c = 0; c < 2 * n; ++c) {
        const float p = c < n ? lows[c] : highs[c - n];
        if (!pl.inside(k, p)) continue;
        // left: starting before p; right: ending after p; planar: lying in p
        uint32_t n_left = 0, n_right = 0, planar = 0;
        for (uint32_t i = 0; i < n; ++i) {
          n_left += lows[i] < p;
          n_right += highs[i] > p;
          planar += (lows[i] == p) & (highs[i] == p);
        }
        const Split s = pl.at(k, p, n_left, n_right, planar);
        if (s.cost < best.cost || (s.cost == best.cost && best.axis == k && p < best.pos)) best = s;
      }
    }
    return best;
  }

  static constexpr uint8_t kNone = 0xff;

  static_assert(kSmall < kNone, "node-local numbers are bytes, kNone excluded");

  /// A small node's triangles split between its children (and the children's voxels).
  struct Children {
    Aabb voxel_left, voxel_right;
    Item left[kSmall], right[kSmall];
    uint32_t n_left = 0, n_right = 0;
    uint8_t to_left[kSmall], to_right[kSmall];  ///< one-sided items: their number in the child, else kNone
    std::bitset<kSmall> clipped_left, clipped_right;  ///< the children's items made by clipping
  };

  /// What build_small() and build_tiny() share: a leaf where `split` does not pay (false), else
  /// the inner node at `index`, the slot of its first child and the children's voxels and items.
  bool split_items(Subtree& out, uint32_t index, const Aabb& voxel, const Split& split, const Item* items, uint32_t n,
                   int depth, Children& c, uint32_t& child) const {
    if (is_leaf(split, n, depth)) {
      make_leaf(out, index, items, n);
      return false;
    }
    child_voxels(voxel, split, c.voxel_left, c.voxel_right);
    partition(items, n, split, c);
    child = add_inner(out, index, split);
    return true;
  }

  /// The children's event lists of a small node: one-sided triangles keep their events under
  /// their new local number; clipped ones get new events, sorted on their own and merged in.
  /// Not inlined, so that its scratch arrays are off the stack while the children are built.
  __attribute__((noinline)) static void child_events(const Children& c, const Event* const ev[3], const size_t sizes[3],
                                                     Event ev_left[3][2 * kSmall], size_t size_left[3],
                                                     Event ev_right[3][2 * kSmall], size_t size_right[3]) {
    Event new_left[3][2 * kSmall], new_right[3][2 * kSmall];
    size_t n_new_left[3] = {0, 0, 0}, n_new_right[3] = {0, 0, 0};
    for (uint32_t i = 0; i < c.n_left; ++i) {
      if (c.clipped_left[i]) add_local_events(new_left, n_new_left, Aabb{c.left[i].lo, c.left[i].hi}, i);
    }
    for (uint32_t i = 0; i < c.n_right; ++i) {
      if (c.clipped_right[i]) add_local_events(new_right, n_new_right, Aabb{c.right[i].lo, c.right[i].hi}, i);
    }
    Event kept_left[2 * kSmall], kept_right[2 * kSmall];  // one-sided events where new ones merge in
    for (int k = 0; k < 3; ++k) {
      std::sort(new_left[k], new_left[k] + n_new_left[k]);
      std::sort(new_right[k], new_right[k] + n_new_right[k]);
      // Each event is written to both sides and kept where its triangle goes: no branch on the
      // side, which comes in no predictable order.
      Event* to_left = n_new_left[k] != 0 ? kept_left : ev_left[k];
      Event* to_right = n_new_right[k] != 0 ? kept_right : ev_right[k];
      size_t sl = 0, sr = 0;
      for (size_t j = 0; j < sizes[k]; ++j) {
        const Event e = ev[k][j];
        const uint8_t l = c.to_left[e.tri()], r = c.to_right[e.tri()];
        to_left[sl] = e.renumbered(l);
        sl += l != kNone;
        to_right[sr] = e.renumbered(r);
        sr += r != kNone;
      }
      if (n_new_left[k] != 0) {
        sl = static_cast<size_t>(std::merge(kept_left, kept_left + sl, new_left[k], new_left[k] + n_new_left[k], ev_left[k]) -
                                 ev_left[k]);
      }
      if (n_new_right[k] != 0) {
        sr = static_cast<size_t>(std::merge(kept_right, kept_right + sr, new_right[k],
                                            new_right[k] + n_new_right[k], ev_right[k]) -
                                 ev_right[k]);
      }
      size_left[k] = sl;
      size_right[k] = sr;
    }
  }

  /// Classification (distribute's rules, read off the boxes): one-sided triangles are copied,
  /// straddlers clipped to each side.
  void partition(const Item* items, uint32_t n, const Split& split, Children& c) const {
    const Aabb& voxel_left = c.voxel_left;
    const Aabb& voxel_right = c.voxel_right;
    const int a = split.axis;
    for (uint32_t i = 0; i < n; ++i) {
      const Item& it = items[i];
      c.to_left[i] = c.to_right[i] = kNone;
      bool go_left, go_right;
      classify(coord(it.lo, a), coord(it.hi, a), split, go_left, go_right);
      if (go_left && go_right) {
        Aabb bl, br;
        clipped_bounds_split(tris_[it.tri], voxel_left, voxel_right, a, split.pos, bl, br);
        if (!bl.empty()) {
          c.clipped_left.set(c.n_left);
          c.left[c.n_left++] = Item{it.tri, bl.lo, bl.hi};
        }
        if (!br.empty()) {
          c.clipped_right.set(c.n_right);
          c.right[c.n_right++] = Item{it.tri, br.lo, br.hi};
        }
      } else if (go_left) {
        c.to_left[i] = static_cast<uint8_t>(c.n_left);
        c.left[c.n_left++] = it;
      } else {
        c.to_right[i] = static_cast<uint8_t>(c.n_right);
        c.right[c.n_right++] = it;
      }
    }
  }

  static void make_leaf(Subtree& out, uint32_t index, const Item* items, uint32_t n) {
    const uint32_t offset = static_cast<uint32_t>(out.prims.size());
    for (uint32_t i = 0; i < n; ++i) out.prims.push_back(items[i].tri);
    std::sort(out.prims.begin() + offset, out.prims.end());
    out.nodes[index] = KdNode::make_leaf(offset, n);
  }

  /// The SAH of planes across a voxel (the sweep, the binned and the tiny search all cost their
  /// candidates here).
  class Planes {
   public:
    Planes(const KdTreeBuildOptions& opt, const Aabb& voxel) : opt_(opt), lo_(voxel.lo), hi_(voxel.hi) {
      const float area = voxel.surface_area();
      const glm::vec3 e = voxel.extent();
      for (int k = 0; k < 3; ++k) {
        const float ea = coord(e, (k + 1) % 3), eb = coord(e, (k + 2) % 3);
        cap_[k] = ea * eb;
        ring_[k] = ea + eb;
        usable_[k] = area > 0.0f && coord(lo_, k) < coord(hi_, k);
      }
      inv_area_ = 1.0f / area;
    }

    /// Whether any plane across axis k can split the voxel (it has an area and a depth on k).
    bool usable(int k) const { return usable_[k]; }
    float lo(int k) const { return coord(lo_, k); }
    float hi(int k) const { return coord(hi_, k); }
    /// Whether a plane at p on axis k splits the voxel (lies strictly inside it).
    bool inside(int k, float p) const { return p > coord(lo_, k) && p < coord(hi_, k); }

    /// The split at p on axis k with n_left triangles starting before p, n_right ending after it
    /// and `planar` lying in it; those go to the cheaper side, the left one on a tie.
    Split at(int k, float p, uint32_t n_left, uint32_t n_right, uint32_t planar) const {
      const float p_left = 2.0f * (cap_[k] + ring_[k] * (p - coord(lo_, k))) * inv_area_;
      const float p_right = 2.0f * (cap_[k] + ring_[k] * (coord(hi_, k) - p)) * inv_area_;
      Split s{k, p, true, sah(p_left, p_right, n_left + planar, n_right)};
      if (planar != 0) {
        const float cost_right = sah(p_left, p_right, n_left, n_right + planar);
        if (!(s.cost <= cost_right)) {
          s.planar_left = false;
          s.cost = cost_right;
        }
      }
      return s;
    }

   private:
    float sah(float p_left, float p_right, uint32_t n_left, uint32_t n_right) const {
      const float lambda = (n_left == 0 || n_right == 0) ? opt_.empty_bonus : 1.0f;
      return lambda * (opt_.traversal_cost + opt_.intersection_cost * (p_left * static_cast<float>(n_left) +
                                                                       p_right * static_cast<float>(n_right)));
    }

    const KdTreeBuildOptions& opt_;
    glm::vec3 lo_, hi_;
    float cap_[3], ring_[3];  ///< a child's area is 2 (cap + ring * its length on the axis)
    bool usable_[3];
    float inv_area_;
  };

  Split find_split(const Aabb& voxel, const EventList ev[3], uint32_t n) const {
    const Event* lists[3] = {ev[0].data(), ev[1].data(), ev[2].data()};
    const size_t sizes[3] = {ev[0].size(), ev[1].size(), ev[2].size()};
    return find_split(voxel, lists, sizes, n);
  }

  /// The sweep of Wald & Havran, section 4.2, over each axis' sorted events.
  Split find_split(const Aabb& voxel, const Event* const lists[3], const size_t sizes[3], uint32_t n) const {
    Split best;
    const Planes pl(opt_, voxel);
    for (int k = 0; k < 3; ++k) {
      if (!pl.usable(k)) continue;
      uint32_t n_left = 0, n_right = n;
      const Event* list = lists[k];
      const size_t size = sizes[k];
      // One pass. The events at a position are counted by type in one packed word (21 bits a
      // type, the increment looked up by type: no branch on the type, which comes in no
      // predictable order); the cost is taken once all events at a position are counted.
      static constexpr uint64_t kCount[4] = {uint64_t{1}, uint64_t{1} << 21, uint64_t{1} << 42, 0};
      uint64_t counts = 0;
      for (size_t i = 0; i < size; ++i) {
        counts += kCount[list[i].type()];
        const uint32_t bits = list[i].pos_bits();
        if (i + 1 < size && list[i + 1].pos_bits() == bits) continue;
        const float p = from_ordered_bits(bits);
        const uint32_t ending = static_cast<uint32_t>(counts) & 0x1fffffu;
        const uint32_t planar = static_cast<uint32_t>(counts >> 21) & 0x1fffffu;
        const uint32_t starting = static_cast<uint32_t>(counts >> 42);
        counts = 0;
        n_right -= planar + ending;
        if (pl.inside(k, p)) {
          const Split s = pl.at(k, p, n_left, n_right, planar);
          if (s.cost < best.cost) best = s;
        }
        n_left += starting + planar;
      }
    }
    return best;
  }

  /// Classifies triangles against the split and builds both children's sorted event lists:
  /// one-sided triangles keep their events, straddling ones are clipped to each child and their
  /// new events sorted and merged in (section 4.3).
  void distribute(const Aabb& voxel_left, const Aabb& voxel_right, const Split& split, const EventList ev[3],
                  EventList left[3], EventList right[3], uint32_t& n_left, uint32_t& n_right) {
    std::vector<uint8_t>& side = sides_.local();
    const EventList& list = ev[split.axis];
    for (const Event& e : list) {
      if (e.type() != kEnd) side[e.tri()] = kBoth;
    }
    for (const Event& e : list) {
      if (e.type() == kEnd && e.pos() <= split.pos) {
        side[e.tri()] = kLeftOnly;
      } else if (e.type() == kStart && e.pos() >= split.pos) {
        side[e.tri()] = kRightOnly;
      } else if (e.type() == kPlanar) {
        const bool to_left = e.pos() < split.pos || (e.pos() == split.pos && split.planar_left);
        side[e.tri()] = to_left ? kLeftOnly : kRightOnly;
      }
    }
    std::vector<uint32_t> straddling;
    for (const Event& e : list) {
      if (e.type() == kEnd) continue;
      switch (side[e.tri()]) {
        case kLeftOnly: ++n_left; break;
        case kRightOnly: ++n_right; break;
        default: straddling.push_back(e.tri()); break;
      }
    }
    EventList new_left[3], new_right[3];
    for (const uint32_t t : straddling) {
      Aabb bl, br;
      clipped_bounds_split(tris_[t], voxel_left, voxel_right, split.axis, split.pos, bl, br);
      if (!bl.empty()) {
        add_events(new_left, bl, t);
        ++n_left;
      }
      if (!br.empty()) {
        add_events(new_right, br, t);
        ++n_right;
      }
    }
    // One pass per axis: one-sided events are copied (they stay sorted) and the straddlers' new
    // events, sorted on their own, are merged in on the way.
    for (int a = 0; a < 3; ++a) {
      std::sort(new_left[a].begin(), new_left[a].end());
      std::sort(new_right[a].begin(), new_right[a].end());
      // at most two events a triangle: written through pointers into lists of that size
      left[a].resize(2 * static_cast<size_t>(n_left));
      right[a].resize(2 * static_cast<size_t>(n_right));
      Event* out_left = left[a].data();
      Event* out_right = right[a].data();
      const Event* nl = new_left[a].data();
      const Event* nl_end = nl + new_left[a].size();
      const Event* nr = new_right[a].data();
      const Event* nr_end = nr + new_right[a].size();
      for (const Event& e : ev[a]) {
        const uint8_t s = side[e.tri()];
        if (s == kLeftOnly) {
          while (nl != nl_end && *nl < e) *out_left++ = *nl++;
          *out_left++ = e;
        } else if (s == kRightOnly) {
          while (nr != nr_end && *nr < e) *out_right++ = *nr++;
          *out_right++ = e;
        }
      }
      out_left = std::copy(nl, nl_end, out_left);
      out_right = std::copy(nr, nr_end, out_right);
      left[a].resize(static_cast<size_t>(out_left - left[a].data()));
      right[a].resize(static_cast<size_t>(out_right - right[a].data()));
    }
  }

  static void make_leaf(Subtree& out, uint32_t index, const EventList& axis0) {
    const uint32_t offset = static_cast<uint32_t>(out.prims.size());
    for (const Event& e : axis0) {
      if (e.type() != kEnd) out.prims.push_back(e.tri());
    }
    std::sort(out.prims.begin() + offset, out.prims.end());
    out.nodes[index] = KdNode::make_leaf(offset, static_cast<uint32_t>(out.prims.size()) - offset);
  }

  const std::vector<Triangle>& tris_;
  const KdTreeBuildOptions& opt_;
  const int max_depth_;
  tbb::enumerable_thread_specific<std::vector<uint8_t>> sides_;
};

/// Where flatten() puts a subtree: its root into node `slot`, its other nodes from `base + 1`,
/// its references from `prim_base`.
struct Placement {
  const Subtree* sub;
  uint32_t slot, base, prim_base;
};

/// Places `sub` after the nodes and references placed so far (ends `node_end`, `prim_end`),
/// then its pending subtrees the same way, depth first.
void place(const Subtree& sub, uint32_t slot, uint32_t& node_end, uint32_t& prim_end, std::vector<Placement>& out) {
  const uint32_t base = node_end - 1u;  // sub index i > 0 -> base + i
  out.push_back({&sub, slot, base, prim_end});
  node_end += static_cast<uint32_t>(sub.nodes.size()) - 1u;
  prim_end += static_cast<uint32_t>(sub.prims.size());
  for (const Subtree::Pending& p : sub.pending) place(*p.sub, base + p.slot, node_end, prim_end, out);
}

/// Copies the tree of subtrees into one node array and one reference array, each node once,
/// the subtrees side by side.
void flatten(const Subtree& root, std::vector<KdNode>& nodes, std::vector<uint32_t>& prims) {
  std::vector<Placement> placements;
  uint32_t node_end = 1, prim_end = 0;
  place(root, 0, node_end, prim_end, placements);
  nodes.resize(node_end);
  prims.resize(prim_end);
  auto relocate = [](const Placement& pl, KdNode n) {
    return n.is_leaf() ? KdNode::make_leaf(n.prim_offset + pl.prim_base, n.prim_count())
                       : KdNode::make_inner(n.axis(), n.split, n.left_child() + pl.base);
  };
  detail::ForkJoin fj;
  const auto copy = [&](size_t i) {
    const Placement& pl = placements[i];
    for (size_t j = 1; j < pl.sub->nodes.size(); ++j) nodes[pl.base + j] = relocate(pl, pl.sub->nodes[j]);
    std::copy(pl.sub->prims.begin(), pl.sub->prims.end(), prims.begin() + pl.prim_base);
  };
  tbb::parallel_for(size_t{0}, placements.size(), fj.task(copy));
  fj.joined();
  // The roots last: a subtree's slot is a placeholder among its parent's nodes.
  for (const Placement& pl : placements) nodes[pl.slot] = relocate(pl, pl.sub->nodes[0]);
}

bool finite(const Triangle& t) {
  return std::isfinite(t.v0.x) && std::isfinite(t.v0.y) && std::isfinite(t.v0.z) &&
         std::isfinite(t.v1.x) && std::isfinite(t.v1.y) && std::isfinite(t.v1.z) &&
         std::isfinite(t.v2.x) && std::isfinite(t.v2.y) && std::isfinite(t.v2.z);
}

}  // namespace

KdTree::KdTree(std::vector<Triangle> tris, const KdTreeBuildOptions& opt) : tris_(std::move(tris)) {
  if (tris_.size() >= (1u << 30)) throw std::length_error("kd-tree: at most 2^30 triangles");
  const uint32_t count = static_cast<uint32_t>(tris_.size());

  // Triangles with non-finite coordinates can never be hit (the watertight test rejects them);
  // they are left out, so that the splits see only ordered positions.
  constexpr size_t kPieces = 16;
  std::vector<uint32_t> piece_finite(kPieces, 0);
  for_chunks(count, kPieces, [&](size_t begin, size_t end, size_t c) {
    for (size_t i = begin; i < end; ++i) piece_finite[c] += finite(tris_[i]) ? 1u : 0u;
  });
  uint32_t n = 0;
  for (const uint32_t f : piece_finite) n += f;
  int max_depth = opt.max_depth;
  if (max_depth <= 0) {
    max_depth = static_cast<int>(6.0 + 1.3 * std::log2(std::max<double>(1.0, n)));
  }
  max_depth = std::min(max_depth, 60);
  // The finite triangles' boxes, in triangle order, and their bounds.
  std::vector<Builder::Ref> refs;
  if (n == count) {  // the common case: side by side
    refs.resize(n);
    std::vector<Aabb> piece_bounds(kPieces);
    for_chunks(count, kPieces, [&](size_t begin, size_t end, size_t c) {
      for (size_t i = begin; i < end; ++i) {
        refs[i] = Builder::Ref{static_cast<uint32_t>(i), Aabb::of(tris_[i])};
        piece_bounds[c].extend(refs[i].box);
      }
    });
    for (const Aabb& b : piece_bounds) bounds_.extend(b);  // min and max: the same in any order
  } else {
    refs.reserve(n);
    for (uint32_t i = 0; i < count; ++i) {
      if (!finite(tris_[i])) continue;
      refs.push_back(Builder::Ref{i, Aabb::of(tris_[i])});
      bounds_.extend(refs.back().box);
    }
  }
  Builder builder(tris_, opt, max_depth);
  Subtree tree;
  tree.nodes.resize(1);
  if (n == 0) {
    tree.nodes[0] = KdNode::make_leaf(0, 0);
  } else if (opt.binned_above > 0 && n > opt.binned_above) {
    builder.build_binned(tree, 0, bounds_, std::move(refs), 0);
  } else {
    builder.build_swept(tree, 0, bounds_, std::move(refs), 0);
  }
  view_bounds_ = padded_root_box(bounds_);
  flatten(tree, nodes_, prim_refs_);
}

}  // namespace artrace::core
