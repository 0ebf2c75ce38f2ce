#include "artrace/ar/compositor.h"

#include "artrace/core/renderer.h"
#include "artrace/core/whitted.h"
#include "artrace/core/srgb.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>

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

  /// What a secondary ray (reflection, refraction) sees: the virtual surfaces in front of the
  /// depth mesh, blended front to back, then the recorded colour.
  glm::vec3 trace(const glm::vec3& o, const glm::vec3& dir, int depth, float path) const {
    const core::Ray r{o, dir};
    float t_real = core::kInfinity;
    glm::vec3 real;
    const bool real_hit = proxy && proxy->intersect(r, t_real, real);
    const core::Hit h = scene.intersect(r);
    if (h.valid() && (!real_hit || h.t <= t_real)) {
      const Sample s = radiance(r, h, depth, path);
      if (s.coverage >= 1.0f) return s.colour;
      return s.colour + (1.0f - s.coverage) * (real_hit ? real : background(o, dir));
    }
    return real_hit ? real : background(o, dir);
  }

  /// Colour and coverage along `r`, whose closest hit is `h`: cut-out points are passed, blended
  /// surfaces composited front to back (Porter & Duff's "over").
  Sample radiance(core::Ray r, core::Hit h, int depth, float path) const {
    Sample out;
    float through = 1.0f;
    for (int k = 0; k < kMaxLayers && h.valid(); ++k) {
      const VirtualMaterial m = look(r, h, path, false);
      if (!m.cutout) {
        const float a = std::clamp(m.alpha, 0.0f, 1.0f);
        if (a > 0.0f) out.colour += through * a * shade(r, h, m, depth, path);
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

  glm::vec3 shade(const core::Ray& ray, const core::Hit& hit, const VirtualMaterial& m, int depth, float path) const {
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
    const glm::vec3 d = glm::normalize(ray.dir);
    const float here = path + hit.t * glm::length(ray.dir);
    // light reaching p from each light, past the virtual objects
    auto lit = [&](const VirtualLight& l, float& cosine) {
      const glm::vec3 to = glm::normalize(l.position - p);
      cosine = glm::dot(n, to);
      if (cosine <= 0.0f || glm::dot(ng, to) <= 0.0f) return 0.0f;
      if (!opt.shadows) return 1.0f;
      const glm::vec3 o = core::offset_ray_origin(p, ng, magnitude);
      return light_passing(core::Ray{o, l.position - o, 0.0f, 1.0f}, true);
    };
    if ((m.kind == VirtualMaterial::kDiffuse && !m.pbr) || depth >= 2) {
      glm::vec3 c = opt.ambient * m.occlusion * m.color;
      for (const VirtualLight& l : lights) {
        float cosine;
        const float pass = lit(l, cosine);
        if (pass > 0.0f) c += m.color * l.color * (cosine * pass);
      }
      return c + m.emissive;
    }
    if (m.kind == VirtualMaterial::kDiffuse) {
      // metallic-roughness
      const glm::vec3 v = -d;
      const float nv = std::max(glm::dot(n, v), 1e-4f);
      const glm::vec3 f0 = glm::mix(glm::vec3(0.04f), m.color, m.metallic);
      const glm::vec3 diffuse = m.color * (1.0f - m.metallic);
      const float a = std::max(m.roughness, 0.03f) * std::max(m.roughness, 0.03f), a2 = a * a, k = 0.5f * a;
      auto fresnel = [&](float cosine) { return f0 + (glm::vec3(1.0f) - f0) * std::pow(1.0f - std::clamp(cosine, 0.0f, 1.0f), 5.0f); };
      const float mirror = std::clamp(1.0f - m.roughness / kMirrorRoughness, 0.0f, 1.0f);
      glm::vec3 c = opt.ambient * m.occlusion * (diffuse + (1.0f - mirror) * f0);
      if (mirror > 0.0f) {
        const glm::vec3 reflected = trace(core::offset_ray_origin(p, ng, magnitude), glm::reflect(d, n), depth + 1, here);
        c += mirror * fresnel(nv) * reflected;
      }
      for (const VirtualLight& l : lights) {
        float nl;
        const float pass = lit(l, nl);
        if (pass <= 0.0f) continue;
        const glm::vec3 h = glm::normalize(glm::normalize(l.position - p) + v);
        const float nh = std::max(glm::dot(n, h), 0.0f), vh = std::max(glm::dot(v, h), 0.0f);
        const float den = nh * nh * (a2 - 1.0f) + 1.0f;
        const float D = a2 / (kPi * den * den);
        const float G = nl / (nl * (1.0f - k) + k) * nv / (nv * (1.0f - k) + k);
        const glm::vec3 F = fresnel(vh);
        // radiance for a light of the Lambert convention above (diffuse: base * light * cos)
        const glm::vec3 specular = kPi * D * G * F / (4.0f * nl * nv);
        c += l.color * (pass * nl) * (diffuse * (glm::vec3(1.0f) - F) + specular);
      }
      return c + m.emissive;
    }
    const glm::vec3 reflected = trace(core::offset_ray_origin(p, ng, magnitude), glm::reflect(d, n), depth + 1, here);
    if (m.kind == VirtualMaterial::kMirror) return m.color * reflected + m.emissive;
    // glass: Fresnel between reflection and refraction; total internal reflection reflects all
    const float eta = front ? 1.0f / m.ior : m.ior;
    const float fresnel = core::fresnel_dielectric(-glm::dot(d, n), eta);
    glm::vec3 refr_dir;
    if (!core::refract_direction(d, n, eta, refr_dir)) return reflected;
    const glm::vec3 refracted = trace(core::offset_ray_origin(p, -ng, magnitude), refr_dir, depth + 1, here);
    return fresnel * reflected + (1.0f - fresnel) * m.color * refracted + m.emissive;
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

/// Pixels whose real points can lie in a virtual object's shadow: the screen bounds of each box's
/// shadow volume (the box, and its corners pushed away from the light to infinity, which project
/// to their vanishing points). The whole image when a volume reaches behind the camera.
Rect shadow_rect(const core::Camera& cam, const std::vector<core::Aabb>& boxes, const std::vector<VirtualLight>& lights,
                 int w, int h) {
  float minx = INFINITY, miny = INFINITY, maxx = -INFINITY, maxy = -INFINITY;
  const glm::mat3 to_cam = glm::transpose(cam.rotation);
  // a point, or a direction (its vanishing point), in camera space; false behind the camera
  auto add = [&](const glm::vec3& c) {
    if (c.z <= 1e-4f) return false;
    const float u = cam.fx * c.x / c.z + cam.cx, v = cam.fy * c.y / c.z + cam.cy;
    minx = std::min(minx, u);
    maxx = std::max(maxx, u);
    miny = std::min(miny, v);
    maxy = std::max(maxy, v);
    return true;
  };
  for (const core::Aabb& b : boxes) {
    if (b.empty()) continue;
    for (const VirtualLight& l : lights) {
      for (int c = 0; c < 8; ++c) {
        const glm::vec3 p((c & 1) ? b.hi.x : b.lo.x, (c & 2) ? b.hi.y : b.lo.y, (c & 4) ? b.hi.z : b.lo.z);
        if (!add(to_cam * (p - cam.position))) return Rect{0, 0, w, h};
        const glm::vec3 away = p - l.position;
        if (glm::dot(away, away) == 0.0f) return Rect{0, 0, w, h};
        if (!add(to_cam * away)) return Rect{0, 0, w, h};
      }
    }
  }
  if (!(minx <= maxx)) return Rect{0, 0, 0, 0};
  return Rect{to_pixel(std::floor(minx) - 2.0f, w), to_pixel(std::floor(miny) - 2.0f, h), to_pixel(std::ceil(maxx) + 2.0f, w),
              to_pixel(std::ceil(maxy) + 2.0f, h)};
}

/// Where the fused room or a support plane knows the real surface better than this frame's sensor:
/// a pixel of `region` whose sensor depth lies within the noise of the model's depth along its ray
/// (3 sigma of Nguyen et al.'s model plus the disparity step, 0.4 % of z^2 a metre) takes the
/// model's depth and normal; one without a reading takes the room's, or inside the objects' screen
/// rectangle a plane's (planes have no edges, so they fill holes only near the objects); anything
/// the sensor sees clearly off the model (a person, a moved chair) keeps the sensor's depth.
void clean_real_depth(const SensorFrame& frame, const core::Camera& cam, const CompositeOptions& opt, const Rect& objects, const Rect& region,
                      DepthImage& depth, std::vector<glm::vec3>& normals) {
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
  core::for_each_tile(region.x1 - region.x0, region.y1 - region.y0, opt.threads, [&](const core::Tile& tile) {
    core::RayPacket rays;
    core::HitPacket hits;
    for (int y = tile.y0; y < tile.y1; y += core::kPacketRows) {
      for (int x = tile.x0; x < tile.x1; x += 4) {
        core::LaneMask mask = 0;
        for (int i = 0; i < core::kPacketSize; ++i) {
          const int px = region.x0 + x + i % 4, py = region.y0 + y + i / 4;
          rays.set(i, cam.ray(px + 0.5f, py + 0.5f));  // direction of camera-space z 1: t is the depth
          if (x + i % 4 < tile.x1 && y + i / 4 < tile.y1) mask |= 1u << i;
          hits.prim[i] = core::kInvalidId;
        }
        if (opt.room && !opt.room->empty()) opt.room->scene().intersect(rays, mask, hits);
        for (int i = 0; i < core::kPacketSize; ++i) {
          if (!((mask >> i) & 1u)) continue;
          const int px = region.x0 + x + i % 4, py = region.y0 + y + i / 4;
          const size_t idx = static_cast<size_t>(py) * w + px;
          const float zs = depth.depth_m[idx];
          const bool inside = px >= objects.x0 && px < objects.x1 && py >= objects.y0 && py < objects.y1;
          auto agrees = [&](float zc) {
            if (!(zs > 0.0f)) return true;
            const double tol = 3.0 * kinect_sigma_m(zc) + 0.004 * zc * zc;
            return std::fabs(zs - zc) <= tol;
          };
          // a support plane first: fitted over many readings, it is the most precise
          const glm::vec3 ray_c((px - k.cx) / k.fx, (py - k.cy) / k.fy, 1.0f);
          bool done = false;
          for (const CamPlane& p : planes) {
            const float den = glm::dot(p.n, ray_c);
            if (std::fabs(den) < 1e-6f) continue;
            const float zp = p.d / den;
            if (!(zp > 0.0f) || !agrees(zp) || (!(zs > 0.0f) && !inside)) continue;
            depth.depth_m[idx] = zp;
            normals[idx] = p.world_n;
            done = true;
            break;
          }
          if (done || hits.prim[i] == core::kInvalidId) continue;
          // the room where the sensor saw the same surface, or nothing (taking the room's depth also
          // where the sensor reads beyond it measured worse: IoU 0.979 against 0.983, bench-occlusion)
          const float zr = hits.t[i];
          if (!agrees(zr)) continue;
          depth.depth_m[idx] = zr;
          normals[idx] = opt.room->normal(hits.get(i), rays.get(i).dir);
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
const std::vector<glm::vec3>& real_shadow_factors(const SensorFrame& frame, const DepthImage& real_depth,
                                                  const std::vector<glm::vec3>& real_normals, const Rect& rect, const Shader& shader,
                                                  const RealScene* proxy, CompositeStats& st) {
  const core::TwoLevelScene& scene = shader.scene;
  const std::vector<VirtualLight>& lights = shader.lights;
  const CompositeOptions& opt = shader.opt;
  const int w = real_depth.width, h = real_depth.height;
  // per-thread scratch kept across frames: no fresh megabytes (and page faults) every frame
  // (taken by reference here: inside the tile lambda a thread_local name would be the worker's own)
  thread_local std::vector<glm::vec3> factor_scratch, smooth_scratch;
  std::vector<glm::vec3>& factor = factor_scratch;
  std::vector<glm::vec3>& smooth = smooth_scratch;
  factor.assign(static_cast<size_t>(w) * h, glm::vec3(1.0f));
  const std::vector<core::Aabb> boxes = opt.object_bounds.empty() ? std::vector<core::Aabb>{scene.bounds()} : opt.object_bounds;
  if (rect.empty()) return factor;
  // small holes filled first, so a noisy depth map does not leave unshadowed specks (in the
  // rectangle and a margin, where holes are judged)
  const OcclusionOptions& oo = opt.occlusion_options;
  const int margin = oo.fill_radius * oo.fill_passes + 2;
  const Rect area{std::max(0, rect.x0 - margin), std::max(0, rect.y0 - margin), std::min(w, rect.x1 + margin),
                  std::min(h, rect.y1 + margin)};
  DepthImage cropped;
  cropped.width = area.x1 - area.x0;
  cropped.height = area.y1 - area.y0;
  cropped.depth_m = crop(real_depth.depth_m, w, area);
  const DepthImage filled = fill_depth_holes(cropped, oo.fill_radius, oo.fill_passes, oo.max_hole_px);
  // every pixel read below (the rectangle and 2 around it, inside the image) is in the crop
  auto depth = [&](int x, int y) { return filled.at(x - area.x0, y - area.y0); };
  auto meets_virtual = [&](const glm::vec3& p, const glm::vec3& to) {
    const glm::vec3 inv = 1.0f / to;
    for (const core::Aabb& b : boxes) {
      if (core::segment_meets_box(p, inv, 0.0f, 1.0f, b)) return true;
    }
    return false;
  };
  const Eigen::Isometry3d pose = frame.world_from_camera.value_or(Eigen::Isometry3d::Identity());
  const PinholeIntrinsics& k = frame.color_intrinsics;
  const Eigen::Matrix3f rot = pose.rotation().cast<float>();
  const Eigen::Vector3f tr = pose.translation().cast<float>();
  auto point = [&](int x, int y, glm::vec3& p) {
    const float z = depth(x, y);
    if (z <= 0.0f) return false;
    const Eigen::Vector3f c(static_cast<float>((x - k.cx) / k.fx) * z, static_cast<float>((y - k.cy) / k.fy) * z, z);
    const Eigen::Vector3f q = rot * c + tr;
    p = glm::vec3(q.x(), q.y(), q.z());
    return true;
  };
  std::atomic<int> rays{0}, darkened{0};
  core::for_each_tile(rect.x1 - rect.x0, rect.y1 - rect.y0, opt.threads, [&](const core::Tile& tile) {
    const core::Tile t{tile.x0 + rect.x0, tile.y0 + rect.y0, tile.x1 + rect.x0, tile.y1 + rect.y0};
    int local_rays = 0, local_dark = 0;
    for (int y = t.y0; y < t.y1; ++y) {
      for (int x = t.x0; x < t.x1; ++x) {
        glm::vec3 p;
        if (!point(x, y, p)) continue;
        // most points' rays to the lights pass nowhere near the virtual objects: nothing changes
        bool near_virtual = false;
        for (const VirtualLight& l : lights) near_virtual = near_virtual || meets_virtual(p, l.position - p);
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
        glm::vec3 all(opt.ambient), lit(opt.ambient);
        bool blocked_any = false;
        for (const VirtualLight& l : lights) {
          const glm::vec3 to = l.position - p;
          const float dist = glm::length(to);
          if (!(dist > 0.0f)) continue;
          const float cosine = glm::dot(n, n) > 0.0f ? glm::dot(n, to / dist) : 1.0f;
          if (cosine <= 0.0f) continue;
          all += l.color * cosine;
          float pass = 1.0f;  // light reaching p past the virtual objects (glass lets some through)
          if (meets_virtual(p, to)) {
            ++local_rays;
            const glm::vec3 side = glm::dot(n, n) > 0.0f ? n : to / dist;
            const glm::vec3 o = core::offset_ray_origin(p, side);
            pass = shader.light_passing(core::Ray{o, l.position - o, 0.0f, 1.0f});
          }
          if (pass < 1.0f && proxy && !proxy->empty() && dist > kRealSkip) {
            const glm::vec3 l_dir = to / dist;
            if (proxy->scene().occluded(core::Ray{p + kRealSkip * l_dir, l_dir, 0.0f, dist - kRealSkip})) {
              all -= l.color * cosine;  // the real scene already shadows this point from this light
              continue;
            }
          }
          blocked_any = blocked_any || pass < 1.0f;
          lit += l.color * (cosine * pass);
        }
        if (blocked_any) {
          factor[static_cast<size_t>(y) * w + x] = lit / all;
          ++local_dark;
        }
      }
    }
    rays += local_rays;
    darkened += local_dark;
  });
  st.shadow_rays_real = rays;
  st.shadowed_real_pixels = darkened;
  if (darkened == 0) return factor;
  // the sensor's noise makes neighbouring normals (and so the factors) jitter: average each factor
  // with its four neighbours on the same surface (depth within 3%), which keeps the shadow's edge
  smooth = factor;
  for (int y = std::max(1, rect.y0); y < std::min(h - 1, rect.y1); ++y) {
    for (int x = std::max(1, rect.x0); x < std::min(w - 1, rect.x1); ++x) {
      const size_t i = static_cast<size_t>(y) * w + x;
      const float z = depth(x, y);
      if (z <= 0.0f || factor[i] == glm::vec3(1.0f)) continue;
      glm::vec3 sum = factor[i];
      int n = 1;
      const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
      for (int k = 0; k < 4; ++k) {
        const size_t j = static_cast<size_t>(ny[k]) * w + nx[k];
        const float zj = depth(nx[k], ny[k]);
        if (zj > 0.0f && std::fabs(zj - z) < 0.03f * z && factor[j] != glm::vec3(1.0f)) {
          sum += factor[j];
          ++n;
        }
      }
      smooth[i] = sum / static_cast<float>(n);
    }
  }
  return smooth;
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
    clean_real_depth(frame, cam, options, r, r, out, n);
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

  // Screen rectangle of the virtual objects' bounds: only those tiles are traced.
  int x0 = 0, y0 = 0, x1 = w, y1 = h;
  const core::Aabb b = scene.bounds();
  if (b.empty()) {
    if (stats) *stats = st;
    return out;
  }
  bool behind = false;
  float minx = INFINITY, miny = INFINITY, maxx = -INFINITY, maxy = -INFINITY;
  for (int c = 0; c < 8; ++c) {
    const glm::vec3 p((c & 1) ? b.hi.x : b.lo.x, (c & 2) ? b.hi.y : b.lo.y, (c & 4) ? b.hi.z : b.lo.z);
    const glm::vec3 q = glm::transpose(cam.rotation) * (p - cam.position);
    if (q.z <= 1e-3f) {
      behind = true;
      break;
    }
    const float u = cam.fx * q.x / q.z + cam.cx, v = cam.fy * q.y / q.z + cam.cy;
    minx = std::min(minx, u);
    maxx = std::max(maxx, u);
    miny = std::min(miny, v);
    maxy = std::max(maxy, v);
  }
  if (!behind) {
    x0 = to_pixel(std::floor(minx) - 1.0f, w);
    x1 = to_pixel(std::ceil(maxx) + 1.0f, w);
    y0 = to_pixel(std::floor(miny) - 1.0f, h);
    y1 = to_pixel(std::ceil(maxy) + 1.0f, h);
  }
  const bool real_shadows = opt.shadows && opt.real_shadows && have_depth;
  const std::vector<core::Aabb> boxes = opt.object_bounds.empty() ? std::vector<core::Aabb>{b} : opt.object_bounds;
  const Rect shadow_area = real_shadows ? shadow_rect(cam, boxes, lights, w, h) : Rect{0, 0, 0, 0};

  // the real depth: the sensor's, cleaned where the fused room or a support plane knows the surface
  auto td = std::chrono::steady_clock::now();
  const OcclusionOptions& oo = opt.occlusion_options;
  const int margin = oo.fill_radius * oo.fill_passes + oo.guide_radius + 4;
  thread_local DepthImage cleaned;
  thread_local std::vector<glm::vec3> real_normals;
  const DepthImage* real_depth = &frame.depth;
  real_normals.clear();
  if (have_depth && (opt.room || !opt.support_planes.empty())) {
    Rect region{x0, y0, x1, y1};
    if (!shadow_area.empty()) {
      region = region.empty() ? shadow_area
                              : Rect{std::min(region.x0, shadow_area.x0), std::min(region.y0, shadow_area.y0), std::max(region.x1, shadow_area.x1),
                                     std::max(region.y1, shadow_area.y1)};
    }
    region = Rect{std::max(0, region.x0 - margin), std::max(0, region.y0 - margin), std::min(w, region.x1 + margin), std::min(h, region.y1 + margin)};
    cleaned = frame.depth;
    real_normals.assign(static_cast<size_t>(w) * h, glm::vec3(0.0f));
    if (!region.empty()) clean_real_depth(frame, cam, opt, Rect{x0, y0, x1, y1}, region, cleaned, real_normals);
    real_depth = &cleaned;
  }
  st.real_depth_ms = ms_since(td);
  // the virtual objects' shadows on the real surfaces (they may fall outside the objects' rectangle)
  const std::vector<glm::vec3>* shadow_ptr = nullptr;
  if (real_shadows) {
    const auto ts = std::chrono::steady_clock::now();
    shadow_ptr = &real_shadow_factors(frame, *real_depth, real_normals, shadow_area, shader, real, st);
    st.real_shadow_ms = ms_since(ts);
    const std::vector<glm::vec3>& shadow = *shadow_ptr;
    if (st.shadowed_real_pixels > 0) {
      for (size_t i = 0; i < shadow.size(); ++i) {
        if (shadow[i] == glm::vec3(1.0f)) continue;
        for (int c = 0; c < 3; ++c) out.rgb[3 * i + c] = core::linear_to_srgb8(core::srgb8_to_linear(frame.color.rgb[3 * i + c]) * shadow[i][c]);
      }
    }
  }
  if (x0 >= x1 || y0 >= y1) {
    if (stats) *stats = st;
    return out;
  }

  auto t0 = std::chrono::steady_clock::now();
  const int rw = x1 - x0, rh = y1 - y0;
  std::vector<float> zv(static_cast<size_t>(w) * h, std::numeric_limits<float>::infinity());
  std::vector<glm::vec3> colour(static_cast<size_t>(w) * h);  // premultiplied by coverage
  std::vector<float> coverage(static_cast<size_t>(w) * h, 0.0f);
  core::for_each_tile(rw, rh, opt.threads, [&](const core::Tile& t) {
    core::RayPacket rays;
    core::HitPacket hits;
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
          const size_t idx = static_cast<size_t>(y0 + y + i / 4) * w + (x0 + x + i % 4);
          const core::Ray r = rays.get(i);
          core::Hit hit = hits.get(i);
          const Sample smp = shader.radiance(r, hit, 0, 0.0f);
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
          zv[idx] = hit.t;  // camera-space z = 1: t is the depth
          colour[idx] = smp.colour;
          coverage[idx] = smp.coverage;
        }
      }
    }
  });
  st.traced_pixels = rw * rh;
  st.trace_ms = ms_since(t0);

  t0 = std::chrono::steady_clock::now();
  std::vector<float> alpha;
  if (opt.occlusion && frame.depth.width == w && frame.depth.height == h) {
    // only around the traced rectangle: a margin wide enough for the hole filling and the
    // colour-guided refinement to see what they would see on the whole image
    const OcclusionOptions& oo = opt.occlusion_options;
    const int m = oo.fill_radius * oo.fill_passes + oo.guide_radius + 4;
    const int cx0 = std::max(0, x0 - m), cy0 = std::max(0, y0 - m), cx1 = std::min(w, x1 + m), cy1 = std::min(h, y1 + m);
    const Rect around{cx0, cy0, cx1, cy1};
    const int cw = cx1 - cx0;
    DepthImage cd;
    ColorImage cc;
    cd.width = cc.width = cw;
    cd.height = cc.height = cy1 - cy0;
    cd.depth_m = crop(real_depth->depth_m, w, around);
    cc.rgb = crop(frame.color.rgb, w, around, 3);
    const std::vector<float> cz = crop(zv, w, around);
    const std::vector<float> ca = occlusion_alpha(cd, cc, cz, oo);
    alpha.assign(zv.size(), 0.0f);
    for (int y = cy0; y < cy1; ++y) {
      std::copy_n(&ca[static_cast<size_t>(y - cy0) * cw], cw, &alpha[static_cast<size_t>(y) * w + cx0]);
    }
  } else {
    alpha.resize(zv.size());
    for (size_t i = 0; i < zv.size(); ++i) alpha[i] = std::isfinite(zv[i]) ? 1.0f : 0.0f;
  }
  st.occlusion_ms = ms_since(t0);
  if (opt.keep_visibility) {
    st.visibility = alpha;
    st.virtual_depth = zv;
  }

  t0 = std::chrono::steady_clock::now();
  for (int y = y0; y < y1; ++y) {
    for (int x = x0; x < x1; ++x) {
      const size_t i = static_cast<size_t>(y) * w + x;
      if (alpha[i] <= 0.0f) continue;
      for (int c = 0; c < 3; ++c) {
        const float real = core::srgb8_to_linear(frame.color.rgb[3 * i + c]) * (shadow_ptr ? (*shadow_ptr)[i][c] : 1.0f);
        // the virtual colour over the real one by its coverage, then by the occlusion's alpha
        out.rgb[3 * i + c] = core::linear_to_srgb8(real + alpha[i] * (colour[i][c] - coverage[i] * real));
      }
    }
  }
  st.composite_ms = ms_since(t0);
  if (stats) *stats = st;
  return out;
}

}  // namespace artrace::ar
