// Width-1 and 4-wide kernels, compiled for the baseline x86-64 instruction set (SSE2).
#include "kernels.h"

#include <atomic>
#include <cmath>
#include <cstring>
#include <type_traits>
#include <utility>
#if defined(__SSE__)
#include <immintrin.h>
#endif

namespace artrace::core::sse {
#include "simd.inc"
#include "traversal.inc"

Hit intersect_single(const KdTreeView& tree, const Ray& ray) {
  const BestHits<1> best = trace_single<false>(tree, ray);
  Hit h;
  if (best.prim != kInvalidId) {
    h.t = best.t;
    h.u = best.u;
    h.v = best.v;
    h.prim = best.prim;
  }
  return h;
}

bool occluded_single(const KdTreeView& tree, const Ray& ray) {
  return trace_single<true>(tree, ray).done != 0;
}

bool intersect_triangle_single(const Ray& ray, const Triangle& tri, uint32_t prim, Hit& hit) {
  const LaneSetup lane = setup_lane(ray.dir.x, ray.dir.y, ray.dir.z);
  const float* const org[3] = {&ray.org.x, &ray.org.y, &ray.org.z};
  const float* const dir[3] = {&ray.dir.x, &ray.dir.y, &ray.dir.z};
  RayGroup<1> g;
  init_group<1>(g, org, dir, &ray.tmin, &lane, 1u, 0);
  BestHits<1> best{hit.t, hit.u, hit.v, hit.prim, hit.inst, 0};
  if (!intersect_triangle<1, false>(g, tri, prim, -1, best)) return false;
  hit.t = best.t;
  hit.u = best.u;
  hit.v = best.v;
  hit.prim = best.prim;
  return true;
}

void intersect_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  if (mask & 0x0fu) trace_lanes<4, false>(tree, rays, 0, mask & 0x0fu, &hits);
  if (mask & 0xf0u) trace_lanes<4, false>(tree, rays, 4, (mask >> 4) & 0x0fu, &hits);
}

LaneMask occluded_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask) {
  LaneMask blocked = 0;
  if (mask & 0x0fu) blocked |= trace_lanes<4, true>(tree, rays, 0, mask & 0x0fu, nullptr);
  if (mask & 0xf0u) blocked |= trace_lanes<4, true>(tree, rays, 4, (mask >> 4) & 0x0fu, nullptr) << 4;
  return blocked;
}

void intersect_packet_scalar(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  for (int i = 0; i < kPacketSize; ++i) {
    if (!((mask >> i) & 1u)) continue;
    const Hit h = intersect_single(tree, rays.get(i));
    hits.t[i] = h.valid() ? h.t : rays.tmax[i];
    hits.u[i] = h.u;
    hits.v[i] = h.v;
    hits.prim[i] = h.prim;
    hits.inst[i] = h.inst;
  }
}

LaneMask occluded_packet_scalar(const KdTreeView& tree, const RayPacket& rays, LaneMask mask) {
  LaneMask blocked = 0;
  for (int i = 0; i < kPacketSize; ++i) {
    if (((mask >> i) & 1u) && occluded_single(tree, rays.get(i))) blocked |= 1u << i;
  }
  return blocked;
}


// ---- BVH and two-level entry points

namespace {

template <bool AnyHit>
BestHits<1> bvh_single(const BvhView& bvh, const Ray& ray, BestHits<1> best) {
  const float org[3][1] = {{ray.org.x}, {ray.org.y}, {ray.org.z}};
  const float dir[3][1] = {{ray.dir.x}, {ray.dir.y}, {ray.dir.z}};
  trace_bvh_lanes<1, AnyHit>(bvh, org, dir, &ray.tmin, 1u, best, kInvalidId);
  return best;
}

BestHits<1> fresh_best(const Ray& ray) {
  BestHits<1> best;
  best.t = ray.tmax;
  best.u = best.v = 0.0f;
  best.prim = best.inst = kInvalidId;
  best.done = 0;
  return best;
}

Hit to_hit(const BestHits<1>& b) {
  Hit h;
  if (b.prim != kInvalidId) {
    h.t = b.t;
    h.u = b.u;
    h.v = b.v;
    h.prim = b.prim;
    h.inst = b.inst;
  }
  return h;
}

}  // namespace

Hit bvh_intersect_single(const BvhView& bvh, const Ray& ray) { return to_hit(bvh_single<false>(bvh, ray, fresh_best(ray))); }

bool bvh_occluded_single(const BvhView& bvh, const Ray& ray) { return bvh_single<true>(bvh, ray, fresh_best(ray)).done != 0; }

