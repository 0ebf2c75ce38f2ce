#include "artrace/core/whitted.h"
#include "artrace/core/simd_level.h"
#include "kernels.h"
#include "quarters.h"

#include <tbb/enumerable_thread_specific.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>
#if defined(__SSE__)
#include <immintrin.h>
#endif
#if defined(__x86_64__) || defined(__i386__)
#include <x86intrin.h>
#endif

namespace artrace::core {

namespace {

using Clock = std::chrono::steady_clock;

inline double ms(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); }

/// A cheap timestamp for the time split, read around every packet: the processor's time-stamp
/// counter where there is one (steady_clock's clock_gettime took 3.5% of a robots frame), turned
/// into milliseconds by the frame's wall time over the same interval; steady_clock elsewhere.
inline uint64_t ticks() {
#if defined(__x86_64__) || defined(__i386__)
  return __rdtsc();
#else
  return static_cast<uint64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count());
#endif
}

/// Ticks since t0 (0 should the counter ever step back, as an unsynchronised one could between
/// cores).
inline uint64_t ticks_since(uint64_t t0) {
  const uint64_t now = ticks();
  return now > t0 ? now - t0 : 0;
}

struct Counters {
  uint64_t primary = 0, shadow = 0, secondary = 0, transmission = 0;
  uint64_t primary_ticks = 0, shadow_ticks = 0, secondary_ticks = 0, total_ticks = 0;
};

inline float max3(const glm::vec3& v) { return std::max(v.x, std::max(v.y, v.z)); }

/// The image is handed out to the threads in blocks of kWaveBlock x kWaveBlock pixels (4 x 4 of
/// the 8x8 tiles). A block's primary rays are traced in 4 x kPacketRows packets; its reflection
/// and refraction rays are pooled as one generation and regrouped by direction, so that more of
/// them share a packet than within one tile. Results do not depend on the grouping:
/// every lane's hit and colour are its own.
constexpr int kWaveBlock = 4 * kTileSize;

/// What every tile needs, worked out once per image.
struct Prepared {
  /// Per material: below this cosine the highlight is under 1e-4; 2 for materials without one
  /// (no exponent, a black highlight colour, or an exponent so large that the cut-off rounds to 1).
  std::vector<float> highlight_cos;
  bool transmissive = false;
  /// Shadow rays see through transmissive triangles in one traversal (the geometry knows their
  /// transmittance); otherwise blocked ones are walked, and the boxes tell which need it.
  bool one_traversal = false;
  std::vector<Aabb> boxes;  ///< around transmissive triangles (for the walk)
  bool have_boxes = false;

  explicit Prepared(const ShadingScene& s) {
    for (const Material& m : s.materials) {
      transmissive |= m.transmittance > 0.0f;
      const float c = m.shine > 0.0f ? std::pow(1e-4f, 1.0f / m.shine) : 2.0f;
      highlight_cos.push_back(c < 1.0f && max3(m.specular) > 0.0f ? c : 2.0f);
    }
    one_traversal = transmissive && s.geometry->has_transmittance();
    if (transmissive && !one_traversal) have_boxes = s.surfaces->transmissive_bounds(boxes);
  }
};

void check(const ShadingScene& scene) {
  if (!scene.geometry || !scene.surfaces) throw std::invalid_argument("ShadingScene needs geometry and surfaces");
}

}  // namespace

// The shading, twice: for the baseline (4 lanes side by side), and for AVX2 (8 lanes) on CPUs
// that have it, chosen with the packet kernels (simd_level() AVX2 or AVX-512). The baseline copy
// comes first, so that every template both use (glm's, the standard library's) is instantiated for
// the baseline; the AVX2 copy's own types and functions live in its namespace.
namespace shade_base {
#include "whitted_wave.inc"
}  // namespace shade_base

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define ARTRACE_SHADE_AVX2 1
#pragma GCC push_options
#pragma GCC target("avx2")
#define ARTRACE_SHADE_ROUNDSS 1
#define ARTRACE_SHADE_LANES 8
namespace shade_avx2 {
#include "whitted_wave.inc"
}  // namespace shade_avx2
#undef ARTRACE_SHADE_LANES
#undef ARTRACE_SHADE_ROUNDSS
#pragma GCC pop_options
#endif

namespace {

/// The copy of the shading the SIMD level picks (AVX2 and AVX-512: the AVX2 copy).
struct ShadeCopy {
  decltype(&shade_base::render_tile) tile;
  decltype(&shade_base::trace_ray) ray;
};

ShadeCopy shade_copy() {
#ifdef ARTRACE_SHADE_AVX2
  if (simd_level() == SimdLevel::kAvx2 || simd_level() == SimdLevel::kAvx512) {
    return {&shade_avx2::render_tile, &shade_avx2::trace_ray};
  }
#endif
  return {&shade_base::render_tile, &shade_base::trace_ray};
}

}  // namespace

glm::vec3 Texture::bilinear(glm::vec2 uv) const { return shade_base::bilinear(*this, uv); }

glm::vec3 Texture::sample(glm::vec2 uv, float lod) const {
  const int level = std::clamp(static_cast<int>(lod + 0.5f), 0, static_cast<int>(mips.size()));
  return sample_level(uv, level);
}

