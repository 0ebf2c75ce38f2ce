// Whitted shading against answers worked out by hand: Lambert's law on a lit plane, a shadowed
// point, a mirror, Snell's law through a glass slab, total internal reflection, what each of the
// four modes adds, and secondary-ray offsets that hold from 1e-3 to 1e4.
#include "artrace/core/whitted.h"
#include "artrace/core/simd_level.h"

#include "../test_util.h"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <random>

namespace artrace::core {
namespace {

/// A static scene with one material per triangle.
struct TestScene : SurfaceAttributes {
  std::vector<Triangle> tris;
  std::vector<uint32_t> mat;
  TwoLevelScene geometry{TwoLevelScene::Config::kKdTreeBvh};
  ShadingScene shading;

  /// When set, every hit is textured with shading.textures[0], at texture coordinates taken from
  /// its barycentrics and far outside [0, 1] (repeats): on odd triangles at the mip level the
  /// footprint picks, on even ones at full size.
  bool textured = false;

  uint32_t material(const Hit& h) const override { return mat.at(h.prim); }
  void shade_packet(const HitPacket& hits, LaneMask mask, const Triangle* world_tris, uint32_t* materials,
                    SurfaceInfo* infos) const override {
    SurfaceAttributes::shade_packet(hits, mask, world_tris, materials, infos);
    if (!textured) return;
    for (int i = 0; i < kPacketSize; ++i) {
      if (!((mask >> i) & 1u)) continue;
      infos[i].texture = 0;
      infos[i].uv = glm::vec2(7.0f * hits.u[i] - 3.0f, 5.0f * hits.v[i] + 0.25f * static_cast<float>(hits.prim[i]));
      infos[i].uv_per_world = hits.prim[i] % 2 ? 4.0f : 0.0f;  // 0: the full-size texture
    }
  }

