#include "artrace/ar/compositor.h"

#include "artrace/core/renderer.h"
#include "artrace/core/srgb.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

namespace artrace::ar {
namespace {

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

/// Offsets a secondary ray's origin off the surface, scaled to the hit point's magnitude (a
/// global epsilon fails for scenes far from the origin or tiny ones).
glm::vec3 offset(const glm::vec3& p, const glm::vec3& n, bool outward) {
  const float scale = 1e-4f * std::max(1.0f, std::max({std::fabs(p.x), std::fabs(p.y), std::fabs(p.z)}));
  return p + (outward ? scale : -scale) * n;
}

struct Shader {
  const SensorFrame& frame;
  const core::TwoLevelScene& scene;
  const MaterialLookup& material;
  const CompositeOptions& opt;
  const std::vector<VirtualLight>& lights;
  core::Camera cam;

  /// The recorded colour seen along a ray that left the virtual objects: the point at the sensor
  /// depth of the pixel it projects to (or 2 m on) is looked up in the colour frame.
  glm::vec3 background(const glm::vec3& org, const glm::vec3& dir) const {
    const glm::vec3 d = glm::normalize(dir);
    for (const float dist : {2.0f, 1.0f, 0.5f}) {
      const glm::vec3 p = org + dist * d;
      const glm::vec3 c = glm::transpose(cam.rotation) * (p - cam.position);
      if (c.z <= 0.05f) continue;
      const int x = static_cast<int>(cam.fx * c.x / c.z + cam.cx), y = static_cast<int>(cam.fy * c.y / c.z + cam.cy);
      if (x < 0 || y < 0 || x >= frame.color.width || y >= frame.color.height) continue;
      const uint8_t* px = frame.color.at(x, y);
      return {core::srgb8_to_linear(px[0]), core::srgb8_to_linear(px[1]), core::srgb8_to_linear(px[2])};
    }
    return glm::vec3(0.5f);
  }

  glm::vec3 shade(const core::Ray& ray, const core::Hit& hit, int depth) const {
    const core::Triangle tri = scene.world_triangle(hit);
    glm::vec3 n = glm::normalize(tri.geometric_normal());
    const bool front = glm::dot(n, ray.dir) < 0.0f;
    if (!front) n = -n;
    const glm::vec3 p = ray.org + hit.t * ray.dir;
    const VirtualMaterial m = material(hit);
    if (m.kind == VirtualMaterial::kDiffuse || depth >= 2) {
      glm::vec3 c = opt.ambient * m.color;
      for (const VirtualLight& l : lights) {
        const glm::vec3 to = l.position - p;
        const float cosine = glm::dot(n, glm::normalize(to));
        if (cosine <= 0.0f) continue;
        if (opt.shadows && scene.occluded(core::Ray{offset(p, n, true), to, 0.0f, 1.0f})) continue;
        c += m.color * l.color * cosine;
      }
      return c;
    }
    const glm::vec3 d = glm::normalize(ray.dir);
    const glm::vec3 refl_dir = glm::reflect(d, n);
    auto trace = [&](const glm::vec3& o, const glm::vec3& dir) {
      const core::Ray r{o, dir};
      const core::Hit h = scene.intersect(r);
      return h.valid() ? shade(r, h, depth + 1) : background(o, dir);
    };
    const glm::vec3 reflected = trace(offset(p, n, true), refl_dir);
    if (m.kind == VirtualMaterial::kMirror) return m.color * reflected;
    // glass: Fresnel (Schlick) between reflection and refraction; total internal reflection handled
    const float eta = front ? 1.0f / m.ior : m.ior;
    const float cos_i = -glm::dot(d, n);
    const float r0 = (1.0f - m.ior) / (1.0f + m.ior);
    const float fresnel = r0 * r0 + (1.0f - r0 * r0) * std::pow(1.0f - cos_i, 5.0f);
    const glm::vec3 refr_dir = glm::refract(d, n, eta);
    if (glm::dot(refr_dir, refr_dir) == 0.0f) return reflected;  // total internal reflection
    const glm::vec3 refracted = trace(offset(p, n, false), refr_dir);
    return fresnel * reflected + (1.0f - fresnel) * m.color * refracted;
  }
};

}  // namespace

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
  Shader shader{frame, scene, material, opt, lights, cam};
  ColorImage out = frame.color;
  CompositeStats st;

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
    x0 = std::clamp(static_cast<int>(std::floor(minx)) - 1, 0, w);
    x1 = std::clamp(static_cast<int>(std::ceil(maxx)) + 1, 0, w);
    y0 = std::clamp(static_cast<int>(std::floor(miny)) - 1, 0, h);
    y1 = std::clamp(static_cast<int>(std::ceil(maxy)) + 1, 0, h);
  }
  if (x0 >= x1 || y0 >= y1) {
    if (stats) *stats = st;
    return out;
  }

  auto t0 = std::chrono::steady_clock::now();
  const int rw = x1 - x0, rh = y1 - y0;
  std::vector<float> zv(static_cast<size_t>(w) * h, std::numeric_limits<float>::infinity());
  std::vector<glm::vec3> colour(static_cast<size_t>(w) * h);
  core::for_each_tile(rw, rh, opt.threads, [&](const core::Tile& t) {
    core::RayPacket rays;
    core::HitPacket hits;
    for (int y = t.y0; y < t.y1; y += 2) {
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
          zv[idx] = hits.t[i];  // camera-space z = 1: t is the depth
          colour[idx] = shader.shade(rays.get(i), hits.get(i), 0);
        }
      }
    }
  });
  st.traced_pixels = rw * rh;
  st.trace_ms = ms_since(t0);

  t0 = std::chrono::steady_clock::now();
  std::vector<float> alpha;
  if (opt.occlusion && frame.depth.width == w && frame.depth.height == h) {
    alpha = occlusion_alpha(frame.depth, frame.color, zv, opt.occlusion_options);
  } else {
    alpha.resize(zv.size());
    for (size_t i = 0; i < zv.size(); ++i) alpha[i] = std::isfinite(zv[i]) ? 1.0f : 0.0f;
  }
  st.occlusion_ms = ms_since(t0);

  t0 = std::chrono::steady_clock::now();
  for (int y = y0; y < y1; ++y) {
    for (int x = x0; x < x1; ++x) {
      const size_t i = static_cast<size_t>(y) * w + x;
      if (alpha[i] <= 0.0f) continue;
      for (int c = 0; c < 3; ++c) {
        const float real = core::srgb8_to_linear(frame.color.rgb[3 * i + c]);
        out.rgb[3 * i + c] = core::linear_to_srgb8(alpha[i] * colour[i][c] + (1.0f - alpha[i]) * real);
      }
    }
  }
  st.composite_ms = ms_since(t0);
  if (stats) *stats = st;
  return out;
}

}  // namespace artrace::ar
