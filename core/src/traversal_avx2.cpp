// 8-wide kernels. This file alone is compiled with -mavx2 -mfma (FMA contraction stays off, so
// its hits match the other widths bit for bit); it is reached only through simd_dispatch.cpp after
// the CPU reported AVX2.
#include "kernels.h"

#include <atomic>
#include <cmath>
#include <cstring>
#include <type_traits>
#include <utility>
#include <immintrin.h>

namespace artrace::core::avx2 {
#include "simd.inc"
#include "traversal.inc"

void intersect_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  if (mask) trace_lanes<8, false>(tree, rays, 0, mask, &hits);
}

LaneMask occluded_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask) {
  return mask ? trace_lanes<8, true>(tree, rays, 0, mask, nullptr) : 0u;
}


void bvh_intersect_packet(const BvhView& bvh, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  if (mask) trace_bvh_packet<8, false>(bvh, rays, 0, mask, &hits);
}

LaneMask bvh_occluded_packet(const BvhView& bvh, const RayPacket& rays, LaneMask mask) {
  return mask ? trace_bvh_packet<8, true>(bvh, rays, 0, mask, nullptr) : 0u;
}

void two_level_intersect_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  if (mask) trace_two_level_packet<8, false>(scene, rays, 0, mask, &hits);
}

LaneMask two_level_occluded_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask) {
  return mask ? trace_two_level_packet<8, true>(scene, rays, 0, mask, nullptr) : 0u;
}

LaneMask transmittance_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, float* trans) {
  return mask ? trace_lanes<8, true, true>(tree, rays, 0, mask, nullptr, trans) : 0u;
}

LaneMask two_level_transmittance_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask, float* trans) {
  return mask ? trace_two_level_packet<8, true, true>(scene, rays, 0, mask, nullptr, trans) : 0u;
}

}  // namespace artrace::core::avx2
