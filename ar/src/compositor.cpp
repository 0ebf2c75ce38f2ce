#include "artrace/ar/compositor.h"

#include "artrace/core/renderer.h"
#include "artrace/core/whitted.h"
#include "artrace/core/srgb.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>

namespace artrace::ar {
namespace {

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

float max_coord(const core::Triangle& t) {
  auto m = [](const glm::vec3& v) { return std::max({std::fabs(v.x), std::fabs(v.y), std::fabs(v.z)}); };
  return std::max({m(t.v0), m(t.v1), m(t.v2)});
}

glm::vec3 pixel_linear(const ColorImage& img, int x, int y) {
  const uint8_t* px = img.at(x, y);
  return {core::srgb8_to_linear(px[0]), core::srgb8_to_linear(px[1]), core::srgb8_to_linear(px[2])};
}

/// The light passing along `r` to its end (1 free, 0 blocked, between through glass): the
/// scene's transmittance query where it has transmissive triangles. A ray crossing more glass
/// than the kernels keep count of is taken as blocked by whatever it meets.
float light_passing(const core::TwoLevelScene& scene, const core::Ray& r) {
  if (!scene.has_transmittance()) return scene.occluded(r) ? 0.0f : 1.0f;
  core::RayPacket packet{};  // the other lanes are masked off, but not left indeterminate
  packet.set(0, r);
  float trans[core::kPacketSize] = {};
  if (scene.transmittance(packet, 1u, trans) & 1u) return scene.occluded(r) ? 0.0f : 1.0f;
  return trans[0];
}

constexpr float kPi = 3.14159265358979f;
/// Surfaces a ray walks past (cut-outs, blended layers) before it gives up.
constexpr int kMaxLayers = 16;
/// Below this roughness a metallic-roughness surface traces a mirror reflection, fading in to a
/// perfect mirror at 0; above it the lights' GGX lobes and the ambient term stand for reflections.
constexpr float kMirrorRoughness = 0.2f;

/// A colour seen along a ray, premultiplied by how much of the ray the virtual surfaces cover.
struct Sample {
  glm::vec3 colour{0.0f};
  float coverage = 0.0f;
};

/// The parts of a tile's shading left for later, to be traced in packets: shadow rays (a light's
/// contribution times the light passing) and secondary rays (a weight times what they see). Each
/// names the pixel it adds to. Contributions add up linearly, so the result is what the shader
/// tracing one ray at a time gives.
struct Deferred {
  struct Light {
    core::Ray ray;
    glm::vec3 add;
    uint32_t pixel;
  };
  struct Secondary {
    glm::vec3 org, dir, weight;
    float path;
    int depth;
    uint32_t pixel;
  };
  std::vector<std::vector<Light>> lights;  ///< one list a light: rays towards one light are coherent
  std::vector<Secondary> secondary[8];     ///< by direction octant
  uint32_t pixel = 0;                       ///< the pixel being shaded
  void clear(size_t n) {
    lights.resize(n);
    for (auto& l : lights) l.clear();
    for (auto& v : secondary) v.clear();
  }
};

struct Shader {
  const SensorFrame& frame;
  const core::TwoLevelScene& scene;
  const MaterialLookup& material;
  const CompositeOptions& opt;
  const std::vector<VirtualLight>& lights;
  const RealScene* proxy;  ///< the real scene for secondary rays; null: none
  core::Camera cam;
  float pixel_spread;  ///< a pixel's angle (radians): the camera rays' cone spread

  VirtualMaterial look(const core::Ray& r, const core::Hit& h, float path, bool shadow) const {
    SurfaceQuery q;
    static_cast<core::Hit&>(q) = h;
    const float len = glm::length(r.dir);
    q.dir = r.dir / len;
    q.cone_width = (path + h.t * len) * pixel_spread;
    q.shadow_ray = shadow;
    return material(q);
  }

  /// The light passing along a shadow ray. With cut-outs and blended surfaces in the scene it walks
  /// the surfaces: cut-out points let everything through, blended ones 1 - alpha, glass its
  /// transmittance, anything else nothing.
  float light_passing(const core::Ray& r, bool from_virtual = false) const {
    // the fused room shadows the virtual objects (real points' own shadows are in the recording)
    if (from_virtual && opt.room && !opt.room->empty() && opt.room->scene().occluded(r)) return 0.0f;
    if (!opt.alpha_tested) return artrace::ar::light_passing(scene, r);
    float pass = 1.0f;
    core::Ray s = r;
    for (int k = 0; k < kMaxLayers; ++k) {
      const core::Hit h = scene.intersect(s);
      if (!h.valid()) return pass;
      const VirtualMaterial m = look(s, h, 0.0f, true);
      if (!m.cutout) {
        if (m.kind == VirtualMaterial::kGlass) pass *= shadow_transmittance(m);
        else if (m.alpha < 1.0f) pass *= 1.0f - std::max(m.alpha, 0.0f);
        else return 0.0f;
        if (pass <= 0.0f) return 0.0f;
      }
      s.tmin = h.t;
    }
    return 0.0f;
  }

  /// light_passing for up to 16 rays at once, with the packet kernels: pass[i] for the lanes in
  /// `mask`. The same answers as one ray at a time.
  void light_passing(const core::RayPacket& rays, core::LaneMask mask, bool from_virtual, float* pass) const {
    if (opt.alpha_tested) {
      for (int i = 0; i < core::kPacketSize; ++i) {
        if ((mask >> i) & 1u) pass[i] = light_passing(rays.get(i), from_virtual);
      }
      return;
    }
    core::LaneMask open = mask;
    if (from_virtual && opt.room && !opt.room->empty()) {
      const core::LaneMask blocked = opt.room->scene().occluded(rays, mask);
      for (int i = 0; i < core::kPacketSize; ++i) {
        if ((blocked >> i) & 1u) pass[i] = 0.0f;
      }
      open &= ~blocked;
    }
    if (!open) return;
    if (!scene.has_transmittance()) {
      const core::LaneMask blocked = scene.occluded(rays, open);
      for (int i = 0; i < core::kPacketSize; ++i) {
        if ((open >> i) & 1u) pass[i] = ((blocked >> i) & 1u) ? 0.0f : 1.0f;
      }
      return;
    }
    float trans[core::kPacketSize] = {};
    const core::LaneMask unsure = scene.transmittance(rays, open, trans);
    const core::LaneMask blocked = unsure ? scene.occluded(rays, unsure) : 0u;
    for (int i = 0; i < core::kPacketSize; ++i) {
      if (!((open >> i) & 1u)) continue;
      pass[i] = ((unsure >> i) & 1u) ? (((blocked >> i) & 1u) ? 0.0f : 1.0f) : trans[i];
    }
  }

  /// The recorded colour seen along a ray that left the virtual objects where the depth mesh has
  /// nothing: the point 2 m (or 1 m, 0.5 m) on is looked up in the colour frame.
  glm::vec3 background(const glm::vec3& org, const glm::vec3& dir) const {
    const glm::vec3 d = glm::normalize(dir);
    for (const float dist : {2.0f, 1.0f, 0.5f}) {
      const glm::vec3 p = org + dist * d;
      const glm::vec3 c = glm::transpose(cam.rotation) * (p - cam.position);
      if (c.z <= 0.05f) continue;
      const int x = static_cast<int>(cam.fx * c.x / c.z + cam.cx), y = static_cast<int>(cam.fy * c.y / c.z + cam.cy);
      if (x < 0 || y < 0 || x >= frame.color.width || y >= frame.color.height) continue;
      return pixel_linear(frame.color, x, y);
    }
    return glm::vec3(0.5f);
  }

  /// What a secondary ray sees, given its closest virtual hit `h` and real-scene hit: the virtual
  /// surfaces in front of the real one, blended front to back, then the recorded colour.
  /// With `d`, the rays of the next generation are left to it, as in radiance().
  glm::vec3 seen(const core::Ray& r, const core::Hit& h, bool real_hit, float t_real, const glm::vec3& real, int depth, float path,
                 Deferred* d = nullptr, const glm::vec3& weight = glm::vec3(1.0f)) const {
    if (h.valid() && (!real_hit || h.t <= t_real)) {
      const Sample s = radiance(r, h, depth, path, d, weight);
      if (s.coverage >= 1.0f) return s.colour;
      return s.colour + (1.0f - s.coverage) * (real_hit ? real : background(r.org, r.dir));
    }
    return real_hit ? real : background(r.org, r.dir);
  }

