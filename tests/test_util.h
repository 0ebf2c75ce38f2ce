// Fixtures shared by the test files: seeded random scenes and rays, closed meshes, shared data.
#pragma once

#include "artrace/core/geometry.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace artrace::test {

using core::Ray;
using core::Triangle;

/// Ray count of a brute-force oracle: a quarter of `n` under the sanitizers, which run it about
/// ten times slower (the same cases, fewer random rays).
constexpr int brute_force_rays(int n) {
#if defined(ARTRACE_SANITIZED)
  return n / 4;
#else
  return n;
#endif
}

/// Folder of the shared BART data: $ARTRACE_SHARED_DATA, else the CMake option's value.
inline std::filesystem::path shared_data() {
  if (const char* env = std::getenv("ARTRACE_SHARED_DATA"); env && *env) return env;
  return ARTRACE_SHARED_DATA_DEFAULT;
}

/// This test process's own folder for the files its test writes, under the system's temporary
/// folder: ctest runs the tests as parallel processes (and two runs may share a machine), so a
/// fixed name there is written and removed by two tests at once. Removed, with whatever is left
/// in it, when the process ends.
inline const std::filesystem::path& scratch_root() {
  struct Root {
    std::filesystem::path path = std::filesystem::temp_directory_path() / ("artrace_tests." + std::to_string(::getpid()));
    Root() { std::filesystem::create_directories(path); }
    ~Root() {
      std::error_code ignored;
      std::filesystem::remove_all(path, ignored);
    }
  };
  static const Root root;
  return root.path;
}

/// `name` (a file or folder) in scratch_root().
inline std::filesystem::path scratch_path(const std::string& name) { return scratch_root() / name; }

/// The whole of a file (a command's log, a written file), empty when it cannot be read.
inline std::string read_file(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

/// The bytes of every .png of a folder (an export's frame_*.png), in name order, so frame order.
/// Throws for an empty or unreadable one, so that frames compared are never two empty strings.
inline std::vector<std::string> read_pngs(const std::filesystem::path& folder) {
  std::vector<std::filesystem::path> files;
  for (const auto& e : std::filesystem::directory_iterator(folder)) {
    if (e.path().extension() == ".png") files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  std::vector<std::string> out;
  for (const auto& f : files) {
    out.push_back(read_file(f));
    if (out.back().empty()) throw std::runtime_error(f.string() + ": empty or unreadable");
  }
  return out;
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

/// Axis-aligned boxes whose faces lie in the planes the SAH picks, rays aimed at their vertices
/// and edges, zero-area triangles and piles of coincident triangles.
inline std::vector<Triangle> adversarial_scene() {
  std::vector<Triangle> tris;
  auto quad = [&](glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d) {
    tris.push_back({a, b, c});
    tris.push_back({a, c, d});
  };
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) {
      const glm::vec3 lo(2.0f * i, 0.0f, 2.0f * j), hi = lo + glm::vec3(1.0f, 1.0f + i, 1.0f);
      quad({lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {hi.x, hi.y, lo.z}, {lo.x, hi.y, lo.z});
      quad({lo.x, lo.y, hi.z}, {lo.x, hi.y, hi.z}, {hi.x, hi.y, hi.z}, {hi.x, lo.y, hi.z});
      quad({lo.x, lo.y, lo.z}, {lo.x, hi.y, lo.z}, {lo.x, hi.y, hi.z}, {lo.x, lo.y, hi.z});
      quad({hi.x, lo.y, lo.z}, {hi.x, lo.y, hi.z}, {hi.x, hi.y, hi.z}, {hi.x, hi.y, lo.z});
      quad({lo.x, hi.y, lo.z}, {lo.x, hi.y, hi.z}, {hi.x, hi.y, hi.z}, {hi.x, hi.y, lo.z});
      quad({lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {hi.x, lo.y, hi.z}, {lo.x, lo.y, hi.z});
    }
  }
  // a floor exactly in the plane y = 0 that the boxes' bottoms share
  quad({-1, 0, -1}, {-1, 0, 9}, {9, 0, 9}, {9, 0, -1});
  // walls in the plane x = 0 written as -0.0 and as +0.0 (one position to the build)
  quad({-0.0f, 0, 0}, {-0.0f, 3, 0}, {-0.0f, 3, 3}, {-0.0f, 0, 3});
  quad({0, 0, 4}, {0, 3, 4}, {0, 3, 7}, {-0.0f, 0, 7});
  // zero-area triangles: a point and a line
  tris.push_back({{3, 3, 3}, {3, 3, 3}, {3, 3, 3}});
  tris.push_back({{0, 2, 0}, {4, 2, 4}, {8, 2, 8}});
  // 50 coincident copies of one triangle, in all vertex orders
  for (int k = 0; k < 50; ++k) {
    const glm::vec3 a(1, 6, 1), b(6, 6, 2), c(2, 6, 6);
    if (k % 3 == 0) tris.push_back({a, b, c});
    else if (k % 3 == 1) tris.push_back({b, c, a});
    else tris.push_back({c, a, b});
  }
  return tris;
}

/// Slivers 2.2 long with two vertices in a plane x = c and the third 1 to 3 ulps off it, beside
/// boxes with faces in that plane every 6 cm up the sliver (so that the SAH splits in the plane and
/// across the sliver), and rays at points of the slivers from both sides.
inline void sliver_scene(std::vector<Triangle>& tris, std::vector<Ray>& rays) {
  std::mt19937 rng(31);
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  for (int k = 0; k < 24; ++k) {
    const float c = 1.0f + 0.25f * static_cast<float>(k % 8);  // the plane x = c
    const float z0 = 0.5f * static_cast<float>(k / 8);
    // boxes with a face in the plane, on one side, every 6 cm up the sliver: the SAH puts split
    // planes in x = c and across the sliver
    const float side = k % 2 ? 1.0f : -1.0f;
    for (int j = 0; j < 36; ++j) {
      const float y = 0.06f * static_cast<float>(j), x1 = c + side * 0.1f;
      const glm::vec3 a(c, y, z0 - 0.1f), b(x1, y, z0 - 0.1f), cc(x1, y + 0.03f, z0 - 0.1f), d(c, y + 0.03f, z0 - 0.1f);
      tris.push_back({a, b, cc});
      tris.push_back({a, cc, d});
      tris.push_back({a, d, glm::vec3(c, y + 0.03f, z0 + 0.2f)});
      tris.push_back({a, glm::vec3(c, y + 0.03f, z0 + 0.2f), glm::vec3(c, y, z0 + 0.2f)});
    }
    // the sliver, 2.2 long: two vertices in the plane, the third 1 to 3 ulps off it, to either side
    const int ulps = 1 + k % 3;
    float off = c;
    for (int u = 0; u < ulps; ++u) off = std::nextafter(off, (k / 2) % 2 ? 10.0f : -10.0f);
    const glm::vec3 A(c, 2.2f, z0), B(c, 2.2f, z0 + 0.13f), C(off, 0.0f, z0 + 0.13f);
    tris.push_back({A, B, C});
    for (int r = 0; r < 200; ++r) {  // rays at points of the sliver, from both sides
      float s = uni(rng), t = uni(rng);
      if (s + t > 1.0f) s = 1.0f - s, t = 1.0f - t;
      const glm::vec3 p = A + s * (B - A) + t * (C - A);
      const glm::vec3 o = p + glm::vec3(r % 2 ? 1.5f : -1.5f, 0.3f * (uni(rng) - 0.5f), 0.3f * (uni(rng) - 0.5f));
      rays.push_back(Ray{o, p - o});
    }
  }
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
