// Third-party glTF features against answers worked out by hand: textures at pixel centres, wrap
// modes and the second texture coordinate set, alpha cut-outs for camera and shadow rays, normal
// maps, emissive colour, morph targets, primitive modes, sparse accessors; and every model of the
// shared data loading and rendering in its texture's colours.
#include "artrace/ar/compositor.h"
#include "artrace/core/srgb.h"
#include "artrace/io/ar_scene.h"
#include "artrace/io/parse_error.h"
#include "../test_util.h"
#include "../../io/src/cv_convert.h"

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <fstream>
#include <set>

namespace artrace::io {
namespace {

using nlohmann::json;

std::string base64(const std::vector<uint8_t>& in) {
  static const char* k = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (size_t i = 0; i < in.size(); i += 3) {
    const uint32_t n = (in[i] << 16) | ((i + 1 < in.size() ? in[i + 1] : 0) << 8) | (i + 2 < in.size() ? in[i + 2] : 0);
    out += k[(n >> 18) & 63];
    out += k[(n >> 12) & 63];
    out += i + 1 < in.size() ? k[(n >> 6) & 63] : '=';
    out += i + 2 < in.size() ? k[n & 63] : '=';
  }
  return out;
}

/// A PNG of w x h RGBA texels as a data URI (texels given top row first, R G B A).
std::string png_uri(int w, int h, const std::vector<uint8_t>& rgba) {
  cv::Mat m(h, w, CV_8UC4);
  for (int i = 0; i < w * h; ++i) m.at<cv::Vec4b>(i / w, i % w) = cv::Vec4b(rgba[4 * i + 2], rgba[4 * i + 1], rgba[4 * i], rgba[4 * i + 3]);
  std::vector<uint8_t> png;
  cv::imencode(".png", m, png);
  return "data:image/png;base64," + base64(png);
}

/// A glTF with one quad (two triangles) built in code: positions, optional texture coordinate sets
/// and normals, a material given as JSON, images as data URIs.
struct QuadGltf {
  std::vector<float> pos, uv0, uv1, normal;
  json material = json::object();
  json images = json::array(), textures = json::array(), samplers = json::array();

  /// The quad [x0, x1] x [y0, y1] at z, its front (counter-clockwise) facing -z, towards a camera at
  /// the origin looking down +z with y down; texture coordinate (0, 0) at (x0, y0), (1, 1) at (x1, y1).
  static QuadGltf at(float x0, float x1, float y0, float y1, float z) {
    QuadGltf q;
    q.pos = {x0, y0, z, x0, y1, z, x1, y1, z, x1, y0, z};
    q.uv0 = {0, 0, 0, 1, 1, 1, 1, 0};
    return q;
  }
  void write(const std::filesystem::path& path) const {
    std::vector<uint8_t> bytes;
    json views = json::array(), accessors = json::array(), attributes = json::object();
    auto add = [&](const std::vector<float>& v, const char* type, int comps, const char* name) {
      if (v.empty()) return;
      const size_t at = bytes.size();
      bytes.resize(at + 4 * v.size());
      std::memcpy(&bytes[at], v.data(), 4 * v.size());
      views.push_back({{"buffer", 0}, {"byteOffset", at}, {"byteLength", 4 * v.size()}});
      json a = {{"bufferView", views.size() - 1}, {"componentType", 5126}, {"count", v.size() / comps}, {"type", type}};
      if (std::string(name) == "POSITION") {
        a["min"] = {std::min({v[0], v[3], v[6], v[9]}), std::min({v[1], v[4], v[7], v[10]}), std::min({v[2], v[5], v[8], v[11]})};
        a["max"] = {std::max({v[0], v[3], v[6], v[9]}), std::max({v[1], v[4], v[7], v[10]}), std::max({v[2], v[5], v[8], v[11]})};
      }
      accessors.push_back(a);
      attributes[name] = accessors.size() - 1;
    };
    add(pos, "VEC3", 3, "POSITION");
    add(uv0, "VEC2", 2, "TEXCOORD_0");
    add(uv1, "VEC2", 2, "TEXCOORD_1");
    add(normal, "VEC3", 3, "NORMAL");
    const uint16_t idx[6] = {0, 1, 2, 0, 2, 3};
    const size_t at = bytes.size();
    bytes.resize(at + 12);
    std::memcpy(&bytes[at], idx, 12);
    views.push_back({{"buffer", 0}, {"byteOffset", at}, {"byteLength", 12}});
    accessors.push_back({{"bufferView", views.size() - 1}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}});
    json g = {{"asset", {{"version", "2.0"}}},
              {"buffers", {{{"byteLength", bytes.size()}, {"uri", "data:application/octet-stream;base64," + base64(bytes)}}}},
              {"bufferViews", views},
              {"accessors", accessors},
              {"materials", {material}},
              {"meshes", {{{"primitives", {{{"attributes", attributes}, {"indices", accessors.size() - 1}, {"material", 0}}}}}}},
              {"nodes", {{{"mesh", 0}}}},
              {"scenes", {{{"nodes", {0}}}}}};
    if (!images.empty()) {
      g["images"] = images;
      g["textures"] = textures;
      if (!samplers.empty()) g["samplers"] = samplers;
    }
    std::ofstream(path) << g.dump();
  }
};

constexpr int kW = 64, kH = 64;
constexpr double kF = 32.0, kC = 31.5;

/// A recorded frame: a grey wall at 5 m (or `wall_z`), identity pose, f = 32 px on 64 x 64.
ar::SensorFrame wall(float wall_z = 5.0f) {
  ar::SensorFrame f;
  f.color.width = f.depth.width = kW;
  f.color.height = f.depth.height = kH;
  f.color.rgb.assign(3 * kW * kH, 100);
  f.depth.depth_m.assign(kW * kH, wall_z);
  f.color_intrinsics = f.depth_intrinsics = ar::PinholeIntrinsics{kW, kH, kF, kF, kC, kC};
  f.world_from_camera = Eigen::Isometry3d::Identity();
  return f;
}

/// Composites an AR scene (one model in its own space, a light, an ambient) over `frame`.
ar::ColorImage render(const std::filesystem::path& model, const ar::SensorFrame& frame, const std::string& material_override,
                      float ambient, const glm::vec3& light, bool shadows = false) {
  const auto scene = model.parent_path() / (model.stem().string() + ".scene.json");
  std::ofstream(scene) << R"({ "models": [ { "file": ")" << model.filename().string() << R"(" )"
                       << (material_override.empty() ? "" : ", \"material\": " + material_override) << R"( } ],
                          "lights": [ { "position": [)" << light.x << "," << light.y << "," << light.z << R"(], "color": [1, 1, 1] } ],
                          "ambient": )" << ambient << " }";
  const ArSceneFile file = load_ar_scene(scene);
  ArRuntime rt(file);
  ar::CompositeOptions opt;
  opt.lights = rt.lights();
  opt.ambient = rt.ambient();
  opt.alpha_tested = rt.alpha_tested();
  opt.shadows = shadows;
  opt.occlusion = false;
  opt.threads = 2;
  return ar::composite(frame, rt.scene(), [&](const ar::SurfaceQuery& q) { return rt.material(q); }, opt);
}

