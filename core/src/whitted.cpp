#include "artrace/core/whitted.h"
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
  const glm::vec3* const row0 = texels.data() + static_cast<size_t>(wrap(iy, height)) * static_cast<size_t>(width);
  const glm::vec3* const row1 = texels.data() + static_cast<size_t>(wrap(iy + 1, height)) * static_cast<size_t>(width);
  return (row0[x0] * (1.0f - ax) + row0[x1] * ax) * (1.0f - ay) + (row1[x0] * (1.0f - ax) + row1[x1] * ax) * ay;
}

glm::vec3 Texture::sample(glm::vec2 uv, float lod) const {
  const int level = std::clamp(static_cast<int>(lod + 0.5f), 0, static_cast<int>(mips.size()));
  return sample_level(uv, level);
}

glm::vec3 Texture::sample_level(glm::vec2 uv, int level) const {
  level = std::clamp(level, 0, static_cast<int>(mips.size()));
  return level == 0 ? bilinear(uv) : mips[static_cast<size_t>(level - 1)].bilinear(uv);
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
  uint8_t key = 0;    ///< the kernels' direction key of a secondary ray (by_direction sorts by it)
  float dist = 0.0f;  ///< path length from the eye to the ray's origin (for texture footprints)
};

inline float max3(const glm::vec3& v) { return std::max(v.x, std::max(v.y, v.z)); }

// The hits' geometry and the light loop work on a wave's lanes in quarters (quarters.h).

/// Lane i of a quarter-grouped vector.
inline glm::vec3 lane3(const F4 (&v)[kQuarters][3], int i) {
  const int h = i >> 2, k = i & 3;
  return glm::vec3(v[h][0][k], v[h][1][k], v[h][2][k]);
}

inline void set_lane3(F4 (&v)[kQuarters][3], int i, const glm::vec3& x) {
  const int h = i >> 2, k = i & 3;
  for (int a = 0; a < 3; ++a) v[h][a][k] = x[a];
}

/// The shaded hits of a wave as structure of arrays (quarters of 4 lanes, one SSE register each).
/// The geometry is worked out side by side with the operations, in the order, of the scalar glm
/// code it replaced (no FMA contraction in this project), so every lane gets the same bits.
struct WaveLanes {
  F4 p[kQuarters][3], ng[kQuarters][3], ns[kQuarters][3], view[kQuarters][3], diffuse[kQuarters][3],
      specular[kQuarters][3], org[kQuarters][3];
  F4 magnitude[kQuarters];                  ///< largest coordinate of the hit triangle
  F4 step[kQuarters];                       ///< offset_ray_origin's step at the hit (origins())
  F4 dist[kQuarters];                       ///< path length from the eye
  /// Highlight cut-off cosine; 2 where there is no highlight (no cosine exceeds it).
  F4 min_cos[kQuarters];
  M4 hit[kQuarters];  ///< lanes with a hit
  M4 inside[kQuarters];                     ///< the ray met the back side (it leaves a solid)
  float shine[kPacketSize];
  const Material* m[kPacketSize];

