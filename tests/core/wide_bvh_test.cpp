#include "artrace/core/wide_bvh.h"
#include "artrace/core/kd_tree.h"
#include "artrace/core/simd_level.h"
#include "../test_util.h"

#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <functional>
#include <limits>

namespace artrace::core {
namespace {

/// Every instruction set this CPU runs, for `fn(level name)`; the level is restored after.
template <class Fn>
void on_every_level(const Fn& fn) {
  const SimdLevel saved = simd_level();
  for (const SimdLevel level : {SimdLevel::kScalar, SimdLevel::kSse, SimdLevel::kAvx2, SimdLevel::kAvx512}) {
    if (!simd_level_supported(level)) {
      std::cout << "[ note ] " << to_string(level) << " not supported by this CPU, not tested\n";
      continue;
    }
    set_simd_level(level);
    fn(to_string(level));
  }
  set_simd_level(saved);
}

/// Closest and any hits equal brute force bit for bit: the same triangle, t, u and v (the
/// kernels run the brute force's arithmetic, and ties go to the smaller triangle either way).
void expect_equals_brute_force(const WideBvh& bvh, const std::vector<Triangle>& tris, const std::vector<Ray>& rays,
                               const std::string& what) {
  size_t wrong = 0, hits = 0, blocked = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    const Hit ref = intersect_brute_force(rays[i], tris);
    const Hit got = bvh.intersect(rays[i]);
    hits += ref.valid();
    const bool same = ref.prim == got.prim && (!ref.valid() || (ref.t == got.t && ref.u == got.u && ref.v == got.v));
    if (!same && ++wrong <= 5) {
      ADD_FAILURE() << what << ": ray " << i << " brute force prim " << ref.prim << " t " << ref.t << ", wide BVH prim "
                    << got.prim << " t " << got.t;
    }
    const bool occluded = occluded_brute_force(rays[i], tris);
    blocked += occluded;
    if (occluded != bvh.occluded(rays[i]) && ++wrong <= 5) {
      ADD_FAILURE() << what << ": ray " << i << " any hit: brute force " << occluded;
    }
  }
  EXPECT_EQ(wrong, 0u) << what;
  EXPECT_GT(hits, rays.size() / 20) << what << ": the test rays should hit something";
  EXPECT_LT(blocked, rays.size()) << what << ": and miss sometimes";
}

/// How many leaf lanes hold each triangle (spatial splits may put one in several leaves).
std::vector<int> lanes_per_triangle(const WideBvh& bvh, size_t triangles) {
  std::vector<int> count(triangles, 0);
  for (const TriBlock& b : bvh.blocks()) {
    for (const uint32_t p : b.prim) {
      if (p != kInvalidId) ++count.at(p);
    }
  }
  return count;
}

/// Long slivers crossing a box in all directions: their own boxes overlap everywhere, the case
/// spatial splits are for.
std::vector<Triangle> crossing_slivers(std::mt19937& rng, int count) {
  std::vector<Triangle> tris;
  for (int i = 0; i < count; ++i) {
    const glm::vec3 a = test::random_point(rng, 0.0f, 10.0f), b = test::random_point(rng, 0.0f, 10.0f);
    tris.push_back({a, b, a + test::random_point(rng, -0.05f, 0.05f)});
  }
  return tris;
}

TEST(WideBvh, EmptySceneAndOneTriangle) {
  const WideBvh none(std::vector<Triangle>{});
  EXPECT_TRUE(none.empty());
  EXPECT_FALSE(none.intersect(Ray{{0, 0, 0}, {1, 0, 0}}).valid());
  EXPECT_FALSE(none.occluded(Ray{{0, 0, 0}, {1, 0, 0}}));
  const WideBvh one(std::vector<Triangle>{{{0, 0, 5}, {1, 0, 5}, {0, 1, 5}}});
  const Hit h = one.intersect(Ray{{0.25f, 0.25f, 0}, {0, 0, 1}});
  ASSERT_TRUE(h.valid());
  EXPECT_EQ(h.t, 5.0f);
  EXPECT_EQ(h.u, 0.25f);
  EXPECT_EQ(h.v, 0.25f);
  EXPECT_FALSE(one.intersect(Ray{{0.25f, 0.25f, 0}, {0, 0, 1}, 0.0f, 4.99f}).valid()) << "tmax is respected";
  EXPECT_TRUE(one.occluded(Ray{{0.25f, 0.25f, 0}, {0, 0, 1}, 0.0f, 5.0f})) << "tmax is inclusive";
  EXPECT_FALSE(one.occluded(Ray{{0.25f, 0.25f, 0}, {0, 0, 1}, 5.0f, 9.0f})) << "tmin is exclusive";
}

TEST(WideBvh, RandomSoupsEqualBruteForceOnEveryInstructionSet) {
  for (const uint32_t seed : {1u, 2u, 3u}) {
    std::mt19937 rng(seed);
    const auto tris = test::random_soup(rng, 3000, seed == 3 ? 2.0f : 0.4f);
    std::vector<Ray> rays = test::random_rays(rng, test::brute_force_rays(4000));
    for (size_t i = 0; i < rays.size(); i += 3) rays[i].tmax = 3.0f;  // segments, as shadow rays are
    for (const float spatial : {0.0f, 0.5f}) {
      WideBvhBuildOptions opt;
      opt.spatial_budget = spatial;
      const WideBvh bvh(tris, opt);
      on_every_level([&](const std::string& level) {
        expect_equals_brute_force(bvh, tris, rays, "seed " + std::to_string(seed) + ", spatial " + std::to_string(spatial) + ", " + level);
      });
    }
  }
}

TEST(WideBvh, AdversarialCasesEqualBruteForce) {
  const auto tris = test::adversarial_scene();
  std::mt19937 rng(7);
  std::vector<Ray> rays = test::random_rays(rng, 3000);
  // through every vertex and edge midpoint, from random origins and along the axes (directions
  // with zero components: infinite inverse directions, NaN slab distances on box planes)
  for (const Triangle& t : tris) {
    for (const glm::vec3 p : {t.v0, t.v1, t.v2, 0.5f * (t.v0 + t.v1), 0.5f * (t.v1 + t.v2)}) {
      const glm::vec3 o = test::random_point(rng, -2.0f, 12.0f);
      rays.push_back(Ray{o, p - o});
      rays.push_back(Ray{p + glm::vec3(0, 5, 0), {0, -1, 0}});
      rays.push_back(Ray{p - glm::vec3(5, 0, 0), {1, 0, 0}});
      rays.push_back(Ray{p + glm::vec3(0, 0, 5), {0, 0, -1}});
    }
  }
  // lying in the boxes' faces
  rays.push_back(Ray{{-2, 0, 0.5f}, {1, 0, 0}});
  rays.push_back(Ray{{1, 0.5f, -3}, {0, 0, 1}});
  rays.push_back(Ray{{1, 1, -3}, {0, 0, 1}});
  // segments reaching behind their origin (tmin < 0), which the kernels widen by magnitude
  const size_t forward = rays.size();
  for (size_t i = 0; i < forward; i += 2) {
    Ray r = rays[i];
    r.org += 6.0f * r.dir / glm::length(r.dir);
    r.tmin = -12.0f / glm::length(r.dir);
    rays.push_back(r);
  }
  for (const auto& [max_leaf, spatial] : {std::pair{1u, 0.0f}, {8u, 0.0f}, {8u, 0.5f}, {32u, 0.5f}}) {
    WideBvhBuildOptions opt;
    opt.max_leaf = max_leaf;
    opt.spatial_budget = spatial;
    const WideBvh bvh(tris, opt);
    on_every_level([&](const std::string& level) {
      expect_equals_brute_force(bvh, tris, rays, "max_leaf " + std::to_string(max_leaf) + ", spatial " + std::to_string(spatial) + ", " + level);
    });
  }
}

TEST(WideBvh, SliversLeaningOffBoxPlanesEqualBruteForce) {
  std::vector<Triangle> tris;
  std::vector<Ray> rays;
  test::sliver_scene(tris, rays);
  for (int i = 0; i < 50; ++i) rays.push_back(Ray{{1.0f + 0.04f * i, 3.0f, 0.5f}, {0.1f, 1.0f, 0.0f}});  // above it all, going up
  for (const float spatial : {0.0f, 0.5f}) {
    WideBvhBuildOptions opt;
    opt.spatial_budget = spatial;
    const WideBvh bvh(tris, opt);
    on_every_level([&](const std::string& level) {
      expect_equals_brute_force(bvh, tris, rays, "slivers, spatial " + std::to_string(spatial) + ", " + level);
    });
  }
}

/// 16 rays of a 4x4 pixel block, as a pinhole camera at `o` looking along `ahead` casts them
/// (pixel pitch `pitch` radians), each origin moved by up to `spread` (shadow-ray-like packets).
RayPacket camera_packet(std::mt19937& rng, glm::vec3 o, glm::vec3 ahead, float pitch, float spread) {
  ahead = glm::normalize(ahead);
  const glm::vec3 side =
      glm::normalize(glm::cross(ahead, std::fabs(ahead.y) < 0.9f ? glm::vec3(0, 1, 0) : glm::vec3(1, 0, 0)));
  const glm::vec3 up = glm::cross(side, ahead);
  RayPacket p;
  for (int i = 0; i < kPacketSize; ++i) {
    const glm::vec3 d = ahead + pitch * ((i % 4 - 1.5f) * side + (i / 4 - 1.5f) * up);
    p.set(i, Ray{o + test::random_point(rng, -spread, spread), d});
  }
  return p;
}

/// Packets give each lane in their mask the single ray's Hit, bit for bit, leave the other lanes
/// alone; with the AVX-512 kernels some packets must be ones the frustums are meant for.
void expect_packets_equal_brute_force(const WideBvh& bvh, const std::vector<Triangle>& tris,
                                      const std::vector<std::pair<RayPacket, LaneMask>>& packets,
                                      const std::string& what) {
  size_t wrong = 0, hits = 0, lanes = 0, paying = 0;
  for (size_t k = 0; k < packets.size(); ++k) {
    const auto& [rays, mask] = packets[k];
    HitPacket got;
    for (int i = 0; i < kPacketSize; ++i) {
      got.t[i] = -1.0f - i;
      got.u[i] = got.v[i] = -2.0f;
      got.prim[i] = got.inst[i] = 1000000u + i;
    }
    bvh.intersect(rays, mask, got);
    paying += WideBvh::frustums_pay(mask);
    for (int i = 0; i < kPacketSize; ++i) {
      if (!((mask >> i) & 1u)) {
        if ((got.t[i] != -1.0f - i || got.prim[i] != 1000000u + i || got.inst[i] != 1000000u + i) && ++wrong <= 5)
          ADD_FAILURE() << what << ": packet " << k << " lane " << i << " is outside the mask but was written";
        continue;
      }
      ++lanes;
      const Hit ref = intersect_brute_force(rays.get(i), tris);
      hits += ref.valid();
      const bool same = ref.prim == got.prim[i] && got.inst[i] == kInvalidId &&
                        (ref.valid() ? ref.t == got.t[i] && ref.u == got.u[i] && ref.v == got.v[i]
                                     : (got.t[i] == rays.tmax[i] || (std::isnan(got.t[i]) && std::isnan(rays.tmax[i]))));
      if (!same && ++wrong <= 5) {
        ADD_FAILURE() << what << ": packet " << k << " lane " << i << " brute force prim " << ref.prim << " t " << ref.t
                      << ", packet prim " << got.prim[i] << " t " << got.t[i];
      }
    }
  }
  EXPECT_EQ(wrong, 0u) << what;
  EXPECT_GT(hits, lanes / 10) << what << ": the test rays should hit something";
  EXPECT_LT(hits, lanes) << what << ": and miss sometimes";
  if (simd_level() == SimdLevel::kAvx512) {
    EXPECT_GT(paying, 0u) << what << ": packets with lanes in both halves";
  }
}

/// Camera-like packets, fine and coarse, from one origin and from spread ones, with partial masks,
/// segments, lanes in several direction octants (several frustums a packet), and the lanes the
/// frustum must leave to single rays (a direction component of zero, tmin < 0); aimed at random
/// points and at the adversarial scene's vertices and edges, whose exact rays join the packets.
std::vector<std::pair<RayPacket, LaneMask>> test_packets(std::mt19937& rng, const std::vector<Triangle>& tris,
                                                         size_t count) {
  std::vector<std::pair<RayPacket, LaneMask>> packets;
  std::uniform_int_distribution<uint32_t> any_mask(1u, kAllLanes);
  for (size_t k = 0; k < count; ++k) {
    const glm::vec3 o = test::random_point(rng, -2.0f, 12.0f);
    const Triangle& aim = tris[rng() % tris.size()];
    const glm::vec3 target =
        k % 3 == 0 ? test::random_point(rng, 0.0f, 10.0f) : (k % 3 == 1 ? aim.v0 : 0.5f * (aim.v1 + aim.v2));
    const float pitch = std::array<float, 4>{1e-4f, 2e-3f, 0.03f, 0.4f}[k % 4];  // 0.4: the lanes span octants
    const float spread = std::array<float, 3>{0.0f, 1e-3f, 0.3f}[k % 3];
    RayPacket p = camera_packet(rng, o, target - o, pitch, spread);
    const int exact = static_cast<int>(rng() % kPacketSize);
    p.set(exact, Ray{o, target - o});  // exactly through the vertex or edge
    LaneMask mask = kAllLanes;
    switch (k % 8) {
      case 7: mask = 1u << exact; break;  // alone: the frustum is that ray, its slack all that is left
      case 1: mask = any_mask(rng); break;
      case 2: mask = 0x00ffu; break;  // one half only: a frustum of eight lanes at most
      case 3: mask = 1u << (rng() % kPacketSize); break;
      case 4: p.dir[rng() % 3][rng() % kPacketSize] = 0.0f; break;  // an infinite inverse direction
      case 5: {  // a segment reaching behind its origin
        const int i = static_cast<int>(rng() % kPacketSize);
        p.org[0][i] += 3.0f * p.dir[0][i];
        p.org[1][i] += 3.0f * p.dir[1][i];
        p.org[2][i] += 3.0f * p.dir[2][i];
        p.tmin[i] = -3.0f;
        break;
      }
      case 6:  // segments, some starting past their origin, one lane's end NaN (it hits nothing)
        for (int i = 0; i < kPacketSize; ++i) {
          p.tmin[i] = (i % 3 == 0) ? 0.5f : 0.0f;
          p.tmax[i] = 2.0f + static_cast<float>(i);
        }
        if (k % 16 == 14) p.tmax[rng() % kPacketSize] = std::numeric_limits<float>::quiet_NaN();
        break;
      default: break;
    }
    packets.emplace_back(p, mask);
  }
  return packets;
}

TEST(WideBvh, PacketsEqualBruteForceOnEveryInstructionSet) {
  if (!simd_level_supported(SimdLevel::kAvx512))
    std::cout << "[ note ] no AVX-512 on this CPU: packets go a ray at a time, the frustums are not tested\n";
  std::mt19937 rng(21);
  auto soup = test::random_soup(rng, 4000, 0.4f);
  const auto sphere = test::closed_sphere({5, 5, 5}, 2.0f, 30);
  soup.insert(soup.end(), sphere.begin(), sphere.end());
  const auto adversarial = test::adversarial_scene();
  const std::vector<Triangle>* scenes[] = {&soup, &adversarial};
  for (const std::vector<Triangle>* tris : scenes) {
    const auto packets = test_packets(rng, *tris, test::brute_force_rays(4000) / 16 + 40);
    for (const auto& [max_leaf, spatial] : {std::pair{1u, 0.0f}, {8u, 0.0f}, {8u, 0.5f}, {32u, 0.0f}}) {
      WideBvhBuildOptions opt;
      opt.max_leaf = max_leaf;
      opt.spatial_budget = spatial;
      const WideBvh bvh(*tris, opt);
      on_every_level([&](const std::string& level) {
        expect_packets_equal_brute_force(bvh, *tris, packets,
                                         std::string(tris == &soup ? "soup" : "adversarial") + ", max_leaf " +
                                             std::to_string(max_leaf) + ", spatial " + std::to_string(spatial) + ", " + level);
      });
    }
  }
  std::vector<Triangle> slivers;
  std::vector<Ray> sliver_rays;
  test::sliver_scene(slivers, sliver_rays);
  for (int i = 0; i < 48; ++i) {  // above it all, going up
    sliver_rays.push_back(Ray{{1.0f + 0.04f * i, 3.0f, 0.5f}, {0.1f, 1.0f, 0.0f}});
  }
  // as the scene lists them (neighbours), shuffled, and each ray alone (a frustum of one ray is
  // that ray: the slack on its far ends is what keeps the hits that lie on a box's far face)
  std::vector<std::pair<RayPacket, LaneMask>> packets;
  std::vector<Ray> shuffled = sliver_rays;
  std::shuffle(shuffled.begin(), shuffled.end(), rng);
  for (const std::vector<Ray>* list : {&sliver_rays, &shuffled}) {
    for (size_t i = 0; i + kPacketSize <= list->size(); i += kPacketSize) {
      RayPacket p;
      for (int j = 0; j < kPacketSize; ++j) p.set(j, (*list)[i + j]);
      packets.emplace_back(p, kAllLanes);
      if (list == &sliver_rays) {
        for (int j = 0; j < kPacketSize; ++j) packets.emplace_back(p, 1u << j);
      }
    }
  }
  const WideBvh bvh(slivers);
  on_every_level([&](const std::string& level) { expect_packets_equal_brute_force(bvh, slivers, packets, "slivers, " + level); });
  const WideBvh none(std::vector<Triangle>{});
  HitPacket h;
  none.intersect(packets[0].first, kAllLanes, h);
  for (int i = 0; i < kPacketSize; ++i) EXPECT_EQ(h.prim[i], kInvalidId);
}

/// The same Hit as the kd-tree, bit for bit, on every ray: either structure may serve a ray.
TEST(WideBvh, SameHitsAsTheKdTree) {
  std::mt19937 rng(12);
  auto tris = test::random_soup(rng, 20000, 0.3f);
  const auto sphere = test::closed_sphere({5, 5, 5}, 2.0f, 30);
  tris.insert(tris.end(), sphere.begin(), sphere.end());
  const KdTree kd(tris);
  const WideBvh bvh(tris);
  size_t hits = 0;
  for (const Ray& r : test::random_rays(rng, 20000)) {
    const Hit a = kd.intersect(r), b = bvh.intersect(r);
    ASSERT_EQ(a.prim, b.prim);
    ASSERT_EQ(a.t, b.t);
    ASSERT_EQ(a.u, b.u);
    ASSERT_EQ(a.v, b.v);
    hits += a.valid();
  }
  EXPECT_GT(hits, 5000u);
}

/// Triangles in geometric progression, each half the last and nested at the origin's corner:
/// every binned split peels off one triangle, so past a depth the builder halves the ranges; the
/// depth (and the traversal's stack) stays bounded and the hits stay right.
TEST(WideBvh, InputsThatDefeatTheSahKeepABoundedDepth) {
  std::vector<Triangle> tris;
  float s = 1.0f;
  for (int i = 0; i < 3000; ++i, s *= 0.97f) {
    tris.push_back({{s, 0, 0}, {0, s, 0}, {0, 0, s}});
    tris.push_back({{s, 0, 0.01f * s}, {0, s, 0.01f * s}, {s, s, 0.01f * s}});
  }
  WideBvhBuildOptions opt;
  opt.bins = 2;  // the coarsest bins: the SAH has almost nothing to choose from
  const WideBvh bvh(tris, opt);
  const WideBvhStats st = bvh.stats(opt);
  EXPECT_LE(st.max_depth, 24u + 11u);
  EXPECT_EQ(st.triangles_in_blocks, tris.size());
  std::mt19937 rng(4);
  std::vector<Ray> rays;
  for (int i = 0; i < 3000; ++i) {
    const glm::vec3 target = test::random_point(rng, 0.0f, 0.5f) * test::random_point(rng, 0.0f, 1.0f).x;
    const glm::vec3 o = test::random_point(rng, -2.0f, 2.0f);
    rays.push_back(Ray{o, target - o});
  }
  expect_equals_brute_force(bvh, tris, rays, "geometric progression");
}

TEST(WideBvh, NonFiniteTrianglesAreLeftOutAndNeverHit) {
  std::mt19937 rng(5);
  auto tris = test::random_soup(rng, 500, 0.5f);
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  tris.push_back({{0, 0, 0}, {inf, 0, 0}, {0, 1, 0}});
  tris.push_back({{nan, 0, 0}, {1, 0, 0}, {0, 1, 0}});
  const WideBvh bvh(tris);
  const std::vector<int> lanes = lanes_per_triangle(bvh, tris.size());
  for (size_t p = 0; p < 500; ++p) EXPECT_GE(lanes[p], 1) << "triangle " << p;
  EXPECT_EQ(lanes[500], 0);
  EXPECT_EQ(lanes[501], 0);
  expect_equals_brute_force(bvh, tris, test::random_rays(rng, 2000), "non-finite");
}

TEST(WideBvh, BuildIsIdenticalForAnyThreadCount) {
  std::mt19937 rng(3);
  const auto tris = test::random_soup(rng, 30000, 0.3f);
  WideBvhBuildOptions opt;
  opt.parallel_above = 256;  // many parallel joins even on this small scene
  auto build = [&](int threads) {
    tbb::task_arena arena(threads);
    WideBvh bvh;
    arena.execute([&] { bvh = WideBvh(tris, opt); });
    return bvh;
  };
  const WideBvh one = build(1), two = build(2), four = build(4);
  for (const WideBvh* other : {&two, &four}) {
    ASSERT_EQ(one.nodes().size(), other->nodes().size());
    ASSERT_EQ(one.blocks().size(), other->blocks().size());
    EXPECT_EQ(0, std::memcmp(one.nodes().data(), other->nodes().data(), one.nodes().size() * sizeof(WideNode)));
    EXPECT_EQ(0, std::memcmp(one.blocks().data(), other->blocks().data(), one.blocks().size() * sizeof(TriBlock)));
  }
}

/// With object splits only, every triangle sits in exactly one leaf lane, leaves hold at most
/// max_leaf, and every child box holds the triangles below it.
TEST(WideBvh, EveryTriangleOnceInsideItsBoxes) {
  std::mt19937 rng(8);
  const auto tris = test::random_soup(rng, 5000, 0.6f);
  WideBvhBuildOptions opt;
  opt.max_leaf = 6;
  opt.spatial_budget = 0.0f;
  const WideBvh bvh(tris, opt);
  std::vector<int> seen(tris.size(), 0);
  std::function<void(uint32_t, const Aabb&)> visit = [&](uint32_t ref, const Aabb& box) {
    if (WideNode::is_leaf(ref)) {
      uint32_t in_leaf = 0;
      for (uint32_t b = 0; b < WideNode::block_count(ref); ++b) {
        for (const uint32_t p : bvh.blocks()[WideNode::first_block(ref) + b].prim) {
          if (p == kInvalidId) continue;
          ++seen[p];
          ++in_leaf;
          const Aabb t = Aabb::of(tris[p]);
          for (int a = 0; a < 3; ++a) {
            EXPECT_LE(box.lo[a], t.lo[a]);
            EXPECT_GE(box.hi[a], t.hi[a]);
          }
        }
      }
      EXPECT_LE(in_leaf, opt.max_leaf);
      return;
    }
    // an inner reference is its node's byte offset in the array
    ASSERT_EQ(ref % sizeof(WideNode), 0u) << "reference " << ref;
    ASSERT_LT(wide_node_index(ref), bvh.nodes().size()) << "reference " << ref;
    const WideNode& n = bvh.nodes()[wide_node_index(ref)];
    int used = 0;
    for (int c = 0; c < 8; ++c) {
      if (n.child[c] == WideNode::kEmpty) continue;
      ++used;
      Aabb b;
      b.lo = {n.lo[0][c], n.lo[1][c], n.lo[2][c]};
      b.hi = {n.hi[0][c], n.hi[1][c], n.hi[2][c]};
      for (int a = 0; a < 3; ++a) {
        EXPECT_LE(box.lo[a], b.lo[a]);
        EXPECT_GE(box.hi[a], b.hi[a]);
      }
      visit(n.child[c], b);
    }
    EXPECT_GE(used, 2) << "a node has at least two children";
  };
  Aabb all;
  for (const Triangle& t : tris) all.extend(Aabb::of(t));
  visit(bvh.view().root, all);
  for (size_t p = 0; p < tris.size(); ++p) ASSERT_EQ(seen[p], 1) << "triangle " << p;
}

/// Spatial splits: a triangle may sit in several leaves, each with a box of part of it. What the
/// traversal needs is that every point of every triangle lies in the boxes of the whole path
/// down to some leaf that holds the triangle. Checked on points spread over each triangle
/// (vertices, edge points, inner points), against the leaves' paths; the references stay within
/// the budget, and the hits equal brute force.
TEST(WideBvh, SpatialSplitsCoverEveryPointOfEveryTriangle) {
  std::mt19937 rng(21);
  const auto tris = crossing_slivers(rng, 4000);
  WideBvhBuildOptions opt;
  opt.spatial_budget = 0.5f;
  const WideBvh bvh(tris, opt);
  const std::vector<int> lanes = lanes_per_triangle(bvh, tris.size());
  size_t refs = 0;
  for (const int c : lanes) refs += static_cast<size_t>(c);
  EXPECT_GT(refs, tris.size() + tris.size() / 10) << "spatial splits should copy many of these slivers";
  EXPECT_LE(refs, tris.size() + static_cast<size_t>(opt.spatial_budget * static_cast<float>(tris.size())));

  // each triangle's leaves, as the intersection of the boxes on their paths
  std::vector<std::vector<Aabb>> paths(tris.size());
  std::function<void(uint32_t, const Aabb&)> visit = [&](uint32_t ref, const Aabb& path) {
    if (WideNode::is_leaf(ref)) {
      for (uint32_t b = 0; b < WideNode::block_count(ref); ++b) {
        for (const uint32_t p : bvh.blocks()[WideNode::first_block(ref) + b].prim) {
          if (p != kInvalidId) paths[p].push_back(path);
        }
      }
      return;
    }
    const WideNode& n = bvh.nodes()[wide_node_index(ref)];
    for (int c = 0; c < 8; ++c) {
      if (n.child[c] == WideNode::kEmpty) continue;
      Aabb b;
      b.lo = glm::max(path.lo, glm::vec3(n.lo[0][c], n.lo[1][c], n.lo[2][c]));
      b.hi = glm::min(path.hi, glm::vec3(n.hi[0][c], n.hi[1][c], n.hi[2][c]));
      visit(n.child[c], b);
    }
  };
  visit(bvh.view().root, Aabb{glm::vec3(-kInfinity), glm::vec3(kInfinity)});
  size_t uncovered = 0;
  for (size_t p = 0; p < tris.size(); ++p) {
    const Triangle& t = tris[p];
    std::vector<glm::vec3> points{t.v0, t.v1, t.v2};
    for (int k = 1; k < 20; ++k) {  // along an edge, and inside (barycentric 0.25 s, 0.5 s, 1 - 0.75 s)
      const float s = static_cast<float>(k) / 20.0f;
      points.push_back(t.v0 + s * (t.v1 - t.v0));
      points.push_back(t.v2 + 0.5f * s * (t.v1 - t.v2) + 0.25f * s * (t.v0 - t.v2));
    }
    for (size_t k = 0; k < points.size(); ++k) {
      const glm::vec3 q = points[k];
      bool inside = false;
      for (const Aabb& b : paths[p]) {
        inside = inside || (q.x >= b.lo.x && q.y >= b.lo.y && q.z >= b.lo.z && q.x <= b.hi.x && q.y <= b.hi.y && q.z <= b.hi.z);
      }
      if (!inside && ++uncovered <= 5) ADD_FAILURE() << "triangle " << p << " point " << k << " lies outside all its leaves' paths";
    }
  }
  EXPECT_EQ(uncovered, 0u);

  // rays through the slivers' vertices and edges, and random ones
  std::vector<Ray> rays = test::random_rays(rng, 2000);
  for (size_t p = 0; p < tris.size(); p += 4) {
    const glm::vec3 o = test::random_point(rng, -2.0f, 12.0f);
    rays.push_back(Ray{o, 0.5f * (tris[p].v0 + tris[p].v1) - o});
    rays.push_back(Ray{o, tris[p].v1 - o});
  }
  on_every_level([&](const std::string& level) { expect_equals_brute_force(bvh, tris, rays, "slivers, " + level); });
}

/// On slivers crossing each other, spatial splits lower the hierarchy's SAH cost below that of
/// object splits alone.
TEST(WideBvh, SpatialSplitsLowerTheCostOfCrossingSlivers) {
  std::mt19937 rng(22);
  const auto tris = crossing_slivers(rng, 4000);
  WideBvhBuildOptions object_only;
  object_only.spatial_budget = 0.0f;
  WideBvhBuildOptions spatial;
  spatial.spatial_budget = 0.5f;
  const double without = WideBvh(tris, object_only).stats(object_only).sah_cost;
  const double with = WideBvh(tris, spatial).stats(spatial).sah_cost;
  EXPECT_LT(with, 0.99 * without) << "SAH cost " << with << " with spatial splits, " << without << " without";
}

TEST(WideBvh, SpatialBudgetOutOfRangeIsRejected) {
  const std::vector<Triangle> tris{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}};
  for (const float bad : {-0.1f, 1.5f, std::numeric_limits<float>::quiet_NaN()}) {
    WideBvhBuildOptions opt;
    opt.spatial_budget = bad;
    EXPECT_THROW(WideBvh(tris, opt), std::invalid_argument) << bad;
  }
}

TEST(WideBvh, BinCountOutOfRangeIsRejected) {
  const std::vector<Triangle> tris{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}};
  for (const int bad : {-1, 0, 1, 257}) {
    WideBvhBuildOptions opt;
    opt.bins = bad;
    EXPECT_THROW(WideBvh(tris, opt), std::invalid_argument) << bad;
  }
  for (const int good : {2, 256}) {  // the ends of the range build
    WideBvhBuildOptions opt;
    opt.bins = good;
    EXPECT_EQ(WideBvh(tris, opt).intersect(Ray{{0.25f, 0.25f, 1.0f}, {0.0f, 0.0f, -1.0f}}).prim, 0u) << good;
  }
}

}  // namespace
}  // namespace artrace::core
