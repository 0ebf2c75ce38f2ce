// Embree as a side-by-side reference in benchmarks only; the product's traversal is its own.
//
// Set up as Embree's documentation advises, at its best for each kind of ray: BVHs of both the
// HIGH build quality (the documentation's choice for final-frame rendering) and the MEDIUM one
// (its default), each kind of ray timed through both and the faster counting;
// RTC_INTERSECT_CONTEXT_FLAG_COHERENT for coherent packets (camera rays), the default
// (incoherent) context for single and bounce rays, and both for shadow packets, of which the
// faster counts. Rays are converted to Embree's layouts before any timing, and its hits back
// after: a timed pass holds Embree's calls and nothing else.
#pragma once

#if defined(ARTRACE_HAVE_EMBREE)
#include "artrace/core/ray_packet.h"

#include <embree3/rtcore.h>

#include <memory>
#include <vector>

namespace artrace::tools {

/// Packets (or single rays) already in Embree's layout, with a pristine copy to restore before
/// each timed pass (Embree writes its answers into them).
class EmbreeBatch {
 public:
  /// `width` 1 (single rays: rtcIntersect1 / rtcOccluded1), 4, 8 or 16; lanes [0, width) of each
  /// of our packets (1: every lane of `mask`, one call each).
  EmbreeBatch(const std::vector<core::RayPacket>& packets, const std::vector<core::LaneMask>& masks, int width);
  ~EmbreeBatch();
  void restore();  ///< untimed: the rays as converted
  size_t calls() const { return calls_; }
  /// The calls of our packets [first, last), which come one after the other.
  size_t first_call(size_t packet) const { return first_call_[packet]; }
  int width() const { return width_; }

  struct Impl;
  std::unique_ptr<Impl> impl_;

 private:
  size_t calls_ = 0;
  int width_ = 1;
  std::vector<size_t> first_call_;  ///< per packet, and one past the last
};

/// The build qualities the reference times rays through.
enum class EmbreeQuality { kHigh = 0, kMedium = 1 };
const char* to_string(EmbreeQuality q);

class EmbreeReference {
 public:
  /// One device of `threads` threads; a scene of each quality. `robust`: the scenes in Embree's
  /// robust mode (RTC_SCENE_FLAG_ROBUST: robust traversal, no optimisations that reduce arithmetic
  /// accuracy), not its default.
  EmbreeReference(const std::vector<core::Triangle>& tris, int threads, bool robust = false);
  ~EmbreeReference();
  EmbreeReference(const EmbreeReference&) = delete;
  EmbreeReference& operator=(const EmbreeReference&) = delete;

  /// (Re)builds the scene of quality `q`.
  void build(EmbreeQuality q);
  /// The flags Embree reports for the scene of quality `q` (rtcGetSceneFlags).
  int scene_flags(EmbreeQuality q) const;
  /// Closest hits of calls [first, last) of a batch through the scene of quality `q`; `coherent`
  /// chooses the context flag.
  void intersect(EmbreeQuality q, EmbreeBatch& batch, size_t first, size_t last, bool coherent) const;
  /// Any hits likewise.
  void occluded(EmbreeQuality q, EmbreeBatch& batch, size_t first, size_t last, bool coherent) const;
  /// After a pass: the primitive hit by each of our lanes (kInvalidId: none), packet by packet.
  static void hits(const EmbreeBatch& batch, std::vector<uint32_t>& prim);
  /// After an occlusion pass: the blocked lanes of each of our packets.
  static void blocked(const EmbreeBatch& batch, std::vector<core::LaneMask>& blocked);

 private:
  template <bool Occluded>
  void trace(EmbreeQuality q, EmbreeBatch& batch, size_t first, size_t last, bool coherent) const;

  const std::vector<core::Triangle>& tris_;
  bool robust_;
  RTCDevice device_ = nullptr;
  RTCScene scenes_[2] = {nullptr, nullptr};  ///< by EmbreeQuality
};

}  // namespace artrace::tools
#endif
