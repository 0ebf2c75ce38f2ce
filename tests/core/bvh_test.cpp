#include "artrace/core/bvh.h"
#include "artrace/core/simd_level.h"
#include "artrace/core/renderer.h"
#include "../test_util.h"


namespace artrace::core {
namespace {

using test::random_rays;
using test::random_soup;

/// Hits of a BVH equal brute force exactly: same triangle, same t (same intersection arithmetic).
size_t mismatches(const Bvh& bvh, const std::vector<Triangle>& tris, const std::vector<Ray>& rays) {
  size_t bad = 0;
  for (const Ray& r : rays) {
    const Hit ref = intersect_brute_force(r, tris);
    const Hit got = bvh.intersect(r);
    if (ref.prim != got.prim || (ref.valid() && ref.t != got.t)) ++bad;
    if (occluded_brute_force(r, tris) != bvh.occluded(r)) ++bad;
  }
  return bad;
}

TEST(Bvh, LazyAndFullMatchBruteForce) {
  std::mt19937 rng(31);
  const auto tris = random_soup(rng, 3000, 0.5f);
  const auto rays = random_rays(rng, 5000);
  const Bvh lazy(tris);
  EXPECT_EQ(lazy.stats().nodes_built, 0u) << "nothing is built before a ray arrives";
  EXPECT_EQ(mismatches(lazy, tris, rays), 0u);
  Bvh full(tris, /*eager=*/true);
  EXPECT_EQ(full.stats().nodes_unbuilt, 0u);
  EXPECT_EQ(mismatches(full, tris, rays), 0u);
}

TEST(Bvh, LazyBuildsOnlyWhatRaysReach) {
  std::mt19937 rng(32);
  const auto tris = random_soup(rng, 20000, 0.1f);
  const Bvh full(tris, true);
  const Bvh lazy(tris);
  // a few rays into one corner of the scene
  for (int i = 0; i < 20; ++i) lazy.intersect(Ray{{-1, -1, -1}, glm::normalize(glm::vec3(1.0f, 1.0f, 1.0f + 0.01f * i))});
  const BvhStats s = lazy.stats();
  EXPECT_GT(s.nodes_built, 0u);
  EXPECT_LT(s.nodes_built * 4, full.stats().nodes_built) << "lazy " << s.nodes_built << " of " << full.stats().nodes_built;
}

/// Rays from several threads in any order build the same tree as one thread: same hits and the
/// same number of nodes.
TEST(Bvh, LazyBuildIsDeterministicAcrossThreads) {
  std::mt19937 rng(33);
  const auto tris = random_soup(rng, 20000, 0.2f);
  const auto rays = random_rays(rng, 20000);
  const Bvh one(tris), two(tris);
  std::vector<Hit> a(rays.size()), b(rays.size());
  for (size_t i = 0; i < rays.size(); ++i) a[i] = one.intersect(rays[i]);
  // 4 threads over a 200 x 100 grid of tiles, one ray a pixel, in reverse order as well (the
  // renderer's own parallel loop, whose hand-over ThreadSanitizer builds can see)
  ASSERT_EQ(rays.size(), 200u * 100u);
  for_each_tile(200, 100, 4, [&](const Tile& t) {
    for (int y = t.y0; y < t.y1; ++y) {
      for (int x = t.x0; x < t.x1; ++x) {
        const size_t i = rays.size() - 1 - (static_cast<size_t>(y) * 200 + x);
        b[i] = two.intersect(rays[i]);
      }
    }
  });
  for (size_t i = 0; i < rays.size(); ++i) {
    ASSERT_EQ(a[i].prim, b[i].prim) << i;
    ASSERT_EQ(a[i].t, b[i].t) << i;
  }
  EXPECT_EQ(one.stats().nodes_built, two.stats().nodes_built);
}

TEST(Bvh, RefitAndRestructureFollowMovingTriangles) {
  std::mt19937 rng(34);
  auto tris = random_soup(rng, 4000, 0.3f);
  Bvh bvh(tris, true);
  std::uniform_real_distribution<float> jitter(-0.2f, 0.2f);
  for (int frame = 0; frame < 6; ++frame) {
    for (auto& t : tris) {
      const glm::vec3 d(jitter(rng), jitter(rng), jitter(rng));
      t.v0 += d;
      t.v1 += d;
      t.v2 += d + glm::vec3(jitter(rng));
    }
    if (frame % 2 == 0) bvh.refit(tris);
    else bvh.restructure(tris);
    const auto rays = random_rays(rng, 2000);
    EXPECT_EQ(mismatches(bvh, tris, rays), 0u) << "frame " << frame;
  }
  EXPECT_THROW(bvh.refit(std::vector<Triangle>(tris.begin(), tris.end() - 1)), std::invalid_argument);
}

/// Scrambling every triangle makes the tree degenerate: restructure resets subtrees (or all) and
/// the hits stay exact.
TEST(Bvh, RestructureRebuildsDegenerateSubtrees) {
  std::mt19937 rng(35);
  auto tris = random_soup(rng, 5000, 0.1f);
  Bvh bvh(tris, true);
  const uint32_t before = bvh.stats().nodes_built;
  std::shuffle(tris.begin(), tris.end(), rng);  // every triangle moves somewhere else
  const uint32_t reset = bvh.restructure(tris);
  EXPECT_GT(reset, 0u);
  EXPECT_LT(bvh.stats().nodes_built, before);
  EXPECT_EQ(mismatches(bvh, tris, random_rays(rng, 3000)), 0u);
  // small motion: nothing degenerates
  for (auto& t : tris) t.v0 += glm::vec3(1e-4f);
  bvh.build_all();
  EXPECT_EQ(bvh.restructure(tris), 0u);
}

/// The tree checked node by node against its own triangles: every node's box is the box of its
/// triangles, to the bit, and every inner node splits along the widest axis of its triangles'
/// centroids (both worked out here from the triangles): after a build, and after a refit and a
/// restructure moved them, once the nodes they left unbuilt are split again (the nodes of `kept`,
/// split before the move and kept by it, keep their axis).
size_t bad_nodes(const Bvh& bvh, const std::vector<bool>& kept = {}) {
  const BvhView v = bvh.view();
  size_t bad = 0;
  std::vector<uint32_t> stack{0};
  while (!stack.empty()) {
    const uint32_t index = stack.back();
    const BvhNode& n = v.nodes[index];
    stack.pop_back();
    Aabb box, cb;
    for (uint32_t i = n.begin; i < n.end; ++i) {
      const Triangle& t = v.tris[v.prim_refs[i]];
      box.extend(Aabb::of(t));
      cb.extend((t.v0 + t.v1 + t.v2) * (1.0f / 3.0f));
    }
    if (box.lo != n.bounds.lo || box.hi != n.bounds.hi) ++bad;
    if (n.split == 0) continue;
    const glm::vec3 e = cb.extent();
    const int widest = e.x >= e.y && e.x >= e.z ? 0 : (e.y >= e.z ? 1 : 2);
    if (e[widest] > 0.0f && n.axis != widest && !(index < kept.size() && kept[index])) ++bad;
    stack.push_back(2 * n.split);
    stack.push_back(2 * n.split + 1);
  }
  return bad;
}

/// The node slots split so far (2N slots; one thread, so none is being split).
std::vector<bool> built_nodes(const Bvh& bvh) {
  std::vector<bool> built(2 * bvh.triangles().size());
  for (size_t i = 0; i < built.size(); ++i) built[i] = bvh.view().state[i].load() == kBvhBuilt;
  return built;
}

TEST(Bvh, NodesHoldTheirTrianglesBoxAndSplitTheirWidestAxis) {
  std::mt19937 rng(36);
  auto tris = random_soup(rng, 6000, 0.2f);
  Bvh bvh(tris, true);
  EXPECT_EQ(bad_nodes(bvh), 0u) << "built";
  // a few triangles move a little way (a tenth of the scene): the small subtrees they leave
  // degenerate, and restructure resets those alone; split again, they must split by where their
  // triangles are now
  std::uniform_int_distribution<size_t> any(0, tris.size() - 1);
  std::uniform_int_distribution<int> axis(0, 2);
  for (int round = 0; round < 3; ++round) {
    for (int k = 0; k < 30; ++k) {
      glm::vec3 d(0.0f);
      d[axis(rng)] = 1.0f;
      Triangle& t = tris[any(rng)];
      t.v0 += d;
      t.v1 += d;
      t.v2 += d;
    }
    EXPECT_GT(bvh.restructure(tris), 0u);
    const std::vector<bool> kept = built_nodes(bvh);
    bvh.build_all();
    EXPECT_EQ(bad_nodes(bvh, kept), 0u) << "restructured";
    EXPECT_EQ(mismatches(bvh, tris, random_rays(rng, 2000)), 0u);
  }
  // a refit of a tree half built: the nodes no ray reached yet split by the new shape
  Bvh lazy(tris);
  for (const Ray& r : random_rays(rng, 30)) lazy.intersect(r);
  const std::vector<bool> split_before = built_nodes(lazy);
  EXPECT_LT(lazy.stats().nodes_built * 4, split_before.size()) << "most of the tree unbuilt";
  for (auto& t : tris) {
    t.v0 *= glm::vec3(1.0f, 6.0f, 0.2f);
    t.v1 *= glm::vec3(1.0f, 6.0f, 0.2f);
    t.v2 *= glm::vec3(1.0f, 6.0f, 0.2f);
  }
  lazy.refit(tris);
  lazy.build_all();
  EXPECT_EQ(bad_nodes(lazy, split_before), 0u) << "refitted half built";
}

TEST(Bvh, PacketsEqualSingleRaysOnEveryKernel) {
  std::mt19937 rng(36);
  const auto tris = random_soup(rng, 3000, 0.5f);
  const Bvh bvh(tris);
  const SimdLevel saved = simd_level();
  for (const SimdLevel level : {SimdLevel::kScalar, SimdLevel::kSse, SimdLevel::kAvx2, SimdLevel::kAvx512}) {
    if (!simd_level_supported(level)) continue;
    set_simd_level(level);
    for (int p = 0; p < 1000; ++p) {
      RayPacket packet;
      const glm::vec3 o = test::random_point(rng, -2.0f, 12.0f);
      const glm::vec3 base = test::random_direction(rng);
      for (int i = 0; i < kPacketSize; ++i) {
        const glm::vec3 d = p % 2 ? test::random_direction(rng) : glm::normalize(base + 0.05f * test::random_direction(rng));
        packet.set(i, Ray{o, d});
      }
      const LaneMask mask = p % 3 == 0 ? 0x6du : p % 3 == 1 ? 0x9b00u : kAllLanes;
      HitPacket hits;
      bvh.intersect(packet, mask, hits);
      const LaneMask blocked = bvh.occluded(packet, mask);
      for (int i = 0; i < kPacketSize; ++i) {
        if (!((mask >> i) & 1u)) continue;
        const Hit h = bvh.intersect(packet.get(i));
        ASSERT_EQ(hits.prim[i], h.prim) << to_string(level);
        if (h.valid()) {
          ASSERT_EQ(hits.t[i], h.t);
        }
        ASSERT_EQ(((blocked >> i) & 1u) != 0, h.valid());
      }
    }
  }
  set_simd_level(saved);
}

TEST(Bvh, EmptyAndTinyInputs) {
  const Bvh empty(std::vector<Triangle>{});
  EXPECT_FALSE(empty.intersect(Ray{{0, 0, 0}, {1, 0, 0}}).valid());
  const Bvh one({{{0, 0, 5}, {4, 0, 5}, {0, 4, 5}}});
  EXPECT_FLOAT_EQ(one.intersect(Ray{{1, 1, 0}, {0, 0, 1}}).t, 5.0f);
  // many identical triangles: all centroids coincide
  const Bvh pile(std::vector<Triangle>(100, Triangle{{0, 0, 5}, {4, 0, 5}, {0, 4, 5}}));
  const Hit h = pile.intersect(Ray{{1, 1, 0}, {0, 0, 1}});
  EXPECT_EQ(h.prim, 0u) << "ties go to the smallest index";
}

}  // namespace
}  // namespace artrace::core
