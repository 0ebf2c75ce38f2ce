#include "artrace/io/ar_scene.h"
#include "artrace/io/gltf_model.h"
#include "artrace/io/parse_error.h"
#include "../test_util.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <map>

namespace artrace::io {
namespace {

TEST(Gltf, WrittenModelsLoadBackWithAnimation) {
  const auto dir = ::artrace::test::scratch_path("artrace_gltf");
  for (const char* name : {"box.gltf", "box.glb", "BOX.GLB"}) {  // the extension's case does not matter
    const auto path = dir / name;
    const GltfModel box = make_spinning_box(0.5f, {0.8f, 0.2f, 0.1f});
    write_gltf(box, path);
    EXPECT_EQ(::artrace::test::read_file(path).substr(0, 4) == "glTF", std::string(name) != "box.gltf")
        << name << ": the binary container's magic";
    const GltfModel m = load_gltf(path);
    ASSERT_EQ(m.meshes.size(), 1u);
    ASSERT_EQ(m.meshes[0].tris.size(), 12u);
    EXPECT_EQ(m.meshes[0].tris[5].v2, box.meshes[0].tris[5].v2);
    ASSERT_EQ(m.materials.size(), 2u);
    EXPECT_FLOAT_EQ(m.materials[m.meshes[0].material[0]].base_color.r, 0.8f);
    ASSERT_EQ(m.animations.size(), 1u);
    EXPECT_FLOAT_EQ(m.animations[0].duration_s, 4.0f);
    // a quarter turn a second about +y: x goes to -z after 1 s, 45 degrees after 0.5 s (slerp)
    const glm::vec4 x(1, 0, 0, 1);
    const glm::vec3 at1 = glm::vec3(m.node_transforms(0, 1.0f)[0] * x);
    EXPECT_NEAR(at1.z, -1.0f, 1e-5f);
    const glm::vec3 at_half = glm::vec3(m.node_transforms(0, 0.5f)[0] * x);
    EXPECT_NEAR(at_half.x, std::sqrt(0.5f), 1e-5f);
    EXPECT_NEAR(at_half.z, -std::sqrt(0.5f), 1e-5f);
    const glm::vec3 looped = glm::vec3(m.node_transforms(0, 5.0f)[0] * x);  // 5 s = 1 s into the loop
    EXPECT_NEAR(looped.z, -1.0f, 1e-5f);
    const glm::vec3 rest = glm::vec3(m.node_transforms(-1, 1.0f)[0] * x);
    EXPECT_NEAR(rest.x, 1.0f, 1e-6f);
  }
  const GltfModel glass = load_gltf((write_gltf(make_glass_sphere(0.1f), dir / "glass.gltf"), dir / "glass.gltf"));
  EXPECT_FLOAT_EQ(glass.materials[1].transmission, 1.0f);
  EXPECT_FLOAT_EQ(glass.materials[1].ior, 1.5f);
  std::filesystem::remove_all(dir);
}

TEST(Gltf, StepAndCubicSplineSamplers) {
  GltfModel m = make_spinning_box(1.0f, glm::vec3(1.0f));
  GltfChannel step;
  step.node = 0;
  step.path = GltfChannel::kTranslation;
  step.interpolation = GltfChannel::kStep;
  step.times = {0.0f, 1.0f, 2.0f};
  step.values = {glm::vec4(0, 0, 0, 0), glm::vec4(5, 0, 0, 0), glm::vec4(9, 0, 0, 0)};
  GltfChannel cubic;
  cubic.node = 0;
  cubic.path = GltfChannel::kScale;
  cubic.interpolation = GltfChannel::kCubic;
  cubic.times = {0.0f, 2.0f};
  // per key: in-tangent, value, out-tangent; zero tangents give smoothstep between the values
  cubic.values = {glm::vec4(0), glm::vec4(1, 1, 1, 0), glm::vec4(0), glm::vec4(0), glm::vec4(3, 3, 3, 0), glm::vec4(0)};
  m.animations[0].channels = {step, cubic};
  m.animations[0].duration_s = 2.5f;
  const auto dir = ::artrace::test::scratch_path("artrace_gltf2");
  write_gltf(m, dir / "samplers.gltf");
  const GltfModel l = load_gltf(dir / "samplers.gltf");
  const glm::mat4 a = l.node_transforms(0, 1.5f)[0];
  EXPECT_FLOAT_EQ(a[3].x, 5.0f) << "STEP holds the value of key 1";
  // scale at t = 1.5: s = 0.75, smoothstep 3 s^2 - 2 s^3 = 0.84375 -> 1 + 2 * 0.84375
  EXPECT_NEAR(glm::length(glm::vec3(a[0])), 1.0f + 2.0f * 0.84375f, 1e-5f);
  std::filesystem::remove_all(dir);
}

TEST(Gltf, BrokenFilesNameTheFile) {
  const auto dir = ::artrace::test::scratch_path("artrace_gltf_bad");
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "garbage.gltf") << "{ this is not json";
  std::ofstream(dir / "empty.glb") << "";
  // a triangle indexing a fourth vertex of three
  std::ofstream(dir / "bad_index.gltf")
      << R"({"asset":{"version":"2.0"},"buffers":[{"byteLength":42,"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAMA"}],)"
      << R"("bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":6}],)"
      << R"("accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},)"
      << R"({"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}],"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],)"
      << R"("nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}]})";
  // one triangle (0, 1, 2): its first vertex's x is NaN in the first file; the second is sound but
  // its node is moved beyond the float range
  auto triangle = [](const char* base64, const char* node) {
    return std::string(R"({"asset":{"version":"2.0"},"buffers":[{"byteLength":42,"uri":"data:application/octet-stream;base64,)") +
           base64 + R"("}],"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":6}],)" +
           R"("accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},)" +
           R"({"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}],"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],)" +
           R"("nodes":[)" + node + R"(],"scenes":[{"nodes":[0]}]})";
  };
  std::ofstream(dir / "nan_position.gltf") << triangle("AADAfwAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIA", R"({"mesh":0})");
  std::ofstream(dir / "huge_translation.gltf")
      << triangle("AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIA", R"({"mesh":0,"name":"far","translation":[1e39,0,0]})");
  std::ofstream(dir / "sound.gltf") << triangle("AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIA", R"({"mesh":0})");
  EXPECT_EQ(load_gltf(dir / "sound.gltf").meshes.at(0).tris.size(), 1u) << "the files below differ from it in one value";
  // positions from an accessor with no bufferView (zeros): a few are a (degenerate) mesh; 100
  // million, with nothing in the file to hold them, are refused before anything is allocated (a
  // fuzz_gltf input asked for 1.2 GB this way); so is a bufferView's accessor declaring more than
  // its view holds
  auto positions_from = [](const char* accessor) {
    return std::string(R"({"asset":{"version":"2.0"},"buffers":[{"byteLength":42,"uri":"data:application/octet-stream;base64,)"
                       R"(AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIA"}],)"
                       R"("bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":6}],)"
                       R"("accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},)"
                       R"({"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"},)") +
           accessor + R"(],"meshes":[{"primitives":[{"attributes":{"POSITION":2},"indices":1}]}],"nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}]})";
  };
  std::ofstream(dir / "zeros.gltf") << positions_from(R"({"componentType":5126,"count":3,"type":"VEC3"})");
  std::ofstream(dir / "unbacked_count.gltf") << positions_from(R"({"componentType":5126,"count":100882573,"type":"VEC3"})");
  std::ofstream(dir / "view_count.gltf") << positions_from(R"({"bufferView":0,"componentType":5126,"count":100882573,"type":"VEC3"})");
  const GltfModel zeros = load_gltf(dir / "zeros.gltf");
  EXPECT_EQ(zeros.meshes.at(0).positions, std::vector<glm::vec3>(3, glm::vec3(0.0f)));
  const std::pair<const char*, const char*> cases[] = {
      {"garbage.gltf", ""}, {"empty.glb", ""}, {"bad_index.gltf", ""}, {"missing.gltf", ""},
      {"nan_position.gltf", "POSITION (accessor 0) holds a non-finite float (element 0)"},
      {"huge_translation.gltf", "node 'far' translation is 1e+39, beyond the float range"},
      {"unbacked_count.gltf", "POSITION (accessor 2) declares 100882573 elements and no bufferView to hold them (at most 65536"},
      {"view_count.gltf", "POSITION (accessor 2) runs past the end of its buffer"}};
  for (const auto& [name, expected] : cases) {
    try {
      load_gltf(dir / name);
      ADD_FAILURE() << name << " was accepted";
    } catch (const ParseError& e) {
      EXPECT_NE(std::string(e.what()).find((dir / name).string()), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  }
  std::filesystem::remove_all(dir);
}

/// Linear blend skinning of the tube worked out by hand: below a third of the length the root
/// holds the vertex, above two thirds the elbow (at half the length) turns it about z.
glm::vec3 bent_tube_vertex(const glm::vec3& v, float length, float degrees) {
  const float w = std::clamp((v.y / length - 1.0f / 3.0f) * 3.0f, 0.0f, 1.0f);
  const glm::vec3 elbow(0.0f, 0.5f * length, 0.0f);
  const float a = glm::radians(degrees);
  const glm::vec3 d = v - elbow;
  const glm::vec3 turned = elbow + glm::vec3(std::cos(a) * d.x - std::sin(a) * d.y, std::sin(a) * d.x + std::cos(a) * d.y, d.z);
  return (1.0f - w) * v + w * turned;
}

TEST(Gltf, SkinnedMeshBendsAsLinearBlendSkinningSays) {
  const auto dir = ::artrace::test::scratch_path("artrace_gltf_skin");
  const float length = 1.2f;
  for (const char* name : {"tube.gltf", "tube.glb"}) {
    write_gltf(make_bending_tube(length, 0.2f, {0.2f, 0.4f, 0.9f}), dir / name);
    const GltfModel m = load_gltf(dir / name);
    ASSERT_EQ(m.skins.size(), 1u);
    ASSERT_EQ(m.skins[0].joints.size(), 2u);
    ASSERT_TRUE(m.meshes[0].skinned());
    int skinned_node = -1;
    for (size_t n = 0; n < m.nodes.size(); ++n) {
      if (m.nodes[n].skin >= 0) skinned_node = static_cast<int>(n);
    }
    ASSERT_GE(skinned_node, 0);
    for (const float t : {0.0f, 0.5f, 1.0f, 1.5f}) {
      const float degrees = 90.0f * (t <= 1.0f ? t : 2.0f - t);
      const std::vector<glm::vec3> v = m.skinned_positions(0, 0, m.node_transforms(0, t));
      ASSERT_EQ(v.size(), m.meshes[0].positions.size());
      for (size_t i = 0; i < v.size(); ++i) {
        const glm::vec3 expected = bent_tube_vertex(m.meshes[0].positions[i], length, degrees);
        // the elbow's rotation is a slerp between the keys, so the angle is linear in t
        EXPECT_NEAR(glm::length(v[i] - expected), 0.0f, 1e-5f) << name << " t=" << t << " vertex " << i;
      }
    }
    // the tip of the bent tube points along -x at the elbow's height
    const std::vector<glm::vec3> bent = m.skinned_positions(0, 0, m.node_transforms(0, 1.0f));
    float min_x = 0.0f;
    for (const glm::vec3& p : bent) min_x = std::min(min_x, p.x);
    EXPECT_NEAR(min_x, -0.5f * length, 1e-5f);
  }
  // a vertex naming a joint the skin does not have
  GltfModel broken = make_bending_tube(length, 0.2f, glm::vec3(0.5f));
  broken.skins[0].joints = {0};
  broken.skins[0].inverse_bind = {glm::mat4(1.0f)};
  write_gltf(broken, dir / "broken.gltf");
  try {
    load_gltf(dir / "broken.gltf");
    ADD_FAILURE() << "accepted a vertex naming joint 1 of a one-joint skin";
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find("broken.gltf"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("joint 1 of a skin with 1"), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

/// Two influence sets (JOINTS_0/WEIGHTS_0 and JOINTS_1/WEIGHTS_1), their weights summing to 2: each
/// weight is divided by the sum, so a vertex held by joint 0 (moved by +x) in the first set and joint
/// 1 (moved by +y) in the second lands half way: worked out by hand, (0.5, 0.5, 0) from the origin.
TEST(Gltf, SkinningTakesEveryInfluenceSetRenormalised) {
  GltfModel m;
  m.nodes.resize(2);
  m.nodes[0].translation = glm::vec3(1, 0, 0);
  m.nodes[1].translation = glm::vec3(0, 1, 0);
  m.skins.push_back(GltfSkin{"two", {0, 1}, {glm::mat4(1.0f), glm::mat4(1.0f)}});
  GltfMesh mesh;
  mesh.positions = {glm::vec3(0.0f)};
  mesh.influence_sets = 2;
  mesh.joints = {glm::uvec4(0, 0, 0, 0), glm::uvec4(1, 0, 0, 0)};
  mesh.weights = {glm::vec4(1, 0, 0, 0), glm::vec4(1, 0, 0, 0)};
  m.meshes.push_back(mesh);
  const std::vector<glm::vec3> v = m.skinned_positions(0, 0, m.node_transforms(-1, 0.0f));
  EXPECT_EQ(v[0], glm::vec3(0.5f, 0.5f, 0.0f));
}

TEST(ArRuntime, TheThreeKindsOfObjectsStaticAnimatedAndSkinned) {
  const auto dir = ::artrace::test::scratch_path("artrace_ar_kinds");
  std::filesystem::create_directories(dir);
  write_gltf(make_bending_tube(1.2f, 0.2f, {0.2f, 0.4f, 0.9f}), dir / "tube.gltf");
  write_gltf(make_spinning_box(0.2f, {0.9f, 0.3f, 0.1f}), dir / "box.gltf");
  std::ofstream(dir / "scene.json") << R"({ "models": [
      { "file": "tube.gltf", "animation": { "clip": "bend" } },
      { "file": "box.gltf", "position": [3, 0, 0] },
      { "file": "box.gltf", "position": [-3, 0, 0], "animation": { "clip": "spin" } } ] })";
  const ArSceneFile file = load_ar_scene(dir / "scene.json");
  ArRuntime rt(file);
  EXPECT_EQ(rt.static_triangles(), 12u) << "the box without animation is in the kd-tree";
  EXPECT_EQ(rt.instance_count(), 1u) << "the spinning box is an instance";
  EXPECT_EQ(rt.skinned_meshes(), 1u) << "the tube deforms";
  // a ray where the bent tube's upper half lies at t = 1 s, and only then
  const core::Ray probe{{-0.45f, 0.6f, 5.0f}, {0.0f, 0.0f, -1.0f}};
  rt.update(0.0);
  EXPECT_FALSE(rt.scene().intersect(probe).valid());
  rt.update(1.0);
  const core::Hit h = rt.scene().intersect(probe);
  ASSERT_TRUE(h.valid());
  EXPECT_NEAR(h.t, 5.0f - 0.1f, 1e-4f);
  EXPECT_EQ(rt.material(ar::SurfaceQuery(h)).color, glm::vec3(0.2f, 0.4f, 0.9f));
  // the static box
  const core::Hit s = rt.scene().intersect(core::Ray{{3.0f, 0.1f, 5.0f}, {0.0f, 0.0f, -1.0f}});
  ASSERT_TRUE(s.valid());
  EXPECT_EQ(s.inst, core::kStaticObject);
  EXPECT_EQ(rt.material(ar::SurfaceQuery(s)).color, glm::vec3(0.9f, 0.3f, 0.1f));
  std::filesystem::remove_all(dir);
}

/// The message load_ar_scene() gives for `text` as DIR/scene.json, or "" when it takes it.
std::string scene_error(const std::filesystem::path& dir, const std::string& text) {
  std::ofstream(dir / "scene.json") << text;
  try {
    load_ar_scene(dir / "scene.json");
  } catch (const ParseError& e) {
    return e.what();
  }
  return "";
}

/// Malformed AR scene files: a ParseError naming the file, the key and the problem, for an unknown
/// key, a wrong type, and numbers too large for the renderer's float arithmetic (3e38 is a float,
/// 1e39 is not even that).
TEST(ArSceneFile, MalformedScenesNameFileKeyAndProblem) {
  const auto dir = ::artrace::test::scratch_path("artrace_ar_malformed");
  std::filesystem::create_directories(dir);
  write_gltf(make_spinning_box(0.2f, {0.9f, 0.3f, 0.1f}), dir / "box.gltf");
  const std::pair<const char*, const char*> cases[] = {
      {R"({ "models": [ { "file": "box.gltf", "positon": [0, 0, 0] } ] })", "models[0].positon: unknown key"},
      {R"({ "models": [ { "file": "box.gltf", "position": [0, 0] } ] })", "models[0].position: expected 3 numbers"},
      {R"({ "lights": [ { "position": [3e38, 2.8, 1.0] } ] })", "lights[0].position: expected a number between -1e+06 and 1e+06, got 3e+38"},
      {R"({ "lights": [ { "position": [1.0, 2.8, 1e39] } ] })", "lights[0].position: expected a number between -1e+06 and 1e+06, got 1e+39"},
      {R"({ "models": [ { "file": "box.gltf", "scale": -2e6 } ] })", "models[0].scale: expected a number between -1e+06 and 1e+06, got -2e+06"},
      {R"({ "ambient": "bright" })", "ambient: expected a number"},
  };
  for (const auto& [text, expected] : cases) {
    const std::string what = scene_error(dir, text);
    EXPECT_FALSE(what.empty()) << "accepted " << text;
    EXPECT_NE(what.find("scene.json"), std::string::npos) << what;
    EXPECT_NE(what.find(expected), std::string::npos) << what;
  }
  // the bounds themselves are accepted
  std::ofstream(dir / "scene.json") << R"({ "lights": [ { "position": [1e6, -1e6, 0.5] } ] })";
  EXPECT_EQ(load_ar_scene(dir / "scene.json").lights.at(0).position, glm::vec3(1e6f, -1e6f, 0.5f));
  std::filesystem::remove_all(dir);
}

/// Numbers a scene's keys cannot mean are refused, naming the file, the key and the value: a scale
/// of 0 (the model flattened to nothing, drawn nowhere), an ambient term or a material factor
/// outside 0-1, a base colour outside 0-1 (a surface giving back more light than it receives), an
/// index of refraction below 1, a negative light colour. Each was rendered without a word. The
/// bounds themselves, and a negative scale (a mirror image), are accepted.
TEST(ArSceneFile, ValuesWithoutAMeaningAreRefused) {
  const auto dir = ::artrace::test::scratch_path("artrace_ar_ranges");
  std::filesystem::create_directories(dir);
  write_gltf(make_spinning_box(0.2f, {0.9f, 0.3f, 0.1f}), dir / "box.gltf");
  auto model = [](const std::string& keys) { return R"({ "models": [ { "file": "box.gltf", )" + keys + " } ] }"; };
  const std::pair<std::string, std::string> cases[] = {
      {model(R"("scale": 0)"), "models[0].scale: expected a scale other than 0, got 0"},
      {model(R"("scale": [1, 0, 2])"), "models[0].scale: expected a scale other than 0, got 0"},
      {R"({ "ambient": 2 })", "ambient: expected a number from 0 to 1, got 2"},
      {R"({ "ambient": -0.25 })", "ambient: expected a number from 0 to 1, got -0.25"},
      {model(R"("material": { "metallic": 1.5 })"), "models[0].material.metallic: expected a number from 0 to 1, got 1.5"},
      {model(R"("material": { "roughness": -0.5 })"), "models[0].material.roughness: expected a number from 0 to 1, got -0.5"},
      {model(R"("material": { "base_color": [0.5, 2, 0.5] })"), "models[0].material.base_color: expected a number from 0 to 1, got 2"},
      {model(R"("material": { "kind": "glass", "ior": 0.5 })"), "models[0].material.ior: expected 1 or more, got 0.5"},
      {R"({ "lights": [ { "position": [0, 1, 0], "color": [1, -1, 1] } ] })", "lights[0].color: expected 0 or more, got -1"},
  };
  for (const auto& [text, expected] : cases) {
    const std::string what = scene_error(dir, text);
    EXPECT_NE(what.find((dir / "scene.json").string() + ": " + expected), std::string::npos) << text << ": " << what;
  }
  // a model with nothing to draw (a node without a mesh; points and lines only): before, the scene
  // was composited without it and without a word
  std::ofstream(dir / "empty.gltf") << R"({"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"name":"camera"}],"scene":0})";
  const std::string empty = scene_error(dir, R"({ "models": [ { "file": "empty.gltf" } ] })");
  EXPECT_NE(empty.find((dir / "scene.json").string() + ": models[0].file: " + (dir / "empty.gltf").string() +
                       " holds no triangles to draw"),
            std::string::npos)
      << empty;
  std::ofstream(dir / "scene.json") << model(R"("scale": -1, "material": { "kind": "glass", "ior": 1, "metallic": 1,
      "roughness": 0, "base_color": [0, 1, 1] })").insert(1, R"( "ambient": 1, "lights": [ { "position": [0, 1, 0], "color": [0, 5, 0] } ], )");
  const ArSceneFile ok = load_ar_scene(dir / "scene.json");
  EXPECT_EQ(ok.ambient, 1.0f);
  EXPECT_EQ(ok.models.at(0).scale, glm::vec3(-1.0f));
  EXPECT_EQ(ok.models.at(0).ior, 1.0f);
  EXPECT_EQ(ok.models.at(0).metallic, 1.0f);
  EXPECT_EQ(ok.models.at(0).roughness, 0.0f);
  EXPECT_EQ(ok.lights.at(0).color, glm::vec3(0.0f, 5.0f, 0.0f));
  std::filesystem::remove_all(dir);
}

