// Image-space parallelism: 8x8 tiles handed out dynamically to all worker threads (oneTBB with
// grain 1, so an idle thread steals the next tile), and a first eye-light shading.
#pragma once

#include "artrace/core/camera.h"
#include "artrace/core/kd_tree.h"

#include <functional>
#include <vector>

namespace artrace::core {

inline constexpr int kTileSize = 8;

/// Linear RGB image, row-major, top row first.
struct Image {
  int width = 0;
  int height = 0;
  std::vector<glm::vec3> pixels;

  Image() = default;
  Image(int w, int h) : width(w), height(h), pixels(static_cast<size_t>(w) * h, glm::vec3(0.0f)) {}
  glm::vec3& at(int x, int y) { return pixels[static_cast<size_t>(y) * width + x]; }
  const glm::vec3& at(int x, int y) const { return pixels[static_cast<size_t>(y) * width + x]; }
};

struct Tile {
  int x0, y0, x1, y1;  ///< pixel range [x0, x1) x [y0, y1)
};

/// Calls `fn` once for every `size` x `size` tile (8x8 unless asked otherwise) of a width x
/// height image, on `threads` workers (0 = all cores). Tiles are independent, so the result does
/// not depend on the thread count.
void for_each_tile(int width, int height, int threads, const std::function<void(const Tile&)>& fn,
                   int size = kTileSize);

/// The rays of the 4 x `rows` pixel block at (x, y) with packet lane i = (x + i % 4, y + i / 4),
/// i < 4 rows; lanes outside the image (and past the block) are left out of the returned mask.
LaneMask primary_packet(const Camera& cam, int x, int y, RayPacket& rays, int rows = kPacketRows);

struct RenderOptions {
  int threads = 0;      ///< 0 = all cores
  bool packets = true;  ///< trace packets of 4 x kPacketRows pixels (else single rays)
};

/// Colour of an eye-light hit (shared by the packet and single-ray paths).
glm::vec3 eye_light(const Triangle& tri, const glm::vec3& dir);

/// Eye-light shading: brightness |cos| between the view ray and the surface, tinted by the
/// normal's direction, so geometry can be looked at before materials exist. Background black.
/// `Tracer` has intersect(Ray) and intersect(RayPacket, LaneMask, HitPacket&) (KdTree, Bvh,
/// TwoLevelScene); `triangle_of(hit)` gives the world-space triangle a hit names.
template <class Tracer, class TriangleOf>
Image render_eye_light(const Tracer& tracer, const TriangleOf& triangle_of, const Camera& cam,
                       const RenderOptions& opt = {}) {
  Image img(cam.width, cam.height);
  for_each_tile(cam.width, cam.height, opt.threads, [&](const Tile& t) {
    if (opt.packets) {
      RayPacket rays;
      HitPacket hits;
      for (int y = t.y0; y < t.y1; y += kPacketRows) {
        for (int x = t.x0; x < t.x1; x += 4) {
          const LaneMask mask = primary_packet(cam, x, y, rays);
          tracer.intersect(rays, mask, hits);
          for (int i = 0; i < kPacketSize; ++i) {
            if (!((mask >> i) & 1u) || hits.prim[i] == kInvalidId) continue;
            img.at(x + i % 4, y + i / 4) = eye_light(triangle_of(hits.get(i)), rays.get(i).dir);
          }
        }
      }
    } else {
      for (int y = t.y0; y < t.y1; ++y) {
        for (int x = t.x0; x < t.x1; ++x) {
          const Ray r = cam.ray(static_cast<float>(x) + 0.5f, static_cast<float>(y) + 0.5f);
          const Hit h = tracer.intersect(r);
          if (h.valid()) img.at(x, y) = eye_light(triangle_of(h), r.dir);
        }
      }
    }
  });
  return img;
}

/// The static kd-tree alone.
Image render_eye_light(const KdTree& tree, const Camera& cam, const RenderOptions& opt = {});

}  // namespace artrace::core