std::filesystem::path test_dir(const std::string& name) {
  const auto d = ::artrace::test::scratch_path(name);
  std::filesystem::remove_all(d);
  std::filesystem::create_directories(d);
  return d;
}

/// A 4 x 4 texture of 16 colours, NEAREST: the quad covers the image exactly (x, y in [-2, 2] at
/// z = 2 with f = 32 on 64 pixels), so each texel covers 16 x 16 pixels; with ambient 1 and Lambert
/// shading every pixel centre shows its texel's colour (sRGB in, linear, sRGB out).
TEST(GltfTexture, TexturedQuadShowsTexelColoursAtPixelCentres) {
  const auto dir = test_dir("artrace_tex_quad");
  std::vector<uint8_t> texels;
  for (int i = 0; i < 16; ++i) texels.insert(texels.end(), {uint8_t(16 * i), uint8_t(255 - 12 * i), uint8_t((i * 77) % 256), 255});
  QuadGltf q = QuadGltf::at(-2, 2, -2, 2, 2);
  q.images = {{{"uri", png_uri(4, 4, texels)}}};
  q.samplers = {{{"magFilter", 9728}, {"minFilter", 9728}}};
  q.textures = {{{"source", 0}, {"sampler", 0}}};
  q.material = {{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}};
  q.write(dir / "quad.gltf");
  const ar::ColorImage out = render(dir / "quad.gltf", wall(), R"({ "kind": "diffuse" })", 1.0f, {0, 0, 10});
  int wrong = 0;
  for (int y = 0; y < kH; ++y) {
    for (int x = 0; x < kW; ++x) {
      const uint8_t* t = &texels[4 * ((y / 16) * 4 + x / 16)];
      const uint8_t* o = out.at(x, y);
      for (int c = 0; c < 3; ++c) wrong += std::abs(o[c] - t[c]) > 1;
    }
  }
  EXPECT_EQ(wrong, 0);
}

/// TEXCOORD_1 runs from -1 to 2 across the quad (TEXCOORD_0 is constant, so a reader using the wrong
/// set shows one colour); a 2 x 1 texture (red, green), NEAREST. Sixths of the quad, worked out by
/// hand from the glTF sampler rules: repeat R G R G R G, clamp R R R G G G, mirrored repeat G R R G G R.
TEST(GltfTexture, WrapModesAndTheSecondTextureCoordinateSet) {
  const auto dir = test_dir("artrace_tex_wrap");
  const std::vector<uint8_t> texels = {255, 0, 0, 255, 0, 255, 0, 255};
  const struct {
    int wrap;
    const char* expected;
  } modes[] = {{10497, "RGRGRG"}, {33071, "RRRGGG"}, {33648, "GRRGGR"}};
  for (const auto& mode : modes) {
    QuadGltf q = QuadGltf::at(-2, 2, -2, 2, 2);
    q.uv0 = {0.25f, 0.5f, 0.25f, 0.5f, 0.25f, 0.5f, 0.25f, 0.5f};
    q.uv1 = {-1, 0, -1, 1, 2, 1, 2, 0};
    q.images = {{{"uri", png_uri(2, 1, texels)}}};
    q.samplers = {{{"magFilter", 9728}, {"minFilter", 9728}, {"wrapS", mode.wrap}, {"wrapT", mode.wrap}}};
    q.textures = {{{"source", 0}, {"sampler", 0}}};
    q.material = {{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}, {"texCoord", 1}}}}}};
    const auto file = dir / ("wrap" + std::to_string(mode.wrap) + ".gltf");
    q.write(file);
    const ar::ColorImage out = render(file, wall(), R"({ "kind": "diffuse" })", 1.0f, {0, 0, 10});
    std::string seen;
    for (int k = 0; k < 6; ++k) {
      const uint8_t* p = out.at(static_cast<int>((k + 0.5) * kW / 6.0), kH / 2);
      seen += p[0] > 200 && p[1] < 50 ? 'R' : p[1] > 200 && p[0] < 50 ? 'G' : '?';
    }
    EXPECT_EQ(seen, mode.expected) << "wrap " << mode.wrap;
  }
}