/// Glass of each kind gives the scene its transmittance: a shadow ray through a glass box (two
/// faces) keeps T^2 of the light, static or node-animated, and one through the skinned tube some
/// but not all of it; the same models, not glass, block it.
TEST(ArRuntime, GlassOfEveryKindLetsShadowRaysThrough) {
  const auto dir = ::artrace::test::scratch_path("artrace_ar_glass");
  std::filesystem::create_directories(dir);
  write_gltf(make_bending_tube(1.2f, 0.2f, {0.2f, 0.4f, 0.9f}), dir / "tube.gltf");
  write_gltf(make_spinning_box(0.2f, {0.9f, 0.3f, 0.1f}), dir / "box.gltf");
  auto scene_json = [](const char* material) {
    return std::string(R"({ "models": [
      { "file": "tube.gltf", "animation": { "clip": "bend" })") + material + R"( },
      { "file": "box.gltf", "position": [3, 0, 0])" + material + R"( },
      { "file": "box.gltf", "position": [-3, 0, 0], "animation": { "clip": "spin" })" + material + " } ] }";
  };
  const char* glass = R"(, "material": { "kind": "glass", "base_color": [0.9, 0.8, 0.7], "ior": 1.5 })";
  const float t = ar::shadow_transmittance({ar::VirtualMaterial::kGlass, glm::vec3(0.9f, 0.8f, 0.7f), 1.5f});
  for (const bool is_glass : {true, false}) {
    std::ofstream(dir / "scene.json") << scene_json(is_glass ? glass : "");
    const ArSceneFile file = load_ar_scene(dir / "scene.json");
    ArRuntime rt(file);
    rt.update(1.0);
    core::RayPacket packet{};
    packet.set(0, core::Ray{{3.0f, 0.1f, 5.0f}, {0.0f, 0.0f, -10.0f}, 0.0f, 1.0f});   // the static box
    packet.set(1, core::Ray{{-3.0f, 0.1f, 5.0f}, {0.0f, 0.0f, -10.0f}, 0.0f, 1.0f});  // the spinning box's axis
    packet.set(2, core::Ray{{-0.45f, 0.6f, 5.0f}, {0.0f, 0.0f, -10.0f}, 0.0f, 1.0f});  // the bent tube
    for (int i = 0; i < 3; ++i) ASSERT_TRUE(rt.scene().occluded(packet.get(i))) << "ray " << i << " meets its model";
    EXPECT_EQ(rt.scene().has_transmittance(), is_glass);
    if (!is_glass) continue;
    float trans[core::kPacketSize];
    ASSERT_EQ(rt.scene().transmittance(packet, 0x7u, trans), 0u) << "no unsure lanes";
    EXPECT_NEAR(trans[0], t * t, 1e-6f) << "static glass box";
    EXPECT_NEAR(trans[1], t * t, 1e-6f) << "node-animated glass box";
    EXPECT_GT(trans[2], 0.0f) << "skinned glass tube";
    EXPECT_LT(trans[2], t) << "skinned glass tube: at least one wall";
  }
  std::filesystem::remove_all(dir);
}

