// BART shading inputs: PPM textures (and the errors for broken ones), the kitchen's materials,
// lights and textures, and its Whitted render being the same for any thread count and either way
// of tracing secondary rays; the packet-wise shading answers equal the hit-by-hit ones.
#include "artrace/core/srgb.h"
#include "artrace/io/bart_shading.h"
#include "artrace/io/parse_error.h"
#include "../test_util.h"

#include <fstream>

namespace artrace::io {
namespace {

void write_bytes(const std::filesystem::path& p, const std::string& bytes) {
  std::ofstream(p, std::ios::binary) << bytes;
}

TEST(Ppm, ReadsBinaryPpmWithCommentsAsLinearColour) {
  const auto dir = ::artrace::test::scratch_path("artrace_ppm");
  std::filesystem::create_directories(dir);
  write_bytes(dir / "ok.ppm", std::string("P6\n# a comment\n2 1\n255\n") + std::string("\x00\x80\xff\x10\x20\x30", 6));
  const core::Texture t = load_ppm(dir / "ok.ppm");
  ASSERT_EQ(t.width, 2);
  ASSERT_EQ(t.height, 1);
  EXPECT_EQ(t.texels[0], glm::vec3(core::srgb8_to_linear(0), core::srgb8_to_linear(0x80), core::srgb8_to_linear(0xff)));
  EXPECT_EQ(t.texels[1], glm::vec3(core::srgb8_to_linear(0x10), core::srgb8_to_linear(0x20), core::srgb8_to_linear(0x30)));
  std::filesystem::remove_all(dir);
}

TEST(Ppm, BrokenFilesAreRefusedWithTheFileNamed) {
  const auto dir = ::artrace::test::scratch_path("artrace_ppm_bad");
  std::filesystem::create_directories(dir);
  write_bytes(dir / "ascii.ppm", "P3\n1 1\n255\n0 0 0\n");
  write_bytes(dir / "truncated.ppm", std::string("P6\n4 4\n255\n") + std::string(10, '\x01'));
  write_bytes(dir / "zero_max.ppm", std::string("P6\n1 1\n0\n") + std::string(3, '\x01'));
  write_bytes(dir / "words.ppm", "P6\nwide 1\n255\n");
  write_bytes(dir / "empty.ppm", "");
  const std::pair<const char*, const char*> cases[] = {{"ascii.ppm", "not a binary PPM"},
                                                        {"truncated.ppm", "truncated pixel data"},
                                                        {"zero_max.ppm", "maximum value"},
                                                        {"words.ppm", "width"},
                                                        {"empty.ppm", "truncated header"},
                                                        {"missing.ppm", "cannot open"}};
  for (const auto& [name, what] : cases) {
    try {
      load_ppm(dir / name);
      ADD_FAILURE() << name << " was accepted";
    } catch (const ParseError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find((dir / name).string()), std::string::npos) << msg;
      EXPECT_NE(msg.find(what), std::string::npos) << msg;
    }
  }
  std::filesystem::remove_all(dir);
}

// Found by fuzz_ppm: a header declaring a huge image made the reader allocate (and zero) memory for
// it before noticing that the file holds a few bytes. The sizes are now checked against the file
// first, and the error says what the header declares and what follows it.
TEST(Ppm, HugeDeclaredSizeIsRefusedBeforeAllocating) {
  const auto dir = ::artrace::test::scratch_path("artrace_ppm_huge");
  std::filesystem::create_directories(dir);
  write_bytes(dir / "huge.ppm", std::string("P6\n8000 8000\n65535\n") + std::string(5, '\x01'));
  try {
    load_ppm(dir / "huge.ppm");
    ADD_FAILURE() << "accepted";
  } catch (const ParseError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("8000x8000 pixels (384000000 bytes) but 5 bytes follow"), std::string::npos) << msg;
  }
  std::filesystem::remove_all(dir);
}

