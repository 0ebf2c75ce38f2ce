// The kd-tree against brute force on the real BART kitchen (shared data).
#include "artrace/core/kd_tree.h"
#include "artrace/io/aff_scene.h"
#include "../test_util.h"

#include <tbb/parallel_for.h>

namespace artrace::core {
namespace {

#if defined(ARTRACE_SANITIZED)
constexpr int kRandomRays = 1000;
constexpr int kStride = 64;
#else
constexpr int kRandomRays = 10000;
constexpr int kStride = 8;
#endif

TEST(KdTreeBart, KitchenMatchesBruteForce) {
  ARTRACE_REQUIRE_SHARED("bart/kitchen/aff/kitchen.aff");
  const io::AffScene scene = io::load_aff(shared_path);
  const std::vector<Triangle> tris = scene.triangles_at(0.0);
  const KdTree tree(tris);
  KdTreeBuildOptions sweep;
  sweep.binned_above = 0;  // Wald & Havran's sweep at every node
  const KdTree exact(tris, sweep);
  const Camera cam = scene.camera_at(0.0, 512, 400);
  std::vector<Ray> rays;
  for (int y = 0; y < cam.height; y += kStride) {
    for (int x = 0; x < cam.width; x += kStride) rays.push_back(cam.ray(x + 0.5f, y + 0.5f));
  }
  // random rays from inside the room's bounds
  std::mt19937 rng(21);
  const Aabb b = tree.bounds();
  std::uniform_real_distribution<float> ux(b.lo.x, b.hi.x), uy(b.lo.y, b.hi.y), uz(b.lo.z, b.hi.z);
  for (int i = 0; i < kRandomRays; ++i) rays.push_back(Ray{{ux(rng), uy(rng), uz(rng)}, test::random_direction(rng)});

  std::vector<Hit> ref(rays.size());
  tbb::parallel_for(size_t(0), rays.size(), [&](size_t i) { ref[i] = intersect_brute_force(rays[i], tris); });
  size_t hits = 0;
  for (const Hit& h : ref) hits += h.valid();
  for (const KdTree* t : {&tree, &exact}) {
    const char* what = t == &tree ? "default build" : "sweep everywhere";
    size_t mismatches = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
      const Hit got = t->intersect(rays[i]);
      if (got.prim != ref[i].prim || (got.valid() && std::fabs(got.t - ref[i].t) > 1e-5f * std::max(1.0f, ref[i].t))) {
        if (++mismatches <= 5) ADD_FAILURE() << what << ", ray " << i << ": brute force " << ref[i].prim << " kd-tree " << got.prim;
      }
    }
    EXPECT_EQ(mismatches, 0u) << what << ": of " << rays.size();
  }
  EXPECT_GT(hits, rays.size() / 4) << "the test rays should mostly hit the kitchen";
}

}  // namespace
}  // namespace artrace::core
