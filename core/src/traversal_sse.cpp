// Width-1 and 4-wide kernels, compiled for the baseline x86-64 instruction set (SSE2).
#include "kernels.h"

#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <type_traits>
#include <utility>
#if defined(__SSE__)
#include <immintrin.h>
#endif

namespace artrace::core::sse {
#include "simd.inc"
#include "traversal.inc"
#include "wide_traversal.inc"

namespace {

/// The portable fallback: lane after lane with a single-ray function that updates a Hit.
template <class Single>
void lane_by_lane(const RayPacket& rays, LaneMask mask, HitPacket& hits, const Single& single) {
  for (int i = 0; i < kPacketSize; ++i) {
    if (!((mask >> i) & 1u)) continue;
    Hit h = hits.get(i);
    single(rays.get(i), h);
    hits.t[i] = h.valid() ? h.t : rays.tmax[i];
    hits.u[i] = h.u;
    hits.v[i] = h.v;
    hits.prim[i] = h.prim;
    hits.inst[i] = h.inst;
  }
}

template <class Occluded>
LaneMask lane_by_lane_occluded(const RayPacket& rays, LaneMask mask, const Occluded& occluded) {
  LaneMask blocked = 0;
  for (int i = 0; i < kPacketSize; ++i) {
    if (((mask >> i) & 1u) && occluded(rays.get(i))) blocked |= 1u << i;
  }
  return blocked;
}

}  // namespace

Hit intersect_single(const KdTreeView& tree, const Ray& ray) { return to_hit(trace_single<false>(tree, ray)); }

bool occluded_single(const KdTreeView& tree, const Ray& ray) {
  return trace_single<true>(tree, ray).done != 0;
}

bool intersect_triangle_single(const Ray& ray, const Triangle& tri, uint32_t prim, Hit& hit) {
  const LaneSetup lane = setup_lane(ray.dir.x, ray.dir.y, ray.dir.z);
  const float* const org[3] = {&ray.org.x, &ray.org.y, &ray.org.z};
  const float* const dir[3] = {&ray.dir.x, &ray.dir.y, &ray.dir.z};
  RayGroup<1> g;
  init_group<1>(g, org, dir, &ray.tmin, lane);
  BestHits<1> best{hit.t, hit.u, hit.v, hit.prim, hit.inst, 0, 1.0f, kInvalidId};
  if (!intersect_triangle<1, false>(g, tri, prim, -1, best)) return false;
  hit.t = best.t;
  hit.u = best.u;
  hit.v = best.v;
  hit.prim = best.prim;
  return true;
}

namespace {

void intersect_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  in_chunks<4>(mask, [&](int off, uint32_t bits) { return trace_lanes<4, false>(tree, rays, off, bits, &hits); });
}

LaneMask occluded_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask) {
  return in_chunks<4>(mask, [&](int off, uint32_t bits) {
    return trace_lanes<4, true>(tree, rays, off, bits, nullptr);
  });
}

void intersect_packet_scalar(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  lane_by_lane(rays, mask, hits, [&](const Ray& r, Hit& h) { h = intersect_single(tree, r); });
}

LaneMask occluded_packet_scalar(const KdTreeView& tree, const RayPacket& rays, LaneMask mask) {
  return lane_by_lane_occluded(rays, mask, [&](const Ray& r) { return occluded_single(tree, r); });
}

}  // namespace

// ---- BVH and two-level entry points

namespace {

template <bool AnyHit>
BestHits<1> bvh_single(const BvhView& bvh, const Ray& ray) {
  BestHits<1> best = fresh_best<1>(&ray.tmax);
  const float org[3][1] = {{ray.org.x}, {ray.org.y}, {ray.org.z}};
  const float dir[3][1] = {{ray.dir.x}, {ray.dir.y}, {ray.dir.z}};
  trace_bvh_lanes<1, AnyHit>(bvh, org, dir, &ray.tmin, 1u, best, kInvalidId);
  return best;
}

template <bool AnyHit>
BestHits<1> two_level_single(const TwoLevelView& scene, const Ray& ray, const Hit& from) {
  BestHits<1> best = fresh_best<1>(&ray.tmax);
  if (from.valid()) {
    best.t = from.t;
    best.u = from.u;
    best.v = from.v;
    best.prim = from.prim;
    best.inst = from.inst;
  }
  const float org[3][1] = {{ray.org.x}, {ray.org.y}, {ray.org.z}};
  const float dir[3][1] = {{ray.dir.x}, {ray.dir.y}, {ray.dir.z}};
  traverse_two_level<1, AnyHit>(scene, org, dir, &ray.tmin, 1u, best);
  return best;
}

}  // namespace

