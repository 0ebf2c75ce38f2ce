#include "artrace/core/kd_tree.h"
#include "artrace/core/simd_level.h"
#include "../test_util.h"

#include <tbb/task_arena.h>

#include <cstring>
#include <limits>

namespace artrace::core {
namespace {

using test::random_rays;
using test::random_soup;
using test::adversarial_scene;

void expect_matches_brute_force(const KdTree& tree, const std::vector<Triangle>& tris, const std::vector<Ray>& rays,
                                const std::string& what);

/// The builds every brute-force test covers: the default (binned splits above 1024 triangles,
/// the exact sweep below), the exact sweep everywhere, and binned splits down to 16 triangles.
std::vector<std::pair<std::string, KdTreeBuildOptions>> builds() {
  KdTreeBuildOptions sweep, binned;
  sweep.binned_above = 0;
  binned.binned_above = 16;
  return {{"default build", KdTreeBuildOptions{}}, {"sweep everywhere", sweep}, {"binned above 16", binned}};
}

/// Closest hits must name the same triangle as brute force, with t equal to 1e-5 relative.
void expect_matches_brute_force(const std::vector<Triangle>& tris, const std::vector<Ray>& rays,
                                const std::string& what) {
  for (const auto& [name, opt] : builds()) expect_matches_brute_force(KdTree(tris, opt), tris, rays, what + ", " + name);
}

void expect_matches_brute_force(const KdTree& tree, const std::vector<Triangle>& tris, const std::vector<Ray>& rays,
                                const std::string& what) {
  size_t mismatches = 0, hits = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    const Hit ref = intersect_brute_force(rays[i], tris);
    const Hit got = tree.intersect(rays[i]);
    hits += ref.valid();
    const bool same = ref.prim == got.prim &&
                      (!ref.valid() || std::fabs(ref.t - got.t) <= 1e-5f * std::max(1.0f, std::fabs(ref.t)));
    if (!same && ++mismatches <= 5) {
      ADD_FAILURE() << what << ": ray " << i << " brute force prim " << ref.prim << " t " << ref.t
                    << ", kd-tree prim " << got.prim << " t " << got.t;
    }
    ASSERT_EQ(occluded_brute_force(rays[i], tris), tree.occluded(rays[i])) << what << ": ray " << i;
    // brute force above calls the kernels' own triangle test; this checks that test too
    if (i % 4 == 0) {
      EXPECT_TRUE(test::agrees_with_exact(rays[i], tris, got)) << what << ": ray " << i;
    }
  }
  EXPECT_EQ(mismatches, 0u) << what;
  if (!rays.empty() && !tris.empty()) {
    EXPECT_GT(hits, 0u) << what << ": the test rays should hit something";
  }
}

TEST(KdTree, EmptySceneReturnsNoHit) {
  const KdTree tree(std::vector<Triangle>{});
  EXPECT_FALSE(tree.intersect(Ray{{0, 0, 0}, {1, 0, 0}}).valid());
  EXPECT_FALSE(tree.occluded(Ray{{0, 0, 0}, {1, 0, 0}}));
  RayPacket p;
  HitPacket h;
  for (int i = 0; i < kPacketSize; ++i) p.set(i, Ray{{0, 0, 0}, {1, 0, 0}});
  tree.intersect(p, kAllLanes, h);
  for (int i = 0; i < kPacketSize; ++i) EXPECT_EQ(h.prim[i], kInvalidId);
  EXPECT_EQ(tree.occluded(p, kAllLanes), 0u);
}

TEST(KdTree, OneTriangle) {
  const std::vector<Triangle> tris{{{0, 0, 5}, {4, 0, 5}, {0, 4, 5}}};
  const KdTree tree(tris);
  const Hit h = tree.intersect(Ray{{1, 1, 0}, {0, 0, 1}});
  ASSERT_TRUE(h.valid());
  EXPECT_FLOAT_EQ(h.t, 5.0f);
  EXPECT_FALSE(tree.intersect(Ray{{5, 5, 0}, {0, 0, 1}}).valid());
}

TEST(KdTree, RandomSoupsMatchBruteForce) {
  for (const uint32_t seed : {1u, 2u, 3u}) {
    std::mt19937 rng(seed);
    const auto tris = random_soup(rng, 3000, seed == 3 ? 2.0f : 0.4f);
    const auto rays = random_rays(rng, test::brute_force_rays(10000));
    expect_matches_brute_force(tris, rays, "soup seed " + std::to_string(seed));
  }
}

TEST(KdTree, AdversarialCasesMatchBruteForce) {
  const auto tris = adversarial_scene();
  std::mt19937 rng(7);
  std::vector<Ray> rays = random_rays(rng, 5000);
  // rays through every vertex and edge midpoint, from random origins and along the axes
  for (const Triangle& t : tris) {
    for (const glm::vec3 p : {t.v0, t.v1, t.v2, 0.5f * (t.v0 + t.v1), 0.5f * (t.v1 + t.v2)}) {
      const glm::vec3 o = test::random_point(rng, -2.0f, 12.0f);
      rays.push_back(Ray{o, p - o});
      rays.push_back(Ray{p + glm::vec3(0, 5, 0), {0, -1, 0}});
      rays.push_back(Ray{p - glm::vec3(5, 0, 0), {1, 0, 0}});
      rays.push_back(Ray{p + glm::vec3(0, 0, 5), {0, 0, -1}});
    }
  }
  // rays lying in split planes
  rays.push_back(Ray{{-2, 0, 0.5f}, {1, 0, 0}});
  rays.push_back(Ray{{1, 0.5f, -3}, {0, 0, 1}});
  expect_matches_brute_force(tris, rays, "adversarial");
}

/// Slivers that lean less than an ulp off the planes of boxes around them (test::sliver_scene):
/// clipped to a voxel, their extent across the plane rounds to the plane itself, and a triangle
/// that really lies a fraction of an ulp on one side must not be handed only to the other (where
/// clipping the original then loses it). Found on a bounce ray in the BART kitchen.
TEST(KdTree, SliversLeaningOffSplitPlanesMatchBruteForce) {
  std::vector<Triangle> tris;
  std::vector<Ray> rays;
  test::sliver_scene(tris, rays);
  expect_matches_brute_force(tris, rays, "slivers");
}

/// A slab far thinner than a float's normal range: bins / extent overflows to infinity in the
/// binned splits, and 0 times it is NaN; every bin must still land inside the counts.
TEST(KdTree, DenormalThinSlabMatchesBruteForce) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> xz(0.0f, 10.0f), y(0.0f, 1e-39f);
  std::vector<Triangle> tris;
  for (int i = 0; i < 3000; ++i) {
    const glm::vec3 c(xz(rng), 0.0f, xz(rng));
    auto vertex = [&] { return c + glm::vec3(xz(rng) * 0.05f, y(rng), xz(rng) * 0.05f); };
    tris.push_back({vertex(), vertex(), vertex()});
  }
  ASSERT_LT(Aabb::of(tris[0]).hi.y, std::numeric_limits<float>::min()) << "the slab should be denormal";
  std::vector<Ray> rays;
  for (int i = 0; i < 3000; ++i) {
    const glm::vec3 o = test::random_point(rng, -2.0f, 12.0f);
    rays.push_back(Ray{o, glm::vec3(xz(rng), 0.0f, xz(rng)) - o});
  }
  expect_matches_brute_force(tris, rays, "denormal slab");
}

