// Width-1 and 4-wide kernels, compiled for the baseline x86-64 instruction set (SSE2).
#include "kernels.h"

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
  BestHits<1> best{hit.t, hit.u, hit.v, hit.prim, 0};
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
  }
}

LaneMask occluded_packet_scalar(const KdTreeView& tree, const RayPacket& rays, LaneMask mask) {
  LaneMask blocked = 0;
  for (int i = 0; i < kPacketSize; ++i) {
    if (((mask >> i) & 1u) && occluded_single(tree, rays.get(i))) blocked |= 1u << i;
  }
  return blocked;
}

}  // namespace artrace::core::sse