/// A 2 x 2 checkerboard of alpha (opaque at texels (0, 0) and (1, 1)), alpha MASK with cutoff 0.5,
/// on a red quad x in [-0.6, -0.2], y in [-0.2, 0.2] at z = 1, before a real wall at z = 2, lit from
/// (0.5, 0, 0). Camera rays see red only at opaque texels and the wall through the others. Shadow
/// rays from the wall pass the quad at the midpoint of the segment to the light (z = 1): the wall
/// at (x, y) is in shadow exactly where ((x + 0.5) / 2, y / 2) is an opaque texel.
TEST(GltfTexture, MaskCutoutsLetCameraAndShadowRaysThrough) {
  const auto dir = test_dir("artrace_tex_mask");
  const std::vector<uint8_t> texels = {255, 0, 0, 255, 255, 0, 0, 0, 255, 0, 0, 0, 255, 0, 0, 255};
  QuadGltf q = QuadGltf::at(-0.6f, -0.2f, -0.2f, 0.2f, 1.0f);
  q.images = {{{"uri", png_uri(2, 2, texels)}}};
  q.samplers = {{{"magFilter", 9728}, {"minFilter", 9728}}};
  q.textures = {{{"source", 0}, {"sampler", 0}}};
  q.material = {{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}, {"alphaMode", "MASK"}, {"alphaCutoff", 0.5}};
  q.write(dir / "mask.gltf");
  const ar::SensorFrame frame = wall(2.0f);
  const ar::ColorImage out = render(dir / "mask.gltf", frame, R"({ "kind": "diffuse" })", 1.0f, {0.5f, 0.0f, 0.0f}, true);
  // the texel a point of the quad's plane falls in; -1 outside the quad
  auto texel = [](double x, double y) {
    if (x < -0.6 || x > -0.2 || y < -0.2 || y > 0.2) return -1;
    return (x < -0.4 ? 0 : 1) + (y < 0.0 ? 0 : 2);
  };
  auto opaque = [](int t) { return t == 0 || t == 3; };
  int red = 0, through = 0, shadowed = 0, lit = 0, wrong = 0;
  for (int y = 0; y < kH; ++y) {
    for (int x = 0; x < kW; ++x) {
      const double dx = (x - kC) / kF, dy = (y - kC) / kF;
      const uint8_t* o = out.at(x, y);
      const int t = texel(dx, dy);  // where the camera ray meets z = 1
      // stay clear of texel edges (pixel centres within a pixel's width of them)
      const double px = 1.5 / kF;
      if (texel(dx - px, dy) != t || texel(dx + px, dy) != t || texel(dx, dy - px) != t || texel(dx, dy + px) != t) continue;
      if (t >= 0 && opaque(t)) {
        ++red;
        wrong += !(o[0] > 200 && o[1] < 30);
        continue;
      }
      // the wall at (2 dx, 2 dy, 2): its segment to the light crosses z = 1 at ((2 dx + 0.5) / 2, dy)
      const double wx = 2 * dx, wy = 2 * dy;
      const int s = texel((wx + 0.5) / 2.0, wy / 2.0);
      if (texel((wx + 0.5 - 2 * px) / 2.0, wy / 2.0) != s || texel((wx + 0.5 + 2 * px) / 2.0, wy / 2.0) != s ||
          texel((wx + 0.5) / 2.0, (wy - 2 * px) / 2.0) != s || texel((wx + 0.5) / 2.0, (wy + 2 * px) / 2.0) != s) {
        continue;
      }
      through += t >= 0;
      const bool in_shadow = s >= 0 && opaque(s);
      const bool darker = o[0] < 100;
      (in_shadow ? shadowed : lit) += 1;
      wrong += in_shadow != darker;
      if (!in_shadow) wrong += o[0] != 100;
    }
  }
  EXPECT_EQ(wrong, 0);
  EXPECT_GT(red, 20);
  EXPECT_GT(through, 15) << "wall pixels seen through the cut-outs";
  EXPECT_GT(shadowed, 10);
  EXPECT_GT(lit, 100);
}

/// A white quad facing the camera, lit from (1, 0, -1) far away, with a constant normal map
/// (204, 128, 230): tangent-space n = 2 c / 255 - 1 = (0.6, 0.0039, 0.8039), tangent +x and
/// bitangent +y (the texture coordinates' directions), normal -z; by hand the world normal is
/// normalize(0.6, 0.0039, -0.8039), and Lambert's cosine with the light direction gives the colour.
TEST(GltfTexture, NormalMapChangesTheShadingAsWorkedOutByHand) {
  const auto dir = test_dir("artrace_tex_normal");
  QuadGltf q = QuadGltf::at(-2, 2, -2, 2, 2);
  q.images = {{{"uri", png_uri(1, 1, {204, 128, 230, 255})}}};
  q.textures = {{{"source", 0}}};
  q.material = {{"normalTexture", {{"index", 0}}}};
  q.write(dir / "bumped.gltf");
  QuadGltf flat = q;
  flat.material = json::object();
  flat.write(dir / "flat.gltf");
  const glm::vec3 light(1000.0f, 0.0f, -1000.0f);
  const ar::ColorImage bumped = render(dir / "bumped.gltf", wall(), R"({ "kind": "diffuse", "base_color": [1, 1, 1] })", 0.0f, light);
  const ar::ColorImage plain = render(dir / "flat.gltf", wall(), R"({ "kind": "diffuse", "base_color": [1, 1, 1] })", 0.0f, light);
  const glm::dvec3 n = glm::normalize(glm::dvec3(2 * 204 / 255.0 - 1, 2 * 128 / 255.0 - 1, -(2 * 230 / 255.0 - 1)));
  int checked = 0;
  for (int y = 8; y < kH - 8; y += 5) {
    for (int x = 8; x < kW - 8; x += 5) {
      const glm::dvec3 p((x - kC) / kF * 2, (y - kC) / kF * 2, 2.0);
      const glm::dvec3 l = glm::normalize(glm::dvec3(light) - p);
      const int expected = core::linear_to_srgb8(static_cast<float>(std::max(0.0, glm::dot(n, l))));
      const int expected_flat = core::linear_to_srgb8(static_cast<float>(std::max(0.0, -l.z)));
      EXPECT_NEAR(bumped.at(x, y)[0], expected, 1) << x << "," << y;
      EXPECT_NEAR(plain.at(x, y)[0], expected_flat, 1) << x << "," << y;
      ++checked;
    }
  }
  EXPECT_GT(checked, 50);
  EXPECT_GT(bumped.at(32, 32)[0], plain.at(32, 32)[0] + 20) << "the map turns the normal towards the light";
}