  uint32_t add_material(const Material& m) {
    shading.materials.push_back(m);
    return static_cast<uint32_t>(shading.materials.size() - 1);
  }
  /// Quad a b c d (counter-clockwise seen from the side its normal points to).
  void quad(glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d, uint32_t m) {
    tris.push_back({a, b, c});
    tris.push_back({a, c, d});
    mat.insert(mat.end(), {m, m});
  }
  /// Square of half size h in the plane z = z0, normal +z (or -z).
  void square_z(float cx, float cy, float z0, float h, uint32_t m, bool up = true) {
    const glm::vec3 a{cx - h, cy - h, z0}, b{cx + h, cy - h, z0}, c{cx + h, cy + h, z0}, d{cx - h, cy + h, z0};
    if (up) {
      quad(a, b, c, d, m);
    } else {
      quad(a, d, c, b, m);
    }
  }
  /// With `transmittance`, the scene also knows each triangle's transmittance, and shadow rays
  /// see through glass in one traversal instead of walking it surface by surface.
  void commit(bool transmittance = false) {
    geometry.set_static(tris);
    if (transmittance) {
      std::vector<float> pass;
      for (const uint32_t m : mat) pass.push_back(shading.materials[m].transmittance);
      geometry.set_static_transmittance(pass);
    }
    geometry.commit();
    shading.geometry = &geometry;
    shading.surfaces = this;
  }
  glm::vec3 trace(const glm::vec3& org, const glm::vec3& dir, ShadingMode mode, int max_depth = 2) const {
    Ray r;
    r.org = org;
    r.dir = glm::normalize(dir);
    WhittedOptions o;
    o.mode = mode;
    o.max_depth = max_depth;
    return trace_whitted(shading, r, o);
  }
};

Material diffuse(glm::vec3 c, glm::vec3 ambient = glm::vec3(0.0f)) {
  Material m;
  m.diffuse = c;
  m.ambient = ambient;
  return m;
}

Material emitter(glm::vec3 c) {  // shows its colour through the ambient term alone
  Material m;
  m.diffuse = glm::vec3(0.0f);
  m.ambient = c;
  return m;
}

Material glass(float ior) {
  Material m;
  m.diffuse = glm::vec3(0.0f);
  m.transmittance = 1.0f;
  m.ior = ior;
  return m;
}

void expect_near(const glm::vec3& a, const glm::vec3& b, float rel, const char* what) {
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(a[k], b[k], rel * std::max(1.0f, std::fabs(b[k]))) << what << " channel " << k;
}

/// Fresnel equations written out independently of the renderer.
double fresnel_reference(double theta_i, double n1, double n2) {
  const double s = n1 / n2 * std::sin(theta_i);
  if (s >= 1.0) return 1.0;
  const double theta_t = std::asin(s), ci = std::cos(theta_i), ct = std::cos(theta_t);
  const double rs = (n1 * ci - n2 * ct) / (n1 * ci + n2 * ct), rp = (n2 * ci - n1 * ct) / (n2 * ci + n1 * ct);
  return 0.5 * (rs * rs + rp * rp);
}

TEST(Whitted, LitDiffusePlaneFollowsLambert) {
  TestScene s;
  s.square_z(0, 0, 0, 10, s.add_material(diffuse({0.5f, 0.4f, 0.3f}, {0.2f, 0.2f, 0.2f})));
  s.shading.ambient = glm::vec3(0.5f);
  const PointLight light{{1.0f, 2.0f, 3.0f}, {0.8f, 0.9f, 1.0f}};
  s.shading.lights = {light};
  s.commit();
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> d(-3.0f, 3.0f);
  for (int i = 0; i < 200; ++i) {
    const glm::vec3 p{d(rng), d(rng), 0.0f};
    const float cos_theta = glm::normalize(light.position - p).z;
    const glm::vec3 expected = 0.5f * glm::vec3(0.2f) + glm::vec3(0.5f, 0.4f, 0.3f) * light.color * cos_theta;
    for (ShadingMode m : {ShadingMode::kDiffuse, ShadingMode::kShadows, ShadingMode::kReflect, ShadingMode::kAll}) {
      expect_near(s.trace(p + glm::vec3(0.3f, -0.2f, 4.0f), glm::vec3(-0.3f, 0.2f, -4.0f), m), expected, 1e-5f, to_string(m));
    }
  }
}

TEST(Whitted, ShadowedPointGetsOnlyAmbient) {
  TestScene s;
  s.square_z(0, 0, 0, 10, s.add_material(diffuse({0.6f, 0.6f, 0.6f}, {0.1f, 0.1f, 0.1f})));
  s.square_z(0, 0, 1, 0.5f, s.add_material(diffuse({0.6f, 0.6f, 0.6f})), false);  // occluder facing the floor
  s.shading.ambient = glm::vec3(1.0f);
  s.shading.lights = {{{0.0f, 0.0f, 3.0f}, {1.0f, 1.0f, 1.0f}}};
  s.commit();
  // seen from the side, under the occluder: lit without shadows, ambient only with them
  const glm::vec3 under = s.trace({5.0f, 0.0f, 1.0f}, {-5.0f, 0.0f, -1.0f}, ShadingMode::kShadows);
  expect_near(under, glm::vec3(0.1f), 1e-6f, "shadowed");
  expect_near(s.trace({5.0f, 0.0f, 1.0f}, {-5.0f, 0.0f, -1.0f}, ShadingMode::kDiffuse), glm::vec3(0.1f + 0.6f), 1e-5f,
              "no shadow rays");
  // (2, 0, 0): the ray to the light passes beside the occluder
  const float c = glm::normalize(glm::vec3(-2.0f, 0.0f, 3.0f)).z;
  expect_near(s.trace({7.0f, 0.0f, 1.0f}, {-5.0f, 0.0f, -1.0f}, ShadingMode::kShadows), glm::vec3(0.1f + 0.6f * c), 1e-5f,
              "lit");
}

TEST(Whitted, TransmissiveSurfacesAttenuateShadowsInsteadOfBlockingThem) {
  for (const bool one_traversal : {false, true}) {
    TestScene s;
    s.square_z(0, 0, 0, 10, s.add_material(diffuse({0.5f, 0.5f, 0.5f})));
    Material veil = diffuse({0.1f, 0.1f, 0.1f});
    veil.transmittance = 0.6f;
    veil.ior = 1.0f;
    s.square_z(0, 0, 2, 10, s.add_material(veil), false);  // a semi-transparent sky under the light
    s.square_z(0, 0, 2.5f, 10, s.add_material(veil), false);
    s.shading.lights = {{{0.0f, 0.0f, 5.0f}, {1.0f, 1.0f, 1.0f}}};
    s.commit(one_traversal);
    // seen from below the veils: two layers pass 0.6 * 0.6 of the light
    const glm::vec3 seen = s.trace({1.0f, 0.0f, 1.0f}, {-1.0f, 0.0f, -1.0f}, ShadingMode::kShadows);
    expect_near(seen, glm::vec3(0.5f * 0.36f), 1e-5f, one_traversal ? "attenuated (one traversal)" : "attenuated (walk)");
  }
}

TEST(Whitted, ShadowsThroughGlassAreTheSameWalkedOrInOneTraversal) {
  // Glass boxes and an opaque block over a floor, two lights: every pixel of the image must come
  // out the same whether shadow rays walk the glass surface by surface or see through it.
  auto build = [](TestScene& s) {
    s.square_z(0, 0, 0, 10, s.add_material(diffuse({0.6f, 0.5f, 0.4f})));
    Material tinted = glass(1.3f);
    tinted.transmittance = 0.7f;
    const uint32_t g = s.add_material(tinted);
    const uint32_t block = s.add_material(diffuse({0.2f, 0.3f, 0.8f}));
    auto box = [&](glm::vec3 lo, glm::vec3 hi, uint32_t m) {
      const glm::vec3 p[8] = {{lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {hi.x, hi.y, lo.z}, {lo.x, hi.y, lo.z},
                              {lo.x, lo.y, hi.z}, {hi.x, lo.y, hi.z}, {hi.x, hi.y, hi.z}, {lo.x, hi.y, hi.z}};
      s.quad(p[0], p[3], p[2], p[1], m);
      s.quad(p[4], p[5], p[6], p[7], m);
      s.quad(p[0], p[1], p[5], p[4], m);
      s.quad(p[2], p[3], p[7], p[6], m);
      s.quad(p[1], p[2], p[6], p[5], m);
      s.quad(p[0], p[4], p[7], p[3], m);
    };
    box({-2.0f, -1.0f, 0.5f}, {-0.5f, 1.0f, 2.0f}, g);
    box({0.2f, -0.5f, 0.3f}, {1.6f, 0.9f, 1.1f}, g);
    box({0.6f, -2.5f, 0.0f}, {1.2f, -1.5f, 1.5f}, block);
    s.shading.lights = {{{1.0f, 2.0f, 6.0f}, {0.7f, 0.7f, 0.7f}}, {{-4.0f, -3.0f, 4.0f}, {0.5f, 0.4f, 0.3f}}};
  };
  TestScene walked, traversed;
  build(walked);
  build(traversed);
  walked.commit(false);
  traversed.commit(true);
  Camera cam = Camera::look_at({5.0f, -6.0f, 6.0f}, {0.0f, 0.0f, 0.5f}, {0.0f, 0.0f, 1.0f}, 50.0f, 96, 72);
  WhittedOptions o;
  o.mode = ShadingMode::kAll;
  const Image a = render_whitted(walked.shading, cam, o);
  const Image b = render_whitted(traversed.shading, cam, o);
  ASSERT_EQ(a.pixels.size(), b.pixels.size());
  size_t tinted = 0;
  for (size_t i = 0; i < a.pixels.size(); ++i) {
    ASSERT_NEAR(a.pixels[i].x, b.pixels[i].x, 1e-5f) << "pixel " << i;
    ASSERT_NEAR(a.pixels[i].y, b.pixels[i].y, 1e-5f) << "pixel " << i;
    ASSERT_NEAR(a.pixels[i].z, b.pixels[i].z, 1e-5f) << "pixel " << i;
  }
  // the glass must matter: the same scene with opaque boxes differs
  TestScene opaque;
  build(opaque);
  opaque.shading.materials[1].transmittance = 0.0f;
  opaque.commit(true);
  const Image c = render_whitted(opaque.shading, cam, o);
  for (size_t i = 0; i < a.pixels.size(); ++i) tinted += glm::length(a.pixels[i] - c.pixels[i]) > 1e-3f;
  EXPECT_GT(tinted, a.pixels.size() / 20);
}

TEST(Whitted, NoShadowRayWhereTheLightAddsNothing) {
  // a black tile (no highlight) beside a grey one, seen from above, one light over the middle
  TestScene s;
  const uint32_t black = s.add_material(diffuse(glm::vec3(0.0f), glm::vec3(0.3f)));
  const uint32_t grey = s.add_material(diffuse(glm::vec3(0.5f)));
  s.square_z(-1.0f, 0.0f, 0.0f, 1.0f, black);
  s.square_z(1.0f, 0.0f, 0.0f, 1.0f, grey);
  s.shading.ambient = glm::vec3(1.0f);
  s.shading.lights = {{{0.0f, 0.0f, 3.0f}, {1.0f, 1.0f, 1.0f}}};
  s.commit();
  const Camera cam = Camera::look_at({0.0f, 0.0f, 4.0f}, {0.0f, 0.0f, 0.0f}, {0, 1, 0}, 60.0f, 40, 24);
  int on_grey = 0, on_black = 0;
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const Hit h = s.geometry.intersect(cam.ray(x + 0.5f, y + 0.5f));
      if (h.valid()) ++(s.mat[h.prim] == grey ? on_grey : on_black);
    }
  }
  ASSERT_GT(on_grey, 50);
  ASSERT_GT(on_black, 50);
  WhittedOptions o;
  o.mode = ShadingMode::kShadows;
  WhittedStats st;
  const Image shadows = render_whitted(s.shading, cam, o, &st);
  EXPECT_EQ(st.shadow_rays, static_cast<uint64_t>(on_grey)) << "one shadow ray for each grey pixel, none for the black";
  o.mode = ShadingMode::kDiffuse;
  const Image plain = render_whitted(s.shading, cam, o);
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) EXPECT_EQ(shadows.at(x, y), plain.at(x, y)) << x << "," << y;
  }

  // a highlight on black is light the shadow ray still decides: under an occluder it goes
  Material shiny = diffuse(glm::vec3(0.0f), glm::vec3(0.3f));
  shiny.specular = glm::vec3(0.5f);
  shiny.shine = 4.0f;
  s.shading.materials[black] = shiny;
  const glm::vec3 eye{-1.0f, 0.0f, 2.0f}, down{0.0f, 0.0f, -1.0f};  // straight down on (-1, 0, 0)
  const glm::vec3 lit = s.trace(eye, down, ShadingMode::kShadows);
  EXPECT_GT(lit.x, 0.3f + 1e-3f) << "the highlight without an occluder";
  s.square_z(-0.5f, 0.0f, 1.5f, 0.2f, grey, false);  // between (-1, 0, 0) and the light
  s.commit();
  expect_near(s.trace(eye, down, ShadingMode::kShadows), glm::vec3(0.3f), 1e-6f, "the highlight in shadow");
}

