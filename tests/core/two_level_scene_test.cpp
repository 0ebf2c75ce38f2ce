#include "artrace/core/kinematic_tree.h"
#include "artrace/core/simd_level.h"
#include "artrace/core/two_level_scene.h"
#include "../test_util.h"

#include <glm/gtc/matrix_transform.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

namespace artrace::core {
namespace {

using Config = TwoLevelScene::Config;

std::vector<Triangle> transformed(const std::vector<Triangle>& tris, const glm::mat4& m) {
  std::vector<Triangle> out;
  for (const Triangle& t : tris) {
    out.push_back({glm::vec3(m * glm::vec4(t.v0, 1)), glm::vec3(m * glm::vec4(t.v1, 1)), glm::vec3(m * glm::vec4(t.v2, 1))});
  }
  return out;
}

/// Compares the scene with brute force over `flat`. Instanced geometry is transformed in float on
/// both sides in different ways, so distances agree to 1e-4 relative and a ray grazing an edge may
/// pick the neighbour: at most `max_disagree` such rays.
void expect_matches_flat(const TwoLevelScene& scene, const std::vector<Triangle>& flat, const std::vector<Ray>& rays,
                         size_t max_disagree, const std::string& what) {
  size_t disagree = 0, hits = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    const Hit ref = intersect_brute_force(rays[i], flat);
    const Hit got = scene.intersect(rays[i]);
    hits += ref.valid();
    const bool same = ref.valid() == got.valid() &&
                      (!ref.valid() || std::fabs(ref.t - got.t) <= 1e-4f * std::max(1.0f, ref.t));
    if (!same) ++disagree;
    if (got.valid()) {
      // the triangle the hit names contains the hit point
      const Triangle w = scene.world_triangle(got);
      const glm::vec3 p = rays[i].org + got.t * rays[i].dir;
      const glm::vec3 q = (1.0f - got.u - got.v) * w.v0 + got.u * w.v1 + got.v * w.v2;
      ASSERT_LT(glm::length(p - q), 1e-3f * (1.0f + glm::length(p))) << what << " ray " << i;
    }
    ASSERT_EQ(scene.occluded(rays[i]), got.valid()) << what << " ray " << i;
  }
  EXPECT_LE(disagree, max_disagree) << what << " (" << hits << " hits of " << rays.size() << ")";
  EXPECT_GT(hits, rays.size() / 10) << what;
}

/// Instances with non-uniform scale, rotation and mirroring are hit where the flattened geometry is.
TEST(TwoLevelScene, InstancesMatchFlattenedGeometry) {
  std::mt19937 rng(41);
  const auto object = test::closed_sphere({0, 0, 0}, 1.0f, 16);
  const auto ground = test::random_soup(rng, 500, 0.5f);
  std::vector<glm::mat4> transforms;
  for (int i = 0; i < 12; ++i) {
    glm::mat4 m = glm::translate(glm::mat4(1.0f), test::random_point(rng, 0.0f, 10.0f));
    m = glm::rotate(m, static_cast<float>(i), glm::normalize(glm::vec3(1.0f, 2.0f, 3.0f - i)));
    m = glm::scale(m, glm::vec3(0.5f + 0.1f * i, 1.5f, (i % 3 == 0) ? -0.7f : 0.7f));  // some mirrored
    transforms.push_back(m);
  }
  for (const Config config : {Config::kKdTreeBvh, Config::kBvh}) {
    TwoLevelScene scene(config);
    scene.set_static(ground);
    const MeshHandle mesh = scene.add_rigid_mesh(object);
    std::vector<Triangle> flat = ground;
    for (const glm::mat4& m : transforms) {
      scene.add_instance(mesh, m);
      const auto t = transformed(object, m);
      flat.insert(flat.end(), t.begin(), t.end());
    }
    scene.commit();
    expect_matches_flat(scene, flat, test::random_rays(rng, test::brute_force_rays(6000)), 6,
                        config == Config::kBvh ? "bvh" : "kdtree+bvh");
  }
}

/// A top level over many objects (its SAH splits) finds what the flattened geometry holds; objects
/// with a NaN transform are never hit and do not upset the others or the top level's build.
TEST(TwoLevelScene, ManyObjectsAndNaNTransforms) {
  std::mt19937 rng(43);
  const auto object = test::closed_sphere({0, 0, 0}, 0.6f, 8);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (const Config config : {Config::kKdTreeBvh, Config::kBvh}) {
    TwoLevelScene scene(config);
    scene.set_static(test::random_soup(rng, 50, 0.5f));
    std::vector<Triangle> flat;  // the objects with finite transforms
    const MeshHandle mesh = scene.add_rigid_mesh(object);
    for (int i = 0; i < 80; ++i) {
      glm::mat4 m = glm::translate(glm::mat4(1.0f), test::random_point(rng, 0.0f, 10.0f));
      m = glm::scale(m, glm::vec3(0.3f + 0.02f * static_cast<float>(i % 20)));
      if (i % 27 == 5) m[3][1] = nan;  // three objects with a NaN translation
      scene.add_instance(mesh, m);
      if (i % 27 == 5) continue;
      const auto t = transformed(object, m);
      flat.insert(flat.end(), t.begin(), t.end());
    }
    scene.commit();
    const auto rays = test::random_rays(rng, 2000);
    size_t disagree = 0, hits = 0;
    for (const Ray& r : rays) {
      const Hit got = scene.intersect(r);
      if (got.valid() && got.inst == kStaticObject) continue;  // the soup is not in `flat`
      if (got.valid()) {
        ASSERT_NE(got.inst % 27, 5u) << "an object with a NaN transform was hit";
      }
      const Hit ref = intersect_brute_force(r, flat);
      hits += ref.valid();
      if (ref.valid() != got.valid() || (ref.valid() && std::fabs(ref.t - got.t) > 1e-4f * std::max(1.0f, ref.t))) {
        ++disagree;
      }
    }
    EXPECT_LE(disagree, 4u) << (config == Config::kBvh ? "bvh" : "kdtree+bvh");
    EXPECT_GT(hits, rays.size() / 20);
  }
}

/// Thousands of objects in two places give the SAH nothing to choose between within each place:
/// the top level stays balanced there (equal costs go to the even split), and rays meet the
/// nearer copies, the first of them by the tie rule (equal distances: the smaller object).
TEST(TwoLevelScene, ObjectsSharingAPlaceKeepTheTopLevelShallow) {
  TwoLevelScene scene;
  const MeshHandle mesh = scene.add_rigid_mesh({{{-1, -1, 0}, {1, -1, 0}, {0, 1, 0}}});
  for (int i = 0; i < 3000; ++i) {
    scene.add_instance(mesh, glm::translate(glm::mat4(1.0f), glm::vec3(0.0f, 0.0f, i < 2000 ? 0.0f : 1.0f)));
  }
  scene.commit();
  EXPECT_LE(scene.top_depth(), 14u) << "3000 objects: about log2(3000) + 1 levels";
  for (float x : {-0.5f, 0.0f, 0.3f}) {
    const Hit h = scene.intersect(Ray{{x, -0.2f, 5.0f}, {0.0f, 0.0f, -1.0f}});
    ASSERT_TRUE(h.valid());
    EXPECT_FLOAT_EQ(h.t, 4.0f);
    EXPECT_EQ(h.inst, 2000u) << "the nearer copies are the last thousand";
    RayPacket p;
    for (int i = 0; i < kPacketSize; ++i) p.set(i, Ray{{x + 0.01f * static_cast<float>(i % 4), -0.2f, 5.0f}, {0, 0, -1}});
    HitPacket hp{};
    for (int i = 0; i < kPacketSize; ++i) hp.prim[i] = hp.inst[i] = kInvalidId, hp.t[i] = kInfinity;
    scene.intersect(p, kAllLanes, hp);
    for (int i = 0; i < kPacketSize; ++i) {
      EXPECT_FLOAT_EQ(hp.t[i], 4.0f) << "lane " << i;
      EXPECT_EQ(hp.inst[i], 2000u) << "lane " << i;
    }
  }
}

TEST(TwoLevelScene, ConfigurationsGiveIdenticalHitsOnStaticGeometry) {
  std::mt19937 rng(42);
  const auto tris = test::random_soup(rng, 3000, 0.4f);
  TwoLevelScene a(Config::kKdTreeBvh), b(Config::kBvh);
  a.set_static(tris);
  b.set_static(tris);
  a.commit();
  b.commit();
  for (const Ray& r : test::random_rays(rng, 3000)) {
    const Hit ha = a.intersect(r), hb = b.intersect(r);
    ASSERT_EQ(ha.prim, hb.prim);
    ASSERT_EQ(ha.inst, hb.inst);
    if (ha.valid()) {
      ASSERT_EQ(ha.t, hb.t);
    }
  }
}

/// Single rays through the wide BVH over the static geometry (the default) and through the kd-tree
/// give the same hits, closest and any, with instances in front of and behind the static soup.
TEST(TwoLevelScene, SingleRaysGiveTheSameHitsWithAndWithoutTheWideBvh) {
  std::mt19937 rng(44);
  const auto tris = test::random_soup(rng, 3000, 0.4f);
  const auto box = test::random_soup(rng, 200, 0.3f);
  TwoLevelScene a(Config::kKdTreeBvh), b(Config::kKdTreeBvh);
  a.set_static(tris);
  b.set_static(tris, false);
  for (TwoLevelScene* s : {&a, &b}) {
    const MeshHandle m = s->add_rigid_mesh(box);
    s->add_instance(m, glm::translate(glm::mat4(1.0f), glm::vec3(-3.0f, 0.0f, 0.0f)));
    s->add_instance(m, glm::scale(glm::mat4(1.0f), glm::vec3(0.5f)));
    s->commit();
  }
  size_t static_hits = 0, instance_hits = 0;
  const std::vector<Ray> rays = test::random_rays(rng, 4000);
  for (size_t i = 0; i < rays.size(); ++i) {
    Ray r = rays[i];
    if (i % 3 == 0) r.tmax = 4.0f;  // segments too
    const Hit ha = a.intersect(r), hb = b.intersect(r);
    ASSERT_EQ(ha.prim, hb.prim);
    ASSERT_EQ(ha.inst, hb.inst);
    if (ha.valid()) {
      ASSERT_EQ(ha.t, hb.t);
      ASSERT_EQ(ha.u, hb.u);
      ASSERT_EQ(ha.v, hb.v);
      (ha.inst == kStaticObject ? static_hits : instance_hits) += 1;
    }
    ASSERT_EQ(a.occluded(r), b.occluded(r));
    ASSERT_EQ(a.occluded(r), ha.valid());
  }
  EXPECT_GT(static_hits, 500u);
  EXPECT_GT(instance_hits, 20u);
}

/// A deforming mesh whose vertices are scrambled every frame stays exact.
TEST(TwoLevelScene, ScrambledDeformingMeshStaysCorrect) {
  std::mt19937 rng(43);
  TriangleMesh mesh;
  for (int i = 0; i < 3000; ++i) mesh.positions.push_back(test::random_point(rng, 0.0f, 10.0f));
  std::uniform_int_distribution<uint32_t> pick(0, 2999);
  for (int i = 0; i < 1000; ++i) mesh.indices.push_back({pick(rng), pick(rng), pick(rng)});
  TwoLevelScene scene(Config::kKdTreeBvh);
  const DeformableHandle h = scene.add_deformable(mesh);
  scene.commit();
  for (int frame = 0; frame < 8; ++frame) {
    DeformableMesh& d = scene.deformable(h);
    for (auto& p : d.positions()) p = test::random_point(rng, 0.0f, 10.0f);
    if (frame % 3 == 0) d.refit();
    else if (frame % 3 == 1) d.restructure();
    else d.rebuild();
    scene.commit();
    std::vector<Triangle> flat;
    d.mesh().flatten_into(flat);
    for (const Ray& r : test::random_rays(rng, 1500)) {
      const Hit ref = intersect_brute_force(r, flat);
      const Hit got = scene.intersect(r);
      ASSERT_EQ(ref.prim, got.prim) << "frame " << frame;
      if (ref.valid()) {
        ASSERT_EQ(ref.t, got.t);
      }
    }
  }
}

TEST(TwoLevelScene, PacketsEqualSingleRays) {
  std::mt19937 rng(44);
  TwoLevelScene scene(Config::kKdTreeBvh);
  scene.set_static(test::random_soup(rng, 2000, 0.4f));
  const MeshHandle mesh = scene.add_rigid_mesh(test::closed_sphere({0, 0, 0}, 1.0f, 12));
  for (int i = 0; i < 8; ++i) {
    scene.add_instance(mesh, glm::scale(glm::translate(glm::mat4(1.0f), test::random_point(rng, 0, 10)), glm::vec3(1, 2, -1)));
  }
  scene.commit();
  const SimdLevel saved = simd_level();
  for (const SimdLevel level : {SimdLevel::kScalar, SimdLevel::kSse, SimdLevel::kAvx2, SimdLevel::kAvx512}) {
    if (!simd_level_supported(level)) continue;
    set_simd_level(level);
    for (int p = 0; p < 600; ++p) {
      RayPacket packet;
      const glm::vec3 o = test::random_point(rng, -2.0f, 12.0f);
      const glm::vec3 base = test::random_direction(rng);
      for (int i = 0; i < kPacketSize; ++i) {
        packet.set(i, Ray{o, p % 2 ? test::random_direction(rng) : glm::normalize(base + 0.05f * test::random_direction(rng))});
      }
      const LaneMask blocked = scene.occluded(packet, kAllLanes);
      // coherent packets take the wide BVH's frustums where the kernels trace them, incoherent
      // ones the kd-tree's packets: the same hits either way
      for (const Coherence coherence : {Coherence::kCoherent, Coherence::kIncoherent}) {
        HitPacket hits;
        scene.intersect(packet, kAllLanes, hits, coherence);
        for (int i = 0; i < kPacketSize; ++i) {
          const Hit h = scene.intersect(packet.get(i));
          ASSERT_EQ(hits.prim[i], h.prim) << to_string(level);
          ASSERT_EQ(hits.inst[i], h.inst);
          if (h.valid()) {
            ASSERT_EQ(hits.t[i], h.t);
            ASSERT_EQ(hits.u[i], h.u);
            ASSERT_EQ(hits.v[i], h.v);
          }
          ASSERT_EQ(((blocked >> i) & 1u) != 0, h.valid());
        }
      }
    }
  }
  set_simd_level(saved);
}

/// A scene of a static soup and instances of one mesh, both with per-triangle transmittance.
TwoLevelScene transmissive_scene(Config config, const std::vector<Triangle>& ground, const std::vector<float>& ground_pass,
                                 const std::vector<Triangle>& object, const std::vector<float>& object_pass,
                                 const std::vector<glm::mat4>& placements) {
  TwoLevelScene scene(config);
  scene.set_static(ground);
  scene.set_static_transmittance(ground_pass);
  const MeshHandle mesh = scene.add_rigid_mesh(object);
  scene.set_mesh_transmittance(mesh, object_pass);
  for (const glm::mat4& m : placements) scene.add_instance(mesh, m);
  scene.commit();
  return scene;
}

/// Partial masks, both configurations, every kernel: the lanes in the mask get the full packet's
/// answers (closest hits and transmittance), the lanes outside keep what the caller left there.
TEST(TwoLevelScene, PartialMasksAnswerTheirLanesAndLeaveTheOthers) {
  std::mt19937 rng(45);
  const std::vector<Triangle> ground = test::random_soup(rng, 2000, 0.4f);
  const std::vector<Triangle> ball = test::closed_sphere({0, 0, 0}, 1.0f, 12);
  std::vector<float> ground_pass(ground.size()), ball_pass(ball.size());
  for (size_t k = 0; k < ground.size(); ++k) ground_pass[k] = k % 3 == 0 ? 0.0f : 0.5f;
  for (size_t k = 0; k < ball.size(); ++k) ball_pass[k] = k % 2 == 0 ? 0.0f : 0.7f;
  const SimdLevel saved = simd_level();
  std::vector<glm::mat4> placements;
  for (int i = 0; i < 6; ++i) placements.push_back(glm::translate(glm::mat4(1.0f), test::random_point(rng, 0, 10)));
  for (const Config config : {Config::kKdTreeBvh, Config::kBvh}) {
    const TwoLevelScene scene = transmissive_scene(config, ground, ground_pass, ball, ball_pass, placements);
    for (const SimdLevel level : {SimdLevel::kScalar, SimdLevel::kSse, SimdLevel::kAvx2, SimdLevel::kAvx512}) {
      if (!simd_level_supported(level)) continue;
      set_simd_level(level);
      size_t inside = 0, hit = 0;
      for (int p = 0; p < 200; ++p) {
        RayPacket packet;
        const glm::vec3 light = test::random_point(rng, 0.0f, 10.0f);
        for (int i = 0; i < kPacketSize; ++i) {
          const glm::vec3 o = test::random_point(rng, -2.0f, 12.0f);
          packet.set(i, Ray{o, light - o, 0.0f, 1.0f});
        }
        HitPacket all;
        float all_trans[kPacketSize];
        scene.intersect(packet, kAllLanes, all);
        const LaneMask all_unsure = scene.transmittance(packet, kAllLanes, all_trans);
        for (const LaneMask mask : {0xb5u, 0xa600u, 0x0001u, 0x8000u, 0x7ffeu}) {
          HitPacket hits;
          float trans[kPacketSize];
          for (int i = 0; i < kPacketSize; ++i) {
            hits.t[i] = -3.0f, hits.u[i] = -4.0f, hits.v[i] = -5.0f, hits.prim[i] = 777u, hits.inst[i] = 888u;
            trans[i] = -7.0f;
          }
          scene.intersect(packet, mask, hits);
          const LaneMask unsure = scene.transmittance(packet, mask, trans);
          EXPECT_EQ(unsure & ~mask, 0u);
          for (int i = 0; i < kPacketSize; ++i) {
            if (!((mask >> i) & 1u)) {
              ASSERT_EQ(hits.t[i], -3.0f) << to_string(level) << " mask " << mask << " lane " << i;
              ASSERT_EQ(hits.u[i], -4.0f);
              ASSERT_EQ(hits.v[i], -5.0f);
              ASSERT_EQ(hits.prim[i], 777u);
              ASSERT_EQ(hits.inst[i], 888u);
              ASSERT_EQ(trans[i], -7.0f) << to_string(level) << " mask " << mask << " lane " << i;
              continue;
            }
            ++inside;
            ASSERT_EQ(hits.prim[i], all.prim[i]) << to_string(level) << " mask " << mask << " lane " << i;
            ASSERT_EQ(hits.inst[i], all.inst[i]);
            ASSERT_EQ(hits.t[i], all.t[i]);
            hit += hits.prim[i] != kInvalidId;
            if (!((unsure >> i) & 1u) && !((all_unsure >> i) & 1u)) {
              ASSERT_EQ(trans[i], all_trans[i]) << to_string(level) << " mask " << mask << " lane " << i;
            }
          }
        }
      }
      EXPECT_GT(hit, inside / 10) << "the rays must hit something";
    }
  }
  set_simd_level(saved);
}

/// Transmittance of a segment by brute force: every triangle tested on its own; crossings at the
/// same distance (an edge shared by two triangles of one pane) count once, as when walking.
float transmittance_brute_force(const Ray& r, const std::vector<Triangle>& tris, const std::vector<float>& pass) {
  std::vector<std::pair<float, float>> crossings;  // distance, transmittance
  for (size_t k = 0; k < tris.size(); ++k) {
    const Hit h = intersect_brute_force(r, {tris[k]});
    if (!h.valid()) continue;
    if (pass[k] == 0.0f) return 0.0f;
    crossings.emplace_back(h.t, pass[k]);
  }
  std::sort(crossings.begin(), crossings.end());
  float t = 1.0f;
  for (size_t k = 0; k < crossings.size(); ++k) {
    if (k == 0 || crossings[k].first != crossings[k - 1].first) t *= crossings[k].second;
  }
  return t;
}

TEST(TwoLevelScene, TransmittanceEqualsBruteForceAndCountsEachSurfaceOnceWithOrWithoutHints) {
  // A static soup, one rigid mesh instanced in place (identity, so that both sides test the same
  // coordinates), and two large panes that cross many kd-tree leaves: a ray meeting a pane in two
  // leaves must still count it once (0.5, not 0.25). Segments end inside the scene.
  std::mt19937 rng(71);
  std::vector<Triangle> ground = test::random_soup(rng, 1500, 0.4f);
  ground.push_back({{-1, -1, 5.1f}, {11, -1, 5.1f}, {11, 11, 5.1f}});
  ground.push_back({{-1, -1, 5.1f}, {11, 11, 5.1f}, {-1, 11, 5.1f}});
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  std::vector<float> ground_pass(ground.size());
  for (float& v : ground_pass) v = uni(rng) < 0.3f ? 0.0f : 0.2f + 0.8f * uni(rng);
  ground_pass[ground.size() - 2] = ground_pass[ground.size() - 1] = 0.5f;
  const std::vector<Triangle> object = test::random_soup(rng, 300, 0.6f);
  std::vector<float> object_pass(object.size());
  for (float& v : object_pass) v = uni(rng) < 0.3f ? 0.0f : 0.2f + 0.8f * uni(rng);
  std::vector<Triangle> flat = ground;
  flat.insert(flat.end(), object.begin(), object.end());
  std::vector<float> flat_pass = ground_pass;
  flat_pass.insert(flat_pass.end(), object_pass.begin(), object_pass.end());

  const SimdLevel saved = simd_level();
  for (const Config config : {Config::kKdTreeBvh, Config::kBvh}) {
    const TwoLevelScene scene = transmissive_scene(config, ground, ground_pass, object, object_pass, {glm::mat4(1.0f)});
    ASSERT_TRUE(scene.has_transmittance());
    for (const SimdLevel level : {SimdLevel::kScalar, SimdLevel::kSse, SimdLevel::kAvx2, SimdLevel::kAvx512}) {
      if (!simd_level_supported(level)) continue;
      set_simd_level(level);
      std::mt19937 r2(5);
      size_t unsure_lanes = 0, partial = 0, counted = 0, hinted = 0;
      ShadowHint natural;  // the last blocker, as a renderer keeps it
      for (int p = 0; p < test::brute_force_rays(400); ++p) {
        RayPacket packet;
        const glm::vec3 light = test::random_point(r2, 0.0f, 10.0f);
        for (int i = 0; i < kPacketSize; ++i) {
          const glm::vec3 o = test::random_point(r2, 0.0f, 10.0f);
          packet.set(i, Ray{o, light - o, 0.0f, 1.0f});  // shadow-ray segments towards one point
        }
        float trans[kPacketSize];
        const LaneMask unsure = scene.transmittance(packet, kAllLanes, trans);
        const LaneMask blocked = scene.occluded(packet, kAllLanes);
        // Hints change the work, never the answer: the natural one, and one naming any triangle
        // (transmissive ones, or past the end, included).
        ShadowHint wild;
        wild.prim = static_cast<uint32_t>(r2() % (ground.size() + 40));
        for (ShadowHint* hint : {&natural, &wild}) {
          float hinted_trans[kPacketSize];
          const uint32_t before = hint->prim;
          ASSERT_EQ(scene.transmittance(packet, kAllLanes, hinted_trans, hint), unsure);
          for (int i = 0; i < kPacketSize; ++i) {
            if (!((unsure >> i) & 1u)) {
              ASSERT_EQ(hinted_trans[i], trans[i]) << to_string(level) << " packet " << p << " lane " << i;
            }
          }
          if (config == Config::kKdTreeBvh && before != kInvalidId && before >= ground.size()) {
            ASSERT_NE(hint->prim, before) << "a hint past the end is dropped";
          }
          if (hint->prim != before && hint->prim != kInvalidId) {  // a new blocker: opaque
            ASSERT_LT(hint->prim, ground.size());
            ASSERT_EQ(ground_pass[hint->prim], 0.0f);
          }
          ASSERT_EQ(scene.occluded(packet, kAllLanes, hint), blocked) << to_string(level) << " packet " << p;
          hinted += hint == &natural && before != kInvalidId;
        }
        for (int i = 0; i < kPacketSize; ++i) {
          if ((unsure >> i) & 1u) {
            ++unsure_lanes;
            continue;
          }
          const float ref = transmittance_brute_force(packet.get(i), flat, flat_pass);
          ASSERT_NEAR(trans[i], ref, 1e-5f * std::max(1.0f, ref)) << to_string(level) << " packet " << p << " lane " << i;
          // nothing crossed: 1, exactly as the any-hit test says
          if (!((blocked >> i) & 1u)) {
            ASSERT_EQ(trans[i], 1.0f);
          }
          partial += ref > 0.0f && ref < 1.0f;
          ++counted;
        }
      }
      EXPECT_LE(unsure_lanes, counted / 100) << "unsure answers should be rare";
      EXPECT_GT(partial, counted / 10) << "the test must exercise transmissive crossings";
      if (config == Config::kKdTreeBvh) {
        // a hint that blocks none of a packet's lanes is dropped (it is tried once), and random
        // packets rarely share a blocker: 47 of these packets start with one
        EXPECT_GT(hinted, static_cast<size_t>(test::brute_force_rays(400) / 16)) << "the natural hint must be exercised";
      }
    }
  }
  set_simd_level(saved);

  TwoLevelScene scene;
  scene.set_static(ground);
  EXPECT_THROW(scene.set_static_transmittance(std::vector<float>(3, 0.5f)), std::invalid_argument);
  std::vector<float> bad = ground_pass;
  bad[7] = 1.5f;
  EXPECT_THROW(scene.set_static_transmittance(bad), std::invalid_argument);
  EXPECT_THROW(scene.set_mesh_transmittance(MeshHandle{}, object_pass), std::invalid_argument);
}

/// A deforming mesh carries its triangles' transmittance too: right after it is added, after its
/// vertices move (refit), and, once set again, after a rebuild with fewer triangles (commit
/// refuses the stale values until then).
TEST(TwoLevelScene, DeformableMeshTransmittanceEqualsBruteForce) {
  std::mt19937 rng(73);
  const std::vector<Triangle> soup = test::random_soup(rng, 400, 0.6f);
  TriangleMesh mesh;
  for (uint32_t k = 0; k < soup.size(); ++k) {
    mesh.positions.insert(mesh.positions.end(), {soup[k].v0, soup[k].v1, soup[k].v2});
    mesh.indices.push_back({3 * k, 3 * k + 1, 3 * k + 2});
  }
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  std::vector<float> pass(soup.size());
  for (float& v : pass) v = uni(rng) < 0.3f ? 0.0f : 0.2f + 0.8f * uni(rng);
  TwoLevelScene scene;
  const DeformableHandle h = scene.add_deformable(mesh);
  scene.set_deformable_transmittance(h, pass);
  auto current = [&] {
    const TriangleMesh& m = scene.deformable(h).mesh();
    std::vector<Triangle> tris;
    for (const glm::uvec3& i : m.indices) tris.push_back({m.positions[i.x], m.positions[i.y], m.positions[i.z]});
    return tris;
  };
  auto check = [&](const std::vector<float>& p, const char* what) {
    const std::vector<Triangle> tris = current();  // (the accessor marks the scene edited)
    scene.commit();
    std::mt19937 r2(6);
    size_t partial = 0;
    for (int k = 0; k < 200; ++k) {
      RayPacket packet;
      const glm::vec3 light = test::random_point(r2, 0.0f, 10.0f);
      for (int i = 0; i < kPacketSize; ++i) {
        const glm::vec3 o = test::random_point(r2, 0.0f, 10.0f);
        packet.set(i, Ray{o, light - o, 0.0f, 1.0f});
      }
      float trans[kPacketSize];
      const LaneMask unsure = scene.transmittance(packet, kAllLanes, trans);
      for (int i = 0; i < kPacketSize; ++i) {
        if ((unsure >> i) & 1u) continue;
        const float ref = transmittance_brute_force(packet.get(i), tris, p);
        ASSERT_NEAR(trans[i], ref, 1e-5f * std::max(1.0f, ref)) << what << " packet " << k << " lane " << i;
        partial += ref > 0.0f && ref < 1.0f;
      }
    }
    EXPECT_GT(partial, 100u) << what << ": the rays must cross transmissive triangles";
  };
  check(pass, "as added");
  for (glm::vec3& v : scene.deformable(h).positions()) v += 0.3f * test::random_direction(rng);
  scene.deformable(h).refit();
  check(pass, "moved");
  scene.deformable(h).indices().resize(250);
  scene.deformable(h).rebuild();
  EXPECT_THROW(scene.commit(), std::logic_error) << "400 values for 250 triangles";
  pass.resize(250);
  scene.set_deformable_transmittance(h, pass);
  check(pass, "rebuilt");
  EXPECT_THROW(scene.set_deformable_transmittance(h, std::vector<float>(10, 0.5f)), std::invalid_argument);
  EXPECT_THROW(scene.set_deformable_transmittance(DeformableHandle{}, pass), std::invalid_argument);
}

TEST(TwoLevelScene, MisuseIsReported) {
  TwoLevelScene scene;
  const MeshHandle mesh = scene.add_rigid_mesh({{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}});
  const InstanceHandle inst = scene.add_instance(mesh, glm::mat4(1.0f));
  EXPECT_THROW(scene.intersect(Ray{}), std::logic_error) << "tracing before commit";
  scene.commit();
  scene.remove_instance(inst);
  EXPECT_THROW(scene.set_transform(inst, glm::mat4(1.0f)), std::invalid_argument) << "stale handle";
  const InstanceHandle again = scene.add_instance(mesh, glm::mat4(1.0f));
  EXPECT_EQ(again.index, inst.index) << "the slot is reused";
  EXPECT_THROW(scene.set_transform(inst, glm::mat4(1.0f)), std::invalid_argument) << "old handle to a reused slot";
  EXPECT_NO_THROW(scene.set_transform(again, glm::mat4(2.0f)));
  EXPECT_THROW(scene.add_instance(MeshHandle{7, 0}, glm::mat4(1.0f)), std::invalid_argument);

  TriangleMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
  m.indices = {{0, 1, 2}};
  const DeformableHandle d = scene.add_deformable(m);
  scene.deformable(d).indices().push_back({1, 3, 2});
  try {
    scene.deformable(d).refit();
    ADD_FAILURE() << "refit after a topology change must throw";
  } catch (const std::logic_error& e) {
    EXPECT_NE(std::string(e.what()).find("call rebuild()"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(scene.deformable(d).rebuild());
  EXPECT_NO_THROW(scene.deformable(d).refit());
  scene.deformable(d).indices().back() = {1, 3, 9};
  EXPECT_THROW(scene.deformable(d).rebuild(), std::out_of_range) << "index past the vertices";
  scene.remove_deformable(d);
  EXPECT_THROW(scene.deformable(d), std::invalid_argument);
}

TEST(KinematicTree, ChildrenFollowTheirParents) {
  TwoLevelScene scene;
  const MeshHandle mesh = scene.add_rigid_mesh({{{-0.5f, -0.5f, 0}, {0.5f, -0.5f, 0}, {0, 0.5f, 0}}});
  KinematicTree tree;
  const int arm = tree.add_node(-1);
  const int hand = tree.add_node(arm, glm::translate(glm::mat4(1.0f), glm::vec3(2, 0, 0)));
  tree.attach(hand, scene.add_instance(mesh, glm::mat4(1.0f)));
  // rotate the arm 90 degrees about z: the hand moves from x=2 to y=2
  tree.set_local(arm, glm::rotate(glm::mat4(1.0f), glm::radians(90.0f), glm::vec3(0, 0, 1)));
  tree.update(scene);
  scene.commit();
  EXPECT_TRUE(scene.intersect(Ray{{0, 2, -5}, {0, 0, 1}}).valid());
  EXPECT_FALSE(scene.intersect(Ray{{2, 0, -5}, {0, 0, 1}}).valid());
  EXPECT_THROW(tree.add_node(5), std::out_of_range);
}

}  // namespace
}  // namespace artrace::core
