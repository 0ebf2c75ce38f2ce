#include "artrace/core/renderer.h"

#include "fork_join.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <stdexcept>
#include <string>

namespace artrace::core {

void for_each_tile(int width, int height, int threads, const std::function<void(const Tile&)>& fn, int size) {
  if (size <= 0) throw std::invalid_argument("for_each_tile: tile size " + std::to_string(size));
  const int tiles_x = (width + size - 1) / size;
  const int tiles_y = (height + size - 1) / size;
  const int count = tiles_x * tiles_y;
  auto body = [&](const tbb::blocked_range<int>& r) {
    for (int i = r.begin(); i != r.end(); ++i) {
      const int tx = i % tiles_x, ty = i / tiles_x;
      const Tile t{tx * size, ty * size, std::min(width, (tx + 1) * size), std::min(height, (ty + 1) * size)};
      fn(t);
    }
  };
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  detail::ForkJoin fj;
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, count, 1), fj.task(body), tbb::simple_partitioner());
  });
  fj.joined();
}

LaneMask primary_packet(const Camera& cam, int x, int y, RayPacket& rays, int rows) {
  LaneMask mask = 0;
  for (int i = 0; i < kPacketSize; ++i) {
    const int px = x + i % 4, py = y + i / 4;
    const bool inside = px < cam.width && py < cam.height && i < 4 * rows;
    rays.set(i, cam.ray(static_cast<float>(px) + 0.5f, static_cast<float>(py) + 0.5f));
    if (inside) mask |= 1u << i;
  }
  return mask;
}

glm::vec3 eye_light(const Triangle& tri, const glm::vec3& dir) {
  glm::vec3 n = tri.geometric_normal();
  const float len = glm::length(n);
  if (!(len > 0.0f)) return glm::vec3(0.5f);
  n /= len;
  const float c = std::fabs(glm::dot(n, dir)) / glm::length(dir);
  if (glm::dot(n, dir) > 0.0f) n = -n;
  const glm::vec3 tint = glm::vec3(0.6f) + 0.4f * n;
  return tint * (0.15f + 0.85f * c);
}

Image render_eye_light(const KdTree& tree, const Camera& cam, const RenderOptions& opt) {
  const auto& tris = tree.triangles();
  return render_eye_light(tree, [&](const Hit& h) { return tris[h.prim]; }, cam, opt);
}

}  // namespace artrace::core