  /// What a secondary ray (reflection, refraction) sees, traced now (one ray).
  glm::vec3 trace(const glm::vec3& o, const glm::vec3& dir, int depth, float path) const {
    const core::Ray r{o, dir};
    float t_real = core::kInfinity;
    glm::vec3 real;
    const bool real_hit = proxy && proxy->intersect(r, t_real, real);
    return seen(r, scene.intersect(r), real_hit, t_real, real, depth, path);
  }

  /// Colour and coverage along `r`, whose closest hit is `h`: cut-out points are passed, blended
  /// surfaces composited front to back (Porter & Duff's "over"). With `d`, shadow and secondary rays
  /// of the first generation are left to it, weighted by `weight`.
  Sample radiance(core::Ray r, core::Hit h, int depth, float path, Deferred* d = nullptr, const glm::vec3& weight = glm::vec3(1.0f)) const {
    Sample out;
    float through = 1.0f;
    for (int k = 0; k < kMaxLayers && h.valid(); ++k) {
      const VirtualMaterial m = look(r, h, path, false);
      if (!m.cutout) {
        const float a = std::clamp(m.alpha, 0.0f, 1.0f);
        if (a > 0.0f) out.colour += through * a * shade(r, h, m, depth, path, d, weight * (through * a));
        through *= 1.0f - a;
        if (through <= 1e-3f) break;
      }
      if (!opt.alpha_tested) break;
      r.tmin = h.t;
      h = scene.intersect(r);
    }
    out.coverage = 1.0f - (through <= 1e-3f ? 0.0f : through);
    return out;
  }

  /// The colour of a virtual surface at a hit. Without `d` everything is traced here, one ray at a
  /// time; with it, the lights' contributions (with their shadow rays) and the secondary rays are
  /// handed to `d` (times `weight`) and left out of the returned colour.
  glm::vec3 shade(const core::Ray& ray, const core::Hit& hit, const VirtualMaterial& m, int depth, float path, Deferred* d = nullptr,
                  const glm::vec3& weight = glm::vec3(1.0f)) const {
    const core::Triangle tri = scene.world_triangle(hit);
    glm::vec3 ng = glm::normalize(tri.geometric_normal());
    const bool front = glm::dot(ng, ray.dir) < 0.0f;
    if (!front) ng = -ng;
    glm::vec3 n = ng;
    if (m.normal != glm::vec3(0.0f)) {
      n = glm::normalize(m.normal);
      if (glm::dot(n, ng) < 0.0f) n = -n;  // the side the ray comes from, as the geometric normal
    }
    const glm::vec3 p = tri.v0 * (1.0f - hit.u - hit.v) + tri.v1 * hit.u + tri.v2 * hit.v;
    const float magnitude = max_coord(tri);
    const glm::vec3 dn = glm::normalize(ray.dir);
    const float here = path + hit.t * glm::length(ray.dir);
    glm::vec3 c(0.0f);
    // a light's contribution `add` where its light passes: now, or left to `d`
    auto lit = [&](size_t li, const glm::vec3& add) {
      const VirtualLight& l = lights[li];
      if (!opt.shadows) {
        c += add;
        return;
      }
      const glm::vec3 o = core::offset_ray_origin(p, ng, magnitude);
      const core::Ray r{o, l.position - o, 0.0f, 1.0f};
      if (d) {
        d->lights[li].push_back({r, add * weight, d->pixel});
      } else {
        c += add * light_passing(r, true);
      }
    };
    // a secondary ray's colour times `w`: now, or left to `d`
    auto secondary = [&](const glm::vec3& o, const glm::vec3& dir, const glm::vec3& w) {
      if (d) {
        const int oct = (dir.x < 0.0f ? 1 : 0) | (dir.y < 0.0f ? 2 : 0) | (dir.z < 0.0f ? 4 : 0);
        d->secondary[oct].push_back({o, dir, w * weight, here, depth + 1, d->pixel});
      } else {
        c += w * trace(o, dir, depth + 1, here);
      }
    };
    // the cosine with the light, 0 where it is behind the surface
    auto facing = [&](const VirtualLight& l, glm::vec3& to) {
      to = glm::normalize(l.position - p);
      const float cosine = glm::dot(n, to);
      return (cosine <= 0.0f || glm::dot(ng, to) <= 0.0f) ? 0.0f : cosine;
    };
    if ((m.kind == VirtualMaterial::kDiffuse && !m.pbr) || depth >= 2) {
      c += opt.ambient * m.occlusion * m.color + m.emissive;
      for (size_t li = 0; li < lights.size(); ++li) {
        glm::vec3 to;
        const float cosine = facing(lights[li], to);
        if (cosine > 0.0f) lit(li, m.color * lights[li].color * cosine);
      }
      return c;
    }
    if (m.kind == VirtualMaterial::kDiffuse) {
      // metallic-roughness
      const glm::vec3 v = -dn;
      const float nv = std::max(glm::dot(n, v), 1e-4f);
      const glm::vec3 f0 = glm::mix(glm::vec3(0.04f), m.color, m.metallic);
      const glm::vec3 diffuse = m.color * (1.0f - m.metallic);
      const float a = std::max(m.roughness, 0.03f) * std::max(m.roughness, 0.03f), a2 = a * a, k = 0.5f * a;
      auto fresnel = [&](float cosine) { return f0 + (glm::vec3(1.0f) - f0) * std::pow(1.0f - std::clamp(cosine, 0.0f, 1.0f), 5.0f); };
      const float mirror = std::clamp(1.0f - m.roughness / kMirrorRoughness, 0.0f, 1.0f);
      c += opt.ambient * m.occlusion * (diffuse + (1.0f - mirror) * f0) + m.emissive;
      if (mirror > 0.0f) secondary(core::offset_ray_origin(p, ng, magnitude), glm::reflect(dn, n), mirror * fresnel(nv));
      for (size_t li = 0; li < lights.size(); ++li) {
        glm::vec3 to;
        const float nl = facing(lights[li], to);
        if (nl <= 0.0f) continue;
        const glm::vec3 h = glm::normalize(to + v);
        const float nh = std::max(glm::dot(n, h), 0.0f), vh = std::max(glm::dot(v, h), 0.0f);
        const float den = nh * nh * (a2 - 1.0f) + 1.0f;
        const float D = a2 / (kPi * den * den);
        const float G = nl / (nl * (1.0f - k) + k) * nv / (nv * (1.0f - k) + k);
        const glm::vec3 F = fresnel(vh);
        // radiance for a light of the Lambert convention above (diffuse: base * light * cos)
        const glm::vec3 specular = kPi * D * G * F / (4.0f * nl * nv);
        lit(li, lights[li].color * nl * (diffuse * (glm::vec3(1.0f) - F) + specular));
      }
      return c;
    }
    c += m.emissive;
    const glm::vec3 reflect_from = core::offset_ray_origin(p, ng, magnitude);
    if (m.kind == VirtualMaterial::kMirror) {
      secondary(reflect_from, glm::reflect(dn, n), m.color);
      return c;
    }
    // glass: Fresnel between reflection and refraction; total internal reflection reflects all
    const float eta = front ? 1.0f / m.ior : m.ior;
    const float fresnel = core::fresnel_dielectric(-glm::dot(dn, n), eta);
    glm::vec3 refr_dir;
    if (!core::refract_direction(dn, n, eta, refr_dir)) {
      secondary(reflect_from, glm::reflect(dn, n), glm::vec3(1.0f));
      return c;
    }
    secondary(reflect_from, glm::reflect(dn, n), glm::vec3(fresnel));
    secondary(core::offset_ray_origin(p, -ng, magnitude), refr_dir, (1.0f - fresnel) * m.color);
    return c;
  }

