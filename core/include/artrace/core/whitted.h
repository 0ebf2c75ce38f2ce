// Whitted ray tracing over a two-level scene: ambient + diffuse + Phong highlights from point lights,
// shadows, mirror reflection and refraction with Fresnel weights and total internal reflection, to a
// maximum recursion depth (2, as in "A Real-Time Ray Tracer").
//
// Rays are traced in generations per 8x8 tile: its primary rays as 4x4 pixel packets, then the
// reflection and refraction rays of all its pixels regrouped into packets of 16 (or, with
// `secondary_packets = false`, traced one by one), and so on. Shadow rays from one packet towards
// one light form a packet and take the any-hit path, the static triangle that blocked the previous
// such packet tested first (ShadowHint); rays blocked only by transmissive surfaces are then walked surface by surface and
// attenuated by their transmittance (a semi-transparent quad must not put a city in shadow). When
// the geometry knows each triangle's transmittance (TwoLevelScene::set_*_transmittance), shadow
// rays instead see through the glass in one traversal that multiplies its transmittance, which
// gives the same image (tested) without the walk's closest-hit steps.
//
// Secondary rays start at the hit point rebuilt from barycentric coordinates and pushed off the
// surface along its geometric normal by a distance relative to the floating-point magnitude of the
// point and its triangle (after Wächter & Binder, "A Fast and Robust Method for Avoiding
// Self-Intersection", Ray Tracing Gems, 2019): no global epsilon, so scenes at 1e-3 and at 1e4,
// near the origin or far from it, are free of acne and of leaks (tested).
#pragma once

#include "artrace/core/renderer.h"
#include "artrace/core/two_level_scene.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

namespace artrace::core {

/// Linear RGB texture, rows top first; sampled with repeat wrapping and bilinear filtering,
/// v = 0 at the bottom row (the OpenGL convention, which BART's texture coordinates follow).
struct Texture {
  int width = 0, height = 0;
  std::vector<glm::vec3> texels;
  std::vector<Texture> mips;  ///< halved levels 1, 2, ... (build_mipmaps)

