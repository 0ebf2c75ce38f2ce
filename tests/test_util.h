// Fixtures shared by the test files: seeded random scenes and rays, closed meshes, shared data.
#pragma once

#include "artrace/core/geometry.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
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