/// Emissive adds its colour: ambient 0.5 on base (0.2, 0.4, 0.6), no light reaching the front,
/// emissive (0.3, 0.1, 0) times KHR_materials_emissive_strength 2.
TEST(GltfTexture, EmissiveAddsItsColour) {
  const auto dir = test_dir("artrace_emissive");
  QuadGltf q = QuadGltf::at(-2, 2, -2, 2, 2);
  q.material = {{"pbrMetallicRoughness", {{"baseColorFactor", {0.2, 0.4, 0.6, 1.0}}}},
                {"emissiveFactor", {0.3, 0.1, 0.0}},
                {"extensions", {{"KHR_materials_emissive_strength", {{"emissiveStrength", 2.0}}}}}};
  q.write(dir / "glow.gltf");
  const ar::ColorImage out = render(dir / "glow.gltf", wall(), R"({ "kind": "diffuse" })", 0.5f, {0, 0, 10});
  const float expected[3] = {0.5f * 0.2f + 0.6f, 0.5f * 0.4f + 0.2f, 0.5f * 0.6f};
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(out.at(32, 32)[c], core::linear_to_srgb8(expected[c]), 1) << "channel " << c;
}

TEST(GltfGeometry, MorphTargetAtHalfWeightMovesItsVerticesHalfWay) {
  const auto dir = test_dir("artrace_morph");
  // the quad, with one target moving every vertex by (0, 0, -1) and vertex 0 by (1, 1, -1) more
  QuadGltf q = QuadGltf::at(-1, 1, -1, 1, 3);
  q.write(dir / "base.gltf");
  json g = json::parse(std::ifstream(dir / "base.gltf"));
  std::vector<float> delta = {1, 1, -2, 0, 0, -1, 0, 0, -1, 0, 0, -1};  // vertex 0 at (-1, -1), 2 at (1, 1)
  std::vector<uint8_t> bytes(48);
  std::memcpy(bytes.data(), delta.data(), 48);
  g["buffers"].push_back({{"byteLength", 48}, {"uri", "data:application/octet-stream;base64," + base64(bytes)}});
  g["bufferViews"].push_back({{"buffer", 1}, {"byteOffset", 0}, {"byteLength", 48}});
  g["accessors"].push_back({{"bufferView", g["bufferViews"].size() - 1}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"}});
  g["meshes"][0]["primitives"][0]["targets"] = {{{"POSITION", g["accessors"].size() - 1}}};
  g["meshes"][0]["weights"] = {0.5};
  std::ofstream(dir / "morph.gltf") << g.dump();
  const GltfModel m = load_gltf(dir / "morph.gltf");
  ASSERT_EQ(m.meshes[0].targets.size(), 1u);
  const std::vector<glm::vec3> half = m.morphed_positions(0, {0.5f});
  EXPECT_EQ(half[0], glm::vec3(-0.5f, -0.5f, 2.0f));
  EXPECT_EQ(half[2], glm::vec3(1.0f, 1.0f, 2.5f));
  // the mesh's default weight (0.5) is what the bind-pose triangles show
  EXPECT_EQ(m.meshes[0].tris[0].v0, glm::vec3(-0.5f, -0.5f, 2.0f));
}

/// Mesh_PrimitiveMode 04-06 and 11-15 (strips, fans, triangles; with and without 8/16/32-bit
/// indices) each draw the same square of two triangles: the same four corners, both triangles
/// facing +z (the winding kept through the strip's alternation), areas adding up to the square's
/// (no overlap, no gap). A fan splits it along the other diagonal than a strip does: that follows
/// from the files' vertex order (the fan's first vertex is a corner of both triangles). The points
/// and lines files draw nothing and say so once.
TEST(GltfGeometry, EveryTriangleFormingPrimitiveModeGivesTheSameSquare) {
  ARTRACE_REQUIRE_SHARED("models/Mesh_PrimitiveMode");
  for (const char* n : {"04", "05", "06", "11", "12", "13", "14", "15"}) {
    const GltfModel m = load_gltf(shared_path / (std::string("Mesh_PrimitiveMode_") + n + ".gltf"));
    ASSERT_EQ(m.triangle_count(), 2u) << n;
    std::set<std::pair<float, float>> corners;
    double area = 0.0;
    for (const core::Triangle& t : m.meshes[0].tris) {
      const glm::vec3 g = t.geometric_normal();
      EXPECT_GT(g.z, 0.0f) << "Mesh_PrimitiveMode_" << n << ": a triangle faces away";
      EXPECT_EQ(t.v0.z, 0.0f);
      area += 0.5 * glm::length(g);
      for (const glm::vec3& v : {t.v0, t.v1, t.v2}) corners.insert({v.x, v.y});
    }
    EXPECT_EQ(corners, (std::set<std::pair<float, float>>{{-0.5f, -0.5f}, {-0.5f, 0.5f}, {0.5f, -0.5f}, {0.5f, 0.5f}})) << n;
    EXPECT_NEAR(area, 1.0, 1e-6) << "Mesh_PrimitiveMode_" << n;
    EXPECT_TRUE(m.warnings.empty()) << n;
  }
  for (const char* n : {"00", "01", "02", "03", "07", "08", "09", "10"}) {
    const GltfModel m = load_gltf(shared_path / (std::string("Mesh_PrimitiveMode_") + n + ".gltf"));
    EXPECT_EQ(m.triangle_count(), 0u) << n;
    ASSERT_EQ(m.warnings.size(), 1u) << n;
    EXPECT_NE(m.warnings[0].find("primitive 0 draws"), std::string::npos) << m.warnings[0];
  }
}

/// SimpleSparseAccessor: 14 vertices of a 2 x 6 grid at y = 0 and 1, of which the sparse accessor
/// replaces vertices 8, 10 and 12 by (1, 2, 0), (3, 3, 0) and (5, 4, 0), as its description says.
TEST(GltfGeometry, SparseAccessorReplacesItsThreeVertices) {
  ARTRACE_REQUIRE_SHARED("models/SimpleSparseAccessor/SimpleSparseAccessor.gltf");
  const GltfModel m = load_gltf(shared_path);
  const std::vector<glm::vec3>& p = m.meshes.at(0).positions;
  ASSERT_EQ(p.size(), 14u);
  EXPECT_EQ(p[8], glm::vec3(1, 2, 0));
  EXPECT_EQ(p[10], glm::vec3(3, 3, 0));
  EXPECT_EQ(p[12], glm::vec3(5, 4, 0));
  EXPECT_EQ(p[9], glm::vec3(2, 1, 0)) << "the others keep their values";
  EXPECT_EQ(p[1], glm::vec3(1, 0, 0));
}

TEST(GltfGeometry, UnsupportedRequiredExtensionIsAnErrorOptionalOnesAWarning) {
  const auto dir = test_dir("artrace_gltf_ext");
  QuadGltf::at(-1, 1, -1, 1, 2).write(dir / "q.gltf");
  json g = json::parse(std::ifstream(dir / "q.gltf"));
  g["extensionsUsed"] = {"KHR_draco_mesh_compression", "EXT_lights_image_based"};
  std::ofstream(dir / "optional.gltf") << g.dump();
  const GltfModel m = load_gltf(dir / "optional.gltf");
  ASSERT_EQ(m.warnings.size(), 1u);
  EXPECT_NE(m.warnings[0].find("KHR_draco_mesh_compression, EXT_lights_image_based"), std::string::npos) << m.warnings[0];
  g["extensionsRequired"] = {"KHR_draco_mesh_compression"};
  std::ofstream(dir / "required.gltf") << g.dump();
  try {
    load_gltf(dir / "required.gltf");
    ADD_FAILURE() << "accepted";
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find("requires extension KHR_draco_mesh_compression"), std::string::npos) << e.what();
  }
  // an image that is missing, and one that does not decode
  QuadGltf q = QuadGltf::at(-1, 1, -1, 1, 2);
  q.images = {{{"uri", "nowhere.png"}}};
  q.textures = {{{"source", 0}}};
  q.material = {{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}};
  q.write(dir / "missing_image.gltf");
  q.images = {{{"uri", "data:image/png;base64,AAAA"}, {"name", "broken"}}};
  q.write(dir / "broken_image.gltf");
  for (const char* name : {"missing_image.gltf", "broken_image.gltf"}) {
    try {
      load_gltf(dir / name);
      ADD_FAILURE() << name << " accepted";
    } catch (const ParseError& e) {
      EXPECT_NE(std::string(e.what()).find((dir / name).string()), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(name[0] == 'm' ? "nowhere.png" : "broken"), std::string::npos) << e.what();
    }
  }
}

/// Material factors outside glTF's ranges (metallic, roughness, base colour, alpha, transmission
/// and occlusion strength 0-1, emissive 0 or more, an IOR of 0 or 1 and more) were used as
/// given: a metallic factor of 5 shaded five times the light it receives. Each is now taken at its
/// range's nearest bound (an invalid IOR as glTF's default, 1.5), with a warning naming the file,
/// the material, the factor and its value; factors within range pass untouched and unwarned.
TEST(GltfGeometry, MaterialFactorsOutsideTheirRangesAreBoundedWithAWarning) {
  const auto dir = test_dir("artrace_gltf_ranges");
  QuadGltf q = QuadGltf::at(-1, 1, -1, 1, 2);
  q.material = {{"name", "odd"},
                {"pbrMetallicRoughness", {{"baseColorFactor", {2.0, 0.5, -0.25, 1.5}}, {"metallicFactor", 5.0}, {"roughnessFactor", -0.5}}},
                {"emissiveFactor", {0.0, -1.0, 0.0}},
                {"extensions", {{"KHR_materials_ior", {{"ior", 0.5}}}, {"KHR_materials_transmission", {{"transmissionFactor", 1.5}}}}}};
  const auto path = dir / "odd.gltf";
  q.write(path);
  const GltfModel m = load_gltf(path);
  ASSERT_EQ(m.materials.size(), 2u);
  const GltfMaterial& g = m.materials[1];
  EXPECT_EQ(g.base_color, glm::vec3(1.0f, 0.5f, 0.0f));
  EXPECT_EQ(g.alpha, 1.0f);
  EXPECT_EQ(g.metallic, 1.0f);
  EXPECT_EQ(g.roughness, 0.0f);
  EXPECT_EQ(g.emissive, glm::vec3(0.0f));
  EXPECT_EQ(g.transmission, 1.0f);
  EXPECT_EQ(g.ior, 1.5f);
  const std::string prefix = path.string() + ": material 'odd' ";
  for (const std::string expected :
       {"baseColorFactor 2 lies outside 0-1 (glTF's range): taken as 1", "baseColorFactor -0.25 lies outside 0-1 (glTF's range): taken as 0",
        "alpha 1.5 lies outside 0-1 (glTF's range): taken as 1", "metallicFactor 5 lies outside 0-1 (glTF's range): taken as 1",
        "roughnessFactor -0.5 lies outside 0-1 (glTF's range): taken as 0", "emissiveFactor -1 lies below 0 (glTF's range): taken as 0",
        "transmissionFactor 1.5 lies outside 0-1 (glTF's range): taken as 1",
        "ior 0.5 is neither 0 nor 1 or more (KHR_materials_ior): taken as 1.5"}) {
    const bool found = std::any_of(m.warnings.begin(), m.warnings.end(), [&](const std::string& w) { return w == prefix + expected; });
    EXPECT_TRUE(found) << expected;
  }
  EXPECT_EQ(m.warnings.size(), 8u);
  // the same factors within range: as given, no warning; an IOR of 0 (a mirror) is glTF's own
  q.material = {{"name", "fine"},
                {"pbrMetallicRoughness", {{"baseColorFactor", {1.0, 0.0, 0.5, 0.25}}, {"metallicFactor", 1.0}, {"roughnessFactor", 0.0}}},
                {"extensions", {{"KHR_materials_ior", {{"ior", 0.0}}}}}};
  q.write(path);
  const GltfModel fine = load_gltf(path);
  EXPECT_TRUE(fine.warnings.empty()) << fine.warnings.front();
  EXPECT_EQ(fine.materials[1].base_color, glm::vec3(1.0f, 0.0f, 0.5f));
  EXPECT_EQ(fine.materials[1].alpha, 0.25f);
  EXPECT_EQ(fine.materials[1].ior, 0.0f);
}

// The image header sniffer that guards OpenCV's decoder, against images OpenCV encodes (the
// oracle): PNG, baseline and progressive JPEG, lossy and lossless WebP, of sizes that are not
// square; other bytes give none.
TEST(GltfImages, DeclaredSizeIsReadFromPngAndJpegHeaders) {
  for (const auto& [ext, params] : std::vector<std::pair<std::string, std::vector<int>>>{
           {".png", {}},
           {".jpg", {}},
           {".jpg", {cv::IMWRITE_JPEG_PROGRESSIVE, 1}},
           {".webp", {cv::IMWRITE_WEBP_QUALITY, 90}},
           {".webp", {cv::IMWRITE_WEBP_QUALITY, 101}}}) {  // above 100: lossless
    if (!cv::haveImageWriter(ext)) continue;
    for (const auto& [w, h] : {std::pair{37, 5}, std::pair{300, 1023}}) {
      std::vector<uint8_t> bytes;
      ASSERT_TRUE(cv::imencode(ext, cv::Mat(h, w, CV_8UC3, cv::Scalar(10, 200, 30)), bytes, params));
      const auto got = declared_image_size(bytes.data(), bytes.size());
      ASSERT_TRUE(got.has_value()) << ext;
      EXPECT_EQ(got->width, static_cast<uint32_t>(w)) << ext;
      EXPECT_EQ(got->height, static_cast<uint32_t>(h)) << ext;
      EXPECT_FALSE(declared_image_size(bytes.data(), 20).has_value()) << ext << ": cut inside the header";
    }
  }
  const uint8_t bmp[30] = {'B', 'M'};
  EXPECT_FALSE(declared_image_size(bmp, sizeof bmp).has_value());
}

/// A quad whose base colour is the PNG `png` (a data URI named `name`), written as `dir/name.gltf`;
/// what loading it throws, or "" when it loads.
std::string load_textured_quad(const std::filesystem::path& dir, const std::vector<uint8_t>& png, const std::string& name) {
  QuadGltf q = QuadGltf::at(-1, 1, -1, 1, 2);
  q.textures = {{{"source", 0}}};
  q.material = {{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}};
  q.images = {{{"uri", "data:image/png;base64," + base64(png)}, {"name", name}}};
  q.write(dir / (name + ".gltf"));
  try {
    load_gltf(dir / (name + ".gltf"));
    return "";
  } catch (const ParseError& e) {
    return e.what();
  }
}

// An image whose header declares a size beyond 16384 a side is refused, naming the image and the
// size, before anything is allocated for it (found by fuzzing: such a PNG made OpenCV allocate
// gigabytes); the same image at its true size loads.
TEST(GltfImages, HugeDeclaredImageIsRefusedBeforeDecoding) {
  const auto dir = test_dir("artrace_gltf_huge");
  std::vector<uint8_t> png;
  ASSERT_TRUE(cv::imencode(".png", cv::Mat(2, 2, CV_8UC3, cv::Scalar(1, 2, 3)), png));
  EXPECT_EQ(load_textured_quad(dir, png, "small"), "");
  // IHDR width and height (big-endian, bytes 16..23) set to 40000 x 40000; the CRC is left wrong,
  // which a decoder would notice only after allocating
  for (const int at : {16, 20}) {
    png[at] = 0;
    png[at + 1] = 0;
    png[at + 2] = 40000 >> 8;
    png[at + 3] = 40000 & 255;
  }
  const std::string msg = load_textured_quad(dir, png, "huge");
  EXPECT_NE(msg.find("image 0 (huge) declares 40000x40000 pixels"), std::string::npos) << msg;
}

// A PNG of sound size with a text chunk declaring 1.85 GB, which libpng would allocate before
// reading it (found by fuzzing: a 25 kB .glb took 1.9 GB and 2 s to refuse). The chunk structure is
// checked first: the error names the chunk, where it starts and what it declares.
TEST(GltfImages, PngChunkRunningPastTheDataIsRefusedBeforeDecoding) {
  const auto dir = test_dir("artrace_gltf_chunk");
  std::vector<uint8_t> png;
  ASSERT_TRUE(cv::imencode(".png", cv::Mat(2, 2, CV_8UC3, cv::Scalar(1, 2, 3)), png));
  // after IHDR (8-byte signature, then 8 + 13 + 4 bytes): an iTXt chunk declaring 1,852,142,681 bytes
  const std::vector<uint8_t> itxt = {0x6e, 0x65, 0x74, 0x59, 'i', 'T', 'X', 't', 'a', 'b', 'c'};
  png.insert(png.begin() + 33, itxt.begin(), itxt.end());
  const std::string msg = load_textured_quad(dir, png, "bomb");
  EXPECT_NE(msg.find("image 0 (bomb) is a broken PNG: its iTXt chunk at byte 33 declares 1852142681 bytes, " +
                     std::to_string(png.size() - 33 - 12) + " follow"),
            std::string::npos)
      << msg;
}

// Found by fuzzing: an image's bufferView reaching past its buffer, whose declared range tinygltf
// hands to the image decoder unchecked (a read past the buffer). Refused, naming the view.
TEST(GltfImages, ImageBufferViewPastItsBufferIsRefused) {
  const auto glb = std::filesystem::path(ARTRACE_SOURCE_DIR) / "tests/fuzz/corpus/gltf/regress-image-bufferview-past-buffer.glb";
  try {
    load_gltf(glb);
    ADD_FAILURE() << "accepted";
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find("image 0: its bufferView 3 (bytes 840 + 23516) runs past its buffer's 24330 bytes"), std::string::npos)
        << e.what();
  }
}

