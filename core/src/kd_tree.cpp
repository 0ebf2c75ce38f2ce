#include "artrace/core/kd_tree.h"
#include "kernels.h"

#include <algorithm>
#include <cmath>

namespace artrace::core {

Aabb padded_root_box(const Aabb& b) {
  if (b.empty()) return b;
  const float m = std::max({std::fabs(b.lo.x), std::fabs(b.lo.y), std::fabs(b.lo.z),
                            std::fabs(b.hi.x), std::fabs(b.hi.y), std::fabs(b.hi.z)});
  const float pad = m * 1e-6f + 1e-30f;
  return Aabb{b.lo - pad, b.hi + pad};
}

namespace {

void walk(const KdTree& tree, uint32_t index, const Aabb& voxel, uint32_t depth, float inv_root_area,
          const KdTreeBuildOptions& opt, KdTreeStats& s) {
  const KdNode& n = tree.nodes()[index];
  s.max_depth = std::max(s.max_depth, depth);
  const double p = static_cast<double>(voxel.surface_area()) * inv_root_area;
  if (n.is_leaf()) {
    ++s.leaves;
    if (n.prim_count() == 0) ++s.empty_leaves;
    s.prim_refs += n.prim_count();
    s.sah_cost += p * opt.intersection_cost * n.prim_count();
    return;
  }
  s.sah_cost += p * opt.traversal_cost;
  Aabb l = voxel, r = voxel;
  l.hi[n.axis()] = n.split;
  r.lo[n.axis()] = n.split;
  walk(tree, n.left_child(), l, depth + 1, inv_root_area, opt, s);
  walk(tree, n.left_child() + 1, r, depth + 1, inv_root_area, opt, s);
}

}  // namespace

KdTreeView KdTree::view(ShadowHint* hint) const {
  KdTreeView v{nodes_.data(), prim_refs_.data(), tris_.data(), view_bounds_};
  if (hint) {
    if (hint->prim != kInvalidId && hint->prim >= tris_.size()) hint->prim = kInvalidId;
    v.hint = &hint->prim;
  }
  return v;
}

Hit KdTree::intersect(const Ray& ray) const {
  if (prim_refs_.empty()) return Hit{};
  return sse::intersect_single(view(), ray);
}

bool KdTree::occluded(const Ray& ray) const {
  if (prim_refs_.empty()) return false;
  return sse::occluded_single(view(), ray);
}

void KdTree::intersect(const RayPacket& rays, LaneMask mask, HitPacket& hits) const {
  mask &= kAllLanes;
  if (prim_refs_.empty()) {
    for (int i = 0; i < kPacketSize; ++i) {
      if ((mask >> i) & 1u) {
        hits.t[i] = rays.tmax[i];
        hits.u[i] = hits.v[i] = 0.0f;
        hits.prim[i] = kInvalidId;
        hits.inst[i] = kInvalidId;
      }
    }
    return;
  }
  packet_kernels().intersect(view(), rays, mask, hits);
}

LaneMask KdTree::occluded(const RayPacket& rays, LaneMask mask, ShadowHint* hint) const {
  mask &= kAllLanes;
  if (prim_refs_.empty() || mask == 0) return 0;
  return packet_kernels().occluded(view(hint), rays, mask);
}

KdTreeStats KdTree::stats(const KdTreeBuildOptions& opt) const {
  KdTreeStats s;
  s.nodes = static_cast<uint32_t>(nodes_.size());
  s.node_bytes = nodes_.size() * sizeof(KdNode);
  if (nodes_.empty()) return s;
  const float area = bounds_.surface_area();
  walk(*this, 0, bounds_, 0, area > 0.0f ? 1.0f / area : 0.0f, opt, s);
  return s;
}

}  // namespace artrace::core