  glm::vec3 bilinear(glm::vec2 uv) const;
  /// Bilinear in the mip level nearest to `lod` (0: this level).
  glm::vec3 sample(glm::vec2 uv, float lod) const;
  /// Bilinear in mip level `level` (clamped to the levels there are; 0: this level).
  glm::vec3 sample_level(glm::vec2 uv, int level) const;
  /// Box-filtered halvings down to 1x1, so distant texture is averaged instead of aliased.
  void build_mipmaps();
};

/// The mip level nearest to log2(texels) for a footprint of `texels` texels (0 for at most one).
/// Inline: the shader asks once per textured hit.
inline int nearest_mip_level(float texels) {
  if (!(texels > 1.0f)) return 0;  // also NaN
  uint32_t bits;
  std::memcpy(&bits, &texels, sizeof bits);
  // texels = m 2^e with m in [1, 2): log2 rounds up where m > sqrt(2) (0x3504f3 is the mantissa
  // of the float just below it; no float equals it)
  const int e = static_cast<int>(bits >> 23) - 127;
  return e + ((bits & 0x7fffffu) > 0x3504f3u ? 1 : 0);
}

struct Material {
  glm::vec3 ambient{0.0f};   ///< times the scene's ambient light
  glm::vec3 diffuse{0.8f};
  glm::vec3 specular{0.0f};  ///< Phong highlight colour and mirror weight
  float shine = 0.0f;        ///< Phong exponent (0: no highlight)
  float transmittance = 0.0f;
  float ior = 1.0f;
  int32_t texture = -1;      ///< multiplies ambient and diffuse
};

struct PointLight {
  glm::vec3 position{0.0f};
  glm::vec3 color{1.0f};
};

/// The four configurations of the paper's Table 1, and the paper's own all-effects workload.
/// kAll is full Whitted: shadow rays at every hit, camera and secondary. kPaper traces shadow rays
/// at the camera rays' hits only and shades reflection and refraction hits without them: what the
/// paper's figures imply, whose all-effects times equal (b) + (c) - (a) to within 1% in every row
/// (shadows at secondary hits would cost extra).
enum class ShadingMode { kDiffuse, kShadows, kReflect, kAll, kPaper };
ShadingMode parse_shading_mode(const std::string& name);  ///< diffuse|shadows|reflect|all|paper
const char* to_string(ShadingMode m);
/// Whether hits of rays of generation `depth` (0: camera rays) trace shadow rays.
inline bool has_shadows(ShadingMode m, int depth) {
  return m == ShadingMode::kShadows || m == ShadingMode::kAll || (m == ShadingMode::kPaper && depth == 0);
}
inline bool has_secondary(ShadingMode m) {
  return m == ShadingMode::kReflect || m == ShadingMode::kAll || m == ShadingMode::kPaper;
}

/// Shading attributes at a hit point.
struct SurfaceInfo {
  glm::vec3 normal{0.0f};  ///< world space, any length; zero: the geometric normal
  glm::vec2 uv{0.0f};
  int32_t texture = -1;    ///< overrides the material's texture when >= 0
  /// Texture-coordinate length per world length on this triangle (sqrt of the uv area over the
  /// world area); with the ray's footprint it picks the mip level. 0: always the full texture.
  float uv_per_world = 0.0f;
};

/// What the renderer asks of the application about a hit: its material and, at the hit's
/// barycentric coordinates, the shading normal, texture coordinates and texture.
class SurfaceAttributes {
 public:
  virtual ~SurfaceAttributes() = default;
  virtual uint32_t material(const Hit& hit) const = 0;
  /// Default: leaves `info` as it is (geometric normal, no texture coordinates).
  virtual void shading(const Hit& hit, const Triangle& world_tri, SurfaceInfo& info) const;
  /// Both for the hits of a packet, lanes of `mask`: materials[i] = material(hit i), and infos[i]
  /// as shading() fills it (world_tris[i]: the hit's triangle in world space). The renderer asks
  /// once per packet; the default asks hit by hit, two virtual calls a hit, which an override can
  /// make direct (and inline).
  virtual void shade_packet(const HitPacket& hits, LaneMask mask, const Triangle* world_tris, uint32_t* materials,
                            SurfaceInfo* infos) const;
  /// World boxes holding every transmissive triangle (for the current frame). A shadow ray found
  /// blocked whose segment meets none of them is blocked by an opaque surface and needs no walk.
  /// Return false when unknown (every blocked shadow ray is then walked).
  virtual bool transmissive_bounds(std::vector<Aabb>& boxes) const {
    (void)boxes;
    return false;
  }
};

struct ShadingScene {
  const TwoLevelScene* geometry = nullptr;
  const SurfaceAttributes* surfaces = nullptr;
  std::vector<Material> materials;
  std::vector<Texture> textures;
  std::vector<PointLight> lights;
  glm::vec3 ambient{0.0f};
  glm::vec3 background{0.0f};
};

struct WhittedOptions {
  ShadingMode mode = ShadingMode::kAll;
  int max_depth = 2;              ///< reflection/refraction generations after the primary ray
  float min_weight = 0.0f;        ///< no secondary ray whose weight (largest channel) is below this
  bool secondary_packets = true;  ///< regroup reflection/refraction rays into packets (else single rays)
  int threads = 0;
};

struct WhittedStats {
  uint64_t primary_rays = 0, shadow_rays = 0, secondary_rays = 0, transmission_rays = 0;
  /// Thread time in each part, milliseconds summed over the workers; `shade` is everything else
  /// (hit points, textures, lighting, spawning rays).
  double primary_ms = 0, shadow_ms = 0, secondary_ms = 0, shade_ms = 0;
  double wall_ms = 0;
};

/// Renders the scene through `cam`; linear RGB. Deterministic for any thread count.
Image render_whitted(const ShadingScene& scene, const Camera& cam, const WhittedOptions& opt,
                     WhittedStats* stats = nullptr);

/// Radiance along one ray with the same shading (for tests and single-pixel probes).
glm::vec3 trace_whitted(const ShadingScene& scene, const Ray& ray, const WhittedOptions& opt);

/// offset_ray_origin's step: this fraction of the largest coordinate (about 64 ulps), at least
/// kOffsetFloor. (The shader's four-lane copy of the function uses the same two constants.)
inline constexpr float kOffsetScale = 0x1p-18f;
inline constexpr float kOffsetFloor = 0x1p-100f;

/// `p` moved off its surface along unit `n` (the side the new ray leaves from) by about 64 ulps of
/// the largest of its coordinates and `magnitude` (the largest coordinate of its triangle).
/// Inline: the shader offsets every shadow origin and secondary ray.
inline glm::vec3 offset_ray_origin(const glm::vec3& p, const glm::vec3& n, float magnitude = 0.0f) {
  // Wächter & Binder 2019 move each coordinate by a fixed number of ulps of itself. The error of
  // a hit point, though, follows the size of the coordinates that went into it (a floor at z = 0
  // far from the origin has error in z of the order of ulp(x)), so the step is taken relative to
  // the largest coordinate of the point and of its triangle: 2^-18 of it, about 64 ulps.
  const float m = std::max(std::max(std::fabs(p.x), std::fabs(p.y)), std::max(std::fabs(p.z), magnitude));
  const float d = std::max(m * kOffsetScale, kOffsetFloor);
  return p + d * n;
}

/// Unpolarised Fresnel reflectance of a dielectric interface; `cos_i` > 0 is the cosine of the
/// incident angle, `eta` = n_incident / n_transmitted. 1 under total internal reflection.
float fresnel_dielectric(float cos_i, float eta);

/// Refracted direction of unit `d` through a surface with unit normal `n` facing the incoming ray
/// (dot(d, n) < 0), eta = n_incident / n_transmitted. False under total internal reflection.
bool refract_direction(const glm::vec3& d, const glm::vec3& n, float eta, glm::vec3& out);

}  // namespace artrace::core