/// An image uri is looked up beside the model, as a regular file. A uri naming a folder is a missing
/// image (tinygltf's own reader took a folder's size as 2^63 - 1 bytes and allocated it: a campaign
/// finding, whose input is in the corpus), and so is a file that exists only in the current folder
/// (tinygltf's own lookup fell back to it, a silently wrong texture). The same file beside the model
/// loads.
TEST(GltfImages, ImageUriIsARegularFileBesideTheModel) {
  const auto dir = test_dir("artrace_gltf_uri"), elsewhere = test_dir("artrace_gltf_uri_cwd");
  std::filesystem::create_directories(dir / "folder");
  std::vector<uint8_t> png;
  cv::imencode(".png", cv::Mat(2, 2, CV_8UC3, cv::Scalar(0, 0, 255)), png);
  std::ofstream(elsewhere / "red.png", std::ios::binary).write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
  QuadGltf q = QuadGltf::at(-1, 1, -1, 1, 2);
  q.textures = {{{"source", 0}}};
  q.material = {{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}};
  q.images = {{{"uri", "folder"}}};
  q.write(dir / "folder_image.gltf");
  q.images = {{{"uri", "red.png"}}};
  q.write(dir / "red_image.gltf");
  const auto cwd = std::filesystem::current_path();
  std::filesystem::current_path(elsewhere);  // red.png is in the current folder, not beside the model
  for (const auto& [name, uri] : {std::pair{"folder_image.gltf", "folder"}, std::pair{"red_image.gltf", "red.png"}}) {
    try {
      load_gltf(dir / name);
      ADD_FAILURE() << name << " accepted";
    } catch (const ParseError& e) {
      EXPECT_NE(std::string(e.what()).find((dir / name).string()), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(std::string("'") + uri + "') is missing"), std::string::npos) << e.what();
    } catch (const std::exception& e) {
      ADD_FAILURE() << name << ": " << e.what();
    }
  }
  std::filesystem::current_path(cwd);
  std::filesystem::copy_file(elsewhere / "red.png", dir / "red.png");
  const GltfModel m = load_gltf(dir / "red_image.gltf");
  ASSERT_EQ(m.images.size(), 1u);
  ASSERT_EQ(m.images[0].width, 2);
  EXPECT_EQ(m.images[0].rgba[0], 255) << "red";
  EXPECT_EQ(m.images[0].rgba[1], 0);
}