TEST(BartShading, KitchenRendersTheSameForAnyThreadCountAndSecondaryRayGrouping) {
  ARTRACE_REQUIRE_SHARED("bart/kitchen/aff/kitchen.aff");
  const AffScene aff = load_aff(shared_path);
  BartAnimation anim(aff, core::TwoLevelScene::Config::kKdTreeBvh);
  BartSurfaces surfaces(anim);
  const core::ShadingScene scene = make_shading_scene(anim, surfaces);
  EXPECT_EQ(scene.materials.size(), aff.materials.size());
  EXPECT_EQ(scene.lights.size(), 6u);
  ASSERT_EQ(scene.textures.size(), aff.textures.size());
  for (const core::Texture& t : scene.textures) EXPECT_FALSE(t.mips.empty());
  anim.set_time(10.0);
  const core::Camera cam = aff.camera_at(10.0, 64, 48);
  core::WhittedOptions o;
  o.mode = core::ShadingMode::kAll;
  o.threads = 1;
  const core::Image one = core::render_whitted(scene, cam, o);
  o.threads = 2;
  const core::Image two = core::render_whitted(scene, cam, o);
  o.secondary_packets = false;
  const core::Image single = core::render_whitted(scene, cam, o);
  EXPECT_EQ(one.pixels, two.pixels);
  EXPECT_EQ(one.pixels, single.pixels);
  int lit = 0;
  for (const glm::vec3& p : one.pixels) {
    ASSERT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z));
    ASSERT_GE(std::min({p.x, p.y, p.z}), 0.0f);
    lit += p.x + p.y + p.z > 0.05f;
  }
  EXPECT_GT(lit, static_cast<int>(one.pixels.size()) * 9 / 10) << "the kitchen is lit";
}

TEST(BartShading, PacketShadingEqualsHitByHit) {
  ARTRACE_REQUIRE_SHARED("bart/robots/aff/Robot.aff");
  const AffScene aff = load_aff(shared_path);
  BartAnimation anim(aff, core::TwoLevelScene::Config::kKdTreeBvh);
  BartSurfaces surfaces(anim);
  anim.set_time(7.5);  // robots mid-walk: hits on moved instances, textured and not
  const core::Camera cam = aff.camera_at(7.5, 64, 48);
  int hits = 0, moved = 0, textured = 0, static_textured = 0;
  for (int y = 0; y < 48; ++y) {
    for (int x0 = 0; x0 < 64; x0 += core::kPacketSize) {
      core::RayPacket rays;
      for (int i = 0; i < core::kPacketSize; ++i) {
        rays.set(i, cam.ray(x0 + i + 0.5f, y + 0.5f));
      }
      core::HitPacket hp;
      anim.scene().intersect(rays, core::kAllLanes, hp);
      core::LaneMask mask = 0;
      core::Triangle tris[core::kPacketSize];
      for (int i = 0; i < core::kPacketSize; ++i) {
        if (hp.prim[i] == core::kInvalidId) continue;
        mask |= 1u << i;
        tris[i] = anim.scene().world_triangle(hp.get(i));
      }
      if ((y + x0) % 3 == 0) mask &= ~1u;  // a lane left out keeps what it had
      uint32_t materials[core::kPacketSize];
      std::fill(std::begin(materials), std::end(materials), 12345u);
      core::SurfaceInfo infos[core::kPacketSize];
      surfaces.shade_packet(hp, mask, tris, materials, infos);
      for (int i = 0; i < core::kPacketSize; ++i) {
        if (!((mask >> i) & 1u)) {
          EXPECT_EQ(materials[i], 12345u) << "a lane outside the mask was written";
          EXPECT_EQ(infos[i].texture, -1);
          EXPECT_EQ(infos[i].normal, glm::vec3(0.0f));
          continue;
        }
        const core::Hit h = hp.get(i);
        core::SurfaceInfo one;
        surfaces.shading(h, tris[i], one);
        ASSERT_EQ(materials[i], surfaces.material(h)) << "lane " << i;
        EXPECT_EQ(infos[i].normal, one.normal);
        EXPECT_EQ(infos[i].uv, one.uv);
        EXPECT_EQ(infos[i].texture, one.texture);
        EXPECT_EQ(infos[i].uv_per_world, one.uv_per_world);
        if (h.inst == core::kStaticObject && one.texture >= 0) {
          // the static triangles' table against the scale worked out from the hit's triangle
          const auto& uv = aff.nodes[0].geometry.uvs[h.prim];
          const glm::vec2 e1 = uv[1] - uv[0], e2 = uv[2] - uv[0];
          const float area = glm::length(tris[i].geometric_normal());
          ASSERT_GT(area, 0.0f);
          EXPECT_EQ(one.uv_per_world, std::sqrt(std::fabs(e1.x * e2.y - e1.y * e2.x) / area)) << "prim " << h.prim;
          ++static_textured;
        }
        ++hits;
        moved += h.inst != core::kStaticObject;
        textured += one.texture >= 0;
      }
    }
  }
  EXPECT_GT(hits, 64 * 48 / 2);
  EXPECT_GT(moved, 50) << "some hits on the robots themselves";
  EXPECT_GT(textured, 50);
  EXPECT_GT(static_textured, 50);
}

}  // namespace
}  // namespace artrace::io
