#include "artrace/io/synth.h"
#include "artrace/io/bart_animation.h"

#include "artrace/core/renderer.h"
#include "artrace/core/srgb.h"

#include <glm/gtc/matrix_transform.hpp>

#include <cmath>

namespace artrace::io {
struct Synthesizer::Impl {
  const AffScene& scene;
  SynthOptions opt;
  BartAnimation anim;
  Impl(const AffScene& s, const SynthOptions& o) : scene(s), opt(o), anim(s, core::TwoLevelScene::Config::kKdTreeBvh) {}

  core::Camera camera(double scene_t, int k) const {
    if (scene.animations.count("camera")) {
      core::Camera c = scene.camera_at(scene_t, opt.width, opt.height);
      const core::Camera f = core::Camera::look_at({0, 0, 0}, {0, 0, -1}, {0, 1, 0}, static_cast<float>(opt.fov_y_deg), opt.width, opt.height);
      c.fx = f.fx;
      c.fy = f.fy;
      return c;
    }
    const AffView v = scene.view.value_or(AffView{});
    const double a = glm::radians(opt.orbit_deg) * (opt.frames > 1 ? static_cast<double>(k) / (opt.frames - 1) : 0.0);
    const glm::mat4 r = glm::rotate(glm::mat4(1.0f), static_cast<float>(a), glm::normalize(v.up));
    const glm::vec3 from = v.at + glm::vec3(r * glm::vec4(v.from - v.at, 0.0f));
    return core::Camera::look_at(from, v.at, v.up, static_cast<float>(opt.fov_y_deg), opt.width, opt.height);
  }
};

Synthesizer::Synthesizer(const AffScene& scene, const SynthOptions& options)
    : impl_(std::make_unique<Impl>(scene, options)) {}

Synthesizer::~Synthesizer() = default;

ar::SensorFrame Synthesizer::render(int k) {
  const SynthOptions& o = impl_->opt;
  const AffScene& scene = impl_->scene;
  // scene time runs with the recording's clock, wrapped into the animation's range
  const double span = scene.anim_end - scene.anim_start;
  double scene_t = scene.anim_start + static_cast<double>(k) / o.fps;
  if (span > 0.0) scene_t = scene.anim_start + std::fmod(scene_t - scene.anim_start, span);
  impl_->anim.set_time(scene_t);
  const core::Camera cam = impl_->camera(scene_t, k);
  const core::TwoLevelScene& tl = impl_->anim.scene();

  ar::SensorFrame f;
  f.index = k;
  f.color_time_s = f.depth_time_s = o.start_time_s + static_cast<double>(k) / o.fps;
  f.color.width = f.depth.width = o.width;
  f.color.height = f.depth.height = o.height;
  f.color.rgb.assign(static_cast<size_t>(o.width) * o.height * 3, 0);
  f.depth.depth_m.assign(static_cast<size_t>(o.width) * o.height, 0.0f);
  std::vector<glm::vec3> lights;
  for (const AffLight& l : scene.lights) lights.push_back(l.position);
  if (lights.empty()) lights.push_back(cam.position);
  core::for_each_tile(o.width, o.height, o.threads, [&](const core::Tile& t) {
    core::RayPacket rays;
    core::HitPacket hits;
    for (int y = t.y0; y < t.y1; y += core::kPacketRows) {
      for (int x = t.x0; x < t.x1; x += 4) {
        const core::LaneMask mask = core::primary_packet(cam, x, y, rays);
        tl.intersect(rays, mask, hits);
        for (int i = 0; i < core::kPacketSize; ++i) {
          const int px = x + i % 4, py = y + i / 4;
          if (!((mask >> i) & 1u)) continue;
          const size_t idx = static_cast<size_t>(py) * o.width + px;
          glm::vec3 c = scene.background;
          if (hits.prim[i] != core::kInvalidId) {
            const core::Hit h = hits.get(i);
            f.depth.depth_m[idx] = h.t;  // camera-space ray directions have z = 1: t is depth
            const core::Triangle tri = tl.world_triangle(h);
            const core::Ray r = rays.get(i);
            glm::vec3 n = glm::normalize(tri.geometric_normal());
            if (glm::dot(n, r.dir) > 0.0f) n = -n;
            const glm::vec3 p = r.org + h.t * r.dir;
            const AffMaterial& m = scene.materials.at(impl_->anim.material(h));
            glm::vec3 light(0.15f);
            for (const glm::vec3& lp : lights) light += glm::vec3(0.8f / lights.size()) * std::fmax(0.0f, glm::dot(n, glm::normalize(lp - p)));
            c = m.diffuse * light;
          }
          for (int ch = 0; ch < 3; ++ch) f.color.rgb[3 * idx + ch] = core::linear_to_srgb8(c[ch]);
        }
      }
    }
  });
  ar::PinholeIntrinsics k_in{o.width, o.height, cam.fx, cam.fy, cam.cx - 0.5, cam.cy - 0.5};
  f.color_intrinsics = f.depth_intrinsics = k_in;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) pose.linear()(r, c) = cam.rotation[c][r];
    pose.translation()[r] = cam.position[r];
  }
  f.world_from_camera = pose;
  if (o.depth_model) apply_depth_model(f.depth, k_in, *o.depth_model, o.seed * 1000003u + static_cast<uint64_t>(k));
  return f;
}

int Synthesizer::write(RecordingWriter& out) {
  for (int k = 0; k < impl_->opt.frames; ++k) out.write(render(k));
  out.close();
  return impl_->opt.frames;
}

}  // namespace artrace::io
