// Run-time choice of the SIMD width used by packet traversal.
#pragma once

#include <string>

namespace artrace::core {

/// Which packet kernels run. `kAuto` picks AVX-512 (16 wide) when the CPU has it (F, VL, DQ, BW),
/// else AVX2 (8 wide), else SSE (4 wide). The shading follows: at kAvx2 and kAvx512 it runs a copy
/// compiled for AVX2 (whitted.cpp), else the baseline one; both give the same bits.
enum class SimdLevel { kAuto, kScalar, kSse, kAvx2, kAvx512 };

/// True when this CPU can run `level` (kScalar, kSse and kAuto always can).
bool simd_level_supported(SimdLevel level);
/// Selects the kernels for every following packet call; throws std::invalid_argument when the CPU
/// lacks the instructions. Not to be called while other threads trace.
void set_simd_level(SimdLevel level);
/// The level in force (never kAuto: the resolved one).
SimdLevel simd_level();
std::string to_string(SimdLevel level);
/// Parses "auto", "scalar", "sse", "avx2", "avx512"; throws std::invalid_argument otherwise.
SimdLevel parse_simd_level(const std::string& name);

}  // namespace artrace::core
