// Fixtures shared by the test files: seeded random scenes and rays, closed meshes, shared data.
#pragma once

#include "artrace/core/geometry.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace artrace::test {

using core::Ray;
using core::Triangle;

/// Folder of the shared BART data: $ARTRACE_SHARED_DATA, else the CMake option's value.
inline std::filesystem::path shared_data() {
  if (const char* env = std::getenv("ARTRACE_SHARED_DATA"); env && *env) return env;
  return ARTRACE_SHARED_DATA_DEFAULT;
}

/// Skips the current test with a clear message when the shared scenes are not there.
#define ARTRACE_REQUIRE_SHARED(rel)                                                                \
  const std::filesystem::path shared_path = ::artrace::test::shared_data() / (rel);               \
  if (!std::filesystem::exists(shared_path)) {                                                     \
    GTEST_SKIP() << "shared data not found at " << shared_path                                     \
                 << " (set ARTRACE_SHARED_DATA or the CMake option ARTRACE_SHARED_DATA)";           \
  }

inline glm::vec3 random_point(std::mt19937& rng, float lo, float hi) {
  std::uniform_real_distribution<float> d(lo, hi);
  return {d(rng), d(rng), d(rng)};
}

inline glm::vec3 random_direction(std::mt19937& rng) {
  std::normal_distribution<float> n(0.0f, 1.0f);
  for (;;) {
    const glm::vec3 d(n(rng), n(rng), n(rng));
    if (glm::length(d) > 1e-3f) return glm::normalize(d);
  }
}

/// Ray/triangle in double precision (Moller & Trumbore, "Fast, minimum storage ray-triangle
/// intersection", JGT 1997): an oracle independent of the float watertight test the kernels use.
/// `slack` > 0 widens the triangle by that much in barycentric terms, < 0 narrows it, so that a
/// caller can tell a clear hit from one within rounding of an edge. Accepts t in (tmin, tmax].
inline bool hit_exact(const Ray& r, const Triangle& tri, double slack, double& t) {
  const glm::dvec3 o(r.org), d(r.dir), v0(tri.v0), v1(tri.v1), v2(tri.v2);
  const glm::dvec3 e1 = v1 - v0, e2 = v2 - v0, p = glm::cross(d, e2);
  const double det = glm::dot(e1, p);
  if (det == 0.0) return false;
  const double inv = 1.0 / det;
  const glm::dvec3 s = o - v0;
  const double u = glm::dot(s, p) * inv;
  const glm::dvec3 q = glm::cross(s, e1);
  const double v = glm::dot(d, q) * inv;
  if (u < -slack || v < -slack || u + v > 1.0 + slack) return false;
  t = glm::dot(e2, q) * inv;
  return t > r.tmin && t <= r.tmax;
}

struct ExactHit {
  uint32_t prim = core::kInvalidId;
  double t = std::numeric_limits<double>::infinity();
  bool valid() const { return prim != core::kInvalidId; }
};

inline ExactHit intersect_exact(const Ray& r, const std::vector<Triangle>& tris, double slack) {
  ExactHit best;
  for (size_t i = 0; i < tris.size(); ++i) {
    double t;
    if (hit_exact(r, tris[i], slack, t) && t < best.t) best = {static_cast<uint32_t>(i), t};
  }
  return best;
}

/// Whether a closest hit `got` (kd-tree, BVH or brute force in float) agrees with the double
/// oracle: no triangle is clearly hit (inside by 1e-6) closer than it, and when it names a
/// triangle, that triangle is hit, within 1e-6 of its edges, at its distance (1e-5 relative).
/// Rays within rounding of an edge may take either neighbour; nothing else may differ.
inline ::testing::AssertionResult agrees_with_exact(const Ray& r, const std::vector<Triangle>& tris, const core::Hit& got) {
  const ExactHit clear = intersect_exact(r, tris, -1e-6);
  if (!got.valid()) {
    if (!clear.valid()) return ::testing::AssertionSuccess();
    return ::testing::AssertionFailure() << "missed triangle " << clear.prim << " at t " << clear.t;
  }
  double t;
  if (got.prim >= tris.size() || !hit_exact(r, tris[got.prim], 1e-6, t)) {
    return ::testing::AssertionFailure() << "triangle " << got.prim << " is not hit (double precision)";
  }
  const double tol = 1e-5 * std::max(1.0, std::fabs(t));
  if (std::fabs(t - got.t) > tol) return ::testing::AssertionFailure() << "t " << got.t << ", double precision " << t;
  if (clear.valid() && clear.t < got.t - tol) {
    return ::testing::AssertionFailure() << "triangle " << clear.prim << " is hit closer, at t " << clear.t << " (got " << got.t << ")";
  }
  return ::testing::AssertionSuccess();
}

/// A soup of `count` random triangles of size about `size` in the cube [0, 10]^3.
inline std::vector<Triangle> random_soup(std::mt19937& rng, size_t count, float size) {
  std::vector<Triangle> tris;
  for (size_t i = 0; i < count; ++i) {
    const glm::vec3 c = random_point(rng, 0.0f, 10.0f);
    tris.push_back({c + random_point(rng, -size, size), c + random_point(rng, -size, size),
                    c + random_point(rng, -size, size)});
  }
  return tris;
}

/// Rays from random points in [-2, 12]^3 in random directions.
inline std::vector<Ray> random_rays(std::mt19937& rng, size_t count) {
  std::vector<Ray> rays;
  for (size_t i = 0; i < count; ++i) rays.push_back(Ray{random_point(rng, -2.0f, 12.0f), random_direction(rng)});
  return rays;
}

/// A closed, consistently wound sphere: `n` x 2n latitude/longitude grid, vertices shared exactly.
inline std::vector<Triangle> closed_sphere(const glm::vec3& c, float r, int n) {
  std::vector<glm::vec3> v;
  auto idx = [&](int i, int j) { return i * (2 * n) + (j % (2 * n)); };
  for (int i = 0; i <= n; ++i) {
    const float th = 3.14159265f * static_cast<float>(i) / static_cast<float>(n);
    for (int j = 0; j < 2 * n; ++j) {
      const float ph = 3.14159265f * static_cast<float>(j) / static_cast<float>(n);
      // the poles are single points repeated exactly
      const float s = (i == 0 || i == n) ? 0.0f : std::sin(th);
      v.push_back(c + r * glm::vec3(s * std::cos(ph), std::cos(th), s * std::sin(ph)));
    }
  }
  std::vector<Triangle> tris;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < 2 * n; ++j) {
      const glm::vec3 a = v[idx(i, j)], b = v[idx(i, j + 1)], cc = v[idx(i + 1, j)], d = v[idx(i + 1, j + 1)];
      tris.push_back({a, b, cc});
      tris.push_back({b, d, cc});
    }
  }
  return tris;
}

}  // namespace artrace::test