TEST(Whitted, MirrorReflectsAKnownColour) {
  TestScene s;
  Material mirror;
  mirror.diffuse = glm::vec3(0.0f);
  mirror.specular = glm::vec3(1.0f);
  s.square_z(0, 0, 0, 2, s.add_material(mirror));
  const glm::vec3 wall{0.2f, 0.6f, 0.3f};
  const uint32_t w = s.add_material(emitter(wall));
  s.quad({-3, -5, -5}, {-3, 5, -5}, {-3, 5, 5}, {-3, -5, 5}, w);  // wall x = -3 facing +x
  s.shading.ambient = glm::vec3(1.0f);
  s.commit();
  expect_near(s.trace({2, 0, 2}, {-1, 0, -1}, ShadingMode::kReflect), wall, 1e-6f, "mirror");
  expect_near(s.trace({2, 0, 2}, {-1, 0, -1}, ShadingMode::kAll), wall, 1e-6f, "mirror, all");
  expect_near(s.trace({2, 0, 2}, {-1, 0, -1}, ShadingMode::kDiffuse), glm::vec3(0.0f), 1e-6f, "no reflection rays");
  expect_near(s.trace({2, 0, 2}, {-1, 0, -1}, ShadingMode::kShadows), glm::vec3(0.0f), 1e-6f, "no reflection rays");
}

