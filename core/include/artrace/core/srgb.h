// sRGB transfer functions (IEC 61966-2-1): images are shaded in linear RGB and stored as 8-bit sRGB.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>

namespace artrace::core {

inline uint8_t linear_to_srgb8(float linear) {
  const float c = std::fmin(std::fmax(linear, 0.0f), 1.0f);
  const float s = c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
  return static_cast<uint8_t>(std::lround(s * 255.0f));
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
