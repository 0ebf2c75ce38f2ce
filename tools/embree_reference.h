// Embree as a side-by-side reference in benchmarks only; the product's traversal is its own.
#pragma once

#if defined(ARTRACE_HAVE_EMBREE)
#include "artrace/core/ray_packet.h"

#include <embree3/rtcore.h>

#include <vector>

namespace artrace::tools {

class EmbreeReference {
 public:
  EmbreeReference(const std::vector<core::Triangle>& tris, int threads);
  ~EmbreeReference();
  EmbreeReference(const EmbreeReference&) = delete;
  EmbreeReference& operator=(const EmbreeReference&) = delete;

  /// (Re)builds the scene with RTC_BUILD_QUALITY_HIGH.
  void build();
  void intersect1(const core::RayPacket& rays, core::LaneMask mask, uint32_t* prim) const;
  /// rtcIntersect8 / rtcIntersect16 (`width` 8 or 16) on lanes [0, width) of the packet.
  void intersect_packet(const core::RayPacket& rays, core::LaneMask mask, uint32_t* prim, int width) const;
  /// rtcOccluded8 / rtcOccluded16 likewise; returns the blocked lanes.
  core::LaneMask occluded_packet(const core::RayPacket& rays, core::LaneMask mask, int width) const;

 private:
  const std::vector<core::Triangle>& tris_;
  RTCDevice device_ = nullptr;
  RTCScene scene_ = nullptr;
};

}  // namespace artrace::tools
#endif
