#include "artrace/ar/real_scene.h"
#include "packet_hits.h"

#include <stdexcept>
#include <string>

namespace artrace::ar {

FusedRoom::FusedRoom(RoomMesh mesh) : mesh_(std::move(mesh)) {
  const size_t n = mesh_.positions.size();
  if (mesh_.colours.size() != n) throw std::invalid_argument("room mesh: " + std::to_string(mesh_.colours.size()) + " colours for " + std::to_string(n) + " vertices");
  normals_.assign(n, glm::vec3(0.0f));
  std::vector<core::Triangle> tris;
  tris.reserve(mesh_.triangles.size());
  for (const glm::uvec3& t : mesh_.triangles) {
    if (t.x >= n || t.y >= n || t.z >= n) throw std::invalid_argument("room mesh: a triangle indexes past the " + std::to_string(n) + " vertices");
    const core::Triangle tri{mesh_.positions[t.x], mesh_.positions[t.y], mesh_.positions[t.z]};
    const glm::vec3 g = tri.geometric_normal();  // area-weighted
    normals_[t.x] += g;
    normals_[t.y] += g;
    normals_[t.z] += g;
    tris.push_back(tri);
  }
  for (glm::vec3& v : normals_) {
    const float len = glm::length(v);
    if (len > 0.0f) v /= len;
  }
  scene_.set_static(std::move(tris));
  scene_.commit();
}

core::LaneMask RealScene::intersect(const core::RayPacket& rays, core::LaneMask mask, float* t, glm::vec3* colour) const {
  core::LaneMask hit = 0;
  for (int i = 0; i < core::kPacketSize; ++i) {
    if (((mask >> i) & 1u) && intersect(rays.get(i), t[i], colour[i])) hit |= 1u << i;
  }
  return hit;
}

glm::vec3 FusedRoom::colour_at(const core::Hit& h) const {
  const glm::uvec3& i = mesh_.triangles[h.prim];
  return (1.0f - h.u - h.v) * mesh_.colours[i.x] + h.u * mesh_.colours[i.y] + h.v * mesh_.colours[i.z];
}

bool FusedRoom::intersect(const core::Ray& ray, float& t, glm::vec3& colour) const {
  const core::Hit h = scene_.intersect(ray);
  if (!h.valid()) return false;
  t = h.t;
  colour = colour_at(h);
  return true;
}

core::LaneMask FusedRoom::intersect(const core::RayPacket& rays, core::LaneMask mask, float* t, glm::vec3* colour) const {
  return detail::packet_hits(scene_, rays, mask, t, colour, [&](int i, const core::HitPacket& hits, glm::vec3& c) {
    c = colour_at(hits.get(i));
    return true;
  });
}

glm::vec3 FusedRoom::normal(const core::Hit& hit, const glm::vec3& dir) const {
  const glm::uvec3& i = mesh_.triangles[hit.prim];
  glm::vec3 n = (1.0f - hit.u - hit.v) * normals_[i.x] + hit.u * normals_[i.y] + hit.v * normals_[i.z];
  const float len = glm::length(n);
  if (!(len > 0.0f)) n = glm::normalize(scene_.world_triangle(hit).geometric_normal());
  else n /= len;
  return glm::dot(n, dir) > 0.0f ? -n : n;
}

}  // namespace artrace::ar