TEST(KdTree, ClosedMeshHasNoLeaks) {
  const auto mesh = test::closed_sphere({5, 5, 5}, 3.0f, 40);
  for (const auto& [name, opt] : builds()) {
    const KdTree tree(mesh, opt);
    std::mt19937 rng(11);
    int misses = 0;
    for (int i = 0; i < 20000; ++i) {
      const glm::vec3 o = glm::vec3(5.0f) + test::random_point(rng, -1.0f, 1.0f);
      if (!tree.intersect(Ray{o, test::random_direction(rng)}).valid()) ++misses;
    }
    for (const Triangle& t : mesh) {
      if (!tree.intersect(Ray{{5, 5, 5}, t.v0 - glm::vec3(5.0f)}).valid()) ++misses;
    }
    EXPECT_EQ(misses, 0) << name;
  }
}

/// Packets traced by every available kernel equal single rays bit for bit, including packets
/// whose lanes point into different octants and partial masks.
TEST(KdTree, PacketsEqualSingleRaysOnEveryKernel) {
  std::mt19937 rng(5);
  const auto tris = random_soup(rng, 4000, 0.5f);
  const KdTree tree(tris);
  const SimdLevel saved = simd_level();
  for (const SimdLevel level : {SimdLevel::kScalar, SimdLevel::kSse, SimdLevel::kAvx2, SimdLevel::kAvx512}) {
    if (!simd_level_supported(level)) {
      std::cout << "[ note ] " << to_string(level) << " not supported by this CPU, not tested\n";
      continue;
    }
    set_simd_level(level);
    std::mt19937 r2(9);
    for (int p = 0; p < 2000; ++p) {
      RayPacket packet;
      const bool coherent = p % 2 == 0;
      const glm::vec3 o = test::random_point(r2, -2.0f, 12.0f);
      const glm::vec3 base = test::random_direction(r2);
      for (int i = 0; i < kPacketSize; ++i) {
        const glm::vec3 d = coherent ? glm::normalize(base + 0.05f * test::random_direction(r2))
                                     : test::random_direction(r2);
        packet.set(i, Ray{coherent ? o : test::random_point(r2, -2.0f, 12.0f), d, 0.0f,
                          i == 3 ? 4.0f : kInfinity});
      }
      // all lanes, the low half only, the high half only (the 16-wide kernel takes 8 at a time there)
      const LaneMask mask = p % 5 == 0 ? 0xb5u : p % 5 == 1 ? 0xa600u : kAllLanes;
      HitPacket hits;
      tree.intersect(packet, mask, hits);
      const LaneMask blocked = tree.occluded(packet, mask);
      for (int i = 0; i < kPacketSize; ++i) {
        if (!((mask >> i) & 1u)) continue;
        const Hit single = tree.intersect(packet.get(i));
        ASSERT_EQ(hits.prim[i], single.prim) << to_string(level) << " packet " << p << " lane " << i;
        if (single.valid()) {
          ASSERT_EQ(hits.t[i], single.t);
          ASSERT_EQ(hits.u[i], single.u);
          ASSERT_EQ(hits.v[i], single.v);
        }
        ASSERT_EQ(((blocked >> i) & 1u) != 0, single.valid()) << "any-hit disagrees with closest hit";
      }
      EXPECT_EQ(blocked & ~mask, 0u);
    }
  }
  set_simd_level(saved);
}

