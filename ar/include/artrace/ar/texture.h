// Textures of virtual objects: 8-bit RGBA images with a mip chain, sampled with glTF's sampler
// states (wrap: repeat, clamp to edge, mirrored repeat; filters: nearest or linear, with or without
// mipmaps). Colour textures are stored sRGB-encoded and filtered in linear light (texels are
// linearised before they are averaged, in the mip chain too); data textures (normals, metallic,
// roughness, occlusion) are filtered as they are.
//
// Level of detail: ray cones (T. Akenine-Moller, J. Nilsson, M. Andersson, C. Barre-Brisebois,
// R. Toth and T. Karras, "Texture Level of Detail Strategies for Real-Time Ray Tracing", Ray
// Tracing Gems, ch. 20, 2019): lod = 0.5 log2(texel area / world area of the triangle) +
// log2(cone width / |cos|), which keeps minified textures from aliasing.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>
#include <vector>

namespace artrace::ar {

enum class Wrap : uint8_t { kRepeat, kClampToEdge, kMirroredRepeat };

struct TextureSampler {
  Wrap wrap_s = Wrap::kRepeat, wrap_t = Wrap::kRepeat;
  bool mag_linear = true;  ///< magnification: bilinear (else nearest)
  bool min_linear = true;  ///< minification within a level: bilinear (else nearest)
  bool mipmaps = true;     ///< minification uses the mip chain
  bool mip_linear = true;  ///< between two levels (trilinear), else the nearest level
};

class Texture {
 public:
  Texture() = default;
  /// `rgba`: width x height x 4 bytes, top row first. `srgb`: the colour channels are sRGB-encoded.
  /// Builds the mip chain. Throws std::invalid_argument for an empty image or a size mismatch.
  Texture(int width, int height, std::vector<uint8_t> rgba, bool srgb);

  int width() const { return levels_.empty() ? 0 : levels_[0].width; }
  int height() const { return levels_.empty() ? 0 : levels_[0].height; }
  int levels() const { return static_cast<int>(levels_.size()); }
  bool srgb() const { return srgb_; }

  /// The filtered value at `uv` (glTF convention: (0, 0) is the image's top-left corner) at level
  /// of detail `lod` (0: full size; each step halves it), linear RGBA in [0, 1].
  glm::vec4 sample(const TextureSampler& s, glm::vec2 uv, float lod) const;
  /// One texel of a level (wrap applied), linear RGBA.
  glm::vec4 texel(int level, int x, int y, const TextureSampler& s) const;

 private:
  struct Level {
    int width = 0, height = 0;
    std::vector<uint8_t> rgba;
  };
  glm::vec4 bilinear(int level, glm::vec2 uv, const TextureSampler& s) const;
  glm::vec4 nearest(int level, glm::vec2 uv, const TextureSampler& s) const;
  glm::vec4 decode(const uint8_t* p) const;

  std::vector<Level> levels_;
  bool srgb_ = false;
};

/// Ray-cone level of detail for a hit: `uv_area` and `world_area` are the triangle's areas in
/// texture coordinates (0..1 units) and in world units, `cone_width` the ray cone's width at the
/// hit (world units), `cos_theta` the cosine between the ray and the normal.
float texture_lod(const Texture& t, float uv_area, float world_area, float cone_width, float cos_theta);

}  // namespace artrace::ar
