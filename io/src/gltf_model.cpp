#include "artrace/io/gltf_model.h"
#include "artrace/io/parse_error.h"

#include <tiny_gltf.h>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/type_ptr.hpp>

#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <sstream>

namespace artrace::io {
namespace {

/// Reads accessor `index` as `comps` floats per element (normalised integers converted).
std::vector<float> read_floats(const tinygltf::Model& m, int index, int comps, const std::string& file) {
  if (index < 0 || index >= static_cast<int>(m.accessors.size())) throw ParseError(file, 0, 0, "accessor " + std::to_string(index) + " does not exist");
  const tinygltf::Accessor& a = m.accessors[index];
  if (a.bufferView < 0) return std::vector<float>(a.count * comps, 0.0f);  // sparse-only: zeros
  const tinygltf::BufferView& v = m.bufferViews.at(a.bufferView);
  const tinygltf::Buffer& b = m.buffers.at(v.buffer);
  const int n = tinygltf::GetNumComponentsInType(a.type);
  if (n != comps) throw ParseError(file, 0, 0, "accessor " + std::to_string(index) + " has " + std::to_string(n) + " components, expected " + std::to_string(comps));
  const int csize = tinygltf::GetComponentSizeInBytes(a.componentType);
  const size_t stride = v.byteStride ? v.byteStride : static_cast<size_t>(csize) * n;
  const size_t start = v.byteOffset + a.byteOffset;
  if (a.count > 0 && start + stride * (a.count - 1) + static_cast<size_t>(csize) * n > b.data.size()) {
    throw ParseError(file, 0, 0, "accessor " + std::to_string(index) + " runs past the end of its buffer");
  }
  std::vector<float> out(a.count * n);
  for (size_t i = 0; i < a.count; ++i) {
    const unsigned char* p = b.data.data() + start + i * stride;
    for (int c = 0; c < n; ++c) {
      const unsigned char* q = p + c * csize;
      float f = 0.0f;
      switch (a.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT:
          std::memcpy(&f, q, 4);
          if (!std::isfinite(f)) {
            throw ParseError(file, 0, 0, "accessor " + std::to_string(index) + " holds a non-finite float (element " + std::to_string(i) + ")");
          }
          break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: f = *q / (a.normalized ? 255.0f : 1.0f); break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { uint16_t s; std::memcpy(&s, q, 2); f = s / (a.normalized ? 65535.0f : 1.0f); break; }
        case TINYGLTF_COMPONENT_TYPE_SHORT: { int16_t s; std::memcpy(&s, q, 2); f = a.normalized ? std::fmax(s / 32767.0f, -1.0f) : s; break; }
        case TINYGLTF_COMPONENT_TYPE_BYTE: { int8_t s; std::memcpy(&s, q, 1); f = a.normalized ? std::fmax(s / 127.0f, -1.0f) : s; break; }
        default: throw ParseError(file, 0, 0, "accessor " + std::to_string(index) + ": unsupported component type");
      }
      out[i * n + c] = f;
    }
  }
  return out;
}

/// A number of the glTF JSON as a float; one beyond the float range (or not finite) is an error.
float to_float(double v, const std::string& file, const std::string& what) {
  if (!(std::fabs(v) <= static_cast<double>(std::numeric_limits<float>::max()))) {
    std::ostringstream m;
    m << what << " is " << v << ", beyond the float range";
    throw ParseError(file, 0, 0, m.str());
  }
  return static_cast<float>(v);
}

/// `values` (3 or 4 of them, as the glTF JSON holds them) as floats, each checked by to_float.
template <class Vec>
Vec to_floats(const std::vector<double>& values, const std::string& file, const std::string& what) {
  Vec out;
  for (int k = 0; k < Vec::length(); ++k) out[k] = to_float(values[static_cast<size_t>(k)], file, what);
  return out;
}

std::vector<uint32_t> read_indices(const tinygltf::Model& m, int index, const std::string& file) {
  const tinygltf::Accessor& a = m.accessors.at(index);
  const tinygltf::BufferView& v = m.bufferViews.at(a.bufferView);
  const tinygltf::Buffer& b = m.buffers.at(v.buffer);
  const int csize = tinygltf::GetComponentSizeInBytes(a.componentType);
  const size_t stride = v.byteStride ? v.byteStride : csize;
  const size_t start = v.byteOffset + a.byteOffset;
  if (a.count > 0 && start + stride * (a.count - 1) + csize > b.data.size()) throw ParseError(file, 0, 0, "index accessor runs past its buffer");
  std::vector<uint32_t> out(a.count);
  for (size_t i = 0; i < a.count; ++i) {
    const unsigned char* p = b.data.data() + start + i * stride;
    if (csize == 1) out[i] = *p;
    else if (csize == 2) { uint16_t s; std::memcpy(&s, p, 2); out[i] = s; }
    else { std::memcpy(&out[i], p, 4); }
  }
  return out;
}

}  // namespace

GltfModel load_gltf(const std::filesystem::path& path) {
  tinygltf::TinyGLTF loader;
  tinygltf::Model m;
  std::string err, warn;
  const std::string file = path.string();
  if (!std::filesystem::exists(path)) throw ParseError(file, 0, 0, "no such file");
  const bool ok = path.extension() == ".glb" ? loader.LoadBinaryFromFile(&m, &err, &warn, file)
                                             : loader.LoadASCIIFromFile(&m, &err, &warn, file);
  if (!ok) throw ParseError(file, 0, 0, "not a readable glTF 2.0 file: " + (err.empty() ? warn : err));
  GltfModel out;
  out.file = path;
  out.materials.emplace_back();  // default
  for (const tinygltf::Material& mat : m.materials) {
    GltfMaterial g;
    g.name = mat.name;
    const auto& pbr = mat.pbrMetallicRoughness;
    const std::string at = "material '" + mat.name + "'";
    if (pbr.baseColorFactor.size() == 4) g.base_color = to_floats<glm::vec3>(pbr.baseColorFactor, file, at + " baseColorFactor");
    g.metallic = to_float(pbr.metallicFactor, file, at + " metallicFactor");
    g.roughness = to_float(pbr.roughnessFactor, file, at + " roughnessFactor");
    if (mat.alphaMode == "BLEND" && pbr.baseColorFactor.size() == 4) g.transmission = 1.0f - to_float(pbr.baseColorFactor[3], file, at + " alpha");
    const auto t = mat.extensions.find("KHR_materials_transmission");
    if (t != mat.extensions.end() && t->second.Has("transmissionFactor")) {
      g.transmission = to_float(t->second.Get("transmissionFactor").GetNumberAsDouble(), file, at + " transmissionFactor");
    }
    const auto i = mat.extensions.find("KHR_materials_ior");
    if (i != mat.extensions.end() && i->second.Has("ior")) g.ior = to_float(i->second.Get("ior").GetNumberAsDouble(), file, at + " ior");
    out.materials.push_back(g);
  }
  for (const tinygltf::Mesh& mesh : m.meshes) {
    GltfMesh gm;
    bool any_skinned = false, any_plain = false;
    for (const tinygltf::Primitive& prim : mesh.primitives) {
      if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != -1) continue;  // points and lines are not rendered
      const auto pos_it = prim.attributes.find("POSITION");
      if (pos_it == prim.attributes.end()) throw ParseError(file, 0, 0, "mesh '" + mesh.name + "' has a primitive without POSITION");
      const std::vector<float> pos = read_floats(m, pos_it->second, 3, file);
      const size_t nv = pos.size() / 3;
      std::vector<uint32_t> idx;
      if (prim.indices >= 0) idx = read_indices(m, prim.indices, file);
      else for (uint32_t k = 0; k < nv; ++k) idx.push_back(k);
      if (idx.size() % 3) throw ParseError(file, 0, 0, "mesh '" + mesh.name + "': index count is not a multiple of 3");
      const uint32_t material = prim.material >= 0 ? static_cast<uint32_t>(prim.material + 1) : 0u;
      if (material >= out.materials.size()) throw ParseError(file, 0, 0, "mesh '" + mesh.name + "' names material " + std::to_string(prim.material) + ", which does not exist");
      const uint32_t base = static_cast<uint32_t>(gm.positions.size());
      for (size_t k = 0; k < nv; ++k) gm.positions.emplace_back(pos[3 * k], pos[3 * k + 1], pos[3 * k + 2]);
      const auto j_it = prim.attributes.find("JOINTS_0"), w_it = prim.attributes.find("WEIGHTS_0");
      if ((j_it == prim.attributes.end()) != (w_it == prim.attributes.end())) {
        throw ParseError(file, 0, 0, "mesh '" + mesh.name + "' has JOINTS_0 without WEIGHTS_0 or the reverse");
      }
      if (j_it != prim.attributes.end()) {
        any_skinned = true;
        const std::vector<float> j = read_floats(m, j_it->second, 4, file), w = read_floats(m, w_it->second, 4, file);
        if (j.size() != 4 * nv || w.size() != 4 * nv) throw ParseError(file, 0, 0, "mesh '" + mesh.name + "': JOINTS_0/WEIGHTS_0 count differs from POSITION");
        gm.joints.resize(gm.positions.size() - nv);
        gm.weights.resize(gm.positions.size() - nv);
        for (size_t k = 0; k < nv; ++k) {
          gm.joints.emplace_back(j[4 * k], j[4 * k + 1], j[4 * k + 2], j[4 * k + 3]);
          gm.weights.emplace_back(w[4 * k], w[4 * k + 1], w[4 * k + 2], w[4 * k + 3]);
        }
      } else {
        any_plain = true;
      }
      for (size_t k = 0; k < idx.size(); k += 3) {
        for (int c = 0; c < 3; ++c) {
          if (idx[k + c] >= nv) throw ParseError(file, 0, 0, "mesh '" + mesh.name + "': index " + std::to_string(idx[k + c]) + " past its " + std::to_string(nv) + " vertices");
        }
        auto v = [&](uint32_t i) { return glm::vec3(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]); };
        gm.tris.push_back({v(idx[k]), v(idx[k + 1]), v(idx[k + 2])});
        gm.indices.emplace_back(base + idx[k], base + idx[k + 1], base + idx[k + 2]);
        gm.material.push_back(material);
      }
    }
    if (any_skinned && any_plain) throw ParseError(file, 0, 0, "mesh '" + mesh.name + "' mixes skinned and unskinned primitives");
    out.meshes.push_back(std::move(gm));
  }
  // nodes: order parents before children (glTF does not promise it)
  std::vector<int> parent(m.nodes.size(), -1);
  for (size_t i = 0; i < m.nodes.size(); ++i) {
    for (const int c : m.nodes[i].children) {
      if (c < 0 || c >= static_cast<int>(m.nodes.size()) || parent[c] != -1) throw ParseError(file, 0, 0, "node " + std::to_string(c) + " has two parents or does not exist");
      parent[c] = static_cast<int>(i);
    }
  }
  std::vector<int> order, new_index(m.nodes.size(), -1);
  std::function<void(int)> visit = [&](int n) {
    if (order.size() > m.nodes.size()) throw ParseError(file, 0, 0, "the node hierarchy has a cycle");
    new_index[n] = static_cast<int>(order.size());
    order.push_back(n);
    for (const int c : m.nodes[n].children) visit(c);
  };
  for (size_t i = 0; i < m.nodes.size(); ++i) {
    if (parent[i] == -1) visit(static_cast<int>(i));
  }
  if (order.size() != m.nodes.size()) throw ParseError(file, 0, 0, "the node hierarchy has a cycle");
  for (const int n : order) {
    const tinygltf::Node& src = m.nodes[n];
    GltfNode g;
    g.name = src.name;
    g.parent = parent[n] >= 0 ? new_index[parent[n]] : -1;
    g.mesh = src.mesh;
    if (g.mesh >= static_cast<int>(out.meshes.size())) throw ParseError(file, 0, 0, "node '" + src.name + "' names a mesh that does not exist");
    g.skin = src.skin;
    if (g.skin >= static_cast<int>(m.skins.size())) throw ParseError(file, 0, 0, "node '" + src.name + "' names a skin that does not exist");
    if (g.skin >= 0 && (g.mesh < 0 || !out.meshes[g.mesh].skinned())) throw ParseError(file, 0, 0, "node '" + src.name + "' has a skin but no mesh with JOINTS_0/WEIGHTS_0");
    if (src.matrix.size() == 16) {
      g.has_matrix = true;
      for (int k = 0; k < 16; ++k) glm::value_ptr(g.matrix)[k] = to_float(src.matrix[k], file, "node '" + src.name + "' matrix");
    }
    if (src.translation.size() == 3) g.translation = to_floats<glm::vec3>(src.translation, file, "node '" + src.name + "' translation");
    if (src.rotation.size() == 4) {
      const glm::vec4 q = to_floats<glm::vec4>(src.rotation, file, "node '" + src.name + "' rotation");
      g.rotation = glm::quat(q.w, q.x, q.y, q.z);
    }
    if (src.scale.size() == 3) g.scale = to_floats<glm::vec3>(src.scale, file, "node '" + src.name + "' scale");
    out.nodes.push_back(g);
  }
  for (const tinygltf::Skin& sk : m.skins) {
    GltfSkin gs;
    gs.name = sk.name;
    for (const int j : sk.joints) {
      if (j < 0 || j >= static_cast<int>(m.nodes.size())) throw ParseError(file, 0, 0, "skin '" + sk.name + "' names joint node " + std::to_string(j) + ", which does not exist");
      gs.joints.push_back(new_index[j]);
    }
    if (sk.inverseBindMatrices >= 0) {
      const std::vector<float> ib = read_floats(m, sk.inverseBindMatrices, 16, file);
      if (ib.size() != 16 * gs.joints.size()) throw ParseError(file, 0, 0, "skin '" + sk.name + "': inverseBindMatrices count differs from its joints");
      for (size_t k = 0; k < gs.joints.size(); ++k) gs.inverse_bind.push_back(glm::make_mat4(&ib[16 * k]));
    } else {
      gs.inverse_bind.assign(gs.joints.size(), glm::mat4(1.0f));
    }
    out.skins.push_back(std::move(gs));
  }
  for (const GltfNode& n : out.nodes) {
    if (n.skin < 0) continue;
    const size_t joints = out.skins[n.skin].joints.size();
    for (const glm::uvec4& j : out.meshes[n.mesh].joints) {
      if (j.x >= joints || j.y >= joints || j.z >= joints || j.w >= joints) {
        throw ParseError(file, 0, 0, "node '" + n.name + "': a vertex names joint " + std::to_string(std::max({j.x, j.y, j.z, j.w})) + " of a skin with " + std::to_string(joints));
      }
    }
  }
  for (const tinygltf::Animation& a : m.animations) {
    GltfAnimation ga;
    ga.name = a.name;
    for (const tinygltf::AnimationChannel& ch : a.channels) {
      if (ch.target_node < 0 || ch.target_node >= static_cast<int>(m.nodes.size())) throw ParseError(file, 0, 0, "animation '" + a.name + "' targets a node that does not exist");
      if (ch.target_path == "weights") continue;  // morph targets are not supported
      const tinygltf::AnimationSampler& s = a.samplers.at(ch.sampler);
      GltfChannel c;
      c.node = new_index[ch.target_node];
      c.path = ch.target_path == "translation" ? GltfChannel::kTranslation : ch.target_path == "rotation" ? GltfChannel::kRotation : GltfChannel::kScale;
      if (ch.target_path != "translation" && ch.target_path != "rotation" && ch.target_path != "scale") throw ParseError(file, 0, 0, "animation '" + a.name + "': unknown target path '" + ch.target_path + "'");
      c.interpolation = s.interpolation == "STEP" ? GltfChannel::kStep : s.interpolation == "CUBICSPLINE" ? GltfChannel::kCubic : GltfChannel::kLinear;
      c.times = read_floats(m, s.input, 1, file);
      const int comps = c.path == GltfChannel::kRotation ? 4 : 3;
      const std::vector<float> v = read_floats(m, s.output, comps, file);
      for (size_t k = 0; k + comps <= v.size(); k += comps) c.values.push_back(glm::vec4(v[k], v[k + 1], v[k + 2], comps == 4 ? v[k + 3] : 0.0f));
      const size_t per_key = c.interpolation == GltfChannel::kCubic ? 3 : 1;
      if (c.times.empty() || c.values.size() != c.times.size() * per_key) throw ParseError(file, 0, 0, "animation '" + a.name + "': sampler input and output counts do not match");
      for (size_t k = 1; k < c.times.size(); ++k) {
        if (!(c.times[k] > c.times[k - 1])) throw ParseError(file, 0, 0, "animation '" + a.name + "': key times must increase");
      }
      ga.duration_s = std::max(ga.duration_s, c.times.back());
      ga.channels.push_back(std::move(c));
    }
    out.animations.push_back(std::move(ga));
  }
  return out;
}