/// Packets of rays parallel to the tree's own split planes, half of them lying in the plane (the
/// split distance is 0 * inf = NaN: both children), half off it (an infinite distance: one
/// child), equal brute force on every kernel, closest and any hit.
TEST(KdTree, PacketsParallelToSplitPlanesMatchBruteForceOnEveryKernel) {
  std::mt19937 rng(21);
  auto tris = adversarial_scene();
  const auto soup = random_soup(rng, 3000, 0.6f);
  tris.insert(tris.end(), soup.begin(), soup.end());
  const KdTree tree(tris);
  std::vector<std::pair<int, float>> planes;
  for (const KdNode& n : tree.nodes()) {
    if (!n.is_leaf()) planes.push_back({n.axis(), n.split});
  }
  ASSERT_GT(planes.size(), 100u);
  const SimdLevel saved = simd_level();
  for (const SimdLevel level : {SimdLevel::kScalar, SimdLevel::kSse, SimdLevel::kAvx2, SimdLevel::kAvx512}) {
    if (!simd_level_supported(level)) continue;
    set_simd_level(level);
    std::mt19937 r2(22);
    size_t hits = 0, checked = 0;
    for (size_t k = 0; k < planes.size(); k += std::max<size_t>(1, planes.size() / 400)) {
      const auto [axis, split] = planes[k];
      RayPacket packet;
      for (int i = 0; i < kPacketSize; ++i) {
        glm::vec3 o = test::random_point(r2, -2.0f, 12.0f), d = test::random_direction(r2);
        o[axis] = i % 2 == 0 ? split : split + 0.25f * static_cast<float>(i);
        d[axis] = 0.0f;
        packet.set(i, Ray{o, glm::normalize(d)});
      }
      HitPacket got;
      tree.intersect(packet, kAllLanes, got);
      const LaneMask blocked = tree.occluded(packet, kAllLanes);
      for (int i = 0; i < kPacketSize; ++i) {
        const Ray r = packet.get(i);
        const Hit ref = intersect_brute_force(r, tris);
        ++checked;
        hits += ref.valid();
        ASSERT_EQ(got.prim[i], ref.prim) << to_string(level) << " plane " << k << " lane " << i;
        if (ref.valid()) {
          ASSERT_NEAR(got.t[i], ref.t, 1e-5f * std::max(1.0f, ref.t));
        }
        ASSERT_EQ(((blocked >> i) & 1u) != 0, occluded_brute_force(r, tris)) << to_string(level) << " plane " << k;
      }
    }
    EXPECT_GT(hits, checked / 10) << "the rays should hit something";
  }
  set_simd_level(saved);
}