  /// Traces what `d` holds, 16 rays a packet, and adds it to the pixels of `colour`: the shadow
  /// rays, then the secondary rays, whose hits leave the next generation's rays to another list
  /// (with opt.packet_generations), traced in its turn, until a generation leaves none. `d` is
  /// used up.
  void resolve(Deferred& d, std::vector<glm::vec3>& colour) const {
    thread_local Deferred next_scratch;
    Deferred& next = next_scratch;  // a worker's own (resolve runs inside one tile at a time)
    Deferred* now = &d;
    Deferred* later = &next;
    for (;;) {
      later->clear(lights.size());
      resolve_generation(*now, colour, opt.packet_generations ? later : nullptr);
      bool more = false;
      for (const auto& l : later->lights) more = more || !l.empty();
      for (const auto& v : later->secondary) more = more || !v.empty();
      if (!more) return;
      std::swap(now, later);
    }
  }

  /// One generation of resolve(); the next one's rays go to `next` (null: traced now, one at a time).
  void resolve_generation(Deferred& d, std::vector<glm::vec3>& colour, Deferred* next) const {
    core::RayPacket rays{};
    float pass[core::kPacketSize];
    for (auto& list : d.lights) {
      for (size_t at = 0; at < list.size(); at += core::kPacketSize) {
        const int n = static_cast<int>(std::min<size_t>(core::kPacketSize, list.size() - at));
        for (int i = 0; i < n; ++i) rays.set(i, list[at + i].ray);
        light_passing(rays, (1u << n) - 1u, true, pass);
        for (int i = 0; i < n; ++i) colour[list[at + i].pixel] += list[at + i].add * pass[i];
      }
    }
    core::HitPacket hits{};
    float t_real[core::kPacketSize];
    glm::vec3 real[core::kPacketSize];
    for (auto& list : d.secondary) {
      for (size_t at = 0; at < list.size(); at += core::kPacketSize) {
        const int n = static_cast<int>(std::min<size_t>(core::kPacketSize, list.size() - at));
        const core::LaneMask mask = (1u << n) - 1u;
        for (int i = 0; i < n; ++i) rays.set(i, core::Ray{list[at + i].org, list[at + i].dir});
        for (int i = 0; i < core::kPacketSize; ++i) hits.prim[i] = core::kInvalidId;
        scene.intersect(rays, mask, hits, core::Coherence::kIncoherent);
        const core::LaneMask real_hits = proxy ? proxy->intersect(rays, mask, t_real, real) : 0u;
        for (int i = 0; i < n; ++i) {
          const Deferred::Secondary& s = list[at + i];
          if (next) next->pixel = s.pixel;
          colour[s.pixel] += s.weight * seen(rays.get(i), hits.get(i), (real_hits >> i) & 1u, t_real[i], real[i], s.depth, s.path, next, s.weight);
        }
      }
    }
  }
};

struct Rect {
  int x0, y0, x1, y1;  ///< [x0, x1) x [y0, y1)
  bool empty() const { return x0 >= x1 || y0 >= y1; }
};

/// The rows [r.y0, r.y1) x columns [r.x0, r.x1) of a row-major image with `channels` values a pixel.
template <class T>
std::vector<T> crop(const std::vector<T>& image, int width, const Rect& r, int channels = 1) {
  const int cw = r.x1 - r.x0;
  std::vector<T> out(static_cast<size_t>(cw) * (r.y1 - r.y0) * channels);
  for (int y = r.y0; y < r.y1; ++y) {
    std::copy_n(&image[(static_cast<size_t>(y) * width + r.x0) * channels], static_cast<size_t>(cw) * channels,
                &out[static_cast<size_t>(y - r.y0) * cw * channels]);
  }
  return out;
}

/// A projected coordinate as a pixel bound in [0, n], clamped while still a float: a corner of a
/// large object near the camera plane, or a shadow volume's vanishing point, can project billions
/// of pixels off screen (or to infinity), and converting such a float to int is undefined (the
/// sanitizer build got INT_MIN; in the release build the rectangles came out empty: no objects
/// traced, no shadows on the real surfaces).
int to_pixel(float x, int n) {
  if (!(x > 0.0f)) return 0;
  return x < static_cast<float>(n) ? static_cast<int>(x) : n;
}

/// Nearer to the camera's plane than this (metres along its axis) nothing is traced or shadowed.
constexpr double kNear = 1e-3;

/// Screen points whose convex hull holds what of a box lies at least kNear in front of the camera
/// and, given a light, of the box's shadow volume from it (the box pushed away from the light to
/// infinity): the corners in front, where segments between corners and rays from corners along the
/// directions away from the light cross z = kNear, and the vanishing points of those directions.
/// None when nothing is in front. False when the part in front has no bounds on screen (a direction
/// away from the light parallel to the image plane, or some pointing ahead and others back), or
/// the light sits on a corner: the volume can then reach anywhere.
bool screen_points(const core::Camera& cam, const core::Aabb& b, const VirtualLight* l, std::vector<glm::dvec2>& out) {
  out.clear();
  const glm::mat3 to_cam = glm::transpose(cam.rotation);
  // corners in front and vanishing points projected in float, crossings (far off the image, as a
  // rule) in double
  auto project = [&](const glm::vec3& c) { out.emplace_back(cam.fx * c.x / c.z + cam.cx, cam.fy * c.y / c.z + cam.cy); };
  auto project_d = [&](const glm::dvec3& c) {
    out.emplace_back(static_cast<double>(cam.fx) * c.x / c.z + cam.cx, static_cast<double>(cam.fy) * c.y / c.z + cam.cy);
  };
  glm::vec3 corner[8], away[8];
  int ahead = 0;
  for (int c = 0; c < 8; ++c) {
    const glm::vec3 p((c & 1) ? b.hi.x : b.lo.x, (c & 2) ? b.hi.y : b.lo.y, (c & 4) ? b.hi.z : b.lo.z);
    corner[c] = to_cam * (p - cam.position);
    if (!l) continue;
    const glm::vec3 a = p - l->position;
    if (glm::dot(a, a) == 0.0f) return false;
    away[c] = to_cam * a;
    if (away[c].z == 0.0f) return false;
    ahead += away[c].z > 0.0f;
  }
  if (l && ahead != 0 && ahead != 8) return false;
  // where p + s d crosses z = kNear: s in [0, 1] for a segment (d = q - p), s >= 0 for a ray
  auto crossing = [&](const glm::vec3& pf, const glm::vec3& df, bool ray) {
    const glm::dvec3 p(pf), d(df);
    if (d.z == 0.0) return;
    const double s = (kNear - p.z) / d.z;
    if (s >= 0.0 && (ray || s <= 1.0)) project_d(p + s * d);
  };
  for (int c = 0; c < 8; ++c) {
    if (corner[c].z >= kNear) project(corner[c]);
    for (int e = c + 1; e < 8; ++e) crossing(corner[c], corner[e] - corner[c], false);
    if (!l) continue;
    for (int d = 0; d < 8; ++d) crossing(corner[c], away[d], true);
    if (ahead == 8) project(away[c]);  // the vanishing point
  }
  return true;
}

/// The extent of screen points.
struct Extent {
  double minx = INFINITY, miny = INFINITY, maxx = -INFINITY, maxy = -INFINITY;
  void add(const std::vector<glm::dvec2>& pts) {
    for (const glm::dvec2& q : pts) {
      minx = std::min(minx, q.x);
      maxx = std::max(maxx, q.x);
      miny = std::min(miny, q.y);
      maxy = std::max(maxy, q.y);
    }
  }
  /// The pixels around it, `grow` pixels wider on each side (bounds rounded to floats first); empty
  /// when it holds no point.
  Rect pixels(float grow, int w, int h) const {
    const float x0 = static_cast<float>(minx), y0 = static_cast<float>(miny), x1 = static_cast<float>(maxx), y1 = static_cast<float>(maxy);
    if (!(x0 <= x1)) return Rect{0, 0, 0, 0};
    return Rect{to_pixel(std::floor(x0) - grow, w), to_pixel(std::floor(y0) - grow, h), to_pixel(std::ceil(x1) + grow, w),
                to_pixel(std::ceil(y1) + grow, h)};
  }
};

/// Pixels as one span of columns a row over a rectangle: those whose real points can lie in one
/// box's shadow volume from one light (shadow_spans), or those near some (pixels_near).
struct VolumeSpans {
  Rect rect;
  std::vector<int> x0, x1;  ///< per row of rect: columns [x0, x1)
  bool contains(int x, int y) const {
    if (y < rect.y0 || y >= rect.y1) return false;
    const size_t r = static_cast<size_t>(y - rect.y0);
    return x >= x0[r] && x < x1[r];
  }
};

/// The pixels whose real points can lie in one box's shadow volume from one light: the volume
/// projects into the convex hull of its screen_points, whose rows are narrower than its rectangle.
/// Each row's span is the hull's extent over the rows within 2 px, widened by 2 px, as the
/// rectangle is; the whole image where the volume has no bounds on screen.
VolumeSpans shadow_spans(const core::Camera& cam, const core::Aabb& b, const VirtualLight& l, int w, int h) {
  VolumeSpans s;
  std::vector<glm::dvec2> pts;
  if (b.empty()) {
    s.rect = Rect{0, 0, 0, 0};
    return s;
  }
  if (!screen_points(cam, b, &l, pts)) {
    s.rect = Rect{0, 0, w, h};
    s.x0.assign(static_cast<size_t>(h), 0);
    s.x1.assign(static_cast<size_t>(h), w);
    return s;
  }
  Extent e;
  e.add(pts);
  s.rect = e.pixels(2.0f, w, h);
  if (s.rect.empty()) {
    s.rect = Rect{0, 0, 0, 0};  // no rows either (it can be empty in width only): contains nothing
    return s;
  }
  const size_t rows = static_cast<size_t>(s.rect.y1 - s.rect.y0);
  s.x0.assign(rows, s.rect.x0);
  s.x1.assign(rows, s.rect.x1);
  for (const glm::dvec2& p : pts) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y)) return s;  // the rectangle
  }
  // convex hull (A. M. Andrew's monotone chain), counter-clockwise
  std::sort(pts.begin(), pts.end(), [](const glm::dvec2& a, const glm::dvec2& c) { return a.x < c.x || (a.x == c.x && a.y < c.y); });
  auto cross = [](const glm::dvec2& o, const glm::dvec2& a, const glm::dvec2& c) {
    return (a.x - o.x) * (c.y - o.y) - (a.y - o.y) * (c.x - o.x);
  };
  std::vector<glm::dvec2> hull(2 * pts.size());
  size_t k = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    while (k >= 2 && cross(hull[k - 2], hull[k - 1], pts[i]) <= 0.0) --k;
    hull[k++] = pts[i];
  }
  for (size_t i = pts.size() - 1, t = k + 1; i-- > 0;) {
    while (k >= t && cross(hull[k - 2], hull[k - 1], pts[i]) <= 0.0) --k;
    hull[k++] = pts[i];
  }
  hull.resize(k > 1 ? k - 1 : k);
  // each row: the hull clipped to the band of rows y - 2 .. y + 2, its extent in x
  std::vector<glm::dvec2> a, c;
  for (int y = s.rect.y0; y < s.rect.y1; ++y) {
    a = hull;
    for (const double sign : {1.0, -1.0}) {
      const double bound = sign > 0 ? y - 2.0 : -(y + 2.0);  // keep sign * v >= bound
      c.clear();
      for (size_t i = 0; i < a.size(); ++i) {
        const glm::dvec2& p = a[i];
        const glm::dvec2& q = a[(i + 1) % a.size()];
        const double dp = sign * p.y - bound, dq = sign * q.y - bound;
        if (dp >= 0.0) c.push_back(p);
        if ((dp < 0.0) != (dq < 0.0)) c.push_back(p + (q - p) * (dp / (dp - dq)));
      }
      a.swap(c);
    }
    const size_t r = static_cast<size_t>(y - s.rect.y0);
    if (a.empty()) {
      s.x1[r] = s.x0[r];
      continue;
    }
    double lo = a[0].x, hi = a[0].x;
    for (const glm::dvec2& p : a) {
      lo = std::min(lo, p.x);
      hi = std::max(hi, p.x);
    }
    // clamped while a double: the hull's x can lie far off screen
    s.x0[r] = std::max(s.rect.x0, to_pixel(static_cast<float>(std::clamp(std::floor(lo) - 2.0, -1.0, w + 1.0)), w));
    s.x1[r] = std::min(s.rect.x1, to_pixel(static_cast<float>(std::clamp(std::ceil(hi) + 2.0, -1.0, w + 1.0)), w));
  }
  return s;
}