glm::vec3 Texture::sample_level(glm::vec2 uv, int level) const { return shade_base::sample_level(*this, uv, level); }

void Texture::build_mipmaps() {
  mips.clear();
  const Texture* from = this;
  while (from->width > 1 || from->height > 1) {
    Texture t;
    t.width = std::max(1, from->width / 2);
    t.height = std::max(1, from->height / 2);
    t.texels.resize(static_cast<size_t>(t.width) * t.height);
    for (int y = 0; y < t.height; ++y) {
      for (int x = 0; x < t.width; ++x) {
        glm::vec3 sum(0.0f);
        for (int k = 0; k < 4; ++k) {
          const int sx = std::min(2 * x + (k & 1), from->width - 1), sy = std::min(2 * y + (k >> 1), from->height - 1);
          sum += from->texels[static_cast<size_t>(sy) * from->width + sx];
        }
        t.texels[static_cast<size_t>(y) * t.width + x] = 0.25f * sum;
      }
    }
    mips.push_back(std::move(t));
    from = &mips.back();
  }
}

ShadingMode parse_shading_mode(const std::string& name) {
  if (name == "diffuse") return ShadingMode::kDiffuse;
  if (name == "shadows") return ShadingMode::kShadows;
  if (name == "reflect") return ShadingMode::kReflect;
  if (name == "all") return ShadingMode::kAll;
  if (name == "paper") return ShadingMode::kPaper;
  throw std::invalid_argument("unknown shading mode \"" + name + "\" (diffuse, shadows, reflect, all or paper)");
}

const char* to_string(ShadingMode m) {
  switch (m) {
    case ShadingMode::kDiffuse: return "diffuse";
    case ShadingMode::kShadows: return "shadows";
    case ShadingMode::kReflect: return "reflect";
    case ShadingMode::kAll: return "all";
    case ShadingMode::kPaper: return "paper";
  }
  return "?";
}

void SurfaceAttributes::shading(const Hit&, const Triangle&, SurfaceInfo&) const {}

void SurfaceAttributes::shade_packet(const HitPacket& hits, LaneMask mask, const Triangle* world_tris,
                                     uint32_t* materials, SurfaceInfo* infos) const {
  for (int i = 0; i < kPacketSize; ++i) {
    if (!((mask >> i) & 1u)) continue;
    const Hit h = hits.get(i);
    materials[i] = material(h);
    shading(h, world_tris[i], infos[i]);
  }
}

float fresnel_dielectric(float cos_i, float eta) {
  cos_i = std::clamp(cos_i, 0.0f, 1.0f);
  const float sin2_t = eta * eta * (1.0f - cos_i * cos_i);
  if (sin2_t >= 1.0f) return 1.0f;
  const float cos_t = std::sqrt(1.0f - sin2_t);
  const float rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
  const float rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
  return 0.5f * (rs * rs + rp * rp);
}

bool refract_direction(const glm::vec3& d, const glm::vec3& n, float eta, glm::vec3& out) {
  const float cos_i = -glm::dot(d, n);
  const float sin2_t = eta * eta * (1.0f - cos_i * cos_i);
  if (sin2_t >= 1.0f) return false;
  out = glm::normalize(eta * d + (eta * cos_i - std::sqrt(1.0f - sin2_t)) * n);
  return true;
}

Image render_whitted(const ShadingScene& scene, const Camera& cam, const WhittedOptions& opt, WhittedStats* stats) {
  check(scene);
  const auto start = Clock::now();
  const uint64_t start_ticks = ticks();
  Image img(cam.width, cam.height);
  const Prepared pre(scene);
  tbb::enumerable_thread_specific<Counters> counters;
  const ShadeCopy copy = shade_copy();
  const auto block = [&](const Tile& t) {
    const uint64_t t0 = ticks();
    Counters& c = counters.local();
    copy.tile(scene, cam, opt, pre, c, t, img);
    c.total_ticks += ticks_since(t0);
  };
  for_each_tile(cam.width, cam.height, opt.threads, block, kWaveBlock);
  if (stats) {
    WhittedStats s;
    s.wall_ms = ms(start, Clock::now());
    const uint64_t frame_ticks = ticks_since(start_ticks);
    const double ms_per_tick = frame_ticks > 0 ? s.wall_ms / static_cast<double>(frame_ticks) : 0.0;
    for (const Counters& c : counters) {
      s.primary_rays += c.primary;
      s.shadow_rays += c.shadow;
      s.secondary_rays += c.secondary;
      s.transmission_rays += c.transmission;
      s.primary_ms += ms_per_tick * static_cast<double>(c.primary_ticks);
      s.shadow_ms += ms_per_tick * static_cast<double>(c.shadow_ticks);
      s.secondary_ms += ms_per_tick * static_cast<double>(c.secondary_ticks);
      s.shade_ms += ms_per_tick * (static_cast<double>(c.total_ticks) - static_cast<double>(c.primary_ticks) -
                                   static_cast<double>(c.shadow_ticks) - static_cast<double>(c.secondary_ticks));
    }
    *stats = s;
  }
  return img;
}

glm::vec3 trace_whitted(const ShadingScene& scene, const Ray& ray, const WhittedOptions& opt) {
  check(scene);
  const Prepared pre(scene);
  return shade_copy().ray(scene, ray, opt, pre);
}

}  // namespace artrace::core