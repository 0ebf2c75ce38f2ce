// Packets of 8 coherent rays in structure-of-arrays layout. The AVX2 kernel traces them 8 wide, the
// SSE kernel as two 4-wide halves (lanes 0-3 and 4-7); `simd_level.h` chooses.
#pragma once

#include "artrace/core/geometry.h"

#include <cstdint>

namespace artrace::core {

inline constexpr int kPacketSize = 8;

struct alignas(32) RayPacket {
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

struct alignas(32) HitPacket {
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