namespace {

glm::vec4 sample(const GltfChannel& c, float t) {
  const auto& k = c.times;
  const bool cubic = c.interpolation == GltfChannel::kCubic;
  auto value = [&](size_t i) { return cubic ? c.values[3 * i + 1] : c.values[i]; };
  if (t <= k.front()) return value(0);
  if (t >= k.back()) return value(k.size() - 1);
  const size_t i = static_cast<size_t>(std::upper_bound(k.begin(), k.end(), t) - k.begin()) - 1;
  const float dt = k[i + 1] - k[i], s = (t - k[i]) / dt;
  if (c.interpolation == GltfChannel::kStep) return value(i);
  if (cubic) {
    // glTF 2.0 spec, appendix C: Hermite with tangents scaled by the key interval
    const glm::vec4 p0 = c.values[3 * i + 1], m0 = dt * c.values[3 * i + 2];
    const glm::vec4 p1 = c.values[3 * (i + 1) + 1], m1 = dt * c.values[3 * (i + 1)];
    const float s2 = s * s, s3 = s2 * s;
    glm::vec4 r = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0 + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * m1;
    if (c.path == GltfChannel::kRotation) r = glm::normalize(r);
    return r;
  }
  if (c.path == GltfChannel::kRotation) {
    const glm::quat a(c.values[i].w, c.values[i].x, c.values[i].y, c.values[i].z);
    const glm::quat b(c.values[i + 1].w, c.values[i + 1].x, c.values[i + 1].y, c.values[i + 1].z);
    const glm::quat q = glm::slerp(a, b, s);
    return glm::vec4(q.x, q.y, q.z, q.w);
  }
  return glm::mix(c.values[i], c.values[i + 1], s);
}

}  // namespace

