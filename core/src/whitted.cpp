#include "artrace/core/whitted.h"
#include "kernels.h"

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

/// std::floor for floats, inline (on the x86-64 baseline std::floor is a call into libm, four a
/// texture lookup). Exact: values of 2^23 and more (and NaN, infinities) are integers already.
inline float floor_exact(float x) {
  if (!(std::fabs(x) < 0x1p23f)) return x;
  const float t = static_cast<float>(static_cast<int32_t>(x));  // towards zero
  return t > x ? t - 1.0f : t;
}

}  // namespace

glm::vec3 Texture::bilinear(glm::vec2 uv) const {
  if (width <= 0 || height <= 0) return glm::vec3(1.0f);
  // repeat: the fractional part, then texel centres at (i + 0.5) / width; v = 0 is the bottom row
  float u = uv.x - floor_exact(uv.x), v = uv.y - floor_exact(uv.y);
  if (!(u >= 0.0f)) u = 0.0f;  // NaN or infinite coordinates: any texel, but one inside the image
  if (!(v >= 0.0f)) v = 0.0f;
  const float x = u * static_cast<float>(width) - 0.5f;
  const float y = (1.0f - v) * static_cast<float>(height) - 0.5f;
  const float fx = floor_exact(x), fy = floor_exact(y);
  const float ax = x - fx, ay = y - fy;
  // fx in [-1, width - 1], fy in [-1, height]: neighbours wrap around without a division
  auto wrap = [](int i, int n) { return i < 0 ? i + n : (i >= n ? i - n : i); };
  const int ix = static_cast<int>(fx), iy = static_cast<int>(fy);
  const int x0 = wrap(ix, width), x1 = wrap(ix + 1, width);
  const int y0 = wrap(iy, height), y1 = wrap(iy + 1, height);
  auto at = [&](int xx, int yy) { return texels[static_cast<size_t>(yy) * width + xx]; };
  return (at(x0, y0) * (1.0f - ax) + at(x1, y0) * ax) * (1.0f - ay) + (at(x0, y1) * (1.0f - ax) + at(x1, y1) * ax) * ay;
}

glm::vec3 Texture::sample(glm::vec2 uv, float lod) const {
  const int level = std::clamp(static_cast<int>(lod + 0.5f), 0, static_cast<int>(mips.size()));
  return sample_level(uv, level);
}

glm::vec3 Texture::sample_level(glm::vec2 uv, int level) const {
  level = std::clamp(level, 0, static_cast<int>(mips.size()));
  return level == 0 ? bilinear(uv) : mips[static_cast<size_t>(level - 1)].bilinear(uv);
}

int nearest_mip_level(float texels) {
  if (!(texels > 1.0f)) return 0;  // also NaN
  uint32_t bits;
  std::memcpy(&bits, &texels, sizeof bits);
  // texels = m 2^e with m in [1, 2): log2 rounds up where m > sqrt(2) (0x3504f3 is the mantissa
  // of the float just below it; no float equals it)
  const int e = static_cast<int>(bits >> 23) - 127;
  return e + ((bits & 0x7fffffu) > 0x3504f3u ? 1 : 0);
}

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
  throw std::invalid_argument("unknown shading mode \"" + name + "\" (diffuse, shadows, reflect or all)");
}