/// An image no material uses loads nothing when it is missing, but says so: a warning names the
/// model and the image, and the model loads. An image that does load gives no warning.
TEST(GltfImages, AnUnusedImageThatCannotLoadIsAWarning) {
  const auto dir = test_dir("artrace_gltf_unused_image");
  std::vector<uint8_t> png;
  cv::imencode(".png", cv::Mat(2, 2, CV_8UC3, cv::Scalar(0, 0, 255)), png);
  std::ofstream(dir / "red.png", std::ios::binary).write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
  QuadGltf q = QuadGltf::at(-1, 1, -1, 1, 2);
  q.images = {{{"uri", "red.png"}}, {{"uri", "absent.png"}}};
  q.write(dir / "unused.gltf");
  const GltfModel m = load_gltf(dir / "unused.gltf");
  ASSERT_EQ(m.images.size(), 2u);
  EXPECT_EQ(m.images[0].width, 2);
  EXPECT_TRUE(m.images[1].rgba.empty());
  ASSERT_EQ(m.warnings.size(), 1u);
  EXPECT_NE(m.warnings[0].find((dir / "unused.gltf").string() + ": image 1 ('absent.png') is missing or cannot be decoded"), std::string::npos)
      << m.warnings[0];
}

/// Every model of the shared data loads; the textured ones, rendered head-on over a grey wall,
/// show their texture's colours: each covered pixel is within a few levels of a colour of the
/// texture (as shaded: ambient 1, Lambert), and the rendered colours span the texture's.
TEST(GltfReal, EveryModelLoadsAndTexturedOnesRenderInTheirTexturesColours) {
  ARTRACE_REQUIRE_SHARED("models");
  int models = 0;
  for (const auto& e : std::filesystem::recursive_directory_iterator(shared_path)) {
    const std::string ext = e.path().extension().string();
    if (ext != ".gltf" && ext != ".glb") continue;
    ++models;
    EXPECT_NO_THROW(load_gltf(e.path())) << e.path();
  }
  EXPECT_GE(models, 22);
  const auto dir = test_dir("artrace_real_textures");  // kept: the renders are worth a look
  for (const char* rel : {"BoxTextured/glTF-Binary/BoxTextured.glb", "BoxTextured/glTF/BoxTextured.gltf", "CesiumMilkTruck/CesiumMilkTruck.glb",
                          "CesiumMan/Cesium_Man.glb"}) {
    const auto src = shared_path / rel;
    const GltfModel model = load_gltf(src);
    ASSERT_FALSE(model.images.empty()) << rel;
    // the colours the model can show (ambient 1, Lambert): each material's base colour factor times
    // its texture's texels (or the factor alone), in sRGB quantised to 32 levels a channel
    std::set<int> palette;
    auto add = [&](const glm::vec3& linear) {
      palette.insert((core::linear_to_srgb8(linear.r) / 8) * 1024 + (core::linear_to_srgb8(linear.g) / 8) * 32 + core::linear_to_srgb8(linear.b) / 8);
    };
    for (const GltfMaterial& g : model.materials) {
      if (!g.base_color_texture.valid()) {
        add(g.base_color);
        continue;
      }
      const GltfImage& img = model.images[static_cast<size_t>(g.base_color_texture.image)];
      for (size_t i = 0; i < img.rgba.size(); i += 4) {
        add(g.base_color * glm::vec3(core::srgb8_to_linear(img.rgba[i]), core::srgb8_to_linear(img.rgba[i + 1]), core::srgb8_to_linear(img.rgba[i + 2])));
      }
    }
    // the model scaled into view: its bounds (through the node transforms) 4 m across, 4 m ahead (f = 32
    // px: about 40 pixels across)
    core::Aabb box;
    const std::vector<glm::mat4> nodes = model.node_transforms(-1, 0.0f);
    for (size_t n = 0; n < model.nodes.size(); ++n) {
      if (model.nodes[n].mesh < 0) continue;
      const bool skinned = model.nodes[n].skin >= 0;  // skinned meshes: their joints place them
      const std::vector<glm::vec3> p = skinned ? model.skinned_positions(model.nodes[n].mesh, model.nodes[n].skin, nodes)
                                               : model.meshes[static_cast<size_t>(model.nodes[n].mesh)].positions;
      for (const glm::vec3& v : p) box.extend(skinned ? v : glm::vec3(nodes[n] * glm::vec4(v, 1.0f)));
    }
    const float size = std::max({box.extent().x, box.extent().y, box.extent().z});
    // rotation 180 about x turns the model's +y up (camera y is down); the centre follows
    const glm::vec3 mid = 0.5f * (box.lo + box.hi) * (4.0f / size);
    const glm::vec3 c(mid.x, -mid.y, -mid.z);
    const auto scene = dir / "scene.json";
    std::ofstream(scene) << R"({ "models": [ { "file": ")" << src.string() << R"(", "position": [)" << -c.x << "," << -c.y << "," << 4.0f - c.z
                         << R"(], "rotation_deg": [180, 0, 0], "scale": )" << 4.0f / size << R"(, "material": { "kind": "diffuse" } } ],
                              "lights": [ { "position": [0, 0, -100], "color": [0, 0, 0] } ], "ambient": 1.0 })";
    const ArSceneFile file = load_ar_scene(scene);
    ArRuntime rt(file);
    ar::CompositeOptions opt;
    opt.lights = rt.lights();
    opt.ambient = 1.0f;
    opt.occlusion = false;
    opt.shadows = false;
    const ar::SensorFrame frame = wall(20.0f);
    const ar::ColorImage out = ar::composite(frame, rt.scene(), [&](const ar::SurfaceQuery& q) { return rt.material(q); }, opt);
    cv::Mat shot(kH, kW, CV_8UC3);
    for (int i = 0; i < kW * kH; ++i) shot.at<cv::Vec3b>(i / kW, i % kW) = cv::Vec3b(out.rgb[3 * i + 2], out.rgb[3 * i + 1], out.rgb[3 * i]);
    cv::imwrite((dir / (std::filesystem::path(rel).stem().string() + ".png")).string(), shot);  // to look at
    int covered = 0, matching = 0;
    std::set<int> seen;
    for (int y = 0; y < kH; ++y) {
      for (int x = 0; x < kW; ++x) {
        const uint8_t* o = out.at(x, y);
        if (o[0] == 100 && o[1] == 100 && o[2] == 100) continue;  // the wall
        ++covered;
        const int key = (o[0] / 8) * 1024 + (o[1] / 8) * 32 + o[2] / 8;
        seen.insert(key);
        // within one level of 8 in each channel of a texture colour (filtering blends neighbours)
        bool near = false;
        for (int dr = -1; dr <= 1 && !near; ++dr)
          for (int dg = -1; dg <= 1 && !near; ++dg)
            for (int db = -1; db <= 1 && !near; ++db) near = palette.count(key + dr * 1024 + dg * 32 + db) > 0;
        matching += near;
      }
    }
    EXPECT_GT(covered, 150) << rel;
    EXPECT_GE(matching, covered * 9 / 10) << rel << ": covered pixels in the texture's colours";
    EXPECT_GE(seen.size(), 8u) << rel << ": the texture's colours, not one flat colour";
  }
}

}  // namespace
}  // namespace artrace::io
