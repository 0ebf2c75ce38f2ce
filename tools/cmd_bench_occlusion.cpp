// artrace bench-occlusion: occlusion-mask accuracy on a synthetic recording with the Kinect-like
// depth model, against the exact mask from the exact depth.
#include "bench_util.h"
#include "commands.h"

#include "artrace/ar/occlusion.h"
#include "artrace/ar/pinhole_intrinsics.h"
#include "artrace/core/two_level_scene.h"
#include "artrace/io/synth.h"

#include <cstdio>
#include <limits>
#include <memory>

namespace artrace::tools {
namespace {

std::vector<core::Triangle> box(const glm::vec3& lo, const glm::vec3& hi) {
  const glm::vec3 v[8] = {{lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {hi.x, hi.y, lo.z}, {lo.x, hi.y, lo.z},
                          {lo.x, lo.y, hi.z}, {hi.x, lo.y, hi.z}, {hi.x, hi.y, hi.z}, {lo.x, hi.y, hi.z}};
  const int f[12][3] = {{0, 3, 2}, {0, 2, 1}, {4, 5, 6}, {4, 6, 7}, {0, 4, 7}, {0, 7, 3},
                        {1, 2, 6}, {1, 6, 5}, {3, 7, 6}, {3, 6, 2}, {0, 1, 5}, {0, 5, 4}};
  std::vector<core::Triangle> t;
  for (const auto& k : f) t.push_back({v[k[0]], v[k[1]], v[k[2]]});
  return t;
}

struct Options {
  std::string scene, json, debug_png;
  int frames = 30, width = 640, height = 480, threads = 0;
  std::vector<float> box_lo{-0.45f, 0.0f, -1.3f}, box_hi{-0.05f, 1.1f, -0.75f};
};

void run(const Options& opt) {
  const io::AffScene scene = io::load_aff(opt.scene);
  io::SynthOptions so;
  so.frames = opt.frames;
  so.width = opt.width;
  so.height = opt.height;
  so.threads = opt.threads;
  io::Synthesizer exact(scene, so);
  so.depth_model = ar::DepthModel{};
  io::Synthesizer noisy(scene, so);
  core::TwoLevelScene virt;
  virt.add_instance(virt.add_rigid_mesh(box({opt.box_lo[0], opt.box_lo[1], opt.box_lo[2]},
                                            {opt.box_hi[0], opt.box_hi[1], opt.box_hi[2]})), glm::mat4(1.0f));
  virt.commit();

  std::vector<double> iou, boundary, outline, jitter, ms;
  int over_1px = 0;
  std::vector<uint8_t> prev_truth, prev_covered;
  std::vector<float> prev_alpha;
  for (int k = 0; k < opt.frames; ++k) {
    const ar::SensorFrame truth_frame = exact.render(k);
    const ar::SensorFrame f = noisy.render(k);
    const core::Camera cam = ar::make_camera(f.color_intrinsics, *f.world_from_camera);
    std::vector<float> zv(static_cast<size_t>(opt.width) * opt.height, std::numeric_limits<float>::infinity());
    core::for_each_tile(opt.width, opt.height, opt.threads, [&](const core::Tile& t) {
      for (int y = t.y0; y < t.y1; ++y)
        for (int x = t.x0; x < t.x1; ++x) {
          const core::Hit h = virt.intersect(cam.ray(x + 0.5f, y + 0.5f));
          if (h.valid()) zv[static_cast<size_t>(y) * opt.width + x] = h.t;
        }
    });
    const auto t0 = std::chrono::steady_clock::now();
    const std::vector<float> alpha = ar::occlusion_alpha(f.depth, f.color, zv);
    ms.push_back(ms_since(t0));
    const std::vector<uint8_t> truth = ar::exact_visibility(truth_frame.depth, zv);
    const std::vector<uint8_t> covered = ar::covered_pixels(zv);
    const ar::MaskScore s = ar::score_mask(alpha, truth, covered, opt.width, opt.height);
    iou.push_back(s.iou);
    outline.push_back(s.outline_boundary_px);
    if (s.boundary_pixels > 0) {
      boundary.push_back(s.boundary_px);
      over_1px += s.boundary_px > 1.0;
    }
    if (!prev_truth.empty()) {
      if (const auto j = ar::occlusion_jitter(prev_alpha, alpha, prev_truth, truth, prev_covered, covered, opt.width, opt.height)) {
        jitter.push_back(*j);
      }
    }
    if (!opt.debug_png.empty() && k == opt.frames / 2) {
      // grey: the recording; green: virtual and right; red: shown but hidden in truth; blue: the reverse
      core::Image img(opt.width, opt.height);
      for (size_t i = 0; i < truth.size(); ++i) {
        const float g = f.color.rgb[3 * i + 1] / 255.0f;
        const bool est = alpha[i] >= 0.5f;
        glm::vec3 c(0.3f * g);
        if (est && truth[i]) c = glm::vec3(0.1f, 0.6f, 0.1f);
        else if (est) c = glm::vec3(1.0f, 0.0f, 0.0f);
        else if (truth[i]) c = glm::vec3(0.0f, 0.2f, 1.0f);
        img.pixels[i] = c;
      }
      write_png(img, opt.debug_png);
      std::printf("frame %d: %d shown wrongly, %d hidden wrongly\n", k, s.false_visible, s.false_hidden);
    }
    prev_truth = truth;
    prev_alpha = alpha;
    prev_covered = covered;
  }
  auto worst = [](const std::vector<double>& v) { return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()); };
  const nlohmann::json out{{"scene", opt.scene}, {"frames", opt.frames}, {"width", opt.width}, {"height", opt.height},
                           {"iou", median(iou)}, {"iou_min", *std::min_element(iou.begin(), iou.end())},
                           {"boundary_px", median(boundary)}, {"boundary_px_worst", worst(boundary)},
                           {"boundary_frames", boundary.size()}, {"boundary_frames_over_1px", over_1px},
                           {"jitter_px", median(jitter)}, {"jitter_px_worst", worst(jitter)},
                           {"outline_boundary_px", median(outline)},
                           {"occlusion_ms_median", median(ms)}};
  std::printf("bench-occlusion %s, %d frames %dx%d, Kinect-like depth:\n"
              "  IoU %.4f (min %.4f)\n"
              "  occlusion boundary %.3f px (worst frame %.3f; %d of %zu frames over 1 px)\n"
              "  jitter %.3f px (worst %.3f) per pixel of true occlusion boundary\n"
              "  outline-inclusive one-sided boundary (the earlier figure) %.3f px\n"
              "  occlusion %.2f ms/frame (medians over frames)\n",
              opt.scene.c_str(), opt.frames, opt.width, opt.height, median(iou), out["iou_min"].get<double>(), median(boundary),
              worst(boundary), over_1px, boundary.size(), median(jitter), worst(jitter), median(outline), median(ms));
  write_json(opt.json, out);
}

}  // namespace

void add_bench_occlusion_command(CLI::App& app) {
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("bench-occlusion", "Occlusion-mask accuracy on a synthetic recording with Kinect-like depth");
  cmd->add_option("--scene", opt->scene, "AFF scene the recording is rendered from")->required()->check(CLI::ExistingFile);
  cmd->add_option("--frames", opt->frames, "frames")->capture_default_str()->check(CLI::Range(2, 10000));
  cmd->add_option("--width", opt->width, "image width")->capture_default_str()->check(CLI::Range(8, 4096));
  cmd->add_option("--height", opt->height, "image height")->capture_default_str()->check(CLI::Range(8, 4096));
  add_threads_option(cmd, opt->threads);
  cmd->add_option("--box-min", opt->box_lo, "virtual box corner (world)")->expected(3)->check(finite_range(-1e6, 1e6));
  cmd->add_option("--box-max", opt->box_hi, "virtual box corner (world)")->expected(3)->check(finite_range(-1e6, 1e6));
  cmd->add_option("--json", opt->json, "write iou, boundary_px, jitter_px as JSON");
  cmd->add_option("--debug-png", opt->debug_png, "write the middle frame's mask errors as a picture");
  cmd->callback([opt] { run(*opt); });
}

}  // namespace artrace::tools