const char* to_string(ShadingMode m) {
  switch (m) {
    case ShadingMode::kDiffuse: return "diffuse";
    case ShadingMode::kShadows: return "shadows";
    case ShadingMode::kReflect: return "reflect";
    case ShadingMode::kAll: return "all";
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

/// A ray waiting to be traced: which pixel of the packet it adds to, with what weight.
struct Pending {
  Ray ray;
  glm::vec3 weight;
  uint8_t lane;
  uint8_t depth;
  float dist = 0.0f;  ///< path length from the eye to the ray's origin (for texture footprints)
};

/// A shaded hit of the current wave.
struct Point {
  glm::vec3 p, ng, ns, view;
  glm::vec3 diffuse, specular;
  float magnitude = 0.0f;  ///< largest coordinate of the hit triangle
  float dist = 0.0f;       ///< path length from the eye
  const Material* m = nullptr;
  bool inside = false;
};

inline float max_abs(const glm::vec3& v) { return std::max({std::fabs(v.x), std::fabs(v.y), std::fabs(v.z)}); }

inline float max3(const glm::vec3& v) { return std::max(v.x, std::max(v.y, v.z)); }

// The light loop works on four lanes side by side (GCC vector extensions: one SSE register on the
// x86-64 baseline), a wave of kPacketSize lanes as quarters. Every lane computes with the same
// operations, in the same order, as scalar code would, so the result does not depend on the grouping.
typedef float F4 __attribute__((vector_size(16)));
typedef int32_t M4 __attribute__((vector_size(16)));
static_assert(kPacketSize % 4 == 0, "the light loop works on a wave in quarters of 4 lanes");
constexpr int kQuarters = kPacketSize / 4;

/// Square roots in place.
inline void sqrt4(F4& x) {
#if defined(__SSE__)
  x = (F4)_mm_sqrt_ps((__m128)x);
#else
  for (int i = 0; i < 4; ++i) x[i] = std::sqrt(x[i]);
#endif
}

/// Bit i set when lane i of the mask is set.
inline uint32_t bits4(M4 m) {
#if defined(__SSE__)
  return static_cast<uint32_t>(_mm_movemask_ps((__m128)m));
#else
  uint32_t b = 0;
  for (int i = 0; i < 4; ++i) b |= (m[i] != 0 ? 1u : 0u) << i;
  return b;
#endif
}

/// The shaded hits of a wave as structure of arrays (quarters of 4 lanes), for the light loop.
struct WaveLanes {
  F4 p[kQuarters][3], ng[kQuarters][3], ns[kQuarters][3], view[kQuarters][3], diffuse[kQuarters][3],
      specular[kQuarters][3], org[kQuarters][3];
  F4 min_cos[kQuarters];                    ///< highlight cut-off cosine (2: none)
  M4 hit[kQuarters], highlight[kQuarters];  ///< lanes with a hit; lanes whose material has a highlight
  float shine[kPacketSize];

  /// `origins`: also the shadow rays' origins (only when shadows are traced).
  void gather(const Point* pt, LaneMask hit_mask, const std::vector<float>& highlight_cos, const Material* materials,
              bool origins) {
    for (int i = 0; i < kPacketSize; ++i) {
      const int h = i >> 2, k = i & 3;
      const Point* q = ((hit_mask >> i) & 1u) ? &pt[i] : nullptr;
      const glm::vec3 o = q && origins ? offset_ray_origin(q->p, q->ng, q->magnitude) : glm::vec3(0.0f);
      for (int a = 0; a < 3; ++a) {
        p[h][a][k] = q ? q->p[a] : 0.0f;
        ng[h][a][k] = q ? q->ng[a] : 0.0f;
        ns[h][a][k] = q ? q->ns[a] : 0.0f;
        view[h][a][k] = q ? q->view[a] : 0.0f;
        diffuse[h][a][k] = q ? q->diffuse[a] : 0.0f;
        specular[h][a][k] = q ? q->specular[a] : 0.0f;
        org[h][a][k] = o[a];
      }
      const float mc = q ? highlight_cos[static_cast<size_t>(q->m - materials)] : 2.0f;
      min_cos[h][k] = mc;
      shine[i] = q ? q->m->shine : 0.0f;
      hit[h][k] = q ? -1 : 0;
      highlight[h][k] = (q && mc < 1.0f && max3(q->specular) > 0.0f) ? -1 : 0;
    }
  }
};

/// One light's share of a wave: the lanes it reaches, what it adds there, the shadow rays.
struct LightLanes {
  F4 contrib[kQuarters][3];  ///< per quarter and colour channel (0 where the light does not reach)
  alignas(16) float trans[kPacketSize];
  RayPacket shadow;
  LaneMask lit = 0;
};

/// What every tile needs, worked out once per image.
struct Prepared {
  std::vector<float> highlight_cos;  ///< per material: below this cosine the highlight is under 1e-4
  bool transmissive = false;
  /// Shadow rays see through transmissive triangles in one traversal (the geometry knows their
  /// transmittance); otherwise blocked ones are walked, and the boxes tell which need it.
  bool one_traversal = false;
  std::vector<Aabb> boxes;  ///< around transmissive triangles (for the walk)
  bool have_boxes = false;

  explicit Prepared(const ShadingScene& s) {
    for (const Material& m : s.materials) {
      transmissive |= m.transmittance > 0.0f;
      highlight_cos.push_back(m.shine > 0.0f ? std::pow(1e-4f, 1.0f / m.shine) : 2.0f);
    }
    one_traversal = transmissive && s.geometry->has_transmittance();
    if (transmissive && !one_traversal) have_boxes = s.surfaces->transmissive_bounds(boxes);
  }
};

class WaveTracer {
 public:
  /// `spread`: footprint of a pixel per unit of distance (0: textures at full resolution).
  WaveTracer(const ShadingScene& s, const WhittedOptions& o, Counters& c, const Prepared& pre, float spread = 0.0f)
      : s_(s), o_(o), c_(c), boxes_(pre.have_boxes ? &pre.boxes : nullptr), pre_(pre), spread_(spread),
        hints_(s.lights.size()), light_lanes_(s.lights.size()) {}

  /// Traces `gen` and every generation it spawns; adds radiance to color[lane].
  void run(std::vector<Pending>& gen, std::vector<Pending>& next, glm::vec3* color) {
    while (!gen.empty()) {
      if (gen[0].depth > 0) by_direction(gen, next);
      next.clear();
      for (size_t first = 0; first < gen.size(); first += kPacketSize) {
        const int n = static_cast<int>(std::min<size_t>(kPacketSize, gen.size() - first));
        wave(&gen[first], n, color, next);
      }
      gen.swap(next);
    }
  }

 private:
  /// Reorders a generation of reflection and refraction rays by the kernels' direction key
  /// (dominant axis and octant; stable: a counting sort), so that a packet's lanes share it: the
  /// packet kernels trace each key's lanes separately. `scratch` is reused.
  static void by_direction(std::vector<Pending>& gen, std::vector<Pending>& scratch) {
    auto key = [](const glm::vec3& d) { return direction_key(d.x, d.y, d.z); };
    int start[kDirectionKeys + 1] = {};
    for (const Pending& r : gen) ++start[key(r.ray.dir) + 1];
    for (int k = 0; k < kDirectionKeys; ++k) start[k + 1] += start[k];
    scratch.resize(gen.size());
    for (const Pending& r : gen) scratch[static_cast<size_t>(start[key(r.ray.dir)]++)] = r;
    gen.swap(scratch);
  }

  const Material& material(uint32_t id) const {
    if (id >= s_.materials.size()) throw std::out_of_range("material index out of range");
    return s_.materials[id];
  }
  const Material& material(const Hit& h) const { return material(s_.surfaces->material(h)); }

  void wave(const Pending* rays, int n, glm::vec3* color, std::vector<Pending>& next) {
    RayPacket rp;
    HitPacket hp;
    const LaneMask mask = n == kPacketSize ? kAllLanes : (1u << n) - 1u;
    for (int i = 0; i < n; ++i) rp.set(i, rays[i].ray);
    const bool primary = rays[0].depth == 0;
    const uint64_t t0 = ticks();
    if (primary || o_.secondary_packets) {
      s_.geometry->intersect(rp, mask, hp);
    } else {
      for (int i = 0; i < n; ++i) {
        const Hit h = s_.geometry->intersect(rays[i].ray);
        hp.t[i] = h.t, hp.u[i] = h.u, hp.v[i] = h.v, hp.prim[i] = h.prim, hp.inst[i] = h.inst;
      }
    }
    (primary ? c_.primary_ticks : c_.secondary_ticks) += ticks_since(t0);
    (primary ? c_.primary : c_.secondary) += static_cast<uint64_t>(n);

    Point pt[kPacketSize];
    glm::vec3 ambient[kPacketSize];  ///< what each hit reflects of the ambient light
    Triangle tris[kPacketSize];
    LaneMask hit_mask = 0;
    for (int i = 0; i < n; ++i) {
      if (hp.prim[i] == kInvalidId) {
        color[rays[i].lane] += rays[i].weight * s_.background;
        continue;
      }
      hit_mask |= 1u << i;
      tris[i] = s_.geometry->world_triangle(hp.get(i));
    }
    if (hit_mask == 0) return;
    uint32_t material_ids[kPacketSize];
    SurfaceInfo infos[kPacketSize];
    s_.surfaces->shade_packet(hp, hit_mask, tris, material_ids, infos);
    for (int i = 0; i < n; ++i) {
      if (!((hit_mask >> i) & 1u)) continue;
      const Pending& r = rays[i];
      const Triangle& tri = tris[i];
      const float hu = hp.u[i], hv = hp.v[i], ht = hp.t[i];
      Point& q = pt[i];
      q.p = tri.v0 * (1.0f - hu - hv) + tri.v1 * hu + tri.v2 * hv;
      q.ng = glm::normalize(tri.geometric_normal());
      q.magnitude = std::max({max_abs(tri.v0), max_abs(tri.v1), max_abs(tri.v2)});
      const SurfaceInfo& info = infos[i];
      q.ns = glm::dot(info.normal, info.normal) > 0.0f ? glm::normalize(info.normal) : q.ng;
      const float dir_len = glm::length(r.ray.dir);  // camera rays are not unit length
      q.view = -r.ray.dir / dir_len;
      q.dist = r.dist + ht * dir_len;
      if (glm::dot(q.ng, q.view) < 0.0f) {  // the back side: the ray leaves a solid
        q.ng = -q.ng;
        q.ns = -q.ns;
        q.inside = true;
      }
      if (glm::dot(q.ns, q.view) <= 0.0f) q.ns = q.ng;  // an interpolated normal facing away
      q.m = &material(material_ids[i]);
      const int32_t texture = info.texture >= 0 ? info.texture : q.m->texture;
      const bool textured = texture >= 0 && texture < static_cast<int32_t>(s_.textures.size());
      const glm::vec3 tex = textured ? s_.textures[texture].sample_level(
                                           info.uv, mip_level(r, ht, info, s_.textures[texture]))
                                     : glm::vec3(1.0f);
      q.diffuse = q.m->diffuse * tex;
      q.specular = q.m->specular;
      ambient[i] = s_.ambient * q.m->ambient * tex;
    }

    // Direct light. First every light's lanes, contributions and shadow rays, the lanes side by
    // side (one origin per hit), then all the shadow packets in one go, then the sums.
    WaveLanes w;
    w.gather(pt, hit_mask, pre_.highlight_cos, s_.materials.data(), has_shadows(o_.mode));
    const size_t light_count = s_.lights.size();
    for (size_t li = 0; li < light_count; ++li) light_lanes(w, s_.lights[li], light_lanes_[li]);
    if (has_shadows(o_.mode)) {
      const uint64_t s0 = ticks();
      for (size_t li = 0; li < light_count; ++li) {
        LightLanes& ll = light_lanes_[li];
        if (ll.lit) shadow_packet(ll.shadow, ll.lit, ll.trans, hints_[li]);
      }
      c_.shadow_ticks += ticks_since(s0);
    }
    // the lights' sums side by side, then each hit's radiance into its pixel
    F4 direct[kQuarters][3] = {};
    for (size_t li = 0; li < light_count; ++li) {
      const LightLanes& ll = light_lanes_[li];
      if (!ll.lit) continue;
      for (int h = 0; h < kQuarters; ++h) {
        F4 trans;
        std::memcpy(&trans, &ll.trans[4 * h], sizeof(F4));
        for (int a = 0; a < 3; ++a) direct[h][a] += ll.contrib[h][a] * trans;
      }
    }
    for (int i = 0; i < n; ++i) {
      if (!((hit_mask >> i) & 1u)) continue;
      const int h = i >> 2, k = i & 3;
      const glm::vec3 light(direct[h][0][k], direct[h][1][k], direct[h][2][k]);
      color[rays[i].lane] += rays[i].weight * (ambient[i] + light);
    }

    // reflection and refraction rays for the next wave
    if (!has_secondary(o_.mode)) return;
    for (int i = 0; i < n; ++i) {
      if (!((hit_mask >> i) & 1u) || rays[i].depth >= o_.max_depth) continue;
      const Point& q = pt[i];
      const Pending& r = rays[i];
      glm::vec3 kr = q.specular;
      const float kt = q.m->transmittance;
      if (kt > 0.0f) {
        const float eta = q.inside ? q.m->ior : 1.0f / q.m->ior;
        const float f = fresnel_dielectric(glm::dot(q.view, q.ns), eta);
        kr += glm::vec3(kt * f);
        glm::vec3 dir;
        const glm::vec3 wt = r.weight * (kt * (1.0f - f));
        if (f < 1.0f && max3(wt) > 0.0f && max3(wt) >= o_.min_weight && refract_direction(-q.view, q.ns, eta, dir)) {
          push(next, q, -q.ng, dir, wt, r);
        }
      }
      const glm::vec3 wr = r.weight * kr;
      if (max3(wr) > 0.0f && max3(wr) >= o_.min_weight) {
        glm::vec3 dir = glm::reflect(-q.view, q.ns);
        if (glm::dot(dir, q.ng) <= 0.0f) dir = glm::reflect(-q.view, q.ng);
        push(next, q, q.ng, dir, wr, r);
      }
    }
  }

  /// One light over the lanes of a wave: which lanes it reaches (in front of both normals), the
  /// diffuse and highlight it adds there, and their shadow rays.
  void light_lanes(const WaveLanes& w, const PointLight& light, LightLanes& ll) const {
    ll.lit = 0;
    for (int h = 0; h < kQuarters; ++h) {
      for (int a = 0; a < 3; ++a) ll.contrib[h][a] = F4{};
      for (int k = 0; k < 4; ++k) ll.trans[4 * h + k] = 1.0f;  // the shadow rays may lower it
      F4 to[3];
      for (int a = 0; a < 3; ++a) to[a] = light.position[a] - w.p[h][a];
      F4 dist = (to[0] * to[0] + to[1] * to[1]) + to[2] * to[2];
      sqrt4(dist);
      F4 l[3];
      for (int a = 0; a < 3; ++a) l[a] = to[a] / dist;
      const F4 ndl = (w.ns[h][0] * l[0] + w.ns[h][1] * l[1]) + w.ns[h][2] * l[2];
      const F4 ngl = (w.ng[h][0] * l[0] + w.ng[h][1] * l[1]) + w.ng[h][2] * l[2];
      const F4 zero = {};
      M4 ok = w.hit[h] & (dist > zero) & (ndl > zero) & (ngl > zero);
      if (!bits4(ok)) continue;
      F4 c[3];
      for (int a = 0; a < 3; ++a) c[a] = w.diffuse[h][a] * ndl;
      // Phong highlight: rv = (2 (n.l) n - l) . view, above the material's cut-off
      const F4 two_ndl = 2.0f * ndl;
      F4 r[3];
      for (int a = 0; a < 3; ++a) r[a] = two_ndl * w.ns[h][a] - l[a];
      const F4 rv = (r[0] * w.view[h][0] + r[1] * w.view[h][1]) + r[2] * w.view[h][2];
      uint32_t shiny = bits4(ok & w.highlight[h] & (rv > w.min_cos[h]));
      while (shiny) {
        const int k = __builtin_ctz(shiny);
        shiny &= shiny - 1;
        const float f = std::pow(rv[k], w.shine[4 * h + k]);
        for (int a = 0; a < 3; ++a) c[a][k] += w.specular[h][a][k] * f;
      }
      for (int a = 0; a < 3; ++a) c[a] *= light.color[a];
      // a lane the light adds nothing to (a black diffuse colour or texel, no highlight) needs no
      // shadow ray either
      ok &= (c[0] != zero) | (c[1] != zero) | (c[2] != zero);
      const uint32_t lit = bits4(ok);
      if (!lit) continue;
      ll.lit |= lit << (4 * h);
      for (int a = 0; a < 3; ++a) ll.contrib[h][a] = (F4)((M4)c[a] & ok);
      if (!has_shadows(o_.mode)) continue;
      F4 back[3];
      for (int a = 0; a < 3; ++a) back[a] = light.position[a] - w.org[h][a];
      F4 tmax = (back[0] * back[0] + back[1] * back[1]) + back[2] * back[2];
      sqrt4(tmax);
      for (int a = 0; a < 3; ++a) {
        std::memcpy(&ll.shadow.org[a][4 * h], &w.org[h][a], sizeof(F4));
        std::memcpy(&ll.shadow.dir[a][4 * h], &l[a], sizeof(F4));
      }
      std::memset(&ll.shadow.tmin[4 * h], 0, sizeof(F4));
      std::memcpy(&ll.shadow.tmax[4 * h], &tmax, sizeof(F4));
    }
  }

  /// The light reaching the lanes of `lit` through `shadow` (0 blocked, 1 free, or what glass
  /// lets through) into trans[lane].
  void shadow_packet(const RayPacket& shadow, LaneMask lit, float* trans, ShadowHint& hint) {
    c_.shadow += static_cast<uint64_t>(__builtin_popcount(lit));
    if (pre_.one_traversal) {
      // one traversal that sees through the marked glass and multiplies its transmittance; the
      // rare unsure lanes are walked
      const LaneMask unsure = s_.geometry->transmittance(shadow, lit, trans, &hint);
      for (int i = 0; i < kPacketSize; ++i) {
        if ((unsure >> i) & 1u) trans[i] = 0.0f;
      }
      if (unsure) transmission(shadow, unsure, trans);
    } else {
      const LaneMask blocked = s_.geometry->occluded(shadow, lit, &hint);
      LaneMask walk = 0;
      for (int i = 0; i < kPacketSize; ++i) {
        if (!((blocked >> i) & 1u)) continue;
        trans[i] = 0.0f;
        if (pre_.transmissive && may_cross_transmissive(shadow.get(i))) walk |= 1u << i;
      }
      if (walk) transmission(shadow, walk, trans);
    }
  }

  /// Mip level: the one nearest to log2 of the texels a pixel's footprint covers at the hit (the
  /// footprint grows with the path length; reflections and refractions are treated as flat).
  int mip_level(const Pending& r, float t, const SurfaceInfo& info, const Texture& tex) const {
    if (spread_ <= 0.0f || info.uv_per_world <= 0.0f) return 0;
    const float footprint = spread_ * (r.dist + t * glm::length(r.ray.dir));
    return nearest_mip_level(footprint * info.uv_per_world * static_cast<float>(std::max(tex.width, tex.height)));
  }

  static void push(std::vector<Pending>& next, const Point& q, const glm::vec3& side, const glm::vec3& dir,
                   const glm::vec3& weight, const Pending& from) {
    Pending& s = next.emplace_back();
    s.ray.org = offset_ray_origin(q.p, side, q.magnitude);
    s.ray.dir = dir;
    s.ray.tmin = 0.0f;
    s.ray.tmax = kInfinity;
    s.weight = weight;
    s.lane = from.lane;
    s.depth = static_cast<uint8_t>(from.depth + 1);
    s.dist = q.dist;
  }

  /// Whether a shadow ray's segment meets a box holding transmissive triangles.
  bool may_cross_transmissive(const Ray& r) const {
    if (!boxes_) return true;
    const glm::vec3 inv = 1.0f / r.dir;
    for (const Aabb& b : *boxes_) {
      if (segment_meets_box(r.org, inv, r.tmin, r.tmax, b)) return true;
    }
    return false;
  }

  /// For the lanes in `walk`, blocked by the any-hit test but possibly only by transmissive
  /// surfaces: walks the surfaces on each ray (closest hits, traced as a packet); opaque ones stop
  /// the light, transmissive ones attenuate it. Writes the fraction that passes to trans[lane].
  void transmission(RayPacket rays, LaneMask walk, float* trans) {
    float t[kPacketSize];
    for (int i = 0; i < kPacketSize; ++i) t[i] = 1.0f;
    HitPacket hp;
    for (int step = 0; step < 16 && walk; ++step) {
      s_.geometry->intersect(rays, walk, hp);
      c_.transmission += static_cast<uint64_t>(__builtin_popcount(walk));
      for (int i = 0; i < kPacketSize; ++i) {
        if (!((walk >> i) & 1u)) continue;
        if (hp.prim[i] == kInvalidId) {  // reached the light
          trans[i] = t[i];
          walk &= ~(1u << i);
          continue;
        }
        const float kt = material(hp.get(i)).transmittance;
        if (kt <= 0.0f) {
          walk &= ~(1u << i);  // trans[i] stays 0
          continue;
        }
        t[i] *= kt;
        rays.tmin[i] = hp.t[i];  // on past this surface
      }
    }
  }

  const ShadingScene& s_;
  const WhittedOptions& o_;
  Counters& c_;
  const std::vector<Aabb>* boxes_;
  const Prepared& pre_;
  float spread_ = 0.0f;
  std::vector<ShadowHint> hints_;  ///< per light: the last static triangle that blocked a shadow packet
  std::vector<LightLanes> light_lanes_;
};

void check(const ShadingScene& scene) {
  if (!scene.geometry || !scene.surfaces) throw std::invalid_argument("ShadingScene needs geometry and surfaces");
}

}  // namespace

Image render_whitted(const ShadingScene& scene, const Camera& cam, const WhittedOptions& opt, WhittedStats* stats) {
  check(scene);
  const auto start = Clock::now();
  const uint64_t start_ticks = ticks();
  Image img(cam.width, cam.height);
  const Prepared pre(scene);
  tbb::enumerable_thread_specific<Counters> counters;
  for_each_tile(cam.width, cam.height, opt.threads, [&](const Tile& t) {
    const uint64_t t0 = ticks();
    Counters& c = counters.local();
    WaveTracer tracer(scene, opt, c, pre, 1.0f / cam.fy);
    // The whole tile is one generation: its primary rays as 4 x kPacketRows packets, then the
    // reflection and refraction rays of all its pixels pooled, so that secondary packets (and
    // their shadow packets) fill their lanes.
    static_assert(kTileSize * kTileSize <= 256, "a pixel of the tile is a uint8_t lane");
    std::vector<Pending> gen, next;
    gen.reserve(kTileSize * kTileSize);
    next.reserve(2 * kTileSize * kTileSize);
    glm::vec3 color[kTileSize * kTileSize] = {};
    RayPacket rays;
    for (int y = t.y0; y < t.y1; y += kPacketRows) {
      for (int x = t.x0; x < t.x1; x += 4) {
        const LaneMask mask = primary_packet(cam, x, y, rays);
        for (int i = 0; i < kPacketSize; ++i) {
          const int pixel = (y + i / 4 - t.y0) * kTileSize + (x + i % 4 - t.x0);
          if ((mask >> i) & 1u) gen.push_back(Pending{rays.get(i), glm::vec3(1.0f), static_cast<uint8_t>(pixel), 0});
        }
      }
    }
    tracer.run(gen, next, color);
    for (int y = t.y0; y < t.y1; ++y) {
      for (int x = t.x0; x < t.x1; ++x) img.at(x, y) = color[(y - t.y0) * kTileSize + (x - t.x0)];
    }
    c.total_ticks += ticks_since(t0);
  });
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
  Counters c;
  const Prepared pre(scene);
  WaveTracer tracer(scene, opt, c, pre);
  std::vector<Pending> gen{Pending{ray, glm::vec3(1.0f), 0, 0}}, next;
  glm::vec3 color[kPacketSize] = {};
  tracer.run(gen, next, color);
  return color[0];
}

}  // namespace artrace::core
