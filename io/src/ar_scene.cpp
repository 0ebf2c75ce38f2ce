#include "artrace/io/ar_scene.h"
#include "artrace/io/parse_error.h"

#include <glm/gtc/matrix_transform.hpp>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

namespace artrace::io {
namespace {

using nlohmann::json;

/// The largest magnitude an AR scene's number may have (1,000 km in metres).
constexpr double kMaxMagnitude = 1e6;

class Checker {
 public:
  explicit Checker(std::string file) : file_(std::move(file)) {}
  [[noreturn]] void fail(const std::string& key, const std::string& what) const { throw ParseError(file_, 0, 0, key + ": " + what); }
  void keys(const json& j, const std::string& where, std::set<std::string> allowed) const {
    if (!j.is_object()) fail(where.empty() ? "(top level)" : where, "expected an object");
    for (const auto& [k, v] : j.items()) {
      if (!allowed.count(k)) fail(where.empty() ? k : where + "." + k, "unknown key");
    }
  }
  glm::vec3 vec3(const json& j, const std::string& key) const {
    if (!j.is_array() || j.size() != 3 || !j[0].is_number() || !j[1].is_number() || !j[2].is_number()) fail(key, "expected 3 numbers");
    return {in_range(j[0], key), in_range(j[1], key), in_range(j[2], key)};
  }
  float number(const json& j, const std::string& key) const {
    if (!j.is_number()) fail(key, "expected a number");
    return in_range(j, key);
  }
  /// A JSON number as a float, refused beyond +-kMaxMagnitude. The keys hold metres, degrees,
  /// colours and factors, where nothing sensible comes near it, and far beyond it the renderer's
  /// float arithmetic breaks down (a light at 3e38 has an infinite squared distance and lights
  /// nothing). Checked as a double: the conversion to float overflows first (1e39).
  float in_range(const json& j, const std::string& key) const {
    const double v = j.get<double>();
    if (!(std::fabs(v) <= kMaxMagnitude)) {
      std::ostringstream what;
      what << "expected a number between " << -kMaxMagnitude << " and " << kMaxMagnitude << ", got " << v;
      fail(key, what.str());
    }
    return static_cast<float>(v);
  }
  std::string string(const json& j, const std::string& key) const {
    if (!j.is_string()) fail(key, "expected a string");
    return j.get<std::string>();
  }

 private:
  std::string file_;
};

}  // namespace

glm::mat4 ArModelPlacement::world_from_model() const {
  glm::mat4 m = glm::translate(glm::mat4(1.0f), position);
  m = glm::rotate(m, glm::radians(rotation_deg.z), glm::vec3(0, 0, 1));
  m = glm::rotate(m, glm::radians(rotation_deg.y), glm::vec3(0, 1, 0));
  m = glm::rotate(m, glm::radians(rotation_deg.x), glm::vec3(1, 0, 0));
  return glm::scale(m, scale);
}

ArSceneFile load_ar_scene(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw ParseError(path.string(), 0, 0, "cannot open file");
  json root;
  try {
    root = json::parse(in);
  } catch (const json::parse_error& e) {
    throw ParseError(path.string(), 0, 0, std::string("not valid JSON: ") + e.what());
  }
  const Checker c(path.string());
  c.keys(root, "", {"models", "lights", "ambient"});
  ArSceneFile out;
  out.file = path;
  if (root.contains("ambient")) out.ambient = c.number(root["ambient"], "ambient");
  if (root.contains("models")) {
    if (!root["models"].is_array()) c.fail("models", "expected an array");
    for (size_t i = 0; i < root["models"].size(); ++i) {
      const json& m = root["models"][i];
      const std::string at = "models[" + std::to_string(i) + "]";
      c.keys(m, at, {"file", "position", "rotation_deg", "scale", "animation", "material"});
      ArModelPlacement p;
      if (!m.contains("file")) c.fail(at + ".file", "missing");
      p.file = path.parent_path() / c.string(m["file"], at + ".file");
      if (m.contains("position")) p.position = c.vec3(m["position"], at + ".position");
      if (m.contains("rotation_deg")) p.rotation_deg = c.vec3(m["rotation_deg"], at + ".rotation_deg");
      if (m.contains("scale")) {
        p.scale = m["scale"].is_number() ? glm::vec3(c.number(m["scale"], at + ".scale")) : c.vec3(m["scale"], at + ".scale");
      }
      GltfModel model = load_gltf(p.file);
      if (m.contains("animation")) {
        const json& a = m["animation"];
        c.keys(a, at + ".animation", {"clip", "speed"});
        if (a.contains("clip")) {
          if (a["clip"].is_number_integer()) {
            p.clip = a["clip"].get<int>();
          } else {
            const std::string name = c.string(a["clip"], at + ".animation.clip");
            for (size_t k = 0; k < model.animations.size(); ++k) {
              if (model.animations[k].name == name) p.clip = static_cast<int>(k);
            }
            if (p.clip < 0) c.fail(at + ".animation.clip", "the model has no animation '" + name + "'");
          }
        } else {
          p.clip = 0;
        }
        if (p.clip >= static_cast<int>(model.animations.size())) {
          c.fail(at + ".animation.clip", "the model has " + std::to_string(model.animations.size()) + " animations");
        }
        if (a.contains("speed")) p.speed = c.number(a["speed"], at + ".animation.speed");
      }
      if (m.contains("material")) {
        const json& mat = m["material"];
        c.keys(mat, at + ".material", {"kind", "base_color", "ior"});
        if (mat.contains("kind")) {
          const std::string k = c.string(mat["kind"], at + ".material.kind");
          if (k == "diffuse") p.kind = SurfaceKind::kDiffuse;
          else if (k == "mirror") p.kind = SurfaceKind::kMirror;
          else if (k == "glass") p.kind = SurfaceKind::kGlass;
          else c.fail(at + ".material.kind", "expected diffuse, mirror or glass, got '" + k + "'");
        }
        if (mat.contains("base_color")) p.base_color = c.vec3(mat["base_color"], at + ".material.base_color");
        if (mat.contains("ior")) p.ior = c.number(mat["ior"], at + ".material.ior");
      }
      out.models.push_back(p);
      out.loaded.push_back(std::move(model));
    }
  }
  if (root.contains("lights")) {
    if (!root["lights"].is_array()) c.fail("lights", "expected an array");
    for (size_t i = 0; i < root["lights"].size(); ++i) {
      const json& l = root["lights"][i];
      const std::string at = "lights[" + std::to_string(i) + "]";
      c.keys(l, at, {"position", "color"});
      ArLightSpec s;
      if (!l.contains("position")) c.fail(at + ".position", "missing");
      s.position = c.vec3(l["position"], at + ".position");
      if (l.contains("color")) s.color = c.vec3(l["color"], at + ".color");
      out.lights.push_back(s);
    }
  }
  return out;
}

}  // namespace artrace::io