Hit bvh_intersect_single(const BvhView& bvh, const Ray& ray) { return to_hit(bvh_single<false>(bvh, ray)); }

bool bvh_occluded_single(const BvhView& bvh, const Ray& ray) { return bvh_single<true>(bvh, ray).done != 0; }

namespace {

void bvh_intersect_packet(const BvhView& bvh, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  in_chunks<4>(mask, [&](int off, uint32_t bits) { return trace_bvh_packet<4, false>(bvh, rays, off, bits, &hits); });
}

LaneMask bvh_occluded_packet(const BvhView& bvh, const RayPacket& rays, LaneMask mask) {
  return in_chunks<4>(mask, [&](int off, uint32_t bits) {
    return trace_bvh_packet<4, true>(bvh, rays, off, bits, nullptr);
  });
}

void bvh_intersect_packet_scalar(const BvhView& bvh, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  lane_by_lane(rays, mask, hits, [&](const Ray& r, Hit& h) { h = bvh_intersect_single(bvh, r); });
}

LaneMask bvh_occluded_packet_scalar(const BvhView& bvh, const RayPacket& rays, LaneMask mask) {
  return lane_by_lane_occluded(rays, mask, [&](const Ray& r) { return bvh_occluded_single(bvh, r); });
}

}  // namespace

void two_level_intersect_single(const TwoLevelView& scene, const Ray& ray, Hit& hit) {
  hit = to_hit(two_level_single<false>(scene, ray, hit));
}

bool two_level_occluded_single(const TwoLevelView& scene, const Ray& ray) {
  return two_level_single<true>(scene, ray, Hit{}).done != 0;
}

namespace {

void two_level_intersect_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  in_chunks<4>(mask, [&](int off, uint32_t bits) {
    return trace_two_level_packet<4, false>(scene, rays, off, bits, &hits);
  });
}

LaneMask two_level_occluded_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask) {
  return in_chunks<4>(mask, [&](int off, uint32_t bits) {
    return trace_two_level_packet<4, true>(scene, rays, off, bits, nullptr);
  });
}

void two_level_intersect_packet_scalar(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  lane_by_lane(rays, mask, hits, [&](const Ray& r, Hit& h) { two_level_intersect_single(scene, r, h); });
}

LaneMask two_level_occluded_packet_scalar(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask) {
  return lane_by_lane_occluded(rays, mask, [&](const Ray& r) { return two_level_occluded_single(scene, r); });
}

}  // namespace

// ---- transmittance

namespace {

LaneMask transmittance_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, float* trans) {
  return in_chunks<4>(mask, [&](int off, uint32_t bits) {
    return trace_lanes<4, true, true>(tree, rays, off, bits, nullptr, trans);
  });
}

LaneMask two_level_transmittance_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask, float* trans) {
  return in_chunks<4>(mask, [&](int off, uint32_t bits) {
    return trace_two_level_packet<4, true, true>(scene, rays, off, bits, nullptr, trans);
  });
}

LaneMask transmittance_packet_scalar(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, float* trans) {
  return in_chunks<1>(mask, [&](int off, uint32_t bits) {
    return trace_lanes<1, true, true>(tree, rays, off, bits, nullptr, trans);
  });
}

LaneMask two_level_transmittance_packet_scalar(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask,
                                               float* trans) {
  return in_chunks<1>(mask, [&](int off, uint32_t bits) {
    return trace_two_level_packet<1, true, true>(scene, rays, off, bits, nullptr, trans);
  });
}

}  // namespace

const PacketKernels& kernels() {
  static constexpr PacketKernels kSet{&intersect_packet,           &occluded_packet,
                                      &bvh_intersect_packet,       &bvh_occluded_packet,
                                      &two_level_intersect_packet, &two_level_occluded_packet,
                                      &transmittance_packet,       &two_level_transmittance_packet};
  return kSet;
}

const PacketKernels& scalar_kernels() {
  static constexpr PacketKernels kSet{&intersect_packet_scalar,           &occluded_packet_scalar,
                                      &bvh_intersect_packet_scalar,       &bvh_occluded_packet_scalar,
                                      &two_level_intersect_packet_scalar, &two_level_occluded_packet_scalar,
                                      &transmittance_packet_scalar,       &two_level_transmittance_packet_scalar};
  return kSet;
}

const SingleRayKernels& single_kernels() {
  static constexpr SingleRayKernels kSet{&wide_intersect1, &wide_occluded1, nullptr};
  return kSet;
}

}  // namespace artrace::core::sse
