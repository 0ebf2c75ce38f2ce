// Four lanes side by side, for the per-packet work outside the traversal kernels (the shader's
// geometry and light loop, the two-level scene's bookkeeping): GCC vector extensions, one SSE
// register on the x86-64 baseline, plain scalar code where there is no SSE. A packet of
// kPacketSize lanes is handled as quarters. Each lane computes with the same operations, in the
// same order, as scalar code would, so results do not depend on the grouping. (The shader's AVX2
// copy takes 8 lanes at a time instead: whitted_wave.inc.)
#pragma once

#include "artrace/core/ray_packet.h"

#include <cmath>
#include <cstdint>
#include <cstring>
#if defined(__SSE__)
#include <immintrin.h>
#endif

namespace artrace::core {

typedef float F4 __attribute__((vector_size(16)));
typedef int32_t M4 __attribute__((vector_size(16)));
static_assert(kPacketSize % 4 == 0, "a packet is handled in quarters of 4 lanes");
inline constexpr int kQuarters = kPacketSize / 4;

/// Square roots in place.
inline void sqrt4(F4& x) {
#if defined(__SSE__)
  x = (F4)_mm_sqrt_ps((__m128)x);
#else
  for (int i = 0; i < 4; ++i) x[i] = std::sqrt(x[i]);
#endif
}

/// Bit i set when lane i of the mask is set.
inline uint32_t bits4(M4 m) {
#if defined(__SSE__)
  return static_cast<uint32_t>(_mm_movemask_ps((__m128)m));
#else
  uint32_t b = 0;
  for (int i = 0; i < 4; ++i) b |= (m[i] != 0 ? 1u : 0u) << i;
  return b;
#endif
}

/// Lane i all ones where bit i of `bits` is set (the low four bits).
inline M4 mask4(uint32_t bits) {
  const M4 lane_bit = {1, 2, 4, 8};
  return ((M4{} + static_cast<int32_t>(bits)) & lane_bit) != 0;
}

/// a < b ? b : a, lane by lane (std::max's rule).
inline F4 max4(F4 a, F4 b) { return (F4)(((M4)b & (a < b)) | ((M4)a & ~(a < b))); }

/// |x|, lane by lane (the sign bit cleared).
inline F4 abs4(F4 x) { return (F4)((M4)x & 0x7fffffff); }

/// mask ? a : b, lane by lane.
inline F4 select4(M4 mask, F4 a, F4 b) { return (F4)(((M4)a & mask) | ((M4)b & ~mask)); }
inline M4 select4(M4 mask, M4 a, M4 b) { return (a & mask) | (b & ~mask); }

/// glm's dot of three-vectors: (x x' + y y') + z z'.
inline F4 dot4(const F4* a, const F4* b) { return (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]; }

/// Quarter h of a packet's floats (or 32-bit integers), and back.
template <class V, class S>
inline V load4(const S* p, int h) {
  V v;
  std::memcpy(&v, p + 4 * h, sizeof(V));
  return v;
}
template <class V, class S>
inline void store4(S* p, int h, const V& v) {
  std::memcpy(p + 4 * h, &v, sizeof(V));
}

}  // namespace artrace::core
