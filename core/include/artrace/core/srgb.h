// sRGB transfer functions (IEC 61966-2-1): images are shaded in linear RGB and stored as 8-bit sRGB.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>

namespace artrace::core {

/// The sRGB byte of a linear value, by the formula (clamped to [0, 1]).
inline uint8_t linear_to_srgb8_formula(float linear) {
  const float c = std::fmin(std::fmax(linear, 0.0f), 1.0f);
  const float s = c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
  return static_cast<uint8_t>(std::lround(s * 255.0f));
}

/// The same byte by its 255 thresholds: up[k - 1] is the least float in [0, 1] that the formula
/// takes to k or more, found by bisection over the floats' bit patterns (which order positive
/// floats as their values). The formula never decreases (checked by hand over every float of
/// [0, 1]; `Srgb.*` checks the floats near every step and a stride through the rest), so counting
/// the thresholds at or below a value gives the formula's byte exactly, with eight comparisons
/// instead of a pow and a round. It runs for every blended pixel and every texel of a texture's
/// mip chain.
inline uint8_t linear_to_srgb8(float linear) {
  static const std::array<float, 255> up = [] {
    std::array<float, 255> t{};
    const auto as_float = [](uint32_t b) {
      float f;
      std::memcpy(&f, &b, sizeof f);
      return f;
    };
    for (int k = 1; k <= 255; ++k) {
      uint32_t lo = 0, hi = 0x3F800000u;  // 0.0f and 1.0f; the formula gives 255 at 1.0f
      while (lo < hi) {
        const uint32_t mid = lo + (hi - lo) / 2;
        if (linear_to_srgb8_formula(as_float(mid)) >= k) hi = mid;
        else lo = mid + 1;
      }
      t[static_cast<size_t>(k - 1)] = as_float(lo);
    }
    return t;
  }();
  const float c = std::fmin(std::fmax(linear, 0.0f), 1.0f);
  // the thresholds at or below c, counted 128, 64, ..., 1 at a time (the index read is at most
  // 255 - step, inside the table)
  size_t n = 0;
  for (size_t step = 128; step > 0; step /= 2) n += up[n + step - 1] <= c ? step : 0;
  return static_cast<uint8_t>(n);
}

/// A table lookup: it runs for every pixel of every composited frame.
inline float srgb8_to_linear(uint8_t v) {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) {
      const float c = i / 255.0f;
      t[i] = c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
    }
    return t;
  }();
  return table[v];
}

}  // namespace artrace::core