TEST(Whitted, GlassSlabRefractsBySnellsLaw) {
  const float ior = 1.5f;
  const double theta = 40.0 * M_PI / 180.0, theta_t = std::asin(std::sin(theta) / ior);
  // slab between z = -1 and z = 0; the ray enters at the origin, leaves at z = -1 displaced by
  // tan(theta_t), and meets the plane z = -2 at x = tan(theta_t) + tan(theta)
  const float x_refracted = static_cast<float>(std::tan(theta_t) + std::tan(theta));
  const float x_straight = static_cast<float>(2.0 * std::tan(theta));
  TestScene s;
  const uint32_t g = s.add_material(glass(ior));
  s.square_z(0, 0, 0, 20, g, true);
  s.square_z(0, 0, -1, 20, g, false);
  const glm::vec3 colour{0.9f, 0.5f, 0.2f}, other{0.1f, 0.2f, 0.9f};
  s.square_z(x_refracted, 0, -2, 0.02f, s.add_material(emitter(colour)));
  s.square_z(x_straight, 0, -2, 0.02f, s.add_material(emitter(other)));
  s.shading.ambient = glm::vec3(1.0f);
  s.commit();
  const glm::vec3 dir{static_cast<float>(std::sin(theta)), 0.0f, static_cast<float>(-std::cos(theta))};
  const glm::vec3 org = -dir * 2.0f;
  const double f = fresnel_reference(theta, 1.0, ior);  // the same at both faces of a parallel slab
  EXPECT_NEAR(fresnel_reference(theta_t, ior, 1.0), f, 1e-9);
  expect_near(s.trace(org, dir, ShadingMode::kReflect), colour * static_cast<float>((1.0 - f) * (1.0 - f)), 1e-5f,
              "through the slab");
  expect_near(s.trace(org, dir, ShadingMode::kDiffuse), glm::vec3(0.0f), 1e-6f, "no refraction rays");
}

