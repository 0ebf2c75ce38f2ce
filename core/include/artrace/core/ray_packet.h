// Packets of 16 coherent rays in structure-of-arrays layout. The AVX-512 kernel traces them 16
// wide, the AVX2 kernel as two 8-wide halves, the SSE kernel as four 4-wide quarters (lanes 0-3,
// 4-7, ...); `simd_level.h` chooses. A packet with lanes in one half only is traced 8 wide
// everywhere (callers that build 8-ray packets lose nothing).
#pragma once

#include "artrace/core/geometry.h"

#include <cstdint>

namespace artrace::core {

inline constexpr int kPacketSize = 16;
/// Camera packets cover 4 x kPacketRows pixels (lane i at column i % 4, row i / 4).
inline constexpr int kPacketRows = kPacketSize / 4;

struct alignas(64) RayPacket {
  float org[3][kPacketSize];
  float dir[3][kPacketSize];
  float tmin[kPacketSize];
  float tmax[kPacketSize];

  void set(int lane, const Ray& r) {
    for (int a = 0; a < 3; ++a) {
      org[a][lane] = r.org[a];
      dir[a][lane] = r.dir[a];
    }
    tmin[lane] = r.tmin;
    tmax[lane] = r.tmax;
  }
  Ray get(int lane) const {
    Ray r;
    for (int a = 0; a < 3; ++a) {
      r.org[a] = org[a][lane];
      r.dir[a] = dir[a][lane];
    }
    r.tmin = tmin[lane];
    r.tmax = tmax[lane];
    return r;
  }
};

struct alignas(64) HitPacket {
  float t[kPacketSize];
  float u[kPacketSize];
  float v[kPacketSize];
  uint32_t prim[kPacketSize];
  uint32_t inst[kPacketSize];  ///< object of the hit in two-level scenes (kInvalidId otherwise)

  Hit get(int lane) const {
    Hit h;
    h.t = t[lane];
    h.u = u[lane];
    h.v = v[lane];
    h.prim = prim[lane];
    h.inst = inst[lane];
    return h;
  }
};

/// Bit i set: lane i takes part.
using LaneMask = uint32_t;
inline constexpr LaneMask kAllLanes = (1u << kPacketSize) - 1u;

}  // namespace artrace::core
