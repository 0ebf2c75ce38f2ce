#include "artrace/core/geometry.h"
#include "kernels.h"

#include <stdexcept>
#include <string>

namespace artrace::core {

void TriangleMesh::flatten_into(std::vector<Triangle>& out) const {
  out.reserve(out.size() + indices.size());
  const size_t n = positions.size();
  for (size_t i = 0; i < indices.size(); ++i) {
    const glm::uvec3& t = indices[i];
    if (t.x >= n || t.y >= n || t.z >= n) {
      throw std::out_of_range("triangle " + std::to_string(i) + " indexes a vertex beyond the " +
                              std::to_string(n) + " the mesh has");
    }
    out.push_back({positions[t.x], positions[t.y], positions[t.z]});
  }
}

bool intersect_triangle(const Ray& ray, const Triangle& tri, uint32_t prim, Hit& hit) {
  return sse::intersect_triangle_single(ray, tri, prim, hit);
}

Hit intersect_brute_force(const Ray& ray, const std::vector<Triangle>& tris) {
  Hit hit;
  hit.t = ray.tmax;
  for (size_t i = 0; i < tris.size(); ++i) intersect_triangle(ray, tris[i], static_cast<uint32_t>(i), hit);
  if (!hit.valid()) hit = Hit{};
  return hit;
}

bool occluded_brute_force(const Ray& ray, const std::vector<Triangle>& tris) {
  Hit hit;
  hit.t = ray.tmax;
  for (size_t i = 0; i < tris.size(); ++i) {
    if (intersect_triangle(ray, tris[i], static_cast<uint32_t>(i), hit)) return true;
  }
  return false;
}

Aabb transform_box(const Aabb& b, const glm::mat4& m) {
  Aabb out;
  if (b.empty()) return out;
  for (int c = 0; c < 8; ++c) {
    const glm::vec3 p((c & 1) ? b.hi.x : b.lo.x, (c & 2) ? b.hi.y : b.lo.y, (c & 4) ? b.hi.z : b.lo.z);
    out.extend(glm::vec3(m * glm::vec4(p, 1.0f)));
  }
  const glm::vec3 pad = 1e-5f * (glm::abs(out.lo) + glm::abs(out.hi) + out.extent()) + glm::vec3(1e-30f);
  return Aabb{out.lo - pad, out.hi + pad};
}

}  // namespace artrace::core
