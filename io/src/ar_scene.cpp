#include "artrace/io/ar_scene.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/text_file.h"

#include <glm/gtc/matrix_transform.hpp>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <set>
#include <sstream>

namespace artrace::io {
namespace {

using nlohmann::json;

/// The largest magnitude an AR scene's number may have (1,000 km in metres).
constexpr double kMaxMagnitude = 1e6;
constexpr float kMaxMagnitudeF = static_cast<float>(kMaxMagnitude);

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
  /// A number from 0 to 1 (a factor or a linear colour's component).
  float unit(const json& j, const std::string& key) const { return within(number(j, key), 0.0f, 1.0f, key, "a number from 0 to 1"); }
  glm::vec3 unit3(const json& j, const std::string& key) const {
    const glm::vec3 v = vec3(j, key);
    for (int k = 0; k < 3; ++k) within(v[k], 0.0f, 1.0f, key, "a number from 0 to 1");
    return v;
  }
  /// `v` if it lies in [lo, hi], else a failure saying what was expected and what came.
  float within(float v, float lo, float hi, const std::string& key, const std::string& expected) const {
    if (!(v >= lo && v <= hi)) {
      std::ostringstream what;
      what << "expected " << expected << ", got " << v;
      fail(key, what.str());
    }
    return v;
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
  if (anchored) return glm::scale(*anchored, scale);
  glm::mat4 m = glm::translate(glm::mat4(1.0f), position);
  m = glm::rotate(m, glm::radians(rotation_deg.z), glm::vec3(0, 0, 1));
  m = glm::rotate(m, glm::radians(rotation_deg.y), glm::vec3(0, 1, 0));
  m = glm::rotate(m, glm::radians(rotation_deg.x), glm::vec3(1, 0, 0));
  return glm::scale(m, scale);
}

ArSceneFile load_ar_scene(const std::filesystem::path& path) {
  json root;
  try {
    root = json::parse(read_text_file(path));
  } catch (const json::parse_error& e) {
    throw ParseError(path.string(), 0, 0, std::string("not valid JSON: ") + e.what());
  }
  const Checker c(path.string());
  c.keys(root, "", {"models", "lights", "ambient", "room"});
  ArSceneFile out;
  out.file = path;
  if (root.contains("ambient")) out.ambient = c.unit(root["ambient"], "ambient");
  if (root.contains("room")) {
    out.room = path.parent_path() / c.string(root["room"], "room");
    if (!std::filesystem::exists(*out.room)) c.fail("room", "no such file: " + out.room->string());
  }
  if (root.contains("models")) {
    if (!root["models"].is_array()) c.fail("models", "expected an array");
    for (size_t i = 0; i < root["models"].size(); ++i) {
      const json& m = root["models"][i];
      const std::string at = "models[" + std::to_string(i) + "]";
      c.keys(m, at, {"file", "position", "rotation_deg", "scale", "animation", "material", "anchor"});
      ArModelPlacement p;
      if (!m.contains("file")) c.fail(at + ".file", "missing");
      p.file = path.parent_path() / c.string(m["file"], at + ".file");
      if (m.contains("position")) p.position = c.vec3(m["position"], at + ".position");
      if (m.contains("rotation_deg")) p.rotation_deg = c.vec3(m["rotation_deg"], at + ".rotation_deg");
      if (m.contains("scale")) {
        p.scale = m["scale"].is_number() ? glm::vec3(c.number(m["scale"], at + ".scale")) : c.vec3(m["scale"], at + ".scale");
        // 0 flattens the model to nothing (drawn nowhere); a negative scale mirrors it
        for (int k = 0; k < 3; ++k) {
          if (p.scale[k] == 0.0f) c.fail(at + ".scale", "expected a scale other than 0, got 0");
        }
      }
      if (m.contains("anchor")) {
        const json& a = m["anchor"];
        const std::string an = at + ".anchor";
        c.keys(a, an, {"frame", "pixel", "offset", "rotation_deg"});
        if (m.contains("position") || m.contains("rotation_deg")) {
          c.fail(an, "an anchored model takes no position or rotation_deg of its own (give anchor.offset and anchor.rotation_deg)");
        }
        ArModelPlacement::Anchor k;
        if (!a.contains("pixel")) c.fail(an + ".pixel", "missing");
        const json& px = a["pixel"];
        if (!px.is_array() || px.size() != 2 || !px[0].is_number() || !px[1].is_number()) c.fail(an + ".pixel", "expected 2 numbers");
        const float u = c.in_range(px[0], an + ".pixel"), v = c.in_range(px[1], an + ".pixel");
        if (u < 0.0f || v < 0.0f) c.fail(an + ".pixel", "expected pixel coordinates of 0 or more");
        k.u = static_cast<int>(u);
        k.v = static_cast<int>(v);
        if (a.contains("frame")) {
          const float fr = c.number(a["frame"], an + ".frame");
          if (fr < 0.0f || fr != std::floor(fr)) c.fail(an + ".frame", "expected a frame index (0 or more)");
          k.frame = static_cast<int>(fr);
        }
        if (a.contains("offset")) k.offset_m = c.number(a["offset"], an + ".offset");
        if (a.contains("rotation_deg")) k.rotation_deg = c.number(a["rotation_deg"], an + ".rotation_deg");
        p.anchor = k;
      }
      GltfModel model = load_gltf(p.file);
      if (model.triangle_count() == 0) {
        c.fail(at + ".file", p.file.string() + " holds no triangles to draw (no mesh, or only points and lines)");
      }
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
        c.keys(mat, at + ".material", {"kind", "base_color", "ior", "metallic", "roughness"});
        if (mat.contains("kind")) {
          const std::string k = c.string(mat["kind"], at + ".material.kind");
          if (k == "diffuse") p.kind = SurfaceKind::kDiffuse;
          else if (k == "mirror") p.kind = SurfaceKind::kMirror;
          else if (k == "glass") p.kind = SurfaceKind::kGlass;
          else c.fail(at + ".material.kind", "expected diffuse, mirror or glass, got '" + k + "'");
        }
        if (mat.contains("base_color")) p.base_color = c.unit3(mat["base_color"], at + ".material.base_color");
        if (mat.contains("ior")) {
          p.ior = c.within(c.number(mat["ior"], at + ".material.ior"), 1.0f, kMaxMagnitudeF, at + ".material.ior", "1 or more");
        }
        if (mat.contains("metallic")) p.metallic = c.unit(mat["metallic"], at + ".material.metallic");
        if (mat.contains("roughness")) p.roughness = c.unit(mat["roughness"], at + ".material.roughness");
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
      if (l.contains("color")) {
        s.color = c.vec3(l["color"], at + ".color");
        for (int k = 0; k < 3; ++k) c.within(s.color[k], 0.0f, kMaxMagnitudeF, at + ".color", "0 or more");
      }
      out.lights.push_back(s);
    }
  }
  return out;
}

void resolve_anchors(ArSceneFile& scene, ar::FrameSource& recording) {
  bool any = false;
  for (size_t i = 0; i < scene.models.size(); ++i) {
    ArModelPlacement& p = scene.models[i];
    if (!p.anchor) continue;
    any = true;
    const std::string at = "models[" + std::to_string(i) + "].anchor";
    const auto count = recording.frame_count();
    if (count && p.anchor->frame >= *count) {
      throw ParseError(scene.file.string(), 0, 0, at + ".frame: the recording has " + std::to_string(*count) + " frames");
    }
    ar::SensorFrame f;
    recording.seek(p.anchor->frame);
    if (!recording.next(f)) throw ParseError(scene.file.string(), 0, 0, at + ".frame: no frame " + std::to_string(p.anchor->frame));
    if (!f.world_from_camera) {
      if (const auto span = recording.trajectory_span()) {  // else a fixed camera: the world is the camera's frame
        char why[160];
        std::snprintf(why, sizeof why, "(t = %.6f s) has no camera pose: the trajectory runs from %.6f to %.6f s, with none in gaps over 0.1 s",
                      f.color_time_s, span->first, span->second);
        throw ParseError(scene.file.string(), 0, 0, at + ".frame: frame " + std::to_string(p.anchor->frame) + " " + why +
                                                        "; anchor on a frame it covers");
      }
    }
    if (p.anchor->u >= f.depth.width || p.anchor->v >= f.depth.height) {
      throw ParseError(scene.file.string(), 0, 0, at + ".pixel: (" + std::to_string(p.anchor->u) + ", " + std::to_string(p.anchor->v) +
                                                      ") lies outside the " + std::to_string(f.depth.width) + "x" +
                                                      std::to_string(f.depth.height) + " depth image");
    }
    const std::optional<ar::Plane> plane = ar::plane_at_pixel(f, p.anchor->u, p.anchor->v);
    if (!plane) {
      throw ParseError(scene.file.string(), 0, 0, at + ": no plane in the depth around pixel (" + std::to_string(p.anchor->u) + ", " +
                                                      std::to_string(p.anchor->v) + ") of frame " + std::to_string(p.anchor->frame) +
                                                      " (too few readings, or no surface holding most of them)");
    }
    // +Y the normal, +Z towards the camera along the plane, X = Y x Z
    const Eigen::Vector3d eye = f.world_from_camera ? Eigen::Vector3d(f.world_from_camera->translation()) : Eigen::Vector3d::Zero();
    const Eigen::Vector3d y = plane->normal;
    Eigen::Vector3d z = (eye - plane->point) - y * y.dot(eye - plane->point);
    if (z.norm() < 1e-6) z = y.unitOrthogonal();  // the camera looks straight down the normal
    z.normalize();
    const Eigen::Vector3d x = y.cross(z);
    const Eigen::Vector3d o = plane->point + y * p.anchor->offset_m;
    glm::mat4 m(1.0f);
    for (int r = 0; r < 3; ++r) {
      m[0][r] = static_cast<float>(x[r]);
      m[1][r] = static_cast<float>(y[r]);
      m[2][r] = static_cast<float>(z[r]);
      m[3][r] = static_cast<float>(o[r]);
    }
    p.anchored = glm::rotate(m, glm::radians(p.anchor->rotation_deg), glm::vec3(0.0f, 1.0f, 0.0f));
    p.support = plane;
  }
  if (any) recording.seek(0);
}

}  // namespace artrace::io

namespace artrace::io {

namespace {

/// A mesh's morph weights are animated by the placement's clip.
bool weights_animated(const GltfModel& model, int clip, int node) {
  if (clip < 0 || clip >= static_cast<int>(model.animations.size())) return false;
  for (const GltfChannel& c : model.animations[static_cast<size_t>(clip)].channels) {
    if (c.path == GltfChannel::kWeights && c.node == node) return true;
  }
  return false;
}

glm::mat3 normal_matrix(const glm::mat4& m) { return glm::transpose(glm::inverse(glm::mat3(m))); }

}  // namespace

ArRuntime::ArRuntime(const ArSceneFile& file) : file_(file) {
  std::vector<core::Triangle> fixed;
  std::vector<float> fixed_pass;  // the static triangles' transmittance (glass lets light through)
  bool glass = false;
  static_bounds_.resize(file.models.size());
  textures_.resize(file.models.size());
  for (size_t p = 0; p < file.models.size(); ++p) {
    const GltfModel& model = file.loaded[p];
    const ArModelPlacement& place = file.models[p];
    // every image twice, as data (linear) and as colour (sRGB), built when a material uses it so
    std::vector<ar::Texture>& tex = textures_[p];
    tex.resize(2 * model.images.size());
    for (const GltfMaterial& g : model.materials) {
      auto need = [&](const GltfTextureRef& t, bool srgb) {
        if (!t.valid()) return;
        ar::Texture& slot = tex[2 * static_cast<size_t>(t.image) + (srgb ? 1 : 0)];
        if (slot.levels() > 0) return;
        const GltfImage& img = model.images[static_cast<size_t>(t.image)];
        slot = ar::Texture(img.width, img.height, img.rgba, srgb);
      };
      need(g.base_color_texture, true);
      need(g.emissive_texture, true);
      need(g.metallic_roughness_texture, false);
      need(g.normal_texture, false);
      need(g.occlusion_texture, false);
      alpha_tested_ = alpha_tested_ || g.alpha_mode != AlphaMode::kOpaque;
    }
    const bool animated = place.clip >= 0 && place.clip < static_cast<int>(model.animations.size());
    const std::vector<glm::mat4> rest = model.node_transforms(-1, 0.0f);
    const std::vector<std::vector<float>> rest_weights = model.node_weights(-1, 0.0f);
    std::vector<core::MeshHandle> meshes(model.meshes.size());
    for (size_t n = 0; n < model.nodes.size(); ++n) {
      const int mesh = model.nodes[n].mesh;
      if (mesh < 0 || model.meshes[static_cast<size_t>(mesh)].tris.empty()) continue;
      const GltfMesh& gm = model.meshes[static_cast<size_t>(mesh)];
      const bool morphing = gm.morphed() && weights_animated(model, place.clip, static_cast<int>(n));
      if (model.nodes[n].skin >= 0 || morphing) {
        // a deforming mesh: its vertices recomputed on every update
        core::TriangleMesh tm;
        tm.positions = gm.positions;
        tm.indices = gm.indices;
        const core::DeformableHandle h = scene_.add_deformable(std::move(tm));
        if (std::vector<float> pass = glass_pass(p, mesh); !pass.empty()) scene_.set_deformable_transmittance(h, std::move(pass));
        if (deforming_.size() <= h.index) deforming_.resize(h.index + 1);
        deforming_[h.index] = Deforming{p, static_cast<int>(n), mesh, model.nodes[n].skin, h, {}};
      } else if (!animated) {
        // static: into the kd-tree, in world space (morph targets at the node's weights)
        const glm::mat4 m = place.world_from_model() * rest[n];
        const std::vector<float> pass = glass_pass(p, mesh);
        glass = glass || !pass.empty();
        const std::vector<glm::vec3> v = gm.morphed() ? model.morphed_positions(mesh, rest_weights[n]) : gm.positions;
        const uint32_t xform = static_cast<uint32_t>(static_xforms_.size());
        static_xforms_.push_back(m);
        for (uint32_t t = 0; t < gm.indices.size(); ++t) {
          const glm::uvec3& i = gm.indices[t];
          fixed.push_back({glm::vec3(m * glm::vec4(v[i.x], 1.0f)), glm::vec3(m * glm::vec4(v[i.y], 1.0f)), glm::vec3(m * glm::vec4(v[i.z], 1.0f))});
          for (const glm::vec3& w : {fixed.back().v0, fixed.back().v1, fixed.back().v2}) static_bounds_[p].extend(w);
          static_parts_.push_back({static_cast<uint32_t>(p), static_cast<uint32_t>(mesh), t, xform});
          fixed_pass.push_back(pass.empty() ? 0.0f : pass[t]);
        }
      } else {
        // hierarchically transformed: an instance of the mesh, moved by the node animation
        if (meshes[static_cast<size_t>(mesh)].index == core::kInvalidId) {
          meshes[static_cast<size_t>(mesh)] = scene_.add_rigid_mesh(gm.tris);
          if (std::vector<float> pass = glass_pass(p, mesh); !pass.empty()) scene_.set_mesh_transmittance(meshes[static_cast<size_t>(mesh)], std::move(pass));
        }
        const core::InstanceHandle h = scene_.add_instance(meshes[static_cast<size_t>(mesh)], glm::mat4(1.0f));
        if (parts_.size() <= h.index) parts_.resize(h.index + 1);
        core::Aabb box;
        for (const core::Triangle& t : gm.tris) box.extend(core::Aabb::of(t));
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
  std::vector<std::vector<std::vector<float>>> weights(file_.models.size());
  for (size_t p = 0; p < file_.models.size(); ++p) {
    const ArModelPlacement& m = file_.models[p];
    const float t = static_cast<float>(time_s * m.speed);
    nodes[p] = file_.loaded[p].node_transforms(m.clip, t);
    weights[p] = file_.loaded[p].node_weights(m.clip, t);
  }
  bounds_ = static_bounds_;
  for (const Part& part : parts_) {
    if (part.mesh < 0) continue;
    const glm::mat4 m = file_.models[part.placement].world_from_model() * nodes[part.placement][static_cast<size_t>(part.node)];
    scene_.set_transform(part.instance, m);
    bounds_[part.placement].extend(core::transform_box(part.object_box, m));  // no pass over the triangles
  }
  for (Deforming& s : deforming_) {
    if (s.mesh < 0) continue;
    const GltfModel& model = file_.loaded[s.placement];
    const GltfMesh& gm = model.meshes[static_cast<size_t>(s.mesh)];
    std::vector<glm::vec3> normals;
    std::vector<glm::vec3> v = gm.morphed() ? model.morphed_positions(s.mesh, weights[s.placement][static_cast<size_t>(s.node)], &normals) : gm.positions;
    if (!gm.morphed()) normals = gm.normals;
    // skinned: the skin's joints place it (the node's own transform does not apply); morphed only:
    // the node's transform
    glm::mat4 world = file_.models[s.placement].world_from_model();
    if (s.skin >= 0) v = model.skinned_positions(s.mesh, s.skin, nodes[s.placement], &v, &normals);
    else world = world * nodes[s.placement][static_cast<size_t>(s.node)];
    const glm::mat3 nm = normal_matrix(world);
    core::DeformableMesh& d = scene_.deformable(s.handle);
    for (size_t i = 0; i < v.size(); ++i) {
      d.positions()[i] = glm::vec3(world * glm::vec4(v[i], 1.0f));
      bounds_[s.placement].extend(d.positions()[i]);
    }
    s.normals.resize(normals.size());
    for (size_t i = 0; i < normals.size(); ++i) s.normals[i] = nm * normals[i];
    d.restructure();
  }
  scene_.commit();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

namespace {

/// A texture reference's coordinates at barycentrics (w0, w1, w2) of triangle `i`, transformed,
/// with the transformed coordinate area of the triangle (for the level of detail).
glm::vec2 tex_coords(const GltfMesh& gm, const GltfTextureRef& t, const glm::uvec3& i, float w0, float w1, float w2, float* area) {
  const std::vector<glm::vec2>& uv = gm.uv[t.tex_coord];
  if (uv.empty()) {
    if (area) *area = 0.0f;
    return glm::vec2(0.0f);
  }
  const glm::vec2 a = glm::vec2(t.transform * glm::vec3(uv[i.x], 1.0f)), b = glm::vec2(t.transform * glm::vec3(uv[i.y], 1.0f)),
                  c = glm::vec2(t.transform * glm::vec3(uv[i.z], 1.0f));
  if (area) {
    const glm::vec2 e1 = b - a, e2 = c - a;
    *area = 0.5f * std::fabs(e1.x * e2.y - e1.y * e2.x);
  }
  return w0 * a + w1 * b + w2 * c;
}

}  // namespace

ar::VirtualMaterial ArRuntime::material(const ar::SurfaceQuery& hit) const {
  size_t placement;
  int mesh;
  uint32_t triangle;
  const glm::mat4* xform = nullptr;       // world from mesh (static parts)
  const std::vector<glm::vec3>* normals_world = nullptr;  // deforming meshes
  if (hit.inst == core::kStaticObject) {
    const StaticTriangle& s = static_parts_.at(hit.prim);
    placement = s.placement;
    mesh = static_cast<int>(s.mesh);
    triangle = s.triangle;
    xform = &static_xforms_[s.xform];
  } else if (hit.inst & 0x80000000u) {
    const Deforming& s = deforming_.at(hit.inst & 0x7fffffffu);
    placement = s.placement;
    mesh = s.mesh;
    triangle = hit.prim;
    normals_world = &s.normals;
  } else {
    const Part& part = parts_.at(hit.inst);
    placement = part.placement;
    mesh = part.mesh;
    triangle = hit.prim;
  }
  ar::VirtualMaterial m = triangle_material(placement, mesh, triangle);
  const GltfModel& model = file_.loaded[placement];
  const GltfMesh& gm = model.meshes[static_cast<size_t>(mesh)];
  const GltfMaterial& g = model.materials[gm.material[triangle]];
  const ArModelPlacement& place = file_.models[placement];
  const glm::uvec3 i = gm.indices[triangle];
  const float w0 = 1.0f - hit.u - hit.v, w1 = hit.u, w2 = hit.v;
  const std::vector<ar::Texture>& tex = textures_[placement];
  // shadow rays need only what decides how much light passes: coverage
  const bool full = !hit.shadow_ray;
  const core::Triangle wt = scene_.world_triangle(hit);
  const glm::vec3 ng = glm::cross(wt.v1 - wt.v0, wt.v2 - wt.v0);
  const float world_area = 0.5f * glm::length(ng);
  const float cosine = world_area > 0.0f ? glm::dot(ng, hit.dir) / (2.0f * world_area) : 1.0f;
  auto sample = [&](const GltfTextureRef& t, bool srgb) {
    float uv_area = 0.0f;
    const glm::vec2 uv = tex_coords(gm, t, i, w0, w1, w2, &uv_area);
    const ar::Texture& tx = tex[2 * static_cast<size_t>(t.image) + (srgb ? 1 : 0)];
    return tx.sample(t.sampler, uv, ar::texture_lod(tx, uv_area, world_area, hit.cone_width, cosine));
  };
  float alpha = g.alpha;
  if (!gm.colors.empty()) {
    const glm::vec4 c = w0 * gm.colors[i.x] + w1 * gm.colors[i.y] + w2 * gm.colors[i.z];
    if (!place.base_color) m.color *= glm::vec3(c);
    alpha *= c.a;
  }
  if (g.base_color_texture.valid() && (!place.base_color || g.alpha_mode != AlphaMode::kOpaque)) {
    const glm::vec4 c = sample(g.base_color_texture, true);
    if (!place.base_color) m.color *= glm::vec3(c);
    alpha *= c.a;
  }
  if (g.alpha_mode == AlphaMode::kMask) m.cutout = alpha < g.alpha_cutoff;
  else if (g.alpha_mode == AlphaMode::kBlend) m.alpha = alpha;
  if (!full || m.cutout) return m;
  if (g.metallic_roughness_texture.valid()) {
    const glm::vec4 c = sample(g.metallic_roughness_texture, false);
    if (!place.roughness) m.roughness *= c.g;
    if (!place.metallic) m.metallic *= c.b;
  }
  if (g.occlusion_texture.valid()) m.occlusion = 1.0f + g.occlusion_texture.scale * (sample(g.occlusion_texture, false).r - 1.0f);
  if (g.emissive_texture.valid()) m.emissive *= glm::vec3(sample(g.emissive_texture, true));
  // the shading normal: interpolated vertex normals, bent by the normal map
  glm::vec3 n(0.0f);
  if (normals_world) {
    if (!normals_world->empty()) n = w0 * (*normals_world)[i.x] + w1 * (*normals_world)[i.y] + w2 * (*normals_world)[i.z];
  } else if (!gm.normals.empty()) {
    const glm::vec3 local = w0 * gm.normals[i.x] + w1 * gm.normals[i.y] + w2 * gm.normals[i.z];
    n = xform ? normal_matrix(*xform) * local : scene_.normal_to_world(hit) * local;
  }
  if (g.normal_texture.valid() && !gm.uv[g.normal_texture.tex_coord].empty()) {
    const glm::vec3 geo = glm::normalize(ng);
    glm::vec3 nn = n == glm::vec3(0.0f) ? geo : glm::normalize(n);
    // tangent frame: TANGENT where given (and the mesh is not deforming), else from the texture
    // coordinates' derivatives over the world triangle
    glm::vec3 t(0.0f);
    float sign = 1.0f;
    if (!gm.tangents.empty() && !normals_world) {
      const glm::vec4 tl = w0 * gm.tangents[i.x] + w1 * gm.tangents[i.y] + w2 * gm.tangents[i.z];
      const glm::mat4 to_world = xform ? *xform : scene_.world_from_object(hit);
      t = glm::mat3(to_world) * glm::vec3(tl);
      sign = tl.w < 0.0f ? -1.0f : 1.0f;
    } else {
      const std::vector<glm::vec2>& uv = gm.uv[g.normal_texture.tex_coord];
      const glm::vec2 d1 = uv[i.y] - uv[i.x], d2 = uv[i.z] - uv[i.x];
      const glm::vec3 e1 = wt.v1 - wt.v0, e2 = wt.v2 - wt.v0;
      const float det = d1.x * d2.y - d2.x * d1.y;
      if (det != 0.0f) {
        t = (e1 * d2.y - e2 * d1.y) / det;
        const glm::vec3 b = (e2 * d1.x - e1 * d2.x) / det;
        sign = glm::dot(glm::cross(nn, t), b) < 0.0f ? -1.0f : 1.0f;
      }
    }
    t -= nn * glm::dot(nn, t);
    if (glm::dot(t, t) > 0.0f) {
      t = glm::normalize(t);
      const glm::vec3 b = sign * glm::cross(nn, t);
      const glm::vec3 c = 2.0f * glm::vec3(sample(g.normal_texture, false)) - 1.0f;
      const glm::vec3 ts(c.x * g.normal_texture.scale, c.y * g.normal_texture.scale, c.z);
      n = ts.x * t + ts.y * b + ts.z * nn;
    }
  }
  m.normal = n;
  return m;
}

std::vector<float> ArRuntime::glass_pass(size_t placement, int mesh) const {
  const size_t n = file_.loaded[placement].meshes.at(static_cast<size_t>(mesh)).indices.size();
  std::vector<float> pass(n);
  bool any = false;
  for (uint32_t t = 0; t < n; ++t) {
    pass[t] = ar::shadow_transmittance(triangle_material(placement, mesh, t));
    any = any || pass[t] > 0.0f;
  }
  if (!any) pass.clear();
  return pass;
}

ar::VirtualMaterial ArRuntime::triangle_material(size_t placement, int mesh, uint32_t triangle) const {
  const ArModelPlacement& place = file_.models[placement];
  const GltfModel& model = file_.loaded[placement];
  const GltfMaterial& g = model.materials[model.meshes.at(static_cast<size_t>(mesh)).material.at(triangle)];
  ar::VirtualMaterial m;
  m.color = place.base_color.value_or(g.base_color);
  m.ior = place.ior.value_or(g.ior);
  m.pbr = g.pbr;
  m.metallic = place.metallic.value_or(g.metallic);
  m.roughness = place.roughness.value_or(g.roughness);
  m.emissive = g.emissive;
  SurfaceKind kind = g.transmission > 0.5f ? SurfaceKind::kGlass : SurfaceKind::kDiffuse;
  kind = place.kind.value_or(kind);
  m.kind = kind == SurfaceKind::kGlass ? ar::VirtualMaterial::kGlass
           : kind == SurfaceKind::kMirror ? ar::VirtualMaterial::kMirror
                                          : ar::VirtualMaterial::kDiffuse;
  if (place.kind == SurfaceKind::kDiffuse && !place.metallic && !place.roughness) m.pbr = false;  // "diffuse": Lambert
  if (place.metallic || place.roughness) m.pbr = true;
  return m;
}

std::vector<ar::VirtualLight> ArRuntime::lights() const {
  std::vector<ar::VirtualLight> out;
  for (const ArLightSpec& l : file_.lights) out.push_back({l.position, l.color});
  return out;
}

}  // namespace artrace::io
