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
/// the thresholds at or below a value gives the formula's byte exactly. The count starts from a
/// second table, the count at the lowest float of each bucket of 2^15 floats (the top eight bits
/// of the mantissa and the exponent, from 2^-12 up; below it the byte is 0 or 1), and steps on
/// while a threshold is at or below the value: a bucket spans at most a third of a byte (0.33),
/// so that is one comparison or two, mostly predicted, instead of a pow and a round, or a search
/// of eight unpredictable branches. It runs for every blended pixel and every texel of a
/// texture's mip chain.
inline uint8_t linear_to_srgb8(float linear) {
  constexpr uint32_t kLow = 0x39800000u;  // 2^-12
  constexpr uint32_t kOne = 0x3F800000u;  // 1.0f
  constexpr int kShift = 15;
  struct Tables {
    std::array<float, 255> up;
    std::array<uint8_t, ((kOne - kLow) >> kShift) + 1> start;
  };
  static const Tables t = [] {
    Tables r{};
    const auto as_float = [](uint32_t b) {
      float f;
      std::memcpy(&f, &b, sizeof f);
      return f;
    };
    for (int k = 1; k <= 255; ++k) {
      uint32_t lo = 0, hi = kOne;  // 0.0f and 1.0f; the formula gives 255 at 1.0f
      while (lo < hi) {
        const uint32_t mid = lo + (hi - lo) / 2;
        if (linear_to_srgb8_formula(as_float(mid)) >= k) hi = mid;
        else lo = mid + 1;
      }
      r.up[static_cast<size_t>(k - 1)] = as_float(lo);
    }
    size_t n = 0;
    for (size_t b = 0; b < r.start.size(); ++b) {
      const float lowest = as_float(kLow + static_cast<uint32_t>(b << kShift));
      while (n < 255 && r.up[n] <= lowest) ++n;
      r.start[b] = static_cast<uint8_t>(n);
    }
    return r;
  }();
  const float c = std::fmin(std::fmax(linear, 0.0f), 1.0f);
  uint32_t bits;
  std::memcpy(&bits, &c, sizeof bits);
  bits &= 0x7fffffffu;  // -0.0f as 0.0f
  size_t n = bits < kLow ? 0 : t.start[(bits - kLow) >> kShift];
  while (n < 255 && t.up[n] <= c) ++n;
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
