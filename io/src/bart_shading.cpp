#include "artrace/io/bart_shading.h"

#include "artrace/core/srgb.h"
#include "artrace/io/parse_error.h"

#include <fstream>
#include <cctype>
#include <cmath>

namespace artrace::io {
namespace {

/// Next header token of a PPM: skips white space and # comments.
std::string ppm_token(std::istream& in, const std::string& file, const char* what) {
  std::string tok;
  int c;
  while ((c = in.get()) != EOF) {
    if (c == '#') {
      while ((c = in.get()) != EOF && c != '\n') {
      }
      continue;
    }
    if (std::isspace(c)) {
      if (!tok.empty()) return tok;
      continue;
    }
    tok.push_back(static_cast<char>(c));
  }
  if (tok.empty()) throw ParseError(file, 0, 0, std::string("truncated header: expected ") + what);
  return tok;
}

int ppm_int(std::istream& in, const std::string& file, const char* what, int lo, int hi) {
  const std::string tok = ppm_token(in, file, what);
  size_t used = 0;
  long v = -1;
  try {
    v = std::stol(tok, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != tok.size() || v < lo || v > hi) {
    throw ParseError(file, 0, 0, std::string("expected ") + what + " (" + std::to_string(lo) + ".." + std::to_string(hi) + "), got " + quote_token(tok));
  }
  return static_cast<int>(v);
}

}  // namespace

core::Texture load_ppm(const std::filesystem::path& path) {
  const std::string file = path.string();
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ParseError(file, 0, 0, "cannot open the texture");
  if (ppm_token(in, file, "the magic number P6") != "P6") throw ParseError(file, 0, 0, "not a binary PPM (P6) image");
  core::Texture t;
  t.width = ppm_int(in, file, "the width", 1, 1 << 15);
  t.height = ppm_int(in, file, "the height", 1, 1 << 15);
  const int maxval = ppm_int(in, file, "the maximum value", 1, 65535);
  // the header ends with exactly one white-space character, already read by ppm_token
  const size_t bytes_per = maxval < 256 ? 1 : 2;
  const size_t n = static_cast<size_t>(t.width) * t.height * 3;
  // check what the header declares against what the file holds before allocating for it
  const std::streamoff header_end = in.tellg();
  in.seekg(0, std::ios::end);
  const std::streamoff file_end = in.tellg();
  in.seekg(header_end);
  if (header_end < 0 || file_end < header_end) throw ParseError(file, 0, 0, "cannot measure the pixel data");
  const size_t held = static_cast<size_t>(file_end - header_end);
  if (held < n * bytes_per) {
    throw ParseError(file, 0, 0, "truncated pixel data: the header declares " + std::to_string(t.width) + "x" + std::to_string(t.height) + " pixels (" +
                                     std::to_string(n * bytes_per) + " bytes) but " + std::to_string(held) + " bytes follow it");
  }
  std::vector<uint8_t> data(n * bytes_per);
  in.read(reinterpret_cast<char*>(data.data()), static_cast<std::streamsize>(data.size()));
  if (static_cast<size_t>(in.gcount()) != data.size()) {
    throw ParseError(file, 0, 0, "truncated pixel data: " + std::to_string(in.gcount()) + " of " + std::to_string(data.size()) + " bytes");
  }
  t.texels.resize(n / 3);
  for (size_t i = 0; i < n; ++i) {
    float v;
    if (bytes_per == 1) {
      v = maxval == 255 ? core::srgb8_to_linear(data[i]) : core::srgb8_to_linear(static_cast<uint8_t>(data[i] * 255 / maxval));
    } else {
      const int raw = (data[2 * i] << 8) | data[2 * i + 1];
      const float c = std::min(1.0f, static_cast<float>(raw) / static_cast<float>(maxval));
      v = c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
    }
    t.texels[i / 3][static_cast<int>(i % 3)] = v;
  }
  return t;
}

namespace {

/// Texture coordinates per unit of world length on a triangle: sqrt(uv area / world area), 0 for
/// one without a world area.
inline float uv_per_world(const std::array<glm::vec2, 3>& uv, const core::Triangle& world) {
  const glm::vec2 e1 = uv[1] - uv[0], e2 = uv[2] - uv[0];
  const float uv_area = std::fabs(e1.x * e2.y - e1.y * e2.x);
  const float world_area = glm::length(world.geometric_normal());
  return world_area > 0.0f ? std::sqrt(uv_area / world_area) : 0.0f;
}

/// Boxes around runs of consecutive transmissive triangles, merged pairwise down to `cap` boxes.
std::vector<core::Aabb> transmissive_runs(const TriangleBatch& b, const AffScene& scene, size_t cap) {
  std::vector<core::Aabb> boxes;
  bool open = false;
  for (size_t i = 0; i < b.size(); ++i) {
    if (!(scene.transmittance(b.material[i]) > 0.0f)) {
      open = false;
      continue;
    }
    if (!open) boxes.emplace_back();
    open = true;
    for (const glm::vec3& v : {b.tris[i].v0, b.tris[i].v1, b.tris[i].v2}) boxes.back().extend(v);
  }
  while (boxes.size() > cap) {
    std::vector<core::Aabb> merged;
    for (size_t i = 0; i < boxes.size(); i += 2) {
      core::Aabb a = boxes[i];
      if (i + 1 < boxes.size()) a.extend(boxes[i + 1]);
      merged.push_back(a);
    }
    boxes.swap(merged);
  }
  return boxes;
}

}  // namespace

BartSurfaces::BartSurfaces(const BartAnimation& animation) : anim_(animation) {
  const AffScene& aff = animation.aff();
  if (!aff.nodes.empty()) {
    const TriangleBatch& b = aff.nodes[0].geometry;
    static_boxes_ = transmissive_runs(b, aff, 64);
    // the static triangles as the scene holds them (the hits' world triangles)
    const core::KdTree* kd = animation.scene().static_kd_tree();
    const std::vector<core::Triangle>& world = kd ? kd->triangles() : b.tris;
    if (world.size() == b.size()) {
      static_uv_per_world_.resize(b.size(), 0.0f);
      for (size_t i = 0; i < b.size(); ++i) {
        if (b.texture[i] >= 0) static_uv_per_world_[i] = uv_per_world(b.uvs[i], world[i]);
      }
    }
  }
  const auto& nodes = animation.instance_nodes();
  for (uint32_t inst = 0; inst < nodes.size(); ++inst) {
    if (nodes[inst] == 0) continue;
    core::Aabb box;
    for (const core::Aabb& b : transmissive_runs(aff.nodes[nodes[inst]].geometry, aff, 1)) box.extend(b);
    if (!box.empty()) object_boxes_.emplace_back(inst, box);
  }
  unknown_ = aff.deforming_transmissive();
}

bool BartSurfaces::transmissive_bounds(std::vector<core::Aabb>& boxes) const {
  if (unknown_) return false;
  boxes = static_boxes_;
  for (const auto& [inst, box] : object_boxes_) {
    core::Hit h;
    h.inst = inst;
    boxes.push_back(core::transform_box(box, anim_.scene().world_from_object(h)));
  }
  return true;
}

namespace {

/// Shading normal, texture coordinates and texture of `hit` on its object's batch `b`;
/// `static_uv_per_world` (optional): uv_per_world() of every static triangle, worked out once.
inline void shade_hit(const BartAnimation& anim, const TriangleBatch* b, const core::Hit& hit,
                      const core::Triangle& world, core::SurfaceInfo& info, const float* static_uv_per_world) {
  if (!b || hit.prim >= b->size()) return;
  const float w = 1.0f - hit.u - hit.v;
  const auto& n = b->normals[hit.prim];
  const glm::vec3 object_normal = w * n[0] + hit.u * n[1] + hit.v * n[2];
  info.normal = hit.inst == core::kStaticObject ? object_normal : anim.scene().normal_to_world(hit) * object_normal;
  const auto& uv = b->uvs[hit.prim];
  info.uv = w * uv[0] + hit.u * uv[1] + hit.v * uv[2];
  info.texture = b->texture[hit.prim];
  if (info.texture >= 0) {
    // the static geometry is its own world space: its triangles are the ones the hits name
    info.uv_per_world = hit.inst == core::kStaticObject && static_uv_per_world ? static_uv_per_world[hit.prim]
                                                                                : uv_per_world(uv, world);
  }
}

}  // namespace

void BartSurfaces::shading(const core::Hit& hit, const core::Triangle& world, core::SurfaceInfo& info) const {
  shade_hit(anim_, anim_.batch(hit), hit, world, info, static_uv_per_world_.empty() ? nullptr : static_uv_per_world_.data());
}

void BartSurfaces::shade_packet(const core::HitPacket& hits, core::LaneMask mask, const core::Triangle* world_tris,
                                uint32_t* materials, core::SurfaceInfo* infos) const {
  // the default's loop, with direct calls: shade_hit inline (one shared loop calling shading() by
  // name was measured at 0.6% more instructions a robots frame: GCC kept shading() out of line)
  const float* const static_uv = static_uv_per_world_.empty() ? nullptr : static_uv_per_world_.data();
  // First every hit's batch found and its attributes asked of memory, then each used: scattered
  // hits miss the cache on each of the arrays, and the misses overlap only when asked for ahead.
  const TriangleBatch* batches[core::kPacketSize];
  for (int i = 0; i < core::kPacketSize; ++i) {
    if (!((mask >> i) & 1u)) continue;
    const core::Hit h = hits.get(i);
    const TriangleBatch* b = batches[i] = anim_.batch(h);
    if (!b || h.prim >= b->size()) continue;
    __builtin_prefetch(&b->normals[h.prim]);
    __builtin_prefetch(&b->uvs[h.prim]);
    __builtin_prefetch(&b->material[h.prim]);
    __builtin_prefetch(&b->texture[h.prim]);
    if (static_uv && h.inst == core::kStaticObject) __builtin_prefetch(&static_uv[h.prim]);
  }
  for (int i = 0; i < core::kPacketSize; ++i) {
    if (!((mask >> i) & 1u)) continue;
    const core::Hit h = hits.get(i);
    // the batch once: its material is what anim_.material() looks up again
    const TriangleBatch* b = batches[i];
    materials[i] = b ? b->material.at(h.prim) : anim_.material(h);
    shade_hit(anim_, b, h, world_tris[i], infos[i], static_uv);
  }
}

core::ShadingScene make_shading_scene(const BartAnimation& animation, const BartSurfaces& surfaces) {
  const AffScene& aff = animation.aff();
  core::ShadingScene s;
  s.geometry = &animation.scene();
  s.surfaces = &surfaces;
  for (const AffMaterial& m : aff.materials) {
    core::Material c;
    c.ambient = m.ambient;
    c.diffuse = m.diffuse;
    c.specular = m.specular;
    c.shine = m.shine;
    c.transmittance = m.transmittance;
    c.ior = m.ior > 0.0f ? m.ior : 1.0f;
    s.materials.push_back(c);
  }
  if (s.materials.empty()) s.materials.push_back(core::Material{});
  for (const auto& t : aff.textures) {
    s.textures.push_back(load_ppm(t));
    s.textures.back().build_mipmaps();
  }
  for (const AffLight& l : aff.lights) s.lights.push_back({l.position, l.color});
  s.ambient = aff.ambient;
  s.background = aff.background;
  return s;
}

}  // namespace artrace::io