TEST(KdTree, BuildIsIdenticalForAnyThreadCount) {
  std::mt19937 rng(3);
  const auto tris = random_soup(rng, 30000, 0.3f);
  for (auto [name, opt] : builds()) {
    opt.parallel_threshold = 256;  // many parallel splices even on this small scene
    auto build = [&, &opt = opt](int threads) {
      tbb::task_arena arena(threads);
      KdTree tree;
      arena.execute([&] { tree = KdTree(tris, opt); });
      return tree;
    };
    const KdTree one = build(1), two = build(2), four = build(4);
    for (const KdTree* other : {&two, &four}) {
      ASSERT_EQ(one.nodes().size(), other->nodes().size()) << name;
      EXPECT_EQ(0, std::memcmp(one.nodes().data(), other->nodes().data(), one.nodes().size() * sizeof(KdNode))) << name;
      EXPECT_EQ(one.prim_refs(), other->prim_refs()) << name;
    }
  }
}

/// The cheapest split of `tris` inside `voxel` by brute force over every candidate plane (each
/// triangle's bounds on each axis, strictly inside the voxel), with Wald & Havran's cost:
/// lambda (K_T + K_I (SA_l / SA n_l + SA_r / SA n_r)), lambda = the empty-space bonus when a side is
/// empty. Triangles that do not straddle a plane (as here) need no clipping. Computed in double,
/// independently of the builder's sweep.
struct SplitCost {
  int axis = -1;
  double pos = 0.0, cost = std::numeric_limits<double>::infinity();
};

double split_cost(const std::vector<Triangle>& tris, const Aabb& voxel, double lambda, int a, double p) {
  auto area = [](const glm::dvec3& e) { return 2.0 * (e.x * e.y + e.y * e.z + e.z * e.x); };
  int nl = 0, nr = 0;
  for (const Triangle& t : tris) {
    const Aabb b = Aabb::of(t);
    nl += b.lo[a] < p;
    nr += b.hi[a] > p;
  }
  glm::dvec3 el(voxel.extent()), er(voxel.extent());
  el[a] = p - voxel.lo[a];
  er[a] = voxel.hi[a] - p;
  const double whole = area(glm::dvec3(voxel.extent()));
  const double l = (nl == 0 || nr == 0) ? lambda : 1.0;
  return l * (2.0 + 1.5 * (area(el) / whole * nl + area(er) / whole * nr));
}

SplitCost cheapest_split(const std::vector<Triangle>& tris, const Aabb& voxel, double lambda) {
  SplitCost best;
  for (int a = 0; a < 3; ++a) {
    for (const Triangle& t : tris) {
      const Aabb b = Aabb::of(t);
      for (const float p : {b.lo[a], b.hi[a]}) {
        if (!(p > voxel.lo[a] && p < voxel.hi[a])) continue;
        const double c = split_cost(tris, voxel, lambda, a, p);
        if (c < best.cost) best = {a, p, c};
      }
    }
  }
  return best;
}