  /// Hit point, normals (geometric and shading, both facing the viewer), view direction and path
  /// length of the lanes of `hit_mask`; zero in the others.
  void geometry(const Triangle* tris, const HitPacket& hp, const Pending* rays, const SurfaceInfo* infos,
                LaneMask hit_mask) {
    for (int h = 0; h < kQuarters; ++h) {
      F4 v0[3], v1[3], v2[3], n[3], d[3];
      // lanes without a hit are masked off below
      const F4 u = load4<F4>(hp.u, h), v = load4<F4>(hp.v, h), t = load4<F4>(hp.t, h);
      F4 from = {};
      M4 lanes = {};
#if defined(__SSE__)
      // each lane's three coordinates as a row of four floats (the fourth is the next field's),
      // transposed into three columns; lanes without a hit are rows of zeros
      __m128 rows[5][4];
      for (int k = 0; k < 4; ++k) {
        const int i = 4 * h + k;
        if (!((hit_mask >> i) & 1u)) {
          for (auto& r : rows) r[k] = _mm_setzero_ps();
          continue;
        }
        lanes[k] = -1;
        from[k] = rays[i].dist;
        const Triangle& tri = tris[i];
        rows[0][k] = _mm_loadu_ps(&tri.v0.x);
        rows[1][k] = _mm_loadu_ps(&tri.v1.x);
        const __m128 last = _mm_loadu_ps(&tri.v1.z);  // v1.z, v2: the triangle's last four floats
        rows[2][k] = _mm_shuffle_ps(last, last, _MM_SHUFFLE(3, 3, 2, 1));
        rows[3][k] = _mm_loadu_ps(&infos[i].normal.x);
        rows[4][k] = _mm_loadu_ps(&rays[i].ray.dir.x);
      }
      F4(*const cols[5])[3] = {&v0, &v1, &v2, &n, &d};
      for (int r = 0; r < 5; ++r) {
        _MM_TRANSPOSE4_PS(rows[r][0], rows[r][1], rows[r][2], rows[r][3]);
        for (int a = 0; a < 3; ++a) (*cols[r])[a] = (F4)rows[r][a];
      }
#else
      for (int a = 0; a < 3; ++a) v0[a] = v1[a] = v2[a] = n[a] = d[a] = F4{};
      for (int k = 0; k < 4; ++k) {
        const int i = 4 * h + k;
        if (!((hit_mask >> i) & 1u)) continue;
        lanes[k] = -1;
        from[k] = rays[i].dist;
        const Triangle& tri = tris[i];
        for (int a = 0; a < 3; ++a) {
          v0[a][k] = tri.v0[a];
          v1[a][k] = tri.v1[a];
          v2[a][k] = tri.v2[a];
          n[a][k] = infos[i].normal[a];
          d[a][k] = rays[i].ray.dir[a];
        }
      }
#endif
      hit[h] = lanes;
      const F4 w = (1.0f - u) - v;
      F4 e1[3], e2[3];
      for (int a = 0; a < 3; ++a) {
        p[h][a] = (F4)((M4)((v0[a] * w + v1[a] * u) + v2[a] * v) & lanes);
        e1[a] = v1[a] - v0[a];
        e2[a] = v2[a] - v0[a];
      }
      // glm::normalize(glm::cross(e1, e2)): v * (1 / sqrt(dot(v, v)))
      F4 g[3] = {e1[1] * e2[2] - e2[1] * e1[2], e1[2] * e2[0] - e2[2] * e1[0], e1[0] * e2[1] - e2[0] * e1[1]};
      F4 len = dot4(g, g);
      sqrt4(len);
      F4 inv = 1.0f / len;
      for (int a = 0; a < 3; ++a) g[a] = g[a] * inv;
      // std::max({|x|, |y|, |z|}) of each vertex, then of the three
      auto max_abs = [](const F4* c) { return max4(max4(abs4(c[0]), abs4(c[1])), abs4(c[2])); };
      magnitude[h] = max4(max4(max_abs(v0), max_abs(v1)), max_abs(v2));
      // the shading normal, normalised, where it has a length; else the geometric one
      const F4 zero = {};
      F4 nn = dot4(n, n);
      const M4 has_n = nn > zero;
      sqrt4(nn);
      inv = 1.0f / nn;
      F4 s[3];
      for (int a = 0; a < 3; ++a) s[a] = select4(has_n, n[a] * inv, g[a]);
      // camera rays are not unit length
      F4 dir_len = dot4(d, d);
      sqrt4(dir_len);
      F4 vw[3];
      for (int a = 0; a < 3; ++a) vw[a] = -d[a] / dir_len;
      dist[h] = (F4)((M4)(from + t * dir_len) & lanes);
      // the back side: the ray leaves a solid
      const M4 back = dot4(g, vw) < zero;
      for (int a = 0; a < 3; ++a) {
        g[a] = select4(back, -g[a], g[a]);
        s[a] = select4(back, -s[a], s[a]);
      }
      inside[h] = back & lanes;
      // an interpolated normal facing away
      const M4 away = dot4(s, vw) <= zero;
      for (int a = 0; a < 3; ++a) {
        ng[h][a] = (F4)((M4)g[a] & lanes);
        ns[h][a] = (F4)((M4)select4(away, g[a], s[a]) & lanes);
        view[h][a] = (F4)((M4)vw[a] & lanes);
      }
      magnitude[h] = (F4)((M4)magnitude[h] & lanes);
    }
  }

