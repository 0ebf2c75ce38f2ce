#include "artrace/io/gltf_model.h"
#include "artrace/io/atomic_file.h"
#include "artrace/io/file_name.h"

#include <tiny_gltf.h>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/type_ptr.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>
#include <stdexcept>

namespace artrace::io {
namespace {

/// Appends raw bytes to buffer 0 and returns an accessor over them.
int add_accessor(tinygltf::Model& m, const void* data, size_t bytes, size_t count, int type, int ctype,
                 std::vector<double> min = {}, std::vector<double> max = {}) {
  tinygltf::Buffer& b = m.buffers[0];
  while (b.data.size() % 4) b.data.push_back(0);
  tinygltf::BufferView v;
  v.buffer = 0;
  v.byteOffset = b.data.size();
  v.byteLength = bytes;
  b.data.insert(b.data.end(), static_cast<const unsigned char*>(data), static_cast<const unsigned char*>(data) + bytes);
  m.bufferViews.push_back(v);
  tinygltf::Accessor a;
  a.bufferView = static_cast<int>(m.bufferViews.size() - 1);
  a.count = count;
  a.type = type;
  a.componentType = ctype;
  a.minValues = std::move(min);
  a.maxValues = std::move(max);
  m.accessors.push_back(a);
  return static_cast<int>(m.accessors.size() - 1);
}

/// A rotation channel about `axis` through the given angles, one key a second.
GltfChannel rotation_keys(int node, const glm::vec3& axis, const std::vector<float>& degrees) {
  GltfChannel c;
  c.node = node;
  c.path = GltfChannel::kRotation;
  for (size_t k = 0; k < degrees.size(); ++k) {
    c.times.push_back(static_cast<float>(k));
    const glm::quat q = glm::angleAxis(glm::radians(degrees[k]), axis);
    c.values.push_back(glm::vec4(q.x, q.y, q.z, q.w));
  }
  return c;
}

}  // namespace

void write_gltf(const GltfModel& model, const std::filesystem::path& path) {
  tinygltf::Model m;
  m.asset.version = "2.0";
  m.asset.generator = "artrace";
  m.buffers.emplace_back();
  for (size_t i = 1; i < model.materials.size(); ++i) {
    const GltfMaterial& g = model.materials[i];
    tinygltf::Material mat;
    mat.name = g.name;
    mat.pbrMetallicRoughness.baseColorFactor = {g.base_color.r, g.base_color.g, g.base_color.b, 1.0};
    mat.pbrMetallicRoughness.metallicFactor = g.metallic;
    mat.pbrMetallicRoughness.roughnessFactor = g.roughness;
    if (g.transmission > 0.0f) {
      tinygltf::Value::Object t;
      t["transmissionFactor"] = tinygltf::Value(static_cast<double>(g.transmission));
      mat.extensions["KHR_materials_transmission"] = tinygltf::Value(t);
      tinygltf::Value::Object ior;
      ior["ior"] = tinygltf::Value(static_cast<double>(g.ior));
      mat.extensions["KHR_materials_ior"] = tinygltf::Value(ior);
      m.extensionsUsed = {"KHR_materials_transmission", "KHR_materials_ior"};
    }
    m.materials.push_back(mat);
  }
  for (const GltfMesh& gm : model.meshes) {
    tinygltf::Mesh mesh;
    // one primitive per material, vertices unshared: flat facets, or the mesh's vertex normals
    // (indexed as its positions) on every corner
    const bool normals = !gm.normals.empty();
    if (normals && gm.indices.size() != gm.tris.size())
      throw std::invalid_argument("write_gltf: a mesh with normals needs an index triple per triangle");
    for (size_t mat = 0; mat < model.materials.size(); ++mat) {
      std::vector<float> pos, nrm, weights;
      std::vector<uint16_t> joints;
      glm::vec3 lo(INFINITY), hi(-INFINITY);
      for (size_t t = 0; t < gm.tris.size(); ++t) {
        if (gm.material[t] != mat) continue;
        for (int c = 0; c < 3; ++c) {
          const glm::vec3 v = c == 0 ? gm.tris[t].v0 : c == 1 ? gm.tris[t].v1 : gm.tris[t].v2;
          pos.insert(pos.end(), {v.x, v.y, v.z});
          lo = glm::min(lo, v);
          hi = glm::max(hi, v);
          if (normals) {
            const glm::vec3 n = gm.normals.at(gm.indices[t][c]);
            nrm.insert(nrm.end(), {n.x, n.y, n.z});
          }
          if (gm.skinned()) {
            const uint32_t i = gm.indices[t][c];
            // the first influence set (the project's models have one)
            const size_t sets = static_cast<size_t>(gm.influence_sets);
            for (int k = 0; k < 4; ++k) {
              joints.push_back(static_cast<uint16_t>(gm.joints[i * sets][k]));
              weights.push_back(gm.weights[i * sets][k]);
            }
          }
        }
      }
      if (pos.empty()) continue;
      tinygltf::Primitive p;
      p.mode = TINYGLTF_MODE_TRIANGLES;
      p.attributes["POSITION"] = add_accessor(m, pos.data(), pos.size() * 4, pos.size() / 3, TINYGLTF_TYPE_VEC3,
                                              TINYGLTF_COMPONENT_TYPE_FLOAT, {lo.x, lo.y, lo.z}, {hi.x, hi.y, hi.z});
      if (normals) {
        p.attributes["NORMAL"] = add_accessor(m, nrm.data(), nrm.size() * 4, nrm.size() / 3, TINYGLTF_TYPE_VEC3,
                                              TINYGLTF_COMPONENT_TYPE_FLOAT);
      }
      if (gm.skinned()) {
        p.attributes["JOINTS_0"] = add_accessor(m, joints.data(), joints.size() * 2, joints.size() / 4, TINYGLTF_TYPE_VEC4,
                                                TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT);
        p.attributes["WEIGHTS_0"] = add_accessor(m, weights.data(), weights.size() * 4, weights.size() / 4, TINYGLTF_TYPE_VEC4,
                                                 TINYGLTF_COMPONENT_TYPE_FLOAT);
      }
      p.material = mat == 0 ? -1 : static_cast<int>(mat - 1);
      mesh.primitives.push_back(p);
    }
    m.meshes.push_back(mesh);
  }
  for (size_t i = 0; i < model.nodes.size(); ++i) {
    const GltfNode& g = model.nodes[i];
    tinygltf::Node n;
    n.name = g.name;
    n.mesh = g.mesh;
    n.skin = g.skin;
    n.translation = {g.translation.x, g.translation.y, g.translation.z};
    n.rotation = {g.rotation.x, g.rotation.y, g.rotation.z, g.rotation.w};
    n.scale = {g.scale.x, g.scale.y, g.scale.z};
    m.nodes.push_back(n);
    if (g.parent >= 0) m.nodes[g.parent].children.push_back(static_cast<int>(i));
  }
  for (const GltfSkin& gs : model.skins) {
    tinygltf::Skin sk;
    sk.name = gs.name;
    sk.joints = gs.joints;
    std::vector<float> ib;
    for (const glm::mat4& mtx : gs.inverse_bind) ib.insert(ib.end(), glm::value_ptr(mtx), glm::value_ptr(mtx) + 16);
    sk.inverseBindMatrices = add_accessor(m, ib.data(), ib.size() * 4, gs.inverse_bind.size(), TINYGLTF_TYPE_MAT4,
                                          TINYGLTF_COMPONENT_TYPE_FLOAT);
    m.skins.push_back(sk);
  }
  tinygltf::Scene scene;
  for (size_t i = 0; i < model.nodes.size(); ++i) {
    if (model.nodes[i].parent < 0) scene.nodes.push_back(static_cast<int>(i));
  }
  m.scenes.push_back(scene);
  m.defaultScene = 0;
  for (const GltfAnimation& ga : model.animations) {
    tinygltf::Animation a;
    a.name = ga.name;
    for (const GltfChannel& c : ga.channels) {
      tinygltf::AnimationSampler s;
      s.input = add_accessor(m, c.times.data(), c.times.size() * 4, c.times.size(), TINYGLTF_TYPE_SCALAR,
                             TINYGLTF_COMPONENT_TYPE_FLOAT, {c.times.front()}, {c.times.back()});
      const int comps = c.path == GltfChannel::kRotation ? 4 : 3;
      std::vector<float> v;
      for (const glm::vec4& x : c.values) for (int k = 0; k < comps; ++k) v.push_back(x[k]);
      s.output = add_accessor(m, v.data(), v.size() * 4, c.values.size(), comps == 4 ? TINYGLTF_TYPE_VEC4 : TINYGLTF_TYPE_VEC3,
                              TINYGLTF_COMPONENT_TYPE_FLOAT);
      s.interpolation = c.interpolation == GltfChannel::kStep ? "STEP" : c.interpolation == GltfChannel::kCubic ? "CUBICSPLINE" : "LINEAR";
      a.samplers.push_back(s);
      tinygltf::AnimationChannel ch;
      ch.sampler = static_cast<int>(a.samplers.size() - 1);
      ch.target_node = c.node;
      ch.target_path = c.path == GltfChannel::kTranslation ? "translation" : c.path == GltfChannel::kRotation ? "rotation" : "scale";
      a.channels.push_back(ch);
    }
    m.animations.push_back(a);
  }
  // serialised in memory (the buffer embedded), then written with every step checked: tinygltf's
  // own file writer reports success when the disk is full
  const bool binary = lower_extension(path) == ".glb";
  std::ostringstream bytes;
  tinygltf::TinyGLTF writer;
  if (!writer.WriteGltfSceneToStream(&m, bytes, /*prettyPrint=*/true, binary)) throw std::runtime_error(path.string() + ": cannot write glTF");
  write_file_atomically(path, bytes.str());
}

GltfModel make_spinning_box(float size, const glm::vec3& color) {
  GltfModel m;
  m.materials.resize(2);
  m.materials[1].name = "painted";
  m.materials[1].base_color = color;
  m.materials[1].roughness = 0.6f;
  GltfMesh mesh;
  const float h = 0.5f * size;
  const glm::vec3 lo(-h, 0.0f, -h), hi(h, size, h);
  mesh.tris = core::box_triangles(lo, hi);
  mesh.material.assign(mesh.tris.size(), 1);
  m.meshes.push_back(mesh);
  GltfNode node;
  node.name = "box";
  node.mesh = 0;
  m.nodes.push_back(node);
  GltfAnimation spin;
  spin.name = "spin";
  spin.channels.push_back(rotation_keys(0, glm::vec3(0, 1, 0), {0.0f, 90.0f, 180.0f, 270.0f, 360.0f}));
  spin.duration_s = 4.0f;
  m.animations.push_back(spin);
  return m;
}

GltfModel make_glass_sphere(float radius) {
  GltfModel m;
  m.materials.resize(2);
  m.materials[1].name = "glass";
  m.materials[1].base_color = glm::vec3(0.95f);
  m.materials[1].roughness = 0.0f;
  m.materials[1].transmission = 1.0f;
  m.materials[1].ior = 1.5f;
  // a UV sphere with the sphere's own normals at its vertices, so that its shading (and above all
  // its refraction, which magnifies any kink) is smooth rather than faceted
  GltfMesh mesh;
  constexpr int kRings = 16, kSegments = 32;
  const glm::vec3 centre(0.0f, radius, 0.0f);
  auto vertex = [&](int i, int j) {  // ring i (0: top pole), segment j (kSegments: seam, = 0)
    return static_cast<uint32_t>(i * (kSegments + 1) + j);
  };
  for (int i = 0; i <= kRings; ++i) {
    for (int j = 0; j <= kSegments; ++j) {
      const float th = 3.14159265f * i / kRings, ph = 6.2831853f * (j % kSegments) / kSegments;
      // the poles exactly on the axis (sin of the float nearest pi is not 0): a point, no hole
      const bool pole = i == 0 || i == kRings;
      const float ring = pole ? 0.0f : std::sin(th), y = i == 0 ? 1.0f : i == kRings ? -1.0f : std::cos(th);
      const glm::vec3 n(ring * std::cos(ph), y, ring * std::sin(ph));
      mesh.positions.push_back(centre + radius * n);
      mesh.normals.push_back(n);
    }
  }
  auto add = [&](uint32_t a, uint32_t b, uint32_t c) {
    mesh.indices.emplace_back(a, b, c);
    mesh.tris.push_back({mesh.positions[a], mesh.positions[b], mesh.positions[c]});
  };
  for (int i = 0; i < kRings; ++i) {
    for (int j = 0; j < kSegments; ++j) {
      // the poles' rings are points: one triangle a segment there
      if (i > 0) add(vertex(i, j), vertex(i, j + 1), vertex(i + 1, j + 1));
      if (i + 1 < kRings) add(vertex(i, j), vertex(i + 1, j + 1), vertex(i + 1, j));
    }
  }
  mesh.material.assign(mesh.tris.size(), 1);
  m.meshes.push_back(mesh);
  GltfNode node;
  node.name = "sphere";
  node.mesh = 0;
  m.nodes.push_back(node);
  return m;
}

GltfModel make_bending_tube(float length, float width, const glm::vec3& color) {
  GltfModel m;
  m.materials.resize(2);
  m.materials[1].name = "rubber";
  m.materials[1].base_color = color;
  m.materials[1].roughness = 0.7f;
  GltfMesh mesh;
  mesh.influence_sets = 1;
  constexpr int kRings = 12;
  const float h = 0.5f * width;
  const glm::vec2 corner[4] = {{-h, -h}, {h, -h}, {h, h}, {-h, h}};
  for (int r = 0; r <= kRings; ++r) {
    const float y = length * static_cast<float>(r) / kRings;
    // weight of the elbow: 0 below a third of the length, 1 above two thirds, linear between
    const float w = std::clamp((y / length - 1.0f / 3.0f) * 3.0f, 0.0f, 1.0f);
    for (const glm::vec2& c : corner) {
      mesh.positions.emplace_back(c.x, y, c.y);
      mesh.joints.emplace_back(0, 1, 0, 0);
      mesh.weights.emplace_back(1.0f - w, w, 0.0f, 0.0f);
    }
  }
  auto quad = [&](uint32_t a, uint32_t b, uint32_t c, uint32_t d) {
    mesh.indices.emplace_back(a, b, c);
    mesh.indices.emplace_back(a, c, d);
  };
  for (uint32_t r = 0; r < kRings; ++r) {
    for (uint32_t k = 0; k < 4; ++k) {
      const uint32_t a = 4 * r + k, b = 4 * r + (k + 1) % 4;
      quad(a, a + 4, b + 4, b);
    }
  }
  quad(0, 1, 2, 3);
  const uint32_t top = 4 * kRings;
  quad(top, top + 3, top + 2, top + 1);
  for (const glm::uvec3& t : mesh.indices) {
    mesh.tris.push_back({mesh.positions[t.x], mesh.positions[t.y], mesh.positions[t.z]});
    mesh.material.push_back(1);
  }
  m.meshes.push_back(mesh);
  GltfNode root, elbow, body;
  root.name = "root";
  elbow.name = "elbow";
  elbow.parent = 0;
  elbow.translation = glm::vec3(0.0f, 0.5f * length, 0.0f);
  body.name = "tube";
  body.mesh = 0;
  body.skin = 0;
  m.nodes = {root, elbow, body};
  GltfSkin skin;
  skin.name = "arm";
  skin.joints = {0, 1};
  skin.inverse_bind = {glm::mat4(1.0f), glm::translate(glm::mat4(1.0f), glm::vec3(0.0f, -0.5f * length, 0.0f))};
  m.skins.push_back(skin);
  GltfAnimation bend;
  bend.name = "bend";
  bend.channels.push_back(rotation_keys(1, glm::vec3(0, 0, 1), {0.0f, 90.0f, 0.0f}));
  bend.duration_s = 2.0f;
  m.animations.push_back(bend);
  return m;
}

}  // namespace artrace::io
