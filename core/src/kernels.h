// Entry points of the traversal kernels, one namespace per instruction set. Internal to core.
#pragma once

#include "artrace/core/bvh.h"
#include "artrace/core/kd_tree.h"
#include "artrace/core/two_level_scene.h"
#include "artrace/core/wide_bvh.h"

#include <cmath>

namespace artrace::core {

/// The axis of a direction's largest component (the first of equal ones), and the group the
/// packet kernels trace a lane with: that axis and the direction's octant, 24 keys. The kernels
/// trace each group of a packet's lanes separately, so callers that can choose their packets
/// (the renderer's secondary rays) group by the same key. `static`: each kernel translation
/// unit, compiled with its own instruction set, keeps its own copy.
static inline int dominant_axis(float dx, float dy, float dz) {
  int kz = 0;
  if (std::fabs(dy) > std::fabs(dx)) kz = 1;
  if (std::fabs(dz) > std::fabs(kz == 0 ? dx : dy)) kz = 2;
  return kz;
}

constexpr int kDirectionKeys = 24;

static inline int direction_key(float dx, float dy, float dz) {
  return dominant_axis(dx, dy, dz) * 8 + (std::signbit(dx) ? 1 : 0) + (std::signbit(dy) ? 2 : 0) +
         (std::signbit(dz) ? 4 : 0);
}

/// The root box the kd-tree kernels clip rays to: the tree's bounds widened by a relative margin,
/// so that rounding in the slab test never loses a ray that grazes the scene's outer faces.
Aabb padded_root_box(const Aabb& b);

/// A set of packet kernels, one entry point per query. Each instruction set's file gives its set;
/// set_simd_level (simd_dispatch.cpp) chooses one.
struct PacketKernels {
  void (*intersect)(const KdTreeView&, const RayPacket&, LaneMask, HitPacket&);
  LaneMask (*occluded)(const KdTreeView&, const RayPacket&, LaneMask);
  void (*bvh_intersect)(const BvhView&, const RayPacket&, LaneMask, HitPacket&);
  LaneMask (*bvh_occluded)(const BvhView&, const RayPacket&, LaneMask);
  void (*two_level_intersect)(const TwoLevelView&, const RayPacket&, LaneMask, HitPacket&);
  LaneMask (*two_level_occluded)(const TwoLevelView&, const RayPacket&, LaneMask);
  LaneMask (*transmittance)(const KdTreeView&, const RayPacket&, LaneMask, float*);
  LaneMask (*two_level_transmittance)(const TwoLevelView&, const RayPacket&, LaneMask, float*);
};

/// Single rays through the wide BVH (wide_traversal.inc), one set per instruction set.
struct SingleRayKernels {
  Hit (*intersect)(const WideBvhView&, const Ray&);
  bool (*occluded)(const WideBvhView&, const Ray&);
  /// Closest hits of a coherent packet's lanes in `mask`, a direction octant's rays as one
  /// frustum; null in the sets without it (narrower frustums did not pay: see WideBvh).
  void (*intersect_packet)(const WideBvhView&, const RayPacket&, LaneMask, HitPacket&);
};

namespace sse {
/// Single rays (width 1, compiled for the baseline instruction set).
Hit intersect_single(const KdTreeView& tree, const Ray& ray);
bool occluded_single(const KdTreeView& tree, const Ray& ray);
bool intersect_triangle_single(const Ray& ray, const Triangle& tri, uint32_t prim, Hit& hit);
Hit bvh_intersect_single(const BvhView& bvh, const Ray& ray);
bool bvh_occluded_single(const BvhView& bvh, const Ray& ray);
/// Two-level: continues from the closest hit in `hit` (the static kd-tree's).
void two_level_intersect_single(const TwoLevelView& scene, const Ray& ray, Hit& hit);
bool two_level_occluded_single(const TwoLevelView& scene, const Ray& ray);

/// Packets as 4-wide quarters. Two-level queries continue from the closest hits already in `hits`
/// (the static kd-tree's); transmittance queries return the unsure lanes (see
/// TwoLevelScene::transmittance).
const PacketKernels& kernels();
/// The portable fallback: the lanes one after the other with the width-1 kernel.
const PacketKernels& scalar_kernels();
/// The wide BVH's single-ray kernels, 8-wide node tests as two 4-wide halves.
const SingleRayKernels& single_kernels();
}  // namespace sse

namespace avx2 {
/// Packets as two 8-wide halves; call only when the CPU has AVX2.
const PacketKernels& kernels();
/// The wide BVH's single-ray kernels, 8-wide node tests in one AVX register.
const SingleRayKernels& single_kernels();
}  // namespace avx2

namespace avx512 {
/// Packets in one 16-wide pass (one-half packets go to the AVX2 set); call only when the CPU has
/// AVX-512 F, VL, DQ and BW.
const PacketKernels& kernels();
/// The wide BVH's single-ray kernels, 8-wide node tests with AVX-512's 32 vector registers, and
/// its 16-ray frustum packets.
const SingleRayKernels& single_kernels();
}  // namespace avx512

/// The packet kernels chosen by set_simd_level (simd_dispatch.cpp).
const PacketKernels& packet_kernels();
/// The single-ray kernels chosen likewise (AVX-512 machines use the AVX2 set).
const SingleRayKernels& single_ray_kernels();

}  // namespace artrace::core
