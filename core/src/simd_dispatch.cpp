#include "artrace/core/simd_level.h"
#include "kernels.h"

#include <stdexcept>

namespace artrace::core {
namespace {

bool cpu_has_avx2() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2");
#else
  return false;
#endif
}

bool cpu_has_avx512() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
         __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512bw");
#else
  return false;
#endif
}

SimdLevel resolve(SimdLevel level) {
  if (level == SimdLevel::kAuto) {
    return cpu_has_avx512() ? SimdLevel::kAvx512 : cpu_has_avx2() ? SimdLevel::kAvx2 : SimdLevel::kSse;
  }
  return level;
}

const PacketKernels& kernels_for(SimdLevel level) {
  switch (level) {
    case SimdLevel::kAvx512: return avx512::kernels();
    case SimdLevel::kAvx2: return avx2::kernels();
    case SimdLevel::kSse: return sse::kernels();
    default: return sse::scalar_kernels();
  }
}

const SingleRayKernels& single_for(SimdLevel level) {
  if (level == SimdLevel::kAvx512) return avx512::single_kernels();
  return level == SimdLevel::kAvx2 ? avx2::single_kernels() : sse::single_kernels();
}

SimdLevel g_level = resolve(SimdLevel::kAuto);
PacketKernels g_kernels = kernels_for(g_level);
SingleRayKernels g_single = single_for(g_level);

}  // namespace

bool simd_level_supported(SimdLevel level) {
  if (level == SimdLevel::kAvx512) return cpu_has_avx512();
  return level != SimdLevel::kAvx2 || cpu_has_avx2();
}

void set_simd_level(SimdLevel level) {
  if (!simd_level_supported(level)) {
    throw std::invalid_argument(level == SimdLevel::kAvx512
                                    ? "this CPU has no AVX-512 (F, VL, DQ, BW): choose 'avx2', 'sse' or 'scalar'"
                                    : "this CPU has no AVX2: choose 'sse' or 'scalar'");
  }
  g_level = resolve(level);
  g_kernels = kernels_for(g_level);
  g_single = single_for(g_level);
}

SimdLevel simd_level() { return g_level; }

const PacketKernels& packet_kernels() { return g_kernels; }

const SingleRayKernels& single_ray_kernels() { return g_single; }

std::string to_string(SimdLevel level) {
  switch (level) {
    case SimdLevel::kAuto: return "auto";
    case SimdLevel::kScalar: return "scalar";
    case SimdLevel::kSse: return "sse";
    case SimdLevel::kAvx2: return "avx2";
    case SimdLevel::kAvx512: return "avx512";
  }
  return "?";
}

SimdLevel parse_simd_level(const std::string& name) {
  if (name == "auto") return SimdLevel::kAuto;
  if (name == "scalar") return SimdLevel::kScalar;
  if (name == "sse") return SimdLevel::kSse;
  if (name == "avx2") return SimdLevel::kAvx2;
  if (name == "avx512") return SimdLevel::kAvx512;
  throw std::invalid_argument("unknown SIMD level '" + name + "' (expected auto, scalar, sse, avx2 or avx512)");
}

}  // namespace artrace::core