TEST(Whitted, TotalInternalReflection) {
  const float ior = 1.5f;
  TestScene s;
  const uint32_t g = s.add_material(glass(ior));
  s.square_z(0, 0, 0, 20, g, true);    // top face of a slab, seen from inside
  s.square_z(0, 0, -1, 20, g, false);  // bottom face
  const glm::vec3 colour{0.3f, 0.8f, 0.4f};
  s.shading.ambient = glm::vec3(1.0f);
  // from (0, 0, -0.5) up to the top face at angle theta, back down to a target at z = -0.75
  for (double deg : {60.0, 45.0, 20.0}) {
    const double theta = deg * M_PI / 180.0;
    TestScene t = {};
    t.tris = s.tris;
    t.mat = s.mat;
    t.shading.materials = s.shading.materials;
    t.shading.ambient = s.shading.ambient;
    const float x = static_cast<float>(1.25 * std::tan(theta));  // 0.5 up, 0.75 down
    t.square_z(x, 0, -0.75f, 0.01f, t.add_material(emitter(colour)));
    t.commit();
    const glm::vec3 dir{static_cast<float>(std::sin(theta)), 0.0f, static_cast<float>(std::cos(theta))};
    const double f = fresnel_reference(theta, ior, 1.0);  // 1 past the critical angle (41.8 degrees)
    if (deg > 41.9) {
      EXPECT_EQ(f, 1.0);
    }
    expect_near(t.trace({0, 0, -0.5f}, dir, ShadingMode::kReflect), colour * static_cast<float>(f), 1e-5f,
                deg > 41.9 ? "total internal reflection" : "partial reflection");
  }
  EXPECT_EQ(fresnel_dielectric(std::cos(60.0f * static_cast<float>(M_PI) / 180.0f), ior), 1.0f);
  glm::vec3 out;
  EXPECT_FALSE(refract_direction(glm::normalize(glm::vec3(0.866f, 0, 0.5f)), {0, 0, -1}, ior, out));
}

/// A small room: floor, a mirror, a glass block, an occluder, two lights; rendered in the four modes.
TestScene room() {
  TestScene s;
  const uint32_t floor = s.add_material(diffuse({0.6f, 0.5f, 0.4f}, {0.1f, 0.1f, 0.1f}));
  Material mirror = diffuse({0.1f, 0.1f, 0.1f});
  mirror.specular = glm::vec3(0.8f);
  const uint32_t m = s.add_material(mirror);
  Material g = glass(1.5f);
  g.specular = glm::vec3(0.05f);
  const uint32_t gl = s.add_material(g);
  const uint32_t box = s.add_material(diffuse({0.2f, 0.7f, 0.3f}));
  s.square_z(0, 0, 0, 4, floor);
  s.quad({-2, 2, 0}, {2, 2, 0}, {2, 2, 2}, {-2, 2, 2}, m);  // mirror at y = 2, facing -y... and +y
  s.square_z(1.2f, 0, 0.6f, 0.4f, gl);                      // a glass sheet
  s.square_z(1.2f, 0, 0.4f, 0.4f, gl, false);
  s.square_z(-1, -0.5f, 0.8f, 0.3f, box);  // a floating tile that casts a shadow
  s.square_z(-1, -0.5f, 0.8f, 0.3f, box, false);
  s.shading.ambient = glm::vec3(0.5f);
  s.shading.lights = {{{-1.2f, -0.6f, 3.0f}, {0.7f, 0.7f, 0.7f}}, {{2.0f, -2.0f, 2.5f}, {0.4f, 0.4f, 0.5f}}};
  s.commit();
  return s;
}

/// A view of room() from the front, above the floor.
Camera room_camera(int width, int height) {
  return Camera::look_at({0.5f, -4.0f, 2.5f}, {0.0f, 0.5f, 0.3f}, {0, 0, 1}, 60.0f, width, height);
}

TEST(Whitted, TheFourModesDifferExactlyInTheEffectsTheyInclude) {
  const TestScene s = room();
  const Camera cam = Camera::look_at({0.0f, -4.0f, 3.0f}, {0.0f, 0.5f, 0.3f}, {0, 0, 1}, 50.0f, 64, 48);
  Image img[4];
  for (int k = 0; k < 4; ++k) {
    WhittedOptions o;
    o.mode = static_cast<ShadingMode>(k);
    o.threads = 2;
    img[k] = render_whitted(s.shading, cam, o);
  }
  const Image &diffuse_only = img[0], &shadows = img[1], &reflect = img[2], &all = img[3];
  int shadowed = 0, reflecting = 0;
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const Hit h = s.geometry.intersect(cam.ray(x + 0.5f, y + 0.5f));
      const bool plain = h.valid() && s.shading.materials[s.mat[h.prim]].transmittance == 0.0f &&
                         s.shading.materials[s.mat[h.prim]].specular == glm::vec3(0.0f);
      if (!h.valid() || plain) {
        // a plain diffuse surface spawns no secondary rays: reflection modes change nothing there
        EXPECT_EQ(reflect.at(x, y), diffuse_only.at(x, y)) << x << "," << y;
        EXPECT_EQ(all.at(x, y), shadows.at(x, y)) << x << "," << y;
      } else {
        reflecting += reflect.at(x, y) != diffuse_only.at(x, y);
      }
      // shadows only take light away
      for (int c = 0; c < 3; ++c) EXPECT_LE(shadows.at(x, y)[c], diffuse_only.at(x, y)[c] + 1e-6f);
      shadowed += plain && shadows.at(x, y) != diffuse_only.at(x, y);
    }
  }
  EXPECT_GT(shadowed, 20) << "the floating tile's shadow";
  EXPECT_GT(reflecting, 100) << "the mirror and the glass";
}

