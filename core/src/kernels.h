// Entry points of the traversal kernels, one namespace per instruction set. Internal to core.
#pragma once

#include "artrace/core/kd_tree.h"

namespace artrace::core {

namespace sse {
/// Single rays (width 1, compiled for the baseline instruction set).
Hit intersect_single(const KdTreeView& tree, const Ray& ray);
bool occluded_single(const KdTreeView& tree, const Ray& ray);
bool intersect_triangle_single(const Ray& ray, const Triangle& tri, uint32_t prim, Hit& hit);
/// Packets of 8 as two 4-wide halves.
void intersect_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, HitPacket& hits);
LaneMask occluded_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask);
/// The portable fallback: the 8 lanes one after the other with the width-1 kernel.
void intersect_packet_scalar(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, HitPacket& hits);
LaneMask occluded_packet_scalar(const KdTreeView& tree, const RayPacket& rays, LaneMask mask);
}  // namespace sse

namespace avx2 {
/// Packets of 8 in one 8-wide pass; call only when the CPU has AVX2.
void intersect_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask, HitPacket& hits);
LaneMask occluded_packet(const KdTreeView& tree, const RayPacket& rays, LaneMask mask);
}  // namespace avx2

/// The packet kernels chosen by set_simd_level (simd_dispatch.cpp).
struct PacketKernels {
  void (*intersect)(const KdTreeView&, const RayPacket&, LaneMask, HitPacket&);
  LaneMask (*occluded)(const KdTreeView&, const RayPacket&, LaneMask);
};
const PacketKernels& packet_kernels();

}  // namespace artrace::core