std::vector<glm::mat4> GltfModel::node_transforms(int clip, float t) const {
  std::vector<glm::vec3> tr(nodes.size()), sc(nodes.size());
  std::vector<glm::quat> rot(nodes.size());
  for (size_t i = 0; i < nodes.size(); ++i) {
    tr[i] = nodes[i].translation;
    rot[i] = nodes[i].rotation;
    sc[i] = nodes[i].scale;
  }
  if (clip >= 0 && clip < static_cast<int>(animations.size())) {
    const GltfAnimation& a = animations[clip];
    const float local = a.duration_s > 0.0f ? std::fmod(std::fmax(t, 0.0f), a.duration_s) : 0.0f;
    for (const GltfChannel& c : a.channels) {
      const glm::vec4 v = sample(c, local);
      if (c.path == GltfChannel::kTranslation) tr[c.node] = glm::vec3(v);
      else if (c.path == GltfChannel::kScale) sc[c.node] = glm::vec3(v);
      else rot[c.node] = glm::normalize(glm::quat(v.w, v.x, v.y, v.z));
    }
  }
  std::vector<glm::mat4> world(nodes.size());
  for (size_t i = 0; i < nodes.size(); ++i) {
    const glm::mat4 local = nodes[i].has_matrix ? nodes[i].matrix
                                                : glm::translate(glm::mat4(1.0f), tr[i]) * glm::mat4_cast(rot[i]) * glm::scale(glm::mat4(1.0f), sc[i]);
    world[i] = nodes[i].parent >= 0 ? world[nodes[i].parent] * local : local;
  }
  return world;
}

