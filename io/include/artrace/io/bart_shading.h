// What the Whitted renderer needs of a BART scene: materials (`f`, `fm`), point lights, ambient
// light and background, PPM textures, and per hit the material, the interpolated shading normal
// (taken to world space through the object's transform) and the texture coordinates.
#pragma once

#include "artrace/core/whitted.h"
#include "artrace/io/bart_animation.h"

#include <filesystem>

namespace artrace::io {

/// Reads a binary PPM (P6, maxval up to 65535) as linear RGB (8-bit values are sRGB-decoded).
/// Throws ParseError naming the file and what is wrong.
core::Texture load_ppm(const std::filesystem::path& file);

class BartSurfaces : public core::SurfaceAttributes {
 public:
  explicit BartSurfaces(const BartAnimation& animation);
  uint32_t material(const core::Hit& hit) const override { return anim_.material(hit); }
  void shading(const core::Hit& hit, const core::Triangle& world_tri, core::SurfaceInfo& info) const override;
  void shade_packet(const core::HitPacket& hits, core::LaneMask mask, const core::Triangle* world_tris,
                    uint32_t* materials, core::SurfaceInfo* infos) const override;
  /// Boxes around runs of transmissive triangles of the static geometry, and the moved box of
  /// every animated object that has some.
  bool transmissive_bounds(std::vector<core::Aabb>& boxes) const override;

 private:
  const BartAnimation& anim_;
  std::vector<core::Aabb> static_boxes_;
  std::vector<std::pair<uint32_t, core::Aabb>> object_boxes_;  ///< (instance, object-space box)
  bool unknown_ = false;  ///< transmissive animated triangles: no boxes
  std::vector<float> static_uv_per_world_;  ///< texture scale of each textured static triangle (mip levels)
};

/// Materials, lights and textures of the scene; geometry and surfaces point at the arguments.
core::ShadingScene make_shading_scene(const BartAnimation& animation, const BartSurfaces& surfaces);

}  // namespace artrace::io