/// Each box's shadow volume from each light, box-major (volume bi * lights + li).
std::vector<VolumeSpans> shadow_volumes(const core::Camera& cam, const std::vector<core::Aabb>& boxes, const std::vector<VirtualLight>& lights,
                                        int w, int h) {
  std::vector<VolumeSpans> v;
  for (const core::Aabb& b : boxes)
    for (const VirtualLight& l : lights) v.push_back(shadow_spans(cam, b, l, w, h));
  return v;
}

/// The pixels within `margin` (in x and in y) of a rectangle or of the volumes' spans, as one span
/// per row (the rows' spans' extent) over their bounding rectangle, clipped to the image.
VolumeSpans pixels_near(const Rect& r, const std::vector<VolumeSpans>& volumes, int margin, int w, int h) {
  VolumeSpans s;
  std::vector<int> lo(static_cast<size_t>(h), w), hi(static_cast<size_t>(h), 0);
  auto add = [&](int y, int x0, int x1) {  // row y's columns [x0, x1), widened by the margin
    if (x0 >= x1) return;
    for (int yy = std::max(0, y - margin); yy < std::min(h, y + margin + 1); ++yy) {
      lo[static_cast<size_t>(yy)] = std::min(lo[static_cast<size_t>(yy)], std::max(0, x0 - margin));
      hi[static_cast<size_t>(yy)] = std::max(hi[static_cast<size_t>(yy)], std::min(w, x1 + margin));
    }
  };
  if (!r.empty()) {
    add(r.y0, r.x0, r.x1);
    for (int y = r.y0 + 1; y < r.y1; ++y) {  // the margin's rows are the first and last row's
      lo[static_cast<size_t>(y)] = std::min(lo[static_cast<size_t>(y)], std::max(0, r.x0 - margin));
      hi[static_cast<size_t>(y)] = std::max(hi[static_cast<size_t>(y)], std::min(w, r.x1 + margin));
    }
    add(r.y1 - 1, r.x0, r.x1);
  }
  for (const VolumeSpans& v : volumes) {
    for (int y = v.rect.y0; y < v.rect.y1; ++y) add(y, v.x0[static_cast<size_t>(y - v.rect.y0)], v.x1[static_cast<size_t>(y - v.rect.y0)]);
  }
  int y0 = 0, y1 = h;
  while (y0 < h && lo[static_cast<size_t>(y0)] >= hi[static_cast<size_t>(y0)]) ++y0;
  while (y1 > y0 && lo[static_cast<size_t>(y1 - 1)] >= hi[static_cast<size_t>(y1 - 1)]) --y1;
  s.rect = Rect{w, y0, 0, y1};
  for (int y = y0; y < y1; ++y) {
    s.x0.push_back(lo[static_cast<size_t>(y)]);
    s.x1.push_back(hi[static_cast<size_t>(y)]);
    s.rect.x0 = std::min(s.rect.x0, lo[static_cast<size_t>(y)]);
    s.rect.x1 = std::max(s.rect.x1, hi[static_cast<size_t>(y)]);
  }
  if (y0 >= y1) s.rect = Rect{0, 0, 0, 0};
  return s;
}

/// How far a model's depth zc and the sensor's may differ and still be one surface: 3 sigma of Nguyen
/// et al.'s noise model plus the disparity step, 0.4 % of z^2 a metre.
double agreement(double zc) { return 3.0 * kinect_sigma_m(zc) + 0.004 * zc * zc; }
/// Up to this depth (metres) a model depth zc agreeing with the sensor's zs lies within
/// [zs - agreement(zs), zs + agreement(zs + 2 agreement(zs))] (beyond ~25 m it need not).
constexpr float kMaxAgreementDepth = 15.0f;