/// The paper's workload (shadow rays at camera hits only) is, pixel by pixel, the shadows image plus
/// what reflection and refraction add without shadows: (d') = (b) + (c) - (a), the identity the
/// paper's Table 1 satisfies. Full Whitted differs from it only by taking light away, where a
/// reflected or refracted point lies in a shadow.
TEST(Whitted, PaperWorkloadIsShadowsPlusUnshadowedSecondaryRays) {
  const TestScene s = room();
  const Camera cam = room_camera(64, 48);
  Image img[5];
  for (const ShadingMode mode : {ShadingMode::kDiffuse, ShadingMode::kShadows, ShadingMode::kReflect, ShadingMode::kAll,
                                 ShadingMode::kPaper}) {
    WhittedOptions o;
    o.mode = mode;
    o.threads = 2;
    img[static_cast<int>(mode)] = render_whitted(s.shading, cam, o);
  }
  const Image &a = img[0], &b = img[1], &c = img[2], &d = img[3], &paper = img[4];
  int darker_in_full = 0;
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(paper.at(x, y)[k], b.at(x, y)[k] + c.at(x, y)[k] - a.at(x, y)[k], 1e-5f) << x << "," << y;
        EXPECT_LE(d.at(x, y)[k], paper.at(x, y)[k] + 1e-6f) << x << "," << y;
      }
      darker_in_full += d.at(x, y) != paper.at(x, y);
    }
  }
  EXPECT_GT(darker_in_full, 5) << "the mirror shows the floating tile's shadow in full Whitted only";
  EXPECT_EQ(parse_shading_mode("paper"), ShadingMode::kPaper);
  EXPECT_STREQ(to_string(ShadingMode::kPaper), "paper");
}

TEST(Whitted, SameImageForAnyThreadCountAndWithSecondaryPacketsOrSingleRays) {
  const TestScene s = room();
  const Camera cam = room_camera(80, 56);
  WhittedOptions o;
  o.mode = ShadingMode::kAll;
  o.threads = 1;
  const Image a = render_whitted(s.shading, cam, o);
  o.threads = 2;
  const Image b = render_whitted(s.shading, cam, o);
  o.secondary_packets = false;
  const Image c = render_whitted(s.shading, cam, o);
  EXPECT_EQ(a.pixels, b.pixels);
  EXPECT_EQ(a.pixels, c.pixels);
}

TEST(Whitted, SameImageWithEveryPacketKernelAndShadingCopy) {
  // the kernels trace a packet 16, 8 or 4 lanes at a time, or lane by lane, with the same float
  // operations: the frame (glass shadows and secondary rays included) must not change
  const TestScene s = room();
  const Camera cam = room_camera(80, 56);
  WhittedOptions o;
  o.mode = ShadingMode::kAll;
  const SimdLevel saved = simd_level();
  // The shading follows the same choice (an AVX2 copy for AVX2 and AVX-512, else the baseline
  // one), so the room is also rendered textured: filtering, mip levels and repeats in both copies.
  TestScene t = room();
  t.textured = true;
  t.shading.surfaces = &t;
  Texture& tex = t.shading.textures.emplace_back();
  tex.width = 16;
  tex.height = 8;
  for (int i = 0; i < tex.width * tex.height; ++i) {
    tex.texels.push_back(glm::vec3((i % 7) / 6.0f, (i % 3) / 2.0f, ((i / 16 + i) % 2) ? 0.9f : 0.2f));
  }
  tex.build_mipmaps();
  set_simd_level(SimdLevel::kScalar);
  const Image want = render_whitted(s.shading, cam, o);
  const Image want_textured = render_whitted(t.shading, cam, o);
  ASSERT_NE(want_textured.pixels, want.pixels);
  for (const SimdLevel level : {SimdLevel::kSse, SimdLevel::kAvx2, SimdLevel::kAvx512}) {
    if (!simd_level_supported(level)) {
      std::cout << "[ note ] " << to_string(level) << " not supported by this CPU, not tested\n";
      continue;
    }
    set_simd_level(level);
    EXPECT_EQ(render_whitted(s.shading, cam, o).pixels, want.pixels) << to_string(level);
    EXPECT_EQ(render_whitted(t.shading, cam, o).pixels, want_textured.pixels) << to_string(level) << ", textured";
  }
  set_simd_level(saved);
}