  /// The mirror directions: glm::reflect(-view, ns), or reflect(-view, ng) where the first would
  /// not leave the surface (its dot with ng <= 0), four lanes at a time with glm's operations in
  /// glm's order (reflect(I, N) = I - N dot(N, I) 2, dot = (x x' + y y') + z z').
  void mirror(F4 (&out)[kQuarters][3]) const {
    for (int h = 0; h < kQuarters; ++h) {
      const F4 in[3] = {-view[h][0], -view[h][1], -view[h][2]};
      const F4 ds = dot4(ns[h], in), dg = dot4(ng[h], in);
      F4 r[3];
      for (int a = 0; a < 3; ++a) r[a] = in[a] - (ns[h][a] * ds) * 2.0f;
      const M4 under = dot4(r, ng[h]) <= F4{};
      for (int a = 0; a < 3; ++a) out[h][a] = select4(under, in[a] - (ng[h][a] * dg) * 2.0f, r[a]);
    }
  }

  /// The origins of shadow and reflection rays, offset_ray_origin(p, ng, magnitude), and its
  /// step (refraction rays take it to the other side), four lanes at a time with the same
  /// operations in the same order (calling it lane by lane: 0.9-1.3% more render instructions).
  void origins() {
    for (int h = 0; h < kQuarters; ++h) {
      const F4 m = max4(max4(abs4(p[h][0]), abs4(p[h][1])), max4(abs4(p[h][2]), magnitude[h]));
      step[h] = max4(m * kOffsetScale, F4{} + kOffsetFloor);
      for (int a = 0; a < 3; ++a) org[h][a] = p[h][a] + step[h] * ng[h][a];
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
    int start[kDirectionKeys + 1] = {};
    for (const Pending& r : gen) ++start[r.key + 1];
    for (int k = 0; k < kDirectionKeys; ++k) start[k + 1] += start[k];
    scratch.resize(gen.size());
    for (const Pending& r : gen) scratch[static_cast<size_t>(start[r.key]++)] = r;
    gen.swap(scratch);
  }

  const Material& material(uint32_t id) const {
    if (id >= s_.materials.size()) throw std::out_of_range("material index out of range");
    return s_.materials[id];
  }
  const Material& material(const Hit& h) const { return material(s_.surfaces->material(h)); }

  void wave(const Pending* rays, int n, glm::vec3* color, std::vector<Pending>& next) {
    RayPacket rp;
    HitPacket hp{};  // every lane defined: the hit geometry reads the lanes four at a time
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
    // The hits' geometry side by side, then each hit's material and texture.
    WaveLanes w;
    w.geometry(tris, hp, rays, infos, hit_mask);
    for (int i = 0; i < kPacketSize; ++i) {
      const int h = i >> 2, k = i & 3;
      if (!((hit_mask >> i) & 1u)) {
        for (int a = 0; a < 3; ++a) w.diffuse[h][a][k] = w.specular[h][a][k] = 0.0f;
        w.min_cos[h][k] = 2.0f;
        w.shine[i] = 0.0f;
        w.m[i] = nullptr;
        continue;
      }
      const Material* m = &material(material_ids[i]);
      const SurfaceInfo& info = infos[i];
      const int32_t texture = info.texture >= 0 ? info.texture : m->texture;
      const bool textured = texture >= 0 && texture < static_cast<int32_t>(s_.textures.size());
      const glm::vec3 tex = textured ? s_.textures[texture].sample_level(
                                           info.uv, mip_level(w.dist[h][k], info, s_.textures[texture]))
                                     : glm::vec3(1.0f);
      set_lane3(w.diffuse, i, m->diffuse * tex);
      set_lane3(w.specular, i, m->specular);
      ambient[i] = s_.ambient * m->ambient * tex;
      const float mc = pre_.highlight_cos[static_cast<size_t>(material_ids[i])];
      w.min_cos[h][k] = mc;
      w.shine[i] = m->shine;
      w.m[i] = m;
    }

    // Direct light. First every light's lanes, contributions and shadow rays, the lanes side by
    // side (one origin per hit), then all the shadow packets in one go, then the sums.
    if (has_shadows(o_.mode) || has_secondary(o_.mode)) w.origins();
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
        const F4 trans = load4<F4>(ll.trans, h);
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
    F4 mirror[kQuarters][3];
    w.mirror(mirror);
    for (int i = 0; i < n; ++i) {
      if (!((hit_mask >> i) & 1u) || rays[i].depth >= o_.max_depth) continue;
      const Material& m = *w.m[i];
      const Pending& r = rays[i];
      const int h = i >> 2, k = i & 3;
      glm::vec3 kr = m.specular;
      const float kt = m.transmittance;
      if (kt > 0.0f) {
        const glm::vec3 view = lane3(w.view, i), ns = lane3(w.ns, i);
        const bool inside = w.inside[h][k] != 0;
        const float eta = inside ? m.ior : 1.0f / m.ior;
        const float f = fresnel_dielectric(glm::dot(view, ns), eta);
        kr += glm::vec3(kt * f);
        glm::vec3 dir;
        const glm::vec3 wt = r.weight * (kt * (1.0f - f));
        if (f < 1.0f && max3(wt) > 0.0f && max3(wt) >= o_.min_weight && refract_direction(-view, ns, eta, dir)) {
          // offset_ray_origin(p, -ng, magnitude): the shadow origins' step, to the other side
          push(next, lane3(w.p, i) + w.step[h][k] * -lane3(w.ng, i), dir, wt, w.dist[h][k], r);
        }
      }
      const glm::vec3 wr = r.weight * kr;
      if (max3(wr) > 0.0f && max3(wr) >= o_.min_weight) {
        push(next, lane3(w.org, i), lane3(mirror, i), wr, w.dist[h][k], r);
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
      // rv is at most 1 (and rounding): never above the 2 of a lane without a highlight
      uint32_t shiny = bits4(ok & (rv > w.min_cos[h]));
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
      if (unsure) {
        for (int i = 0; i < kPacketSize; ++i) {
          if ((unsure >> i) & 1u) trans[i] = 0.0f;
        }
        transmission(shadow, unsure, trans);
      }
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

  /// Mip level: the one nearest to log2 of the texels a pixel's footprint covers at a hit `dist`
  /// along its path from the eye (the footprint grows with the path length; reflections and
  /// refractions are treated as flat).
  int mip_level(float dist, const SurfaceInfo& info, const Texture& tex) const {
    if (spread_ <= 0.0f || info.uv_per_world <= 0.0f) return 0;
    const float footprint = spread_ * dist;
    return nearest_mip_level(footprint * info.uv_per_world * static_cast<float>(std::max(tex.width, tex.height)));
  }

  /// Queues a secondary ray from `org` (already off the surface), `dist` along the path from the eye.
  static void push(std::vector<Pending>& next, const glm::vec3& org, const glm::vec3& dir, const glm::vec3& weight,
                   float dist, const Pending& from) {
    Pending& s = next.emplace_back();
    s.ray.org = org;
    s.ray.dir = dir;
    s.key = static_cast<uint8_t>(direction_key(dir.x, dir.y, dir.z));
    s.ray.tmin = 0.0f;
    s.ray.tmax = kInfinity;
    s.weight = weight;
    s.lane = from.lane;
    s.depth = static_cast<uint8_t>(from.depth + 1);
    s.dist = dist;
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