/// Where the fused room or a support plane knows the real surface better than this frame's sensor:
/// a pixel of `region` whose sensor depth lies within the noise of the model's depth along its ray
/// (agreement) takes the model's depth and normal (the room's nearest surface that agrees: one in
/// front of what the sensor sees, a chair since moved away, does not count); one without a reading
/// takes the room's, or inside the objects' screen rectangle a plane's (planes have no edges, so
/// they fill holes only near the objects); anything the sensor sees clearly off the model (a
/// person, a moved chair) keeps the sensor's depth. The room's normals are worked out only inside
/// the spans of `normals_in` when given (the shadows ask for no others; they cost a cache miss or
/// three a pixel).
void clean_real_depth(const SensorFrame& frame, const core::Camera& cam, const CompositeOptions& opt, const Rect& objects,
                      const VolumeSpans& region, DepthImage& depth, std::vector<glm::vec3>& normals,
                      const std::vector<VolumeSpans>* normals_in = nullptr) {
  const int w = depth.width;
  const Eigen::Isometry3d pose = frame.world_from_camera.value_or(Eigen::Isometry3d::Identity());
  // the planes in camera space: n . X = d
  struct CamPlane {
    glm::vec3 n, world_n;
    float d;
  };
  std::vector<CamPlane> planes;
  for (const Plane& p : opt.support_planes) {
    const Eigen::Vector3d n = pose.rotation().transpose() * p.normal;
    const Eigen::Vector3d q = pose.inverse() * p.point;
    planes.push_back({glm::vec3(n.x(), n.y(), n.z()), glm::vec3(p.normal.x(), p.normal.y(), p.normal.z()), static_cast<float>(n.dot(q))});
  }
  const PinholeIntrinsics& k = frame.color_intrinsics;
  const Rect& rect = region.rect;
  core::for_each_tile(rect.x1 - rect.x0, rect.y1 - rect.y0, opt.threads, [&](const core::Tile& tile) {
    core::RayPacket rays;
    core::HitPacket hits;
    for (int y = tile.y0; y < tile.y1; y += core::kPacketRows) {
      for (int x = tile.x0; x < tile.x1; x += 4) {
        core::LaneMask mask = 0;
        for (int i = 0; i < core::kPacketSize; ++i) {
          const int px = rect.x0 + x + i % 4, py = rect.y0 + y + i / 4;
          rays.set(i, cam.ray(px + 0.5f, py + 0.5f));  // direction of camera-space z 1: t is the depth
          if (x + i % 4 < tile.x1 && y + i / 4 < tile.y1 && region.contains(px, py)) mask |= 1u << i;
          hits.prim[i] = core::kInvalidId;
        }
        if (!mask) continue;
        // whether the sensor's depth at a lane agrees with a model's depth zc there
        auto agrees = [&](int i, float zc) {
          const float zs = depth.depth_m[static_cast<size_t>(rect.y0 + y + i / 4) * w + rect.x0 + x + i % 4];
          if (!(zs > 0.0f)) return true;
          return std::fabs(zs - zc) <= agreement(zc);
        };
        // a support plane first: fitted over many readings, it is the most precise
        core::LaneMask open = mask;
        for (int i = 0; i < core::kPacketSize && !planes.empty(); ++i) {
          if (!((mask >> i) & 1u)) continue;
          const int px = rect.x0 + x + i % 4, py = rect.y0 + y + i / 4;
          const size_t idx = static_cast<size_t>(py) * w + px;
          const float zs = depth.depth_m[idx];
          const bool inside = px >= objects.x0 && px < objects.x1 && py >= objects.y0 && py < objects.y1;
          const glm::vec3 ray_c((px - k.cx) / k.fx, (py - k.cy) / k.fy, 1.0f);
          for (const CamPlane& p : planes) {
            const float den = glm::dot(p.n, ray_c);
            if (std::fabs(den) < 1e-6f) continue;
            const float zp = p.d / den;
            if (!(zp > 0.0f) || !agrees(i, zp) || (!(zs > 0.0f) && !inside)) continue;
            depth.depth_m[idx] = zp;
            normals[idx] = p.world_n;
            open &= ~(1u << i);
            break;
          }
        }
        // then the room, cast only for the lanes no plane took, and only along the stretch of each
        // ray where the room's depth would agree with the sensor's reading (all of it where there is
        // none): the kd-tree skips what lies in front and behind
        if (!open || !opt.room || opt.room->empty()) continue;
        for (int i = 0; i < core::kPacketSize; ++i) {
          if (!((open >> i) & 1u)) continue;
          const float zs = depth.depth_m[static_cast<size_t>(rect.y0 + y + i / 4) * w + rect.x0 + x + i % 4];
          if (!(zs > 0.0f) || zs > kMaxAgreementDepth) continue;
          const double below = agreement(zs), above = agreement(zs + 2.0 * below);  // agreement grows with depth
          rays.tmin[i] = static_cast<float>(std::max(0.0, zs - 1.01 * below));
          rays.tmax[i] = static_cast<float>(zs + 1.01 * above);
        }
        opt.room->scene().intersect(rays, open, hits);
        for (int i = 0; i < core::kPacketSize; ++i) {
          if (!((open >> i) & 1u) || hits.prim[i] == core::kInvalidId) continue;
          const int px = rect.x0 + x + i % 4, py = rect.y0 + y + i / 4;
          const size_t idx = static_cast<size_t>(py) * w + px;
          // the room where the sensor saw the same surface, or nothing (taking the room's depth also
          // where the sensor reads beyond it measured worse: IoU 0.979 against 0.983, bench-occlusion)
          const float zr = hits.t[i];
          if (!agrees(i, zr)) continue;
          depth.depth_m[idx] = zr;
          bool wanted = !normals_in;
          for (size_t v = 0; normals_in && v < normals_in->size() && !wanted; ++v) wanted = (*normals_in)[v].contains(px, py);
          if (wanted) normals[idx] = opt.room->normal(hits.get(i), rays.get(i).dir);
        }
      }
    }
  });
}