namespace artrace::io {

ArRuntime::ArRuntime(const ArSceneFile& file) : file_(file) {
  std::vector<core::Triangle> fixed;
  std::vector<float> fixed_pass;  // the static triangles' transmittance (glass lets light through)
  bool glass = false;
  static_bounds_.resize(file.models.size());
  for (size_t p = 0; p < file.models.size(); ++p) {
    const GltfModel& model = file.loaded[p];
    const ArModelPlacement& place = file.models[p];
    const bool animated = place.clip >= 0 && place.clip < static_cast<int>(model.animations.size());
    const std::vector<glm::mat4> rest = model.node_transforms(-1, 0.0f);
    std::vector<core::MeshHandle> meshes(model.meshes.size());
    for (size_t n = 0; n < model.nodes.size(); ++n) {
      const int mesh = model.nodes[n].mesh;
      if (mesh < 0 || model.meshes[mesh].tris.empty()) continue;
      const GltfMesh& gm = model.meshes[mesh];
      if (model.nodes[n].skin >= 0) {
        // a deforming mesh: skinned on every update
        core::TriangleMesh tm;
        tm.positions = gm.positions;
        tm.indices = gm.indices;
        const core::DeformableHandle h = scene_.add_deformable(std::move(tm));
        if (std::vector<float> pass = glass_pass(p, mesh); !pass.empty()) scene_.set_deformable_transmittance(h, std::move(pass));
        if (skinned_.size() <= h.index) skinned_.resize(h.index + 1);
        skinned_[h.index] = Skinned{p, static_cast<int>(n), mesh, model.nodes[n].skin, h};
      } else if (!animated) {
        // static: into the kd-tree, in world space
        const glm::mat4 m = place.world_from_model() * rest[n];
        const std::vector<float> pass = glass_pass(p, mesh);
        glass = glass || !pass.empty();
        for (uint32_t t = 0; t < gm.tris.size(); ++t) {
          const core::Triangle& tri = gm.tris[t];
          fixed.push_back({glm::vec3(m * glm::vec4(tri.v0, 1.0f)), glm::vec3(m * glm::vec4(tri.v1, 1.0f)),
                           glm::vec3(m * glm::vec4(tri.v2, 1.0f))});
          for (const glm::vec3& v : {fixed.back().v0, fixed.back().v1, fixed.back().v2}) static_bounds_[p].extend(v);
          static_parts_.push_back({static_cast<uint32_t>(p), static_cast<uint32_t>(mesh), t});
          fixed_pass.push_back(pass.empty() ? 0.0f : pass[t]);
        }
      } else {
        // hierarchically transformed: an instance of the mesh, moved by the node animation
        if (meshes[mesh].index == core::kInvalidId) {
          meshes[mesh] = scene_.add_rigid_mesh(gm.tris);
          if (std::vector<float> pass = glass_pass(p, mesh); !pass.empty()) scene_.set_mesh_transmittance(meshes[mesh], std::move(pass));
        }
        const core::InstanceHandle h = scene_.add_instance(meshes[mesh], glm::mat4(1.0f));
        if (parts_.size() <= h.index) parts_.resize(h.index + 1);
        core::Aabb box;
        for (const glm::vec3& v : gm.positions) box.extend(v);
        parts_[h.index] = Part{p, static_cast<int>(n), mesh, h, box};
      }
    }
  }
  scene_.set_static(std::move(fixed));
  if (glass) scene_.set_static_transmittance(std::move(fixed_pass));
  update(0.0);
}

double ArRuntime::update(double time_s) {
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::vector<glm::mat4>> nodes(file_.models.size());
  for (size_t p = 0; p < file_.models.size(); ++p) {
    const ArModelPlacement& m = file_.models[p];
    nodes[p] = file_.loaded[p].node_transforms(m.clip, static_cast<float>(time_s * m.speed));
  }
  bounds_ = static_bounds_;
  for (const Part& part : parts_) {
    if (part.mesh < 0) continue;
    const glm::mat4 m = file_.models[part.placement].world_from_model() * nodes[part.placement][part.node];
    scene_.set_transform(part.instance, m);
    bounds_[part.placement].extend(core::transform_box(part.object_box, m));  // no pass over the triangles
  }
  for (const Skinned& s : skinned_) {
    if (s.mesh < 0) continue;
    const glm::mat4 world = file_.models[s.placement].world_from_model();
    const std::vector<glm::vec3> v = file_.loaded[s.placement].skinned_positions(s.mesh, s.skin, nodes[s.placement]);
    core::DeformableMesh& d = scene_.deformable(s.handle);
    for (size_t i = 0; i < v.size(); ++i) {
      d.positions()[i] = glm::vec3(world * glm::vec4(v[i], 1.0f));
      bounds_[s.placement].extend(d.positions()[i]);
    }
    d.restructure();
  }
  scene_.commit();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

ar::VirtualMaterial ArRuntime::material(const core::Hit& hit) const {
  if (hit.inst == core::kStaticObject) {
    const StaticTriangle& s = static_parts_.at(hit.prim);
    return material_of(s.placement, static_cast<int>(s.mesh), s.triangle);
  }
  if (hit.inst & 0x80000000u) {
    const Skinned& s = skinned_.at(hit.inst & 0x7fffffffu);
    return material_of(s.placement, s.mesh, hit.prim);
  }
  const Part& part = parts_.at(hit.inst);
  return material_of(part.placement, part.mesh, hit.prim);
}

std::vector<float> ArRuntime::glass_pass(size_t placement, int mesh) const {
  const size_t n = file_.loaded[placement].meshes.at(static_cast<size_t>(mesh)).tris.size();
  std::vector<float> pass(n);
  bool any = false;
  for (uint32_t t = 0; t < n; ++t) {
    pass[t] = ar::shadow_transmittance(material_of(placement, mesh, t));
    any = any || pass[t] > 0.0f;
  }
  if (!any) pass.clear();
  return pass;
}

ar::VirtualMaterial ArRuntime::material_of(size_t placement, int mesh, uint32_t triangle) const {
  const ArModelPlacement& place = file_.models[placement];
  const GltfModel& model = file_.loaded[placement];
  const GltfMaterial& g = model.materials[model.meshes.at(static_cast<size_t>(mesh)).material.at(triangle)];
  ar::VirtualMaterial m;
  m.color = place.base_color.value_or(g.base_color);
  m.ior = place.ior.value_or(g.ior);
  SurfaceKind kind = SurfaceKind::kDiffuse;
  if (g.transmission > 0.5f) kind = SurfaceKind::kGlass;
  else if (g.metallic > 0.5f && g.roughness < 0.3f) kind = SurfaceKind::kMirror;
  kind = place.kind.value_or(kind);
  m.kind = kind == SurfaceKind::kGlass ? ar::VirtualMaterial::kGlass
           : kind == SurfaceKind::kMirror ? ar::VirtualMaterial::kMirror
                                          : ar::VirtualMaterial::kDiffuse;
  return m;
}

std::vector<ar::VirtualLight> ArRuntime::lights() const {
  std::vector<ar::VirtualLight> out;
  for (const ArLightSpec& l : file_.lights) out.push_back({l.position, l.color});
  return out;
}

}  // namespace artrace::io
