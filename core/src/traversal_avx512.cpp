// 16-wide kernels, the wide BVH's 8-wide single-ray kernel with AVX-512's 32 vector registers
// (the AVX2 build spills its ray to the stack), and its 16-ray frustum packets. This file alone is
// compiled for AVX-512 (F, VL, DQ, BW; FMA contraction stays off, so its hits match the other
// widths bit for bit); it is reached only through simd_dispatch.cpp after the CPU reported those
// extensions. A kd-tree packet with lanes in one half only goes to the AVX2 kernel (callers with
// 8-ray packets would otherwise pay for 16 lanes).
#include "kernels.h"

#include <atomic>
#include <cmath>
#include <cstring>
#include <type_traits>
#include <utility>
#include <immintrin.h>

namespace artrace::core::avx512 {
#include "simd.inc"
#include "traversal.inc"
#include "wide_traversal.inc"

namespace {

static_assert(kPacketSize == 16, "one 16-wide pass a packet");

/// Whether only one half of the packet takes part: then the AVX2 kernel traces it, 8 wide. This
/// file's own width-8 code was 7% slower with vector masks, and no faster with mask registers.
inline bool one_half(LaneMask mask) { return (mask >> 8) == 0 || (mask & 0xffu) == 0; }

void intersect_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  if (one_half(mask)) return avx2::kernels().intersect(tree, rays, mask, hits);
  trace_lanes<16, false>(tree, rays, 0, mask, &hits);
}

LaneMask occluded_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask) {
  if (one_half(mask)) return avx2::kernels().occluded(tree, rays, mask);
  return trace_lanes<16, true>(tree, rays, 0, mask, nullptr);
}

void bvh_intersect_packet(const BvhView& bvh, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  if (one_half(mask)) return avx2::kernels().bvh_intersect(bvh, rays, mask, hits);
  trace_bvh_packet<16, false>(bvh, rays, 0, mask, &hits);
}

LaneMask bvh_occluded_packet(const BvhView& bvh, const RayPacket& rays, LaneMask mask) {
  if (one_half(mask)) return avx2::kernels().bvh_occluded(bvh, rays, mask);
  return trace_bvh_packet<16, true>(bvh, rays, 0, mask, nullptr);
}

void two_level_intersect_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  if (one_half(mask)) return avx2::kernels().two_level_intersect(scene, rays, mask, hits);
  trace_two_level_packet<16, false>(scene, rays, 0, mask, &hits);
}

LaneMask two_level_occluded_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask) {
  if (one_half(mask)) return avx2::kernels().two_level_occluded(scene, rays, mask);
  return trace_two_level_packet<16, true>(scene, rays, 0, mask, nullptr);
}

LaneMask transmittance_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, float* trans) {
  if (one_half(mask)) return avx2::kernels().transmittance(tree, rays, mask, trans);
  return trace_lanes<16, true, true>(tree, rays, 0, mask, nullptr, trans);
}

LaneMask two_level_transmittance_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask, float* trans) {
  if (one_half(mask)) return avx2::kernels().two_level_transmittance(scene, rays, mask, trans);
  return trace_two_level_packet<16, true, true>(scene, rays, 0, mask, nullptr, trans);
}

void wide_intersect_packet(const WideBvhView& bvh, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  wide_trace_lanes<16>(bvh, rays, 0, mask, &hits);
}

}  // namespace

const PacketKernels& kernels() {
  static constexpr PacketKernels kSet{&intersect_packet,           &occluded_packet,
                                      &bvh_intersect_packet,       &bvh_occluded_packet,
                                      &two_level_intersect_packet, &two_level_occluded_packet,
                                      &transmittance_packet,       &two_level_transmittance_packet};
  return kSet;
}

const SingleRayKernels& single_kernels() {
  static constexpr SingleRayKernels kSet{&wide_intersect1, &wide_occluded1, &wide_intersect_packet};
  return kSet;
}

}  // namespace artrace::core::avx512
