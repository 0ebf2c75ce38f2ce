// The BART scenes played through the update API against brute force over the flattened scene.
#include "artrace/io/bart_animation.h"
#include "../test_util.h"

#include <tbb/parallel_for.h>

namespace artrace::io {
namespace {

#if defined(ARTRACE_SANITIZED)
constexpr int kStride = 48;
#else
constexpr int kStride = 12;
#endif

void check_scene(const char* rel, std::initializer_list<double> times) {
  const std::filesystem::path path = test::shared_data() / rel;
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "shared data not found at " << path;
  const AffScene aff = load_aff(path);
  BartAnimation kd(aff, core::TwoLevelScene::Config::kKdTreeBvh);
  BartAnimation bvh(aff, core::TwoLevelScene::Config::kBvh);
  size_t dynamic_hits = 0;
  for (const double t : times) {
    const auto flat = aff.triangles_at(t);
    const core::Camera cam = aff.camera_at(t, 512, 400);
    std::vector<core::Ray> rays;
    for (int y = 0; y < cam.height; y += kStride) {
      for (int x = 0; x < cam.width; x += kStride) rays.push_back(cam.ray(x + 0.5f, y + 0.5f));
    }
    std::vector<core::Hit> ref(rays.size());
    tbb::parallel_for(size_t(0), rays.size(), [&](size_t i) { ref[i] = core::intersect_brute_force(rays[i], flat); });
    for (BartAnimation* anim : {&kd, &bvh}) {
      anim->set_time(t);
      size_t disagree = 0;
      for (size_t i = 0; i < rays.size(); ++i) {
        const core::Hit got = anim->scene().intersect(rays[i]);
        dynamic_hits += got.valid() && got.inst != core::kStaticObject;
        const bool same = ref[i].valid() == got.valid() &&
                          (!got.valid() || std::fabs(ref[i].t - got.t) <= 1e-4f * std::max(1.0f, ref[i].t));
        disagree += !same;
      }
      // Transforms are composed in float here and in double for the flattened scene: a ray through
      // a shared edge may pick the neighbour; anything more is a bug.
      EXPECT_LE(disagree, rays.size() / 500) << rel << " t=" << t << (anim == &kd ? " kdtree+bvh" : " bvh");
    }
  }
  EXPECT_GT(dynamic_hits, 0u) << rel << ": the camera should see moving parts";
}

TEST(BartAnimation, KitchenMatchesFlattenedScene) { check_scene("bart/kitchen/aff/kitchen.aff", {5.0, 10.0, 15.0}); }

TEST(BartAnimation, RobotsMatchFlattenedScene) { check_scene("bart/robots/aff/Robot.aff", {2.0, 10.0, 30.0}); }

}  // namespace
}  // namespace artrace::io
