// The packet query both real scenes answer (the per-frame depth mesh and the fused room): closest
// hits of the lanes in `mask`, their distances into t[] and, where `colour_of(lane, hits, colour)`
// finds one, their recorded colours; the lanes with a colour are returned.
#pragma once

#include "artrace/core/two_level_scene.h"

#include <glm/vec3.hpp>

namespace artrace::ar::detail {

template <class ColourOf>
core::LaneMask packet_hits(const core::TwoLevelScene& scene, const core::RayPacket& rays, core::LaneMask mask, float* t,
                           glm::vec3* colour, const ColourOf& colour_of) {
  core::HitPacket hits;
  for (int i = 0; i < core::kPacketSize; ++i) hits.prim[i] = core::kInvalidId;
  scene.intersect(rays, mask, hits);
  core::LaneMask out = 0;
  for (int i = 0; i < core::kPacketSize; ++i) {
    if (!((mask >> i) & 1u) || hits.prim[i] == core::kInvalidId) continue;
    t[i] = hits.t[i];
    if (colour_of(i, hits, colour[i])) out |= 1u << i;
  }
  return out;
}

}  // namespace artrace::ar::detail
