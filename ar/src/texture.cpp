#include "artrace/ar/texture.h"

#include "artrace/core/srgb.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace artrace::ar {
namespace {

int wrap(int i, int n, Wrap w) {
  if (static_cast<unsigned>(i) < static_cast<unsigned>(n)) return i;  // inside the image, as most are: every mode agrees
  switch (w) {
    case Wrap::kClampToEdge:
      return std::clamp(i, 0, n - 1);
    case Wrap::kMirroredRepeat: {
      const int period = 2 * n;
      int m = i % period;
      if (m < 0) m += period;
      return m < n ? m : period - 1 - m;
    }
    case Wrap::kRepeat:
    default: {
      const int m = i % n;
      return m < 0 ? m + n : m;
    }
  }
}

/// Texture coordinates far outside [0, 1] (a repeat over thousands of tiles, or garbage in a
/// file) stay within int range: only the position modulo the pattern's period matters for
/// repeat and mirror, and clamp needs no more than a little outside.
float tame(float t) {
  if (!std::isfinite(t)) return 0.0f;
  if (std::fabs(t) < 1e6f) return t;
  return t - 2.0f * std::floor(t / 2.0f);
}

}  // namespace

Texture::Texture(int width, int height, std::vector<uint8_t> rgba, bool srgb) : srgb_(srgb) {
  if (width <= 0 || height <= 0) throw std::invalid_argument("texture: empty image");
  if (rgba.size() != static_cast<size_t>(width) * height * 4) {
    throw std::invalid_argument("texture: " + std::to_string(rgba.size()) + " bytes for a " + std::to_string(width) + "x" +
                                std::to_string(height) + " RGBA image");
  }
  levels_.push_back(Level{width, height, std::move(rgba)});
  // the mip chain: each level the box-filtered half of the one above (in linear light for colour)
  while (levels_.back().width > 1 || levels_.back().height > 1) {
    const Level& up = levels_.back();
    Level l;
    l.width = std::max(1, up.width / 2);
    l.height = std::max(1, up.height / 2);
    l.rgba.resize(static_cast<size_t>(l.width) * l.height * 4);
    for (int y = 0; y < l.height; ++y) {
      for (int x = 0; x < l.width; ++x) {
        // the source block: 2x2, or 3 wide/high at the last column/row of an odd size
        const int x0 = 2 * x, y0 = 2 * y;
        const int x1 = (x == l.width - 1) ? up.width : std::min(up.width, x0 + 2);
        const int y1 = (y == l.height - 1) ? up.height : std::min(up.height, y0 + 2);
        glm::vec4 sum(0.0f);
        int n = 0;
        for (int yy = y0; yy < y1; ++yy) {
          for (int xx = x0; xx < x1; ++xx) {
            sum += decode(&up.rgba[(static_cast<size_t>(yy) * up.width + xx) * 4]);
            ++n;
          }
        }
        const glm::vec4 avg = sum / static_cast<float>(n);
        uint8_t* out = &l.rgba[(static_cast<size_t>(y) * l.width + x) * 4];
        for (int c = 0; c < 3; ++c) {
          out[c] = srgb_ ? core::linear_to_srgb8(avg[c]) : static_cast<uint8_t>(std::lround(std::clamp(avg[c], 0.0f, 1.0f) * 255.0f));
        }
        out[3] = static_cast<uint8_t>(std::lround(std::clamp(avg[3], 0.0f, 1.0f) * 255.0f));
      }
    }
    levels_.push_back(std::move(l));
  }
}

glm::vec4 Texture::decode(const uint8_t* p) const {
  if (srgb_) return {core::srgb8_to_linear(p[0]), core::srgb8_to_linear(p[1]), core::srgb8_to_linear(p[2]), p[3] / 255.0f};
  return glm::vec4(p[0], p[1], p[2], p[3]) / 255.0f;
}

glm::vec4 Texture::texel(int level, int x, int y, const TextureSampler& s) const {
  const Level& l = levels_[static_cast<size_t>(level)];
  const int xx = wrap(x, l.width, s.wrap_s), yy = wrap(y, l.height, s.wrap_t);
  return decode(&l.rgba[(static_cast<size_t>(yy) * l.width + xx) * 4]);
}

glm::vec4 Texture::nearest(int level, glm::vec2 uv, const TextureSampler& s) const {
  const Level& l = levels_[static_cast<size_t>(level)];
  return texel(level, static_cast<int>(std::floor(tame(uv.x) * l.width)), static_cast<int>(std::floor(tame(uv.y) * l.height)), s);
}

glm::vec4 Texture::bilinear(int level, glm::vec2 uv, const TextureSampler& s) const {
  const Level& l = levels_[static_cast<size_t>(level)];
  const float px = tame(uv.x) * l.width - 0.5f, py = tame(uv.y) * l.height - 0.5f;
  const float fx0 = std::floor(px), fy0 = std::floor(py);
  const int x0 = static_cast<int>(fx0), y0 = static_cast<int>(fy0);
  const float fx = px - fx0, fy = py - fy0;
  // the four texels' columns and rows, each wrapped once
  const size_t xa = static_cast<size_t>(wrap(x0, l.width, s.wrap_s)) * 4, xb = static_cast<size_t>(wrap(x0 + 1, l.width, s.wrap_s)) * 4;
  const uint8_t* row0 = &l.rgba[static_cast<size_t>(wrap(y0, l.height, s.wrap_t)) * l.width * 4];
  const uint8_t* row1 = &l.rgba[static_cast<size_t>(wrap(y0 + 1, l.height, s.wrap_t)) * l.width * 4];
  const glm::vec4 a = decode(row0 + xa), b = decode(row0 + xb), c = decode(row1 + xa), d = decode(row1 + xb);
  return (a * (1.0f - fx) + b * fx) * (1.0f - fy) + (c * (1.0f - fx) + d * fx) * fy;
}

glm::vec4 Texture::sample(const TextureSampler& s, glm::vec2 uv, float lod) const {
  if (levels_.empty()) return glm::vec4(1.0f);
  if (!(lod > 0.0f) || !s.mipmaps) {
    const bool linear = (lod > 0.0f) ? s.min_linear : s.mag_linear;
    return linear ? bilinear(0, uv, s) : nearest(0, uv, s);
  }
  const float top = static_cast<float>(levels_.size() - 1);
  const float level = std::min(lod, top);
  auto at = [&](int l) { return s.min_linear ? bilinear(l, uv, s) : nearest(l, uv, s); };
  if (!s.mip_linear) return at(static_cast<int>(std::lround(level)));
  const int l0 = static_cast<int>(std::floor(level));
  const float f = level - static_cast<float>(l0);
  if (f == 0.0f || l0 + 1 > static_cast<int>(top)) return at(l0);
  return at(l0) * (1.0f - f) + at(l0 + 1) * f;
}

float texture_lod(const Texture& t, float uv_area, float world_area, float cone_width, float cos_theta) {
  const float texel_area = uv_area * static_cast<float>(t.width()) * static_cast<float>(t.height());
  const float c = std::fabs(cos_theta);
  if (!(texel_area > 0.0f) || !(world_area > 0.0f) || !(cone_width > 0.0f) || !(c > 1e-6f)) return 0.0f;
  return 0.5f * std::log2(texel_area / world_area) + std::log2(cone_width / c);
}

}  // namespace artrace::ar
