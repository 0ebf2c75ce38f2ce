#include "artrace/core/geometry.h"
#include "../test_util.h"

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
