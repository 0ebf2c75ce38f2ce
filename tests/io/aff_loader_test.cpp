#include "artrace/io/aff_scene.h"
#include "artrace/io/parse_error.h"
#include "../test_util.h"

#include <fstream>

namespace artrace::io {
namespace {

/// A temporary folder with AFF files written from strings.
class AffFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::artrace::test::scratch_root() /
           ("artrace_aff_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_ / "aff");
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path write(const std::string& name, const std::string& text) {
    const auto p = dir_ / "aff" / name;
    std::ofstream(p) << text;
    return p;
  }
  /// Loads and returns the error message (fails the test when loading succeeds).
  std::string error_of(const std::filesystem::path& p) {
    try {
      load_aff(p);
    } catch (const ParseError& e) {
      return e.what();
    }
    ADD_FAILURE() << "no error for " << p;
    return {};
  }
  std::filesystem::path dir_;
};

TEST_F(AffFiles, ReadsViewLightsMaterialsAndGeometry) {
  const auto p = write("scene.aff", R"(# comment
v
from 0 0 5
at 0 0 0
up 0 1 0
angle 45
hither 0.1
resolution 64 48
b 0.1 0.2 0.3
am 0.5 0.5 0.5
l 1 2 3
l 4 5 6 0.5 0.25 0.125 % colour given
f 1 0.5 0.25 0.8 0.2 10 0 1
p 4
0 0 0  1 0 0  1 1 0  0 1 0
fm 0.1 0.1 0.1  0.2 0.3 0.4  0.5 0.5 0.5  20 0.5 1.5
m
vertices 4
0 0 1
1 0 1
1 1 1
0 1 1
normals 1
0 0 1
texturecoords 2 tex.ppm
0 0
1 1
triangles 2
0 1 2  0 0 0  0 1 1
0 2 3  0 0 0  0 1 0
tt tex.ppm
0 0 2 0 0
1 0 2 1 0
0 1 2 0 1
)");
  const AffScene s = load_aff(p);
  ASSERT_TRUE(s.view.has_value());
  EXPECT_EQ(s.view->width, 64);
  EXPECT_FLOAT_EQ(s.view->fov_y_deg, 45.0f);
  EXPECT_EQ(s.background, glm::vec3(0.1f, 0.2f, 0.3f));
  ASSERT_EQ(s.lights.size(), 2u);
  EXPECT_EQ(s.lights[0].color, glm::vec3(1.0f));
  EXPECT_EQ(s.lights[1].color, glm::vec3(0.5f, 0.25f, 0.125f));
  ASSERT_EQ(s.materials.size(), 3u);  // default + f + fm
  EXPECT_EQ(s.materials[1].diffuse, glm::vec3(0.8f, 0.4f, 0.2f));
  EXPECT_FLOAT_EQ(s.materials[2].ior, 1.5f);
  EXPECT_EQ(s.triangle_count(), 5u);  // quad (2) + mesh (2) + tt (1)
  const TriangleBatch& b = s.nodes[0].geometry;
  EXPECT_EQ(b.material[0], 1u);
  EXPECT_EQ(b.material[2], 2u);
  EXPECT_EQ(b.material[4], 2u);
  EXPECT_EQ(b.uvs[2][2], glm::vec2(1, 1));
  EXPECT_EQ(b.texture[2], 0);
  EXPECT_EQ(b.texture[4], 0) << "the same texture name gives the same index";
  EXPECT_EQ(s.textures.size(), 1u);
  EXPECT_EQ(s.textures[0].filename(), "tex.ppm");
}

TEST_F(AffFiles, StaticAndAnimatedTransformsCompose) {
  write("part.aff", "p 3\n0 0 0\n1 0 0\n0 1 0\n");
  const auto p = write("scene.aff", R"(
xs 2 2 2  0 0 1 90  10 0 0
{
  i 0 part.aff
  x spin
  {
    xs 1 1 1  0 1 0 0  0 0 1
    {
      i 0 part.aff
    }
  }
}
k spin
{
  transl 2
  0  0 0 0  0 0 0
  10 0 0 10 0 0 0
}
a 0 10 11
)");
  const AffScene s = load_aff(p);
  ASSERT_EQ(s.nodes.size(), 2u);
  EXPECT_EQ(s.static_triangle_count(), 1u);
  // static: scale 2, rotate 90 about z, translate (10,0,0): (1,0,0) -> (10, 2, 0)
  const auto t0 = s.triangles_at(0.0);
  ASSERT_EQ(t0.size(), 2u);
  EXPECT_NEAR(t0[0].v1.x, 10.0f, 1e-5f);
  EXPECT_NEAR(t0[0].v1.y, 2.0f, 1e-5f);
  // animated part: parent (scale 2, rot z 90, +10 x) . translation (0,0,z(t)) . offset z+1
  // at t=5 a linear two-key track (padded) is halfway: z(t) = 5; point (0,0,0) -> (10, 0, 2*(5+1))
  const auto t5 = s.triangles_at(5.0);
  EXPECT_NEAR(t5[1].v0.x, 10.0f, 1e-4f);
  EXPECT_NEAR(t5[1].v0.z, 12.0f, 1e-4f);
  EXPECT_DOUBLE_EQ(s.frame_time(5), 5.0);
  EXPECT_DOUBLE_EQ(s.frame_time(10), 10.0);
}

TEST(KeyframeAnimation, TcbSplineInterpolatesKeysAndHoldsOutside) {
  std::vector<TcbKey> keys;
  for (int i = 0; i < 6; ++i) {
    TcbKey k;
    k.time = i;
    k.value = glm::dvec3(i * i, 0, 0);
    keys.push_back(k);
  }
  const TcbTrack track(keys);
  for (int i = 1; i <= 4; ++i) EXPECT_NEAR(track.evaluate(i).x, i * i, 1e-12) << "passes through key " << i;
  EXPECT_NEAR(track.evaluate(-3.0).x, 1.0, 1e-12) << "held before key 1";
  EXPECT_NEAR(track.evaluate(9.0).x, 16.0, 1e-12) << "held after key n-2";
  // With T=C=B=0 on uniform keys this is Catmull-Rom; for x = i^2 it reproduces t^2 exactly.
  EXPECT_NEAR(track.evaluate(2.5).x, 6.25, 1e-12);
  EXPECT_NEAR(track.evaluate(1.25).x, 1.5625, 1e-12);
}

TEST(KeyframeAnimation, RotationsPassKeysAndSurviveAxisFlips) {
  std::vector<TcbKey> keys;
  const double angles[] = {0, 0, 90, 180, 270, 270};
  for (int i = 0; i < 6; ++i) {
    TcbKey k;
    k.time = i;
    // key 3 states the same rotation with the axis and angle negated
    k.value = i == 3 ? glm::dvec3(0, -1, 0) : glm::dvec3(0, 1, 0);
    k.angle_deg = i == 3 ? -angles[i] : angles[i];
    keys.push_back(k);
  }
  const TcbRotationTrack track(keys);
  const glm::dvec3 x(1, 0, 0);
  const glm::dvec3 at2 = track.evaluate(2.0) * x;
  EXPECT_NEAR(at2.z, -1.0, 1e-9) << "90 degrees about +y takes x to -z";
  const glm::dvec3 at3 = track.evaluate(3.0) * x;
  EXPECT_NEAR(at3.x, -1.0, 1e-9);
  // between keys the rotation turns monotonically about y, never the long way round
  double prev = 0.0;
  for (double t = 1.0; t <= 4.0; t += 0.05) {
    const glm::dvec3 v = track.evaluate(t) * x;
    double a = std::atan2(-v.z, v.x);
    if (a < prev - 1e-9) a += 2.0 * 3.141592653589793;
    EXPECT_GE(a, prev - 1e-9) << "t=" << t;
    EXPECT_NEAR(glm::length(v), 1.0, 1e-9);
    prev = a;
  }
}

struct BadCase {
  const char* name;
  const char* text;
  int line;
  const char* message;
};

TEST_F(AffFiles, MalformedInputNamesFileLineAndProblem) {
  const BadCase cases[] = {
      {"unknown", "b 0 0 0\nbogus 1 2\n", 2, "unknown record \"bogus\""},
      {"missing_include", "\n\ni 0 nowhere.aff\n", 3, "cannot open included file"},
      {"not_a_number", "l 1 two 3\n", 1, "expected a light position component, got \"two\""},
      {"nan", "b 0 nan 0\n", 1, "non-finite"},
      {"truncated", "p 4\n0 0 0\n1 0 0\n", 4, "unexpected end of file"},
      {"index_range", "m\nvertices 3\n0 0 0\n1 0 0\n0 1 0\ntriangles 1\n0 1 3\n", 7, "vertex index 3 is out of range"},
      {"negative_count", "p -3\n", 1, "vertex count -3 is out of range"},
      {"unclosed", "xs 1 1 1 0 0 1 0 0 0 0\n{\np 3\n0 0 0\n1 0 0\n0 1 0\n", 2, "'{' is never closed"},
      {"stray_brace", "}\n", 1, "'}' without a matching '{'"},
      {"view_keyword", "v\nfrom 0 0 0\nto 1 1 1\n", 3, "expected 'at'"},
      // views that make no camera (before, the error came when rendering, without the file)
      {"view_angle", "v\nfrom 0 0 3\nat 0 0 0\nup 0 1 0\nangle 180\nhither 0.01\nresolution 8 8\n", 5,
       "the view angle \"180\" is not between 0 and 180 degrees"},
      {"view_up", "v\nfrom 0 0 3\nat 0 0 0\nup 0 0 2\nangle 45\nhither 0.01\nresolution 8 8\n", 4,
       "'up' not parallel to the view direction"},
      {"view_at", "v\nfrom 1 2 3\nat 1 2 3\nup 0 1 0\nangle 45\nhither 0.01\nresolution 8 8\n", 4,
       "the view needs 'at' apart from 'from'"},
      {"beyond_float", "p 3\n0 0 0\n1e39 0 0\n0 1 0\n", 3, "got \"1e39\", beyond the float range"},
      {"mesh_block", "m\nvertices 1\n0 0 0\nfaces 1\n", 4, "expected 'triangles' in mesh"},
      {"track_keyword", "k a\n{\nspin 1\n}\n", 3, "expected 'transl', 'rot', 'scale' or '}'"},
      // a corrupt file's token: binary bytes escaped, and no more than 40 characters of it quoted
      {"binary_token", "l 1 t\x01\xd6 3\n", 1, "got \"t\\x01\\xd6\""},
      // a count the rest of the file cannot hold is refused before anything is allocated for it
      // (before, 24 bytes made the reader zero 2.4 GB of vertices and normals, then fail)
      {"polygon_count", "pp 50000000\n0 0 0 0 0 1\n", 1,
       "the vertex count 50000000 needs at least 599999999 more bytes (6 numbers each), but the file has 13 left"},
      {"normal_count", "m\nvertices 1\n0 0 0\nnormals 9999999\n0 0 1\n", 4,
       "the normal count 9999999 needs at least 59999993 more bytes (3 numbers each), but the file has 7 left"},
      {"key_count", "k a\n{\ntransl 100000\n0 0 0 0 0 0 0\n}\n", 3, "the key count 100000 needs at least 1399999 more bytes (7 numbers each)"},
      // a small count is read item by item: the error is where the file really went wrong
      {"small_count", "p 3\n0 0 0\n1 y 0\n", 3, "expected a vertex coordinate, got \"y\""},
      {"long_token", "l 1 yyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyy 3\n", 1, "got \"yyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyyy\"..."},
  };
  for (const BadCase& c : cases) {
    const auto p = write(std::string(c.name) + ".aff", c.text);
    const std::string msg = error_of(p);
    EXPECT_NE(msg.find(p.string() + ":" + std::to_string(c.line) + ":"), std::string::npos) << c.name << ": " << msg;
    EXPECT_NE(msg.find(c.message), std::string::npos) << c.name << ": " << msg;
  }
  EXPECT_NE(error_of(dir_ / "absent.aff").find("cannot open file"), std::string::npos);
  // an error inside an included file names that file
  write("inner.aff", "p 3\n0 0 0\n1 x 0\n");
  const std::string msg = error_of(write("outer.aff", "i 0 inner.aff\n"));
  EXPECT_NE(msg.find("inner.aff:3:"), std::string::npos) << msg;
  // an include cycle is reported at the include that closes it, naming the chain
  const auto self = write("cycle.aff", "i 0 cycle.aff\n");
  const std::string self_msg = error_of(self);
  EXPECT_NE(self_msg.find(self.string() + ":1:"), std::string::npos) << self_msg;
  EXPECT_NE(self_msg.find("include cycle: cycle.aff -> cycle.aff"), std::string::npos) << self_msg;
  write("ping.aff", "i 0 sub/../pong.aff\n");
  std::filesystem::create_directories(dir_ / "aff" / "sub");
  const auto pong = write("pong.aff", "\ni 0 ping.aff\n");
  const std::string pair_msg = error_of(pong);
  EXPECT_NE(pair_msg.find("ping.aff:1:"), std::string::npos) << pair_msg;
  EXPECT_NE(pair_msg.find("include cycle: pong.aff -> ping.aff -> pong.aff"), std::string::npos) << pair_msg;
  // a chain of distinct files deeper than 32 is refused by depth (no cycle)
  for (int i = 0; i < 40; ++i) write("deep" + std::to_string(i) + ".aff", "i 0 deep" + std::to_string(i + 1) + ".aff\n");
  write("deep40.aff", "");
  const std::string deep_msg = error_of(dir_ / "aff" / "deep0.aff");
  EXPECT_NE(deep_msg.find("nested deeper than 32"), std::string::npos) << deep_msg;
  EXPECT_EQ(deep_msg.find("cycle"), std::string::npos) << deep_msg;
  // the same file included twice side by side is no cycle
  write("leaf.aff", "p 3\n0 0 0\n1 0 0\n0 1 0\n");
  EXPECT_EQ(load_aff(write("twice.aff", "i 0 leaf.aff\ni 0 leaf.aff\n")).triangle_count(), 2u);
}

TEST(BartScenes, KitchenHasThePublishedTriangleCounts) {
  ARTRACE_REQUIRE_SHARED("bart/kitchen/aff/kitchen.aff");
  const AffScene s = load_aff(shared_path);
  EXPECT_EQ(s.triangle_count(), 110561u);
  EXPECT_EQ(s.static_triangle_count(), 103343u);
  EXPECT_EQ(s.anim_frames, 800);
  EXPECT_DOUBLE_EQ(s.anim_end, 20.0);
  EXPECT_TRUE(s.animations.count("camera"));
  EXPECT_TRUE(s.animations.count("toycar"));
  EXPECT_EQ(s.lights.size(), 6u);
}

TEST(BartScenes, RobotsHaveThePublishedTriangleCounts) {
  ARTRACE_REQUIRE_SHARED("bart/robots/aff/Robot.aff");
  const AffScene s = load_aff(shared_path);
  EXPECT_EQ(s.triangle_count(), 71708u);
  EXPECT_EQ(s.static_triangle_count(), 9218u);
  size_t parts = 0;
  for (size_t n = 1; n < s.nodes.size(); ++n) parts += !s.nodes[n].geometry.tris.empty();
  EXPECT_EQ(parts, 160u) << "160 animated parts with geometry (of " << s.nodes.size() - 1 << " animated transforms)";
  EXPECT_DOUBLE_EQ(s.anim_end, 50.0);
}

/// The toy car moves: between t=0 and t=10 its triangles move, the static ones do not.
TEST(BartScenes, KitchenCarMovesStaticGeometryStays) {
  ARTRACE_REQUIRE_SHARED("bart/kitchen/aff/kitchen.aff");
  const AffScene s = load_aff(shared_path);
  const auto a = s.triangles_at(0.0), b = s.triangles_at(10.0);
  ASSERT_EQ(a.size(), b.size());
  const size_t n_static = s.static_triangle_count();
  for (size_t i = 0; i < n_static; i += 997) EXPECT_EQ(a[i].v0, b[i].v0);
  size_t moved = 0;
  for (size_t i = n_static; i < a.size(); ++i) moved += glm::length(a[i].v0 - b[i].v0) > 1e-3f;
  EXPECT_GT(moved, (a.size() - n_static) * 9 / 10);
}

}  // namespace
}  // namespace artrace::io