/// Floor z = 0 split by a wall x = 0 (both at scale s, moved by `shift`), a light on the +x side
/// and a grazing one: floor points on the far side are in shadow up to the wall's foot (no light
/// leaks under it), points on the near side get Lambert's value from each light (no acne).
void check_offsets(float scale, glm::vec3 shift) {
  TestScene s;
  const uint32_t floor = s.add_material(diffuse({0.5f, 0.5f, 0.5f}));
  const uint32_t wall = s.add_material(diffuse({0.5f, 0.5f, 0.5f}));
  auto P = [&](float x, float y, float z) { return shift + scale * glm::vec3(x, y, z); };
  s.quad(P(-1, -1, 0), P(1, -1, 0), P(1, 1, 0), P(-1, 1, 0), floor);
  s.quad(P(0, -1, 0), P(0, 1, 0), P(0, 1, 1), P(0, -1, 1), wall);
  // and a low ceiling over x > 0, y > 0.5: a thousandth of the scale above the floor, or 1e-5 of
  // the largest coordinate where that is more (closer surfaces are at the limit of float)
  const float big = std::max({std::fabs(shift.x), std::fabs(shift.y), std::fabs(shift.z)}) + scale;
  const float gap = std::max(1e-3f, 1e-5f * big / scale);
  s.quad(P(0, 0.5f, gap), P(0, 1, gap), P(1, 1, gap), P(1, 0.5f, gap), wall);
  s.commit();
  // Points closer to the wall than a few units in the last place of the coordinates cannot be
  // told apart from points on it: the probes keep 8 ulps of the largest coordinate away.
  const float min_gap = 8.0f * (std::nextafter(big, 2.0f * big) - big);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-0.9f, 0.9f), tiny(-6.0f, -1.0f);
  int leaks = 0, acne = 0, probes = 0;
  for (const PointLight light : {PointLight{P(0.5f, 0.0f, 0.5f), glm::vec3(1.0f)}, PointLight{P(3.0f, 0.2f, 0.02f), glm::vec3(1.0f)}}) {
    s.shading.lights = {light};
    for (int i = 0; i < 300; ++i) {
      // half of the probes hug the wall: 10^-6 .. 10^-1 of the scale from it
      float x = scale * u(rng);
      if (i % 2) x = std::copysign(std::max(scale * std::pow(10.0f, tiny(rng)), min_gap), x);
      float y = scale * u(rng);
      if (y > 0.45f * scale) y = -y;  // probes under the ceiling come below
      const glm::vec3 p = shift + glm::vec3(x, y, 0.0f);
      ++probes;
      const glm::vec3 seen = s.trace(p + glm::vec3(0, 0, 2.0f * scale), {0, 0, -1}, ShadingMode::kShadows);
      if (p.x < shift.x) {
        leaks += seen != glm::vec3(0.0f);
      } else {
        const float expected = 0.5f * glm::normalize(light.position - p).z;
        acne += std::fabs(seen.x - expected) > 0.02f * expected;
      }
    }
  }
  // under the ceiling, seen from the open side: no light from above gets in
  s.shading.lights = {PointLight{P(0.5f, 0.75f, 0.5f), glm::vec3(1.0f)}};  // right above the ceiling
  for (int i = 0; i < 100; ++i) {
    const glm::vec3 p = P(0.1f + 0.8f * (u(rng) + 0.9f) / 1.8f, 0.6f + 0.3f * (u(rng) + 0.9f) / 1.8f, 0.0f);
    // a ray from the side below the ceiling (x < 0 is walled off, so come in from y = 0.4)
    const glm::vec3 from = glm::vec3(p.x, shift.y + 0.4f * scale, shift.z + 0.5f * gap * scale);
    leaks += s.trace(from, p - from, ShadingMode::kShadows) != glm::vec3(0.0f);
    ++probes;
  }
  EXPECT_EQ(leaks, 0) << "scale " << scale << ": light leaking under the wall or the ceiling";
  EXPECT_EQ(acne, 0) << "scale " << scale << ": shadow acne";
  EXPECT_EQ(probes, 700);
}

TEST(Whitted, SecondaryRayOffsetsHoldFromTinyToHugeCoordinates) {
  for (float scale : {1e-3f, 1.0f, 1e2f, 1e4f}) check_offsets(scale, glm::vec3(0.0f));
  check_offsets(1.0f, glm::vec3(1e4f, -1e4f, 1e3f));   // small scene far from the origin
  check_offsets(1e-3f, glm::vec3(10.0f, 5.0f, -3.0f));
}

TEST(Whitted, ImagePixelsEqualSingleRaysThroughThem) {
  // camera rays are not unit length: shading must not care (Fresnel, highlights, refraction)
  const TestScene s = room();
  const Camera cam = room_camera(40, 30);
  WhittedOptions o;
  o.mode = ShadingMode::kAll;
  o.threads = 2;
  const Image img = render_whitted(s.shading, cam, o);
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      Ray r = cam.ray(x + 0.5f, y + 0.5f);
      r.dir = glm::normalize(r.dir);
      expect_near(img.at(x, y), trace_whitted(s.shading, r, o), 1e-4f, "pixel against single ray");
    }
  }
}

