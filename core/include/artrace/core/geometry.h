// Basic geometric types shared by every part of the ray tracer.
#pragma once

#include <glm/glm.hpp>

#include <algorithm>

#include <cstdint>
#include <limits>
#include <vector>

namespace artrace::core {

inline constexpr uint32_t kInvalidId = 0xffffffffu;
inline constexpr float kInfinity = std::numeric_limits<float>::infinity();

/// A ray o + t d, valid for t in (tmin, tmax]. The direction need not be normalised.
struct Ray {
  glm::vec3 org{0.0f};
  glm::vec3 dir{0.0f, 0.0f, 1.0f};
  float tmin = 0.0f;
  float tmax = kInfinity;
};

/// Closest hit: parameter t, barycentrics (u weights v1, v weights v2) and the primitive index.
/// `prim == kInvalidId` means no hit.
struct Hit {
  float t = kInfinity;
  float u = 0.0f;
  float v = 0.0f;
  uint32_t prim = kInvalidId;
  uint32_t inst = kInvalidId;  ///< instance / object id for two-level scenes
  bool valid() const { return prim != kInvalidId; }
};

struct Triangle {
  glm::vec3 v0, v1, v2;
  glm::vec3 geometric_normal() const { return glm::cross(v1 - v0, v2 - v0); }
};

/// Axis-aligned box; an empty box has lo > hi.
struct Aabb {
  glm::vec3 lo{kInfinity};
  glm::vec3 hi{-kInfinity};

  bool empty() const { return lo.x > hi.x || lo.y > hi.y || lo.z > hi.z; }
  void extend(const glm::vec3& p) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  void extend(const Aabb& b) {
    lo = glm::min(lo, b.lo);
    hi = glm::max(hi, b.hi);
  }
  glm::vec3 extent() const { return hi - lo; }
  float surface_area() const {
    if (empty()) return 0.0f;
    const glm::vec3 e = extent();
    return 2.0f * (e.x * e.y + e.y * e.z + e.z * e.x);
  }
  static Aabb of(const Triangle& t) {
    Aabb b;
    b.extend(t.v0);
    b.extend(t.v1);
    b.extend(t.v2);
    return b;
  }
};

/// An indexed triangle mesh as the application hands it over.
struct TriangleMesh {
  std::vector<glm::vec3> positions;
  std::vector<glm::uvec3> indices;

  size_t triangle_count() const { return indices.size(); }
  /// Appends the mesh's triangles to `out` (throws std::out_of_range on a bad index).
  void flatten_into(std::vector<Triangle>& out) const;
};

/// Closest-hit test of one ray against one triangle with the watertight algorithm of
/// Woop, Benthin & Wald, "Watertight Ray/Triangle Intersection", JCGT 2(1), 2013.
/// Accepts t in (ray.tmin, hit.t], ties in t go to the smaller `prim`; updates `hit` on success.
/// This is the exact arithmetic every traversal kernel uses, so it is also the brute-force oracle.
bool intersect_triangle(const Ray& ray, const Triangle& tri, uint32_t prim, Hit& hit);

/// The twelve triangles of the box [lo, hi], wound counter-clockwise seen from outside.
inline std::vector<Triangle> box_triangles(const glm::vec3& lo, const glm::vec3& hi) {
  const glm::vec3 v[8] = {{lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {hi.x, hi.y, lo.z}, {lo.x, hi.y, lo.z},
                          {lo.x, lo.y, hi.z}, {hi.x, lo.y, hi.z}, {hi.x, hi.y, hi.z}, {lo.x, hi.y, hi.z}};
  constexpr int f[12][3] = {{0, 3, 2}, {0, 2, 1}, {4, 5, 6}, {4, 6, 7}, {0, 4, 7}, {0, 7, 3},
                            {1, 2, 6}, {1, 6, 5}, {3, 7, 6}, {3, 6, 2}, {0, 1, 5}, {0, 5, 4}};
  std::vector<Triangle> t;
  t.reserve(12);
  for (const auto& k : f) t.push_back({v[k[0]], v[k[1]], v[k[2]]});
  return t;
}

/// Brute force over every triangle: the reference the acceleration structures are tested against.
Hit intersect_brute_force(const Ray& ray, const std::vector<Triangle>& tris);
bool occluded_brute_force(const Ray& ray, const std::vector<Triangle>& tris);

/// Whether the part t in [t0, t1] of the line org + t dir meets the box; `inv_dir` = 1 / dir
/// (computed once for many boxes).
inline bool segment_meets_box(const glm::vec3& org, const glm::vec3& inv_dir, float t0, float t1, const Aabb& b) {
  for (int a = 0; a < 3; ++a) {
    float n = (b.lo[a] - org[a]) * inv_dir[a], f = (b.hi[a] - org[a]) * inv_dir[a];
    if (n > f) std::swap(n, f);
    t0 = std::max(t0, n);
    t1 = std::min(t1, f);
    if (t0 > t1) return false;
  }
  return true;
}

/// Bounds of a box under an affine transform (its eight moved corners), widened by a relative
/// margin so that rounding never culls a ray that reaches what the box holds. Empty stays empty.
Aabb transform_box(const Aabb& b, const glm::mat4& m);

}  // namespace artrace::core