/// A light that reaches a real point only through virtual objects but is blocked by the real
/// scene too (a floor under a real table) was not reaching it in the recording either: it changes
/// nothing. The depth mesh tells, from kRealSkip off the point: the mesh is coarser than the depth
/// map and as noisy as the sensor, so it is not asked about the point's own surface.
constexpr float kRealSkip = 0.1f;
const std::vector<glm::vec3>& real_shadow_factors(const SensorFrame& frame, const DepthImage& filled,
                                                  const std::vector<glm::vec3>& real_normals, const Rect& rect,
                                                  const std::vector<VolumeSpans>& volume, const Shader& shader, const RealScene* proxy,
                                                  CompositeStats& st, const std::vector<uint32_t>*& darkened_pixels) {
  const core::TwoLevelScene& scene = shader.scene;
  const std::vector<VirtualLight>& lights = shader.lights;
  const CompositeOptions& opt = shader.opt;
  const int w = filled.width, h = filled.height;
  // per-thread factors kept across frames, all 1 but for the pixels of `pixels`, which the next
  // call resets: no fresh megabytes (and page faults) every frame (taken by reference here: inside
  // the tile lambda a thread_local name would be the worker's own)
  thread_local std::vector<glm::vec3> factor_scratch;
  thread_local std::vector<uint32_t> pixels_scratch;
  std::vector<glm::vec3>& factor = factor_scratch;
  std::vector<uint32_t>& pixels = pixels_scratch;
  if (factor.size() != static_cast<size_t>(w) * h) {
    factor.assign(static_cast<size_t>(w) * h, glm::vec3(1.0f));
  } else {
    for (const uint32_t i : pixels) factor[i] = glm::vec3(1.0f);
  }
  pixels.clear();
  darkened_pixels = &pixels;
  const std::vector<core::Aabb> boxes = opt.object_bounds.empty() ? std::vector<core::Aabb>{scene.bounds()} : opt.object_bounds;
  if (rect.empty()) return factor;
  // the depth with its small holes filled (composite() did, over the rectangle and a margin), so a
  // noisy depth map does not leave unshadowed specks
  auto depth = [&](int x, int y) { return filled.at(x, y); };
  // each box's shadow volume from each light (`volume`, box-major) has screen spans of its own,
  // much smaller than their union: a point is tested against a box only inside that box's spans
  // whether the segment from p to light li (p + to) meets a box; (x, y) is p's pixel
  auto meets_virtual = [&](int x, int y, size_t li, const glm::vec3& p, const glm::vec3& to) {
    const glm::vec3 inv = 1.0f / to;
    for (size_t bi = 0; bi < boxes.size(); ++bi) {
      if (!volume[bi * lights.size() + li].contains(x, y)) continue;
      if (core::segment_meets_box(p, inv, 0.0f, 1.0f, boxes[bi])) return true;
    }
    return false;
  };
  const Eigen::Isometry3d pose = frame.world_from_camera.value_or(Eigen::Isometry3d::Identity());
  const PinholeIntrinsics& k = frame.color_intrinsics;
  const Eigen::Matrix3f rot = pose.rotation().cast<float>();
  const Eigen::Vector3f tr = pose.translation().cast<float>();
  // (x - cx) / fx per column and (y - cy) / fy per row, worked out once (the same floats as before)
  thread_local std::vector<float> ux, vy;
  ux.resize(static_cast<size_t>(w));
  vy.resize(static_cast<size_t>(h));
  for (int x = 0; x < w; ++x) ux[static_cast<size_t>(x)] = static_cast<float>((x - k.cx) / k.fx);
  for (int y = 0; y < h; ++y) vy[static_cast<size_t>(y)] = static_cast<float>((y - k.cy) / k.fy);
  const std::vector<float>& ux_ = ux;  // the workers' thread_local names would be their own
  const std::vector<float>& vy_ = vy;
  auto point = [&](int x, int y, glm::vec3& p) {
    const float z = depth(x, y);
    if (z <= 0.0f) return false;
    const Eigen::Vector3f c(ux_[static_cast<size_t>(x)] * z, vy_[static_cast<size_t>(y)] * z, z);
    const Eigen::Vector3f q = rot * c + tr;
    p = glm::vec3(q.x(), q.y(), q.z());
    return true;
  };
  std::atomic<int> rays{0}, darkened{0};
  std::mutex pixels_lock;
  core::for_each_tile(rect.x1 - rect.x0, rect.y1 - rect.y0, opt.threads, [&](const core::Tile& tile) {
    const core::Tile t{tile.x0 + rect.x0, tile.y0 + rect.y0, tile.x1 + rect.x0, tile.y1 + rect.y0};
    // the tile's real points whose rays to a light meet the virtual objects' boxes, first all of
    // them, then their shadow rays 16 a packet (rays towards one light share its end point)
    struct Point {
      uint32_t pixel;
      glm::vec3 p, n;  ///< n zero where unknown
    };
    struct Shadow {
      uint32_t point;
      float cosine, dist;
      core::Ray ray;
      float pass;
      bool real_blocked;  ///< the real scene lies between the point and the light
    };
    thread_local std::vector<Point> points;
    thread_local std::vector<std::vector<Shadow>> shadows;  // per light
    points.clear();
    shadows.resize(lights.size());
    for (auto& v : shadows) v.clear();
    int local_rays = 0, local_dark = 0;
    for (int y = t.y0; y < t.y1; ++y) {
      for (int x = t.x0; x < t.x1; ++x) {
        bool inside = false;  // in some shadow volume's rectangle
        for (const VolumeSpans& v : volume) inside = inside || v.contains(x, y);
        if (!inside) continue;
        glm::vec3 p;
        if (!point(x, y, p)) continue;
        // most points' rays to the lights pass nowhere near the virtual objects: nothing changes
        bool near_virtual = false;
        for (size_t li = 0; li < lights.size() && !near_virtual; ++li) near_virtual = meets_virtual(x, y, li, p, lights[li].position - p);
        if (!near_virtual) continue;
        // normal of the depth map from neighbours 2 pixels away (less noise), facing the camera;
        // unknown at holes and image borders
        constexpr int r = 2;
        glm::vec3 n(0.0f), px0, px1, py0, py1;
        if (!real_normals.empty() && real_normals[static_cast<size_t>(y) * w + x] != glm::vec3(0.0f)) {
          n = real_normals[static_cast<size_t>(y) * w + x];  // the fused room's, or a support plane's
        } else if (x >= r && y >= r && x + r < w && y + r < h && point(x - r, y, px0) && point(x + r, y, px1) &&
                   point(x, y - r, py0) && point(x, y + r, py1)) {
          n = glm::cross(py1 - py0, px1 - px0);
          const float len = glm::length(n);
          n = len > 0.0f ? n / len : glm::vec3(0.0f);
          const glm::vec3 eye(static_cast<float>(tr.x()), static_cast<float>(tr.y()), static_cast<float>(tr.z()));
          if (glm::dot(n, eye - p) < 0.0f) n = -n;
        }
        const uint32_t k = static_cast<uint32_t>(points.size());
        points.push_back({static_cast<uint32_t>(static_cast<size_t>(y) * w + x), p, n});
        for (size_t li = 0; li < lights.size(); ++li) {
          const glm::vec3 to = lights[li].position - p;
          const float dist = glm::length(to);
          if (!(dist > 0.0f)) continue;
          const float cosine = glm::dot(n, n) > 0.0f ? glm::dot(n, to / dist) : 1.0f;
          if (cosine <= 0.0f) continue;
          Shadow sh{k, cosine, dist, core::Ray{}, 1.0f, false};
          if (meets_virtual(x, y, li, p, to)) {
            const glm::vec3 o = core::offset_ray_origin(p, glm::dot(n, n) > 0.0f ? n : to / dist);
            sh.ray = core::Ray{o, lights[li].position - o, 0.0f, 1.0f};
            sh.pass = -1.0f;  // to trace
          }
          shadows[li].push_back(sh);
        }
      }
    }
    // the light passing past the virtual objects (glass lets some through), in packets
    core::RayPacket packet{};
    float pass[core::kPacketSize];
    uint32_t lane_of[core::kPacketSize];
    for (auto& list : shadows) {
      int n = 0;
      auto flush = [&] {
        if (n == 0) return;
        shader.light_passing(packet, (1u << n) - 1u, false, pass);
        for (int i = 0; i < n; ++i) list[lane_of[i]].pass = pass[i];
        local_rays += n;
        n = 0;
      };
      for (uint32_t k = 0; k < list.size(); ++k) {
        if (list[k].pass >= 0.0f) continue;
        packet.set(n, list[k].ray);
        lane_of[n++] = k;
        if (n == core::kPacketSize) flush();
      }
      flush();
    }
    // where a virtual object takes light, whether the real scene took it already (from kRealSkip
    // off the point towards the light), in packets too
    if (proxy && !proxy->empty()) {
      for (size_t li = 0; li < shadows.size(); ++li) {
        std::vector<Shadow>& list = shadows[li];
        int n = 0;
        auto flush = [&] {
          if (n == 0) return;
          const core::LaneMask hit = proxy->scene().occluded(packet, (1u << n) - 1u);
          for (int i = 0; i < n; ++i) list[lane_of[i]].real_blocked = (hit >> i) & 1u;
          n = 0;
        };
        for (uint32_t k = 0; k < list.size(); ++k) {
          const Shadow& sh = list[k];
          if (!(sh.pass < 1.0f) || !(sh.dist > kRealSkip)) continue;
          const glm::vec3 p = points[sh.point].p;
          const glm::vec3 l_dir = (lights[li].position - p) / sh.dist;
          packet.set(n, core::Ray{p + kRealSkip * l_dir, l_dir, 0.0f, sh.dist - kRealSkip});
          lane_of[n++] = k;
          if (n == core::kPacketSize) flush();
        }
        flush();
      }
    }
    // the factors: (ambient + light reaching the point) / (ambient + light that would reach it)
    thread_local std::vector<glm::vec3> all, lit;
    thread_local std::vector<uint8_t> blocked;
    all.assign(points.size(), glm::vec3(opt.ambient));
    lit.assign(points.size(), glm::vec3(opt.ambient));
    blocked.assign(points.size(), 0);
    for (size_t li = 0; li < shadows.size(); ++li) {
      const VirtualLight& l = lights[li];
      for (const Shadow& sh : shadows[li]) {
        if (sh.real_blocked) continue;  // the real scene already shadows this point from this light
        all[sh.point] += l.color * sh.cosine;
        blocked[sh.point] |= sh.pass < 1.0f;
        lit[sh.point] += l.color * (sh.cosine * sh.pass);
      }
    }
    thread_local std::vector<uint32_t> mine;
    mine.clear();
    for (size_t k = 0; k < points.size(); ++k) {
      if (!blocked[k]) continue;
      factor[points[k].pixel] = lit[k] / all[k];
      mine.push_back(points[k].pixel);
      ++local_dark;
    }
    if (!mine.empty()) {
      const std::lock_guard<std::mutex> hold(pixels_lock);  // the order of the list does not matter
      pixels.insert(pixels.end(), mine.begin(), mine.end());
    }
    rays += local_rays;
    darkened += local_dark;
  });
  st.shadow_rays_real = rays;
  st.shadowed_real_pixels = darkened;
  if (darkened == 0) return factor;
  // the sensor's noise makes neighbouring normals (and so the factors) jitter: average each factor
  // with its four neighbours on the same surface (depth within 3%), which keeps the shadow's edge
  // (all averages from the unsmoothed factors, then written: the same for any order of `pixels`)
  thread_local std::vector<glm::vec3> smooth;
  smooth.resize(pixels.size());
  for (size_t k = 0; k < pixels.size(); ++k) {
    const size_t i = pixels[k];
    const int x = static_cast<int>(i % static_cast<size_t>(w)), y = static_cast<int>(i / static_cast<size_t>(w));
    smooth[k] = factor[i];
    if (x < 1 || y < 1 || x >= w - 1 || y >= h - 1) continue;
    const float z = depth(x, y);
    glm::vec3 sum = factor[i];
    int n = 1;
    const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
    for (int k2 = 0; k2 < 4; ++k2) {
      const size_t j = static_cast<size_t>(ny[k2]) * w + nx[k2];
      const float zj = depth(nx[k2], ny[k2]);
      if (zj > 0.0f && std::fabs(zj - z) < 0.03f * z && factor[j] != glm::vec3(1.0f)) {
        sum += factor[j];
        ++n;
      }
    }
    smooth[k] = sum / static_cast<float>(n);
  }
  for (size_t k = 0; k < pixels.size(); ++k) factor[pixels[k]] = smooth[k];
  return factor;
}

}  // namespace

