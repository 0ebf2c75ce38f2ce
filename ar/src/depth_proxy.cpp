#include "artrace/ar/depth_proxy.h"
#include "packet_hits.h"

#include "artrace/ar/pinhole_intrinsics.h"
#include "artrace/core/srgb.h"

#include <chrono>
#include <cmath>

namespace artrace::ar {

namespace {
constexpr float kMinCos = 0.1f;  ///< about 84 degrees from the view ray
}  // namespace

DepthProxy::DepthProxy(int step, float max_jump) : step_(std::max(1, step)), max_jump_(max_jump) {}

double DepthProxy::update(const SensorFrame& frame) {
  const auto t0 = std::chrono::steady_clock::now();
  frame_ = &frame;
  const DepthImage& d = frame.depth;
  const int gw = d.width > 0 ? (d.width - 1) / step_ + 1 : 0, gh = d.height > 0 ? (d.height - 1) / step_ + 1 : 0;
  core::TriangleMesh mesh;
  mesh.positions.resize(static_cast<size_t>(gw) * gh);
  std::vector<float> z(mesh.positions.size(), 0.0f);
  const Eigen::Isometry3d pose = frame.world_from_camera.value_or(Eigen::Isometry3d::Identity());
  camera_from_world_ = pose.inverse();
  const PinholeIntrinsics& k = frame.color_intrinsics;
  for (int gy = 0; gy < gh; ++gy) {
    for (int gx = 0; gx < gw; ++gx) {
      const int x = gx * step_, y = gy * step_;
      // edge-preserving average over the cell around the vertex: the depths within 3% of the
      // centre's (sensor noise and disparity steps smoothed, edges kept)
      const float centre = d.at(x, y);
      float depth = 0.0f;
      if (centre > 0.0f) {
        float sum = 0.0f;
        int n = 0;
        const int r = std::max(1, step_ / 2);
        for (int yy = std::max(0, y - r); yy <= std::min(d.height - 1, y + r); ++yy) {
          for (int xx = std::max(0, x - r); xx <= std::min(d.width - 1, x + r); ++xx) {
            const float v = d.at(xx, yy);
            if (v > 0.0f && std::fabs(v - centre) <= 0.03f * centre) {
              sum += v;
              ++n;
            }
          }
        }
        depth = sum / static_cast<float>(n);
      }
      const size_t i = static_cast<size_t>(gy) * gw + gx;
      z[i] = depth;
      if (depth <= 0.0f) continue;
      const Eigen::Vector3d p = pose * k.unproject(x, y, depth);
      mesh.positions[i] = glm::vec3(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
    }
  }
  // A triangle across a depth discontinuity joins a foreground edge to the background: it is seen
  // nearly edge-on from the camera. Surfaces seen at a grazing angle (a table top from across the
  // room) change depth quickly too, so the test is on the angle, with a cap on the jump.
  const glm::vec3 eye(static_cast<float>(pose.translation().x()), static_cast<float>(pose.translation().y()),
                      static_cast<float>(pose.translation().z()));
  auto ok = [&](size_t a, size_t b, size_t c) {
    const float za = z[a], zb = z[b], zc = z[c];
    if (za <= 0.0f || zb <= 0.0f || zc <= 0.0f) return false;
    const float lo = std::min({za, zb, zc}), hi = std::max({za, zb, zc});
    if (hi - lo > 6.0f * max_jump_ * lo) return false;
    if (hi - lo <= max_jump_ * lo) return true;
    const glm::vec3 &pa = mesh.positions[a], &pb = mesh.positions[b], &pc = mesh.positions[c];
    const glm::vec3 n = glm::cross(pb - pa, pc - pa);
    const glm::vec3 view = (pa + pb + pc) / 3.0f - eye;
    const float nl = glm::length(n), vl = glm::length(view);
    return nl > 0.0f && vl > 0.0f && std::fabs(glm::dot(n, view)) > kMinCos * nl * vl;
  };
  for (int gy = 0; gy + 1 < gh; ++gy) {
    for (int gx = 0; gx + 1 < gw; ++gx) {
      const uint32_t a = static_cast<uint32_t>(gy * gw + gx), b = a + 1, c = a + static_cast<uint32_t>(gw), e = c + 1;
      if (ok(a, c, b)) mesh.indices.push_back({a, c, b});
      if (ok(b, c, e)) mesh.indices.push_back({b, c, e});
    }
  }
  triangles_ = mesh.indices.size();
  if (has_mesh_) {
    scene_.remove_deformable(mesh_);
    has_mesh_ = false;
  }
  if (triangles_ > 0) {
    mesh_ = scene_.add_deformable(std::move(mesh));
    has_mesh_ = true;
  }
  scene_.commit();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

bool DepthProxy::intersect(const core::Ray& ray, float& t, glm::vec3& colour) const {
  if (empty() || !frame_) return false;
  const core::Hit h = scene_.intersect(ray);
  if (!h.valid()) return false;
  t = h.t;
  return colour_at(ray.org + h.t * ray.dir, colour);
}

core::LaneMask DepthProxy::intersect(const core::RayPacket& rays, core::LaneMask mask, float* t, glm::vec3* colour) const {
  if (empty() || !frame_) return 0u;
  return detail::packet_hits(scene_, rays, mask, t, colour, [&](int i, const core::HitPacket& hits, glm::vec3& c) {
    const core::Ray r = rays.get(i);
    return colour_at(r.org + hits.t[i] * r.dir, c);
  });
}

bool DepthProxy::colour_at(const glm::vec3& p, glm::vec3& colour) const {
  // the recorded colour where the hit point projects into the colour frame
  const Eigen::Vector3d c = camera_from_world_ * Eigen::Vector3d(p.x, p.y, p.z);
  const ColorImage& img = frame_->color;
  if (c.z() <= 0.0) return false;
  const Eigen::Vector2d uv = frame_->color_intrinsics.project(c);
  const int x = std::clamp(static_cast<int>(std::lround(uv.x())), 0, img.width - 1);
  const int y = std::clamp(static_cast<int>(std::lround(uv.y())), 0, img.height - 1);
  const uint8_t* px = img.at(x, y);
  colour = {core::srgb8_to_linear(px[0]), core::srgb8_to_linear(px[1]), core::srgb8_to_linear(px[2])};
  return true;
}

}  // namespace artrace::ar
