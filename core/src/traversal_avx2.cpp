// 8-wide kernels (a packet as two halves). This file alone is compiled with -mavx2 -mfma (FMA contraction stays off, so
// its hits match the other widths bit for bit); it is reached only through simd_dispatch.cpp after
// the CPU reported AVX2.
#include "kernels.h"

#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <type_traits>
#include <utility>
#include <immintrin.h>

namespace artrace::core::avx2 {
#include "simd.inc"
#include "traversal.inc"
#include "wide_traversal.inc"

namespace {

void intersect_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  in_chunks<8>(mask, [&](int off, uint32_t bits) { return trace_lanes<8, false>(tree, rays, off, bits, &hits); });
}

LaneMask occluded_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask) {
  return in_chunks<8>(mask, [&](int off, uint32_t bits) {
    return trace_lanes<8, true>(tree, rays, off, bits, nullptr);
  });
}


void bvh_intersect_packet(const BvhView& bvh, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  in_chunks<8>(mask, [&](int off, uint32_t bits) { return trace_bvh_packet<8, false>(bvh, rays, off, bits, &hits); });
}

LaneMask bvh_occluded_packet(const BvhView& bvh, const RayPacket& rays, LaneMask mask) {
  return in_chunks<8>(mask, [&](int off, uint32_t bits) {
    return trace_bvh_packet<8, true>(bvh, rays, off, bits, nullptr);
  });
}

void two_level_intersect_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask, HitPacket& hits) {
  in_chunks<8>(mask, [&](int off, uint32_t bits) {
    return trace_two_level_packet<8, false>(scene, rays, off, bits, &hits);
  });
}

LaneMask two_level_occluded_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask) {
  return in_chunks<8>(mask, [&](int off, uint32_t bits) {
    return trace_two_level_packet<8, true>(scene, rays, off, bits, nullptr);
  });
}

LaneMask transmittance_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, float* trans) {
  return in_chunks<8>(mask, [&](int off, uint32_t bits) {
    return trace_lanes<8, true, true>(tree, rays, off, bits, nullptr, trans);
  });
}

LaneMask two_level_transmittance_packet(const TwoLevelView& scene, const RayPacket& rays, LaneMask mask, float* trans) {
  return in_chunks<8>(mask, [&](int off, uint32_t bits) {
    return trace_two_level_packet<8, true, true>(scene, rays, off, bits, nullptr, trans);
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

const SingleRayKernels& single_kernels() {
  static constexpr SingleRayKernels kSet{&wide_intersect1, &wide_occluded1, nullptr};
  return kSet;
}

}  // namespace artrace::core::avx2