TEST(Whitted, MipmapsAverageTheTexture) {
  Texture t;
  t.width = 8;
  t.height = 4;
  for (int y = 0; y < 4; ++y) {
    for (int x = 0; x < 8; ++x) t.texels.push_back(glm::vec3((x + y) % 2 ? 1.0f : 0.0f, 0.5f, 0.25f));
  }
  t.build_mipmaps();
  ASSERT_EQ(t.mips.size(), 3u);  // 4x2, 2x1, 1x1
  EXPECT_EQ(t.mips[0].width, 4);
  EXPECT_EQ(t.mips[0].height, 2);
  EXPECT_EQ(t.mips.back().width, 1);
  for (const Texture& m : t.mips) {
    for (const glm::vec3& c : m.texels) expect_near(c, glm::vec3(0.5f, 0.5f, 0.25f), 1e-6f, "a checkerboard averages to grey");
  }
  expect_near(t.sample({0.3f, 0.6f}, 10.0f), glm::vec3(0.5f, 0.5f, 0.25f), 1e-6f, "far away");
  const glm::vec3 near = t.sample({2.5f / 8.0f, 0.5f / 4.0f}, 0.0f);  // texel (2, 3) of the rows top first: white
  expect_near(near, glm::vec3(1.0f, 0.5f, 0.25f), 1e-6f, "close up");
}

TEST(Whitted, TexturesAreFilteredBilinearly) {
  Texture t;
  t.width = 2;
  t.height = 1;
  t.texels = {glm::vec3(0.0f), glm::vec3(1.0f)};
  expect_near(t.bilinear({0.25f, 0.5f}), glm::vec3(0.0f), 1e-6f, "texel centre");
  expect_near(t.bilinear({0.5f, 0.5f}), glm::vec3(0.5f), 1e-6f, "half way");
  expect_near(t.bilinear({0.0f, 0.5f}), glm::vec3(0.5f), 1e-6f, "wraps around");
  expect_near(t.bilinear({1.25f, 0.5f}), glm::vec3(0.0f), 1e-6f, "repeats");
}

TEST(Whitted, TextureCoordinatesRepeatAtAnyMagnitude) {
  Texture t;
  t.width = 4;
  t.height = 2;
  for (int i = 0; i < 8; ++i) t.texels.push_back(glm::vec3(static_cast<float>(i)));
  for (const float u : {0.1f, 0.37f, 0.5f, 0.875f}) {
    for (const float v : {0.2f, 0.75f}) {
      const glm::vec3 want = t.bilinear({u, v});
      expect_near(t.bilinear({u - 1.0f, v}), want, 1e-4f, "one period to the left");
      expect_near(t.bilinear({u + 3.0f, v - 2.0f}), want, 1e-4f, "periods away");
      expect_near(t.bilinear({u - 4096.0f, v + 4096.0f}), want, 2e-3f, "far away");
    }
  }
  // integers beyond 2^23 (and the largest float) are whole periods: u = 0, the edge between texel 3 and 0
  expect_near(t.bilinear({0x1p24f, 0.75f}), t.bilinear({0.0f, 0.75f}), 0.0f, "2^24");
  expect_near(t.bilinear({-3.0e38f, 0.75f}), t.bilinear({0.0f, 0.75f}), 0.0f, "-3e38");
  // coordinates that are not numbers give a texel of the image, not a read outside it
  for (const float bad : {std::nanf(""), INFINITY, -INFINITY}) {
    const glm::vec3 c = t.bilinear({bad, bad});
    EXPECT_TRUE(c.x >= 0.0f && c.x <= 7.0f) << c.x;
  }
}

TEST(Whitted, NearestMipLevelIsLog2Rounded) {
  EXPECT_EQ(nearest_mip_level(0.0f), 0);
  EXPECT_EQ(nearest_mip_level(-5.0f), 0);
  EXPECT_EQ(nearest_mip_level(std::nanf("")), 0);
  EXPECT_EQ(nearest_mip_level(1.0f), 0);
  EXPECT_EQ(nearest_mip_level(2.0f), 1);
  EXPECT_EQ(nearest_mip_level(1024.0f), 10);
  // either side of sqrt(2) 2^k, where log2 crosses k + 1/2
  for (int k = 0; k < 20; ++k) {
    const float edge = std::ldexp(1.41421356237f, k);
    EXPECT_EQ(nearest_mip_level(std::nextafter(edge, 0.0f)), k) << k;
    EXPECT_EQ(nearest_mip_level(std::nextafter(edge, INFINITY)), k + 1) << k;
  }
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> exponent(0.0f, 30.0f);
  for (int i = 0; i < 100000; ++i) {
    const float x = std::exp2(exponent(rng));
    EXPECT_EQ(nearest_mip_level(x), static_cast<int>(std::floor(std::log2(static_cast<double>(x)) + 0.5))) << x;
  }
}

}  // namespace
}  // namespace artrace::core