void bvh_intersect_packet(const BvhView& bvh, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  if (mask & 0x0fu) trace_bvh_packet<4, false>(bvh, rays, 0, mask & 0x0fu, &hits);
  if (mask & 0xf0u) trace_bvh_packet<4, false>(bvh, rays, 4, (mask >> 4) & 0x0fu, &hits);
}

LaneMask bvh_occluded_packet(const BvhView& bvh, const RayPacket& rays, LaneMask mask) {
  LaneMask blocked = 0;
  if (mask & 0x0fu) blocked |= trace_bvh_packet<4, true>(bvh, rays, 0, mask & 0x0fu, nullptr);
  if (mask & 0xf0u) blocked |= trace_bvh_packet<4, true>(bvh, rays, 4, (mask >> 4) & 0x0fu, nullptr) << 4;
  return blocked;
}

void bvh_intersect_packet_scalar(const BvhView& bvh, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  for (int i = 0; i < kPacketSize; ++i) {
    if (!((mask >> i) & 1u)) continue;
    const Ray r = rays.get(i);
    const BestHits<1> b = bvh_single<false>(bvh, r, fresh_best(r));
    hits.t[i] = b.t;
    hits.u[i] = b.u;
    hits.v[i] = b.v;
    hits.prim[i] = b.prim;
    hits.inst[i] = b.inst;
  }
}

LaneMask bvh_occluded_packet_scalar(const BvhView& bvh, const RayPacket& rays, LaneMask mask) {
  LaneMask blocked = 0;
  for (int i = 0; i < kPacketSize; ++i) {
    if (((mask >> i) & 1u) && bvh_occluded_single(bvh, rays.get(i))) blocked |= 1u << i;
  }
  return blocked;
}

void two_level_intersect_single(const TwoLevelView& scene, const Ray& ray, Hit& hit) {
  BestHits<1> best = fresh_best(ray);
  if (hit.valid()) {
    best.t = hit.t;
    best.u = hit.u;
    best.v = hit.v;
    best.prim = hit.prim;
    best.inst = hit.inst;
  }
  const float org[3][1] = {{ray.org.x}, {ray.org.y}, {ray.org.z}};
  const float dir[3][1] = {{ray.dir.x}, {ray.dir.y}, {ray.dir.z}};
  traverse_two_level<1, false>(scene, org, dir, &ray.tmin, 1u, best);
  hit = to_hit(best);
}

bool two_level_occluded_single(const TwoLevelView& scene, const Ray& ray) {
  BestHits<1> best = fresh_best(ray);
  const float org[3][1] = {{ray.org.x}, {ray.org.y}, {ray.org.z}};
  const float dir[3][1] = {{ray.dir.x}, {ray.dir.y}, {ray.dir.z}};
  traverse_two_level<1, true>(scene, org, dir, &ray.tmin, 1u, best);
  return best.done != 0;
}

void two_level_intersect_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  if (mask & 0x0fu) trace_two_level_packet<4, false>(scene, rays, 0, mask & 0x0fu, &hits);
  if (mask & 0xf0u) trace_two_level_packet<4, false>(scene, rays, 4, (mask >> 4) & 0x0fu, &hits);
}

LaneMask two_level_occluded_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask) {
  LaneMask blocked = 0;
  if (mask & 0x0fu) blocked |= trace_two_level_packet<4, true>(scene, rays, 0, mask & 0x0fu, nullptr);
  if (mask & 0xf0u) blocked |= trace_two_level_packet<4, true>(scene, rays, 4, (mask >> 4) & 0x0fu, nullptr) << 4;
  return blocked;
}

void two_level_intersect_packet_scalar(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  for (int i = 0; i < kPacketSize; ++i) {
    if (!((mask >> i) & 1u)) continue;
    Hit h = hits.get(i);
    if (h.prim == kInvalidId) h = Hit{};
    two_level_intersect_single(scene, rays.get(i), h);
    if (h.valid()) {
      hits.t[i] = h.t;
      hits.u[i] = h.u;
      hits.v[i] = h.v;
      hits.prim[i] = h.prim;
      hits.inst[i] = h.inst;
    }
  }
}

LaneMask two_level_occluded_packet_scalar(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask) {
  LaneMask blocked = 0;
  for (int i = 0; i < kPacketSize; ++i) {
    if (((mask >> i) & 1u) && two_level_occluded_single(scene, rays.get(i))) blocked |= 1u << i;
  }
  return blocked;
}

}  // namespace artrace::core::sse