/// Two clusters 0.7 apart along x: the root splits between them, and its left child's voxel holds
/// cluster A with empty space beside it. With the default empty-space bonus (0.8) the cheapest
/// split there cuts that space off (an empty right side); with lambda = 1 a split through the
/// cluster is cheaper. Each build's split must be the brute force's cheapest for its lambda.
TEST(KdTree, SplitsAreTheCheapestPlanesWithTheEmptySpaceBonus) {
  std::mt19937 rng(1);
  std::vector<Triangle> a = random_soup(rng, 16, 0.3f), b = random_soup(rng, 40, 0.3f), tris;
  for (Triangle t : a) {  // A in [0, 1]^3
    for (glm::vec3* v : {&t.v0, &t.v1, &t.v2}) *v *= 0.1f;
    tris.push_back(t);
  }
  for (Triangle t : b) {  // B in [1.7, 2.7] x [0, 1]^2
    for (glm::vec3* v : {&t.v0, &t.v1, &t.v2}) *v = *v * 0.1f + glm::vec3(1.7f, 0.0f, 0.0f);
    tris.push_back(t);
  }
  const std::vector<Triangle> cluster_a(tris.begin(), tris.begin() + 16);
  Aabb bounds_a, all;
  for (const Triangle& t : cluster_a) bounds_a.extend(Aabb::of(t));
  for (const Triangle& t : tris) all.extend(Aabb::of(t));
  SplitCost chosen[2];
  for (const double lambda : {0.8, 1.0}) {
    KdTreeBuildOptions opt;
    opt.empty_bonus = static_cast<float>(lambda);
    opt.binned_above = 0;
    const KdTree tree(tris, opt);
    const KdNode root = tree.nodes()[0];
    ASSERT_FALSE(root.is_leaf());
    ASSERT_EQ(root.axis(), 0);
    ASSERT_GE(root.split, bounds_a.hi.x) << "the root split lies between the clusters";
    ASSERT_LT(root.split, 1.7f);
    Aabb left = all;
    left.hi.x = root.split;
    const KdNode node = tree.nodes()[root.left_child()];
    ASSERT_FALSE(node.is_leaf()) << "lambda " << lambda;
    const SplitCost best = cheapest_split(cluster_a, left, lambda);
    const double got = split_cost(cluster_a, left, lambda, node.axis(), node.split);
    EXPECT_NEAR(got, best.cost, 1e-4 * best.cost) << "lambda " << lambda << ": the builder split axis " << node.axis() << " at "
                                                  << node.split << ", brute force axis " << best.axis << " at " << best.pos;
    chosen[lambda == 0.8 ? 0 : 1] = best;
  }
  // the scene is one where the bonus decides: the cheapest split with it has an empty side and
  // costs clearly less (with the bonus) than the split chosen without it
  EXPECT_EQ(chosen[0].axis, 0);
  EXPECT_GE(chosen[0].pos, bounds_a.hi.x) << "with the bonus, the empty space right of A is cut off";
  EXPECT_LT(chosen[1].pos, bounds_a.hi.x) << "without it, a plane through A";
}

TEST(KdTree, StatsDescribeATreeNotALeaf) {
  std::mt19937 rng(4);
  const KdTree tree(random_soup(rng, 20000, 0.2f));
  const KdTreeStats s = tree.stats();
  EXPECT_EQ(s.node_bytes, s.nodes * 8u);
  EXPECT_EQ(s.nodes, 2 * s.leaves - 1);
  EXPECT_GT(s.max_depth, 10u);
  EXPECT_GE(s.prim_refs, 20000u);
  // a single leaf would cost K_I * N = 30000; a useful tree costs a tiny fraction of that
  EXPECT_LT(s.sah_cost, 300.0);
}

}  // namespace
}  // namespace artrace::core
