#include "artrace/core/geometry.h"
#include "../test_util.h"

#include <cmath>

namespace artrace::core {
namespace {

using test::closed_sphere;

TEST(Triangle, HitsAtAnalyticDistanceWithBarycentrics) {
  const Triangle tri{{0, 0, 5}, {4, 0, 5}, {0, 4, 5}};
  Hit h;
  ASSERT_TRUE(intersect_triangle(Ray{{1, 1, 0}, {0, 0, 2}}, tri, 7, h));
  EXPECT_FLOAT_EQ(h.t, 2.5f);
  EXPECT_FLOAT_EQ(h.u, 0.25f);
  EXPECT_FLOAT_EQ(h.v, 0.25f);
  EXPECT_EQ(h.prim, 7u);
}

TEST(Triangle, RespectsSegmentAndBothWindings) {
  const Triangle tri{{0, 0, 5}, {4, 0, 5}, {0, 4, 5}};
  const Triangle flipped{tri.v0, tri.v2, tri.v1};
  Hit h;
  h.t = 4.0f;
  EXPECT_FALSE(intersect_triangle(Ray{{1, 1, 0}, {0, 0, 1}, 0.0f, 4.0f}, tri, 0, h));
  h = Hit{};
  EXPECT_TRUE(intersect_triangle(Ray{{1, 1, 0}, {0, 0, 1}}, flipped, 0, h));
  h = Hit{};
  EXPECT_FALSE(intersect_triangle(Ray{{1, 1, 6}, {0, 0, 1}}, tri, 0, h)) << "behind the origin";
  h = Hit{};
  EXPECT_FALSE(intersect_triangle(Ray{{3, 3, 0}, {0, 0, 1}}, tri, 0, h)) << "outside the hypotenuse";
}

TEST(Triangle, DegenerateTrianglesAreNeverHit) {
  const Triangle line{{0, 0, 5}, {1, 1, 5}, {2, 2, 5}};
  const Triangle point{{1, 1, 5}, {1, 1, 5}, {1, 1, 5}};
  Hit h;
  EXPECT_FALSE(intersect_triangle(Ray{{1, 1, 0}, {0, 0, 1}}, line, 0, h));
  EXPECT_FALSE(intersect_triangle(Ray{{1, 1, 0}, {0, 0, 1}}, point, 0, h));
}

// Watertightness: every ray from the centre of a closed mesh aimed exactly at a vertex or at the
// midpoint of an edge must hit the mesh (no slipping between neighbours).
TEST(Triangle, RaysThroughVerticesAndEdgesOfClosedMeshHit) {
  for (const glm::vec3 centre : {glm::vec3(0.0f), glm::vec3(0.3f, -0.2f, 0.1f), glm::vec3(1000.0f, 3.0f, -20.0f)}) {
    const std::vector<Triangle> mesh = closed_sphere(centre, 1.0f, 12);
    int misses = 0, rays = 0;
    for (const Triangle& t : mesh) {
      for (const glm::vec3 target : {t.v0, t.v1, t.v2, 0.5f * (t.v0 + t.v1), 0.5f * (t.v1 + t.v2),
                                     0.5f * (t.v2 + t.v0)}) {
        for (const glm::vec3 origin : {centre, centre + glm::vec3(0.01f, 0.02f, -0.03f)}) {
          ++rays;
          if (!intersect_brute_force(Ray{origin, target - origin}, mesh).valid()) ++misses;
        }
      }
    }
    EXPECT_EQ(misses, 0) << "of " << rays << " rays from " << centre.x;
  }
}

/// Rays exactly through shared edges and vertices, where the edge functions come out exactly zero
/// in float: a closed cube of integer coordinates, 4 x 4 unit squares a face, two triangles each,
/// and rays from integer points inside it with directions of small integers (the shear factors
/// d_x / d_z are exact) aimed at every vertex and edge midpoint. Each must hit, at the analytic
/// distance to the target.
TEST(Triangle, RaysExactlyThroughGridEdgesAndVerticesHit) {
  std::vector<Triangle> cube;
  for (int axis = 0; axis < 3; ++axis) {
    for (const float side : {0.0f, 4.0f}) {
      for (int i = 0; i < 4; ++i) {
        for (int j = 0; j < 4; ++j) {
          auto p = [&](int a, int b) {
            glm::vec3 v;
            v[axis] = side;
            v[(axis + 1) % 3] = static_cast<float>(a);
            v[(axis + 2) % 3] = static_cast<float>(b);
            return v;
          };
          // alternate the diagonal so that both orientations of shared edges occur
          if ((i + j) % 2) {
            cube.push_back({p(i, j), p(i + 1, j), p(i + 1, j + 1)});
            cube.push_back({p(i, j), p(i + 1, j + 1), p(i, j + 1)});
          } else {
            cube.push_back({p(i, j), p(i + 1, j), p(i, j + 1)});
            cube.push_back({p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)});
          }
        }
      }
    }
  }
  int rays = 0, misses = 0, wrong_t = 0;
  for (const glm::vec3 origin : {glm::vec3(2, 2, 2), glm::vec3(1, 2, 3), glm::vec3(2, 1, 2)}) {
    for (const Triangle& t : cube) {
      for (const glm::vec3 target : {t.v0, t.v1, t.v2, 0.5f * (t.v0 + t.v1), 0.5f * (t.v1 + t.v2), 0.5f * (t.v2 + t.v0)}) {
        const glm::vec3 d = target - origin;
        ++rays;
        const Hit h = intersect_brute_force(Ray{origin, d}, cube);
        if (!h.valid()) {
          if (++misses <= 3) ADD_FAILURE() << "miss from " << origin.x << "," << origin.y << "," << origin.z << " to " << target.x << "," << target.y << "," << target.z;
        } else if (std::fabs(h.t - 1.0f) > 1e-6f) {
          ++wrong_t;  // the target lies on the surface at t = 1
        }
      }
    }
  }
  EXPECT_EQ(misses, 0) << "of " << rays;
  EXPECT_EQ(wrong_t, 0) << "of " << rays;
}

/// A ray that passes 2^-24 beside a shared edge, where the float edge functions round to exactly
/// zero for both triangles: the double-precision recomputation must give it to the triangle it
/// really crosses (prim 1), not by the tie rule to prim 0. Worked out by hand: the edge b-c with
/// b = (1, 1 + 2^-12), c = (-1 - 2^-12, -1 - 2^-11); the edge function at the origin is
/// c.x b.y - c.y b.x = -(1 + 2^-12)^2 + (1 + 2^-11) = -2^-24, but (1 + 2^-12)^2 rounds to 1 + 2^-11.
TEST(Triangle, RayBesideASharedEdgeTakesTheTriangleItCrosses) {
  const float e12 = std::ldexp(1.0f, -12), e11 = std::ldexp(1.0f, -11);
  ASSERT_EQ((1.0f + e12) * (1.0f + e12), 1.0f + e11) << "the float product must round as assumed";
  const glm::vec3 a(-1, 1, 0), b(1, 1 + e12, 0), c(-1 - e12, -1 - e11, 0), d(1, -1, 0);
  const std::vector<Triangle> pair{{a, b, c}, {d, c, b}};
  const Ray r{{0, 0, -1}, {0, 0, 1}};
  const Hit h = intersect_brute_force(r, pair);
  ASSERT_TRUE(h.valid());
  EXPECT_EQ(h.prim, 1u);
  EXPECT_EQ(h.t, 1.0f);
  const test::ExactHit exact = test::intersect_exact(r, pair, 0.0);
  EXPECT_EQ(exact.prim, 1u) << "the double-precision oracle agrees";
}

TEST(Box, TwelveTrianglesFacingOutCoverTheSurfaceOnce) {
  const glm::vec3 lo(-1.0f, 0.5f, 2.0f), hi(2.0f, 1.5f, 2.5f), centre = 0.5f * (lo + hi);
  const std::vector<Triangle> tris = box_triangles(lo, hi);
  ASSERT_EQ(tris.size(), 12u);
  const glm::vec3 e = hi - lo;
  float area = 0.0f;
  glm::vec3 flux(0.0f);  // sum of the area vectors: zero for a closed surface
  for (const Triangle& t : tris) {
    const glm::vec3 n = t.geometric_normal();  // twice the area, along the right-hand normal
    area += 0.5f * glm::length(n);
    flux += n;
    // outward: the normal points away from the box's centre, along one axis only
    EXPECT_GT(glm::dot(n, (t.v0 + t.v1 + t.v2) / 3.0f - centre), 0.0f);
    EXPECT_EQ((n.x != 0.0f) + (n.y != 0.0f) + (n.z != 0.0f), 1);
    for (const glm::vec3& v : {t.v0, t.v1, t.v2})
      for (int a = 0; a < 3; ++a) EXPECT_TRUE(v[a] == lo[a] || v[a] == hi[a]);
  }
  EXPECT_NEAR(area, 2.0f * (e.x * e.y + e.y * e.z + e.z * e.x), 1e-5f);
  EXPECT_NEAR(glm::length(flux), 0.0f, 1e-5f);
  // a ray through the box crosses exactly two of its triangles (in and out)
  const Ray ray{{0.3f, 1.0f, -5.0f}, {0.0f, 0.0f, 1.0f}};
  int crossings = 0;
  for (const Triangle& t : tris) {
    Hit h;
    crossings += intersect_triangle(ray, t, 0, h) ? 1 : 0;
  }
  EXPECT_EQ(crossings, 2);
}

TEST(TriangleMesh, FlattenChecksIndices) {
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.indices = {{0, 1, 2}};
  std::vector<Triangle> out;
  m.flatten_into(out);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].v1, glm::vec3(1, 0, 0));
  m.indices.push_back({0, 1, 3});
  EXPECT_THROW(m.flatten_into(out), std::out_of_range);
}

}  // namespace
}  // namespace artrace::core