/// The shipped glass sphere carries the sphere's own normals: read back from the file, every
/// vertex's normal is the unit vector from the centre to it (the analytic oracle), and the mesh is
/// closed (every edge, by position, shared by exactly two triangles: no crack at the seam or the
/// poles, through which refraction rays would leak).
TEST(Gltf, GlassSphereHasTheSpheresNormalsAndNoCracks) {
  const auto dir = ::artrace::test::scratch_path("artrace_gltf_sphere");
  const float r = 0.1f;
  write_gltf(make_glass_sphere(r), dir / "glass.gltf");
  const GltfModel m = load_gltf(dir / "glass.gltf");
  ASSERT_EQ(m.meshes.size(), 1u);
  const GltfMesh& g = m.meshes[0];
  ASSERT_EQ(g.normals.size(), g.positions.size()) << "no NORMAL attribute: flat facets";
  const glm::vec3 centre(0.0f, r, 0.0f);
  size_t off_sphere = 0, wrong_normal = 0;
  for (size_t i = 0; i < g.positions.size(); ++i) {
    if (std::fabs(glm::length(g.positions[i] - centre) - r) > 1e-6f) ++off_sphere;
    if (glm::length(g.normals[i] - glm::normalize(g.positions[i] - centre)) > 1e-5f) ++wrong_normal;
  }
  EXPECT_EQ(off_sphere, 0u) << "vertices off the sphere, of " << g.positions.size();
  EXPECT_EQ(wrong_normal, 0u) << "normals not the sphere's, of " << g.positions.size();
  std::map<std::pair<std::array<float, 3>, std::array<float, 3>>, int> edges;
  auto key = [](const glm::vec3& v) { return std::array<float, 3>{v.x, v.y, v.z}; };
  for (const core::Triangle& t : g.tris) {
    const glm::vec3 v[3] = {t.v0, t.v1, t.v2};
    ASSERT_GT(glm::length(t.geometric_normal()), 0.0f) << "a degenerate triangle";
    for (int k = 0; k < 3; ++k) {
      auto a = key(v[k]), b = key(v[(k + 1) % 3]);
      if (b < a) std::swap(a, b);
      ++edges[{a, b}];
    }
  }
  for (const auto& [edge, count] : edges) ASSERT_EQ(count, 2) << "an edge of " << count << " triangles";
  // the copy in data/models is what make-models writes now
  const GltfModel shipped = load_gltf(std::filesystem::path(ARTRACE_SOURCE_DIR) / "data/models/glass_sphere.gltf");
  write_gltf(make_glass_sphere(kShippedGlassSphereRadius), dir / "made.gltf");
  const GltfMesh made = load_gltf(dir / "made.gltf").meshes.at(0);
  ASSERT_EQ(shipped.meshes.size(), 1u);
  EXPECT_EQ(shipped.meshes[0].positions, made.positions) << "data/models/glass_sphere.gltf is stale: artrace make-models data/models";
  EXPECT_EQ(shipped.meshes[0].normals, made.normals) << "data/models/glass_sphere.gltf is stale: artrace make-models data/models";
  // normals need the corners' vertex numbers
  GltfModel unindexed = make_glass_sphere(r);
  unindexed.meshes[0].indices.clear();
  EXPECT_THROW(write_gltf(unindexed, dir / "bad.gltf"), std::invalid_argument);
  std::filesystem::remove_all(dir);
}