float shadow_transmittance(const VirtualMaterial& m) {
  if (m.kind != VirtualMaterial::kGlass) return 0.0f;
  const float r0 = (m.ior - 1.0f) / (m.ior + 1.0f);
  const float tint = (m.color.r + m.color.g + m.color.b) / 3.0f;
  return std::clamp((1.0f - r0 * r0) * tint, 0.0f, 1.0f);
}

DepthImage clean_depth(const SensorFrame& frame, const CompositeOptions& options, int x0, int y0, int x1, int y1,
                       std::vector<glm::vec3>* normals) {
  DepthImage out = frame.depth;
  std::vector<glm::vec3> n(static_cast<size_t>(out.width) * out.height, glm::vec3(0.0f));
  const Rect r{std::max(0, x0), std::max(0, y0), std::min(out.width, x1), std::min(out.height, y1)};
  if (!r.empty() && (options.room || !options.support_planes.empty())) {
    const core::Camera cam = make_camera(frame.color_intrinsics, frame.world_from_camera.value_or(Eigen::Isometry3d::Identity()));
    clean_real_depth(frame, cam, options, r, pixels_near(r, {}, 0, out.width, out.height), out, n);
  }
  if (normals) *normals = std::move(n);
  return out;
}

VirtualLight estimate_light(const SensorFrame& frame) {
  double sum = 0.0;
  for (size_t i = 0; i < frame.color.rgb.size(); i += 3) {
    sum += 0.2126 * core::srgb8_to_linear(frame.color.rgb[i]) + 0.7152 * core::srgb8_to_linear(frame.color.rgb[i + 1]) +
           0.0722 * core::srgb8_to_linear(frame.color.rgb[i + 2]);
  }
  const double mean = frame.color.rgb.empty() ? 0.5 : sum / (frame.color.rgb.size() / 3);
  VirtualLight l;
  const Eigen::Isometry3d pose = frame.world_from_camera.value_or(Eigen::Isometry3d::Identity());
  // 2 m above the camera along its up direction (camera -y), 1 m forward
  const Eigen::Vector3d p = pose * Eigen::Vector3d(0.0, -2.0, 1.0);
  l.position = glm::vec3(p.x(), p.y(), p.z());
  l.color = glm::vec3(static_cast<float>(std::clamp(mean / 0.25, 0.4, 1.5)));
  return l;
}