std::vector<glm::vec3> GltfModel::skinned_positions(int mesh, int skin, const std::vector<glm::mat4>& node_world) const {
  const GltfMesh& m = meshes.at(static_cast<size_t>(mesh));
  const GltfSkin& s = skins.at(static_cast<size_t>(skin));
  std::vector<glm::mat4> joint(s.joints.size());
  for (size_t j = 0; j < joint.size(); ++j) joint[j] = node_world.at(static_cast<size_t>(s.joints[j])) * s.inverse_bind[j];
  std::vector<glm::vec3> out(m.positions.size());
  for (size_t v = 0; v < out.size(); ++v) {
    const glm::vec4 w = m.weights[v];
    const float sum = w.x + w.y + w.z + w.w;
    if (!(sum > 0.0f)) {
      out[v] = m.positions[v];  // no weights: the bind pose
      continue;
    }
    const glm::mat4 blend = (w.x * joint[m.joints[v].x] + w.y * joint[m.joints[v].y] + w.z * joint[m.joints[v].z] +
                             w.w * joint[m.joints[v].w]) / sum;
    out[v] = glm::vec3(blend * glm::vec4(m.positions[v], 1.0f));
  }
  return out;
}

size_t GltfModel::triangle_count() const {
  size_t n = 0;
  for (const GltfMesh& m : meshes) n += m.tris.size();
  return n;
}

}  // namespace artrace::io