/// Through ArRuntime, what the compositor shades and refracts with: at hits all over the glass
/// sphere the shading normal is the sphere's (within 0.2 degrees), where the facets' own normals
/// are up to several degrees off it.
TEST(ArRuntime, GlassSphereShadesWithTheSpheresNormal) {
  const auto dir = ::artrace::test::scratch_path("artrace_ar_sphere");
  const float r = 0.12f;
  write_gltf(make_glass_sphere(r), dir / "glass.gltf");
  std::ofstream(dir / "scene.json") << R"({ "models": [ { "file": "glass.gltf", "position": [0.5, -0.2, 2.0], "scale": 1.5 } ] })";
  const ArSceneFile file = load_ar_scene(dir / "scene.json");
  ArRuntime rt(file);
  rt.update(0.0);
  const glm::vec3 centre = glm::vec3(0.5f, -0.2f, 2.0f) + 1.5f * glm::vec3(0.0f, r, 0.0f);
  const float radius = 1.5f * r;
  float worst_shading = 0.0f, worst_facet = 0.0f;
  int hits = 0;
  for (int iy = -9; iy <= 9; ++iy) {
    for (int ix = -9; ix <= 9; ++ix) {
      // rays from a point in front towards a grid over the sphere's disc
      const glm::vec3 target = centre + radius * glm::vec3(ix / 10.0f, iy / 10.0f, 0.0f);
      const core::Ray ray{glm::vec3(0.2f, 0.1f, 0.0f), target - glm::vec3(0.2f, 0.1f, 0.0f)};
      const core::Hit h = rt.scene().intersect(ray);
      if (!h.valid()) continue;
      ++hits;
      ar::SurfaceQuery q(h);
      q.dir = ray.dir;
      const ar::VirtualMaterial mat = rt.material(q);
      ASSERT_NE(mat.normal, glm::vec3(0.0f)) << "no shading normal: the facets' own";
      const glm::vec3 p = ray.org + h.t * ray.dir;
      const glm::vec3 exact = glm::normalize(p - centre);
      auto degrees = [&](float cosine) { return glm::degrees(std::acos(std::clamp(cosine, -1.0f, 1.0f))); };
      // the shading normal points out of the sphere; a facet's either way (its winding)
      worst_shading = std::max(worst_shading, degrees(glm::dot(glm::normalize(mat.normal), exact)));
      const glm::vec3 facet = glm::normalize(rt.scene().world_triangle(h).geometric_normal());
      worst_facet = std::max(worst_facet, degrees(std::fabs(glm::dot(facet, exact))));
    }
  }
  EXPECT_GT(hits, 200);
  EXPECT_LT(worst_shading, 0.2f);
  EXPECT_GT(worst_facet, 2.0f) << "the facets differ from the sphere: the check above can tell";
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace artrace::io