ColorImage composite(const SensorFrame& frame, const core::TwoLevelScene& scene, const MaterialLookup& material,
                     const CompositeOptions& opt, CompositeStats* stats) {
  const int w = frame.color.width, h = frame.color.height;
  const core::Camera cam = make_camera(frame.color_intrinsics, frame.world_from_camera.value_or(Eigen::Isometry3d::Identity()));
  const std::vector<VirtualLight> lights = opt.lights.empty() ? std::vector<VirtualLight>{estimate_light(frame)} : opt.lights;
  ColorImage out = frame.color;
  CompositeStats st;
  const bool have_depth = frame.depth.width == w && frame.depth.height == h;
  DepthProxy local_proxy;
  const RealScene* real = nullptr;  // the real scene as geometry: the fused room, or this frame's depth mesh
  if ((opt.real_reflections || (opt.shadows && opt.real_shadows)) && have_depth && !scene.bounds().empty()) {
    if (opt.room) {
      real = opt.room;
    } else {
      DepthProxy* proxy = opt.proxy ? opt.proxy : &local_proxy;
      st.proxy_ms = proxy->update(frame);
      real = proxy;
    }
  }
  const Shader shader{frame, scene, material, opt, lights, opt.real_reflections ? real : nullptr, cam,
                      static_cast<float>(1.0 / std::max(1e-6, frame.color_intrinsics.fx))};

  // Screen rectangle of the virtual objects' bounds (what of them lies in front of the camera), 1 px
  // wider on each side: only those tiles are traced.
  const core::Aabb b = scene.bounds();
  if (b.empty()) {
    if (stats) *stats = st;
    return out;
  }
  std::vector<glm::dvec2> pts;
  screen_points(cam, b, nullptr, pts);
  Extent extent;
  extent.add(pts);
  const Rect objects = extent.pixels(1.0f, w, h);
  const int x0 = objects.x0, y0 = objects.y0, x1 = objects.x1, y1 = objects.y1;
  const bool real_shadows = opt.shadows && opt.real_shadows && have_depth;
  const std::vector<core::Aabb> boxes = opt.object_bounds.empty() ? std::vector<core::Aabb>{b} : opt.object_bounds;
  // the pixels whose real points can lie in a virtual object's shadow: each box's shadow volume
  // from each light, row by row, and their bounding rectangle
  const std::vector<VolumeSpans> volumes = real_shadows ? shadow_volumes(cam, boxes, lights, w, h) : std::vector<VolumeSpans>{};
  Rect shadow_area{0, 0, 0, 0};
  for (const VolumeSpans& v : volumes) {
    if (v.rect.empty()) continue;
    shadow_area = shadow_area.empty() ? v.rect
                                      : Rect{std::min(shadow_area.x0, v.rect.x0), std::min(shadow_area.y0, v.rect.y0),
                                             std::max(shadow_area.x1, v.rect.x1), std::max(shadow_area.y1, v.rect.y1)};
  }
  st.shadow_area_pixels = shadow_area.empty() ? 0 : (shadow_area.x1 - shadow_area.x0) * (shadow_area.y1 - shadow_area.y0);

  // the real depth: the sensor's, cleaned where the fused room or a support plane knows the surface
  auto td = std::chrono::steady_clock::now();
  OcclusionOptions oo = opt.occlusion_options;
  oo.threads = opt.threads;
  // how far around the pixels it decides the occlusion reads: the hole filling's reach and the
  // refinement's window, and a few pixels more
  const int margin = oo.fill_radius * oo.fill_passes + oo.guide_radius + 4;
  auto grow = [&](const Rect& r) {  // r widened by the margin, inside the image
    return r.empty() ? r : Rect{std::max(0, r.x0 - margin), std::max(0, r.y0 - margin), std::min(w, r.x1 + margin), std::min(h, r.y1 + margin)};
  };
  thread_local DepthImage cleaned;
  thread_local std::vector<glm::vec3> real_normals;
  const DepthImage* real_depth = &frame.depth;
  real_normals.clear();
  if (have_depth && (opt.room || !opt.support_planes.empty())) {
    // the pixels the occlusion and the shadows look at, and around them the margin the hole
    // filling reads
    const VolumeSpans region = pixels_near(Rect{x0, y0, x1, y1}, volumes, margin, w, h);
    cleaned = frame.depth;
    real_normals.assign(static_cast<size_t>(w) * h, glm::vec3(0.0f));
    if (!region.rect.empty()) clean_real_depth(frame, cam, opt, Rect{x0, y0, x1, y1}, region, cleaned, real_normals, &volumes);
    real_depth = &cleaned;
  }
  st.real_depth_ms = ms_since(td);
  // small holes filled once, for the occlusion and the shadows on real surfaces: over their
  // rectangles and a margin wide enough to judge the holes there as on the whole image
  td = std::chrono::steady_clock::now();
  thread_local DepthImage filled;
  if (have_depth) {
    Rect area = grow(opt.occlusion ? Rect{x0, y0, x1, y1} : Rect{0, 0, 0, 0});
    const Rect sa = grow(shadow_area);
    if (!sa.empty()) area = area.empty() ? sa : Rect{std::min(area.x0, sa.x0), std::min(area.y0, sa.y0), std::max(area.x1, sa.x1), std::max(area.y1, sa.y1)};
    filled = *real_depth;
    if (!area.empty()) {
      DepthImage cropped;
      cropped.width = area.x1 - area.x0;
      cropped.height = area.y1 - area.y0;
      cropped.depth_m = crop(real_depth->depth_m, w, area);
      const DepthImage f = fill_depth_holes(cropped, oo.fill_radius, oo.fill_passes, oo.max_hole_px, oo.threads);
      for (int y = area.y0; y < area.y1; ++y) {
        std::copy_n(&f.depth_m[static_cast<size_t>(y - area.y0) * cropped.width], cropped.width, &filled.depth_m[static_cast<size_t>(y) * w + area.x0]);
      }
    }
  }
  st.occlusion_ms = ms_since(td);  // the occlusion's share; the rest is added below
  // the virtual objects' shadows on the real surfaces (they may fall outside the objects' rectangle)
  const std::vector<glm::vec3>* shadow_ptr = nullptr;
  if (real_shadows) {
    const auto ts = std::chrono::steady_clock::now();
    const std::vector<uint32_t>* darkened = nullptr;
    shadow_ptr = &real_shadow_factors(frame, filled, real_normals, shadow_area, volumes, shader, real, st, darkened);
    const std::vector<glm::vec3>& shadow = *shadow_ptr;
    for (const uint32_t i : *darkened) {
      for (int c = 0; c < 3; ++c) out.rgb[3 * i + c] = core::linear_to_srgb8(core::srgb8_to_linear(frame.color.rgb[3 * i + c]) * shadow[i][c]);
    }
    st.real_shadow_ms = ms_since(ts);
  }
  if (x0 >= x1 || y0 >= y1) {
    if (stats) *stats = st;
    return out;
  }

  auto t0 = std::chrono::steady_clock::now();
  const int rw = x1 - x0, rh = y1 - y0;
  // the buffers cover the traced rectangle and, around it, the margin the occlusion looks at
  // (hole filling, colour-guided refinement): the region's own indices, kept across frames
  const Rect around = grow(Rect{x0, y0, x1, y1});
  const int aw = around.x1 - around.x0, ah = around.y1 - around.y0;
  auto local = [&](int x, int y) { return static_cast<size_t>(y - around.y0) * aw + (x - around.x0); };
  thread_local std::vector<float> zv, coverage, alpha;
  thread_local std::vector<glm::vec3> colour;  // premultiplied by coverage
  zv.assign(static_cast<size_t>(aw) * ah, std::numeric_limits<float>::infinity());
  colour.assign(zv.size(), glm::vec3(0.0f));
  coverage.assign(zv.size(), 0.0f);
  std::vector<float>& zv_ = zv;  // the workers' thread_local names would be their own
  std::vector<float>& coverage_ = coverage;
  std::vector<glm::vec3>& colour_ = colour;
  core::for_each_tile(rw, rh, opt.threads, [&](const core::Tile& t) {
    core::RayPacket rays;
    core::HitPacket hits;
    thread_local Deferred deferred;  // this tile's shadow and secondary rays, traced in packets at its end
    deferred.clear(lights.size());
    for (int y = t.y0; y < t.y1; y += core::kPacketRows) {
      for (int x = t.x0; x < t.x1; x += 4) {
        core::LaneMask mask = 0;
        for (int i = 0; i < core::kPacketSize; ++i) {
          const int px = x0 + x + i % 4, py = y0 + y + i / 4;
          rays.set(i, cam.ray(px + 0.5f, py + 0.5f));
          if (x + i % 4 < t.x1 && y + i / 4 < t.y1) mask |= 1u << i;
        }
        scene.intersect(rays, mask, hits);
        for (int i = 0; i < core::kPacketSize; ++i) {
          if (!((mask >> i) & 1u) || hits.prim[i] == core::kInvalidId) continue;
          const size_t idx = local(x0 + x + i % 4, y0 + y + i / 4);
          const core::Ray r = rays.get(i);
          core::Hit hit = hits.get(i);
          deferred.pixel = static_cast<uint32_t>(idx);
          const Sample smp = shader.radiance(r, hit, 0, 0.0f, &deferred);
          if (smp.coverage <= 0.0f) continue;  // cut out all along
          if (opt.alpha_tested) {
            // the occlusion test takes the first surface that is not cut out
            core::Ray next = r;
            for (int k = 0; k < kMaxLayers && hit.valid() && shader.look(next, hit, 0.0f, false).cutout; ++k) {
              next.tmin = hit.t;
              hit = scene.intersect(next);
            }
            if (!hit.valid()) continue;
          }
          zv_[idx] = hit.t;  // camera-space z = 1: t is the depth
          colour_[idx] = smp.colour;  // the deferred rays add theirs at the end of the tile
          coverage_[idx] = smp.coverage;
        }
      }
    }
    shader.resolve(deferred, colour_);
  });
  st.traced_pixels = rw * rh;
  st.trace_ms = ms_since(t0);

  t0 = std::chrono::steady_clock::now();
  if (opt.occlusion && have_depth) {
    DepthImage cd;
    ColorImage cc;
    cd.width = cc.width = aw;
    cd.height = cc.height = ah;
    cd.depth_m = crop(filled.depth_m, w, around);
    cc.rgb = crop(frame.color.rgb, w, around, 3);
    alpha = occlusion_alpha_filled(cd, cc, zv, oo);
  } else {
    alpha.resize(zv.size());
    for (size_t i = 0; i < zv.size(); ++i) alpha[i] = std::isfinite(zv[i]) ? 1.0f : 0.0f;
  }
  st.occlusion_ms += ms_since(t0);
  if (opt.keep_visibility) {
    st.visibility.assign(static_cast<size_t>(w) * h, 0.0f);
    st.virtual_depth.assign(static_cast<size_t>(w) * h, std::numeric_limits<float>::infinity());
    for (int y = around.y0; y < around.y1; ++y) {
      std::copy_n(&alpha[local(around.x0, y)], aw, &st.visibility[static_cast<size_t>(y) * w + around.x0]);
      std::copy_n(&zv[local(around.x0, y)], aw, &st.virtual_depth[static_cast<size_t>(y) * w + around.x0]);
    }
  }

  t0 = std::chrono::steady_clock::now();
  const std::vector<float>& alpha_ = alpha;  // the workers' thread_local name would be their own
  core::for_each_tile(rw, rh, opt.threads, [&](const core::Tile& t) {  // every pixel on its own
    for (int y = y0 + t.y0; y < y0 + t.y1; ++y) {
      for (int x = x0 + t.x0; x < x0 + t.x1; ++x) {
        const size_t i = static_cast<size_t>(y) * w + x, l = local(x, y);
        if (alpha_[l] <= 0.0f) continue;
        for (int c = 0; c < 3; ++c) {
          const float real = core::srgb8_to_linear(frame.color.rgb[3 * i + c]) * (shadow_ptr ? (*shadow_ptr)[i][c] : 1.0f);
          // the virtual colour over the real one by its coverage, then by the occlusion's alpha
          out.rgb[3 * i + c] = core::linear_to_srgb8(real + alpha_[l] * (colour_[l][c] - coverage_[l] * real));
        }
      }
    }
  });
  st.composite_ms = ms_since(t0);
  if (stats) *stats = st;
  return out;
}

}  // namespace artrace::ar
