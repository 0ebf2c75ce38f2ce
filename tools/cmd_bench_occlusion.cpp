// artrace bench-occlusion: occlusion-mask accuracy on a synthetic recording with the Kinect-like
// depth model, against the exact mask from the exact depth.
#include "bench_util.h"
#include "commands.h"
#include "recording_options.h"

#include "artrace/ar/depth_registration.h"
#include "artrace/ar/occlusion.h"
#include "artrace/ar/pinhole_intrinsics.h"
#include "artrace/core/two_level_scene.h"
#include "artrace/io/fusion.h"
#include "artrace/io/synth.h"

#include "artrace/ar/compositor.h"

#include <cstdio>
#include <limits>
#include <memory>

namespace artrace::tools {
namespace {

struct Options {
  std::string scene, json, debug_png, depth_shift = "auto";
  int frames = 30, width = 640, height = 480, threads = 0;
  std::vector<float> box_lo{-0.45f, 0.0f, -1.3f}, box_hi{-0.05f, 1.1f, -0.75f};
  bool fuse = false;
  int debug_frame = -1;
  io::FusionOptions fusion = [] {
    io::FusionOptions f;
    f.max_depth_m = 8.0;  // the room is 4-7 m from the camera; the depth model reads to 8 m
    return f;
  }();
  ar::OcclusionOptions occlusion;
};

void run(const Options& opt) {
  check_outputs({{opt.json}, {opt.debug_png}}, {opt.scene});
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
  virt.add_instance(virt.add_rigid_mesh(core::box_triangles({opt.box_lo[0], opt.box_lo[1], opt.box_lo[2]},
                                            {opt.box_hi[0], opt.box_hi[1], opt.box_hi[2]})), glm::mat4(1.0f));
  virt.commit();

  // the frames first: the fused room (when asked for) integrates them all before any is judged
  std::vector<ar::SensorFrame> truth_frames, frames;
  for (int k = 0; k < opt.frames; ++k) {
    truth_frames.push_back(exact.render(k));
    frames.push_back(noisy.render(k));
  }
  // the depth lined up with the colour, as the recording commands do (--depth-shift)
  const ar::DepthShift shift = resolve_depth_shift(opt.depth_shift, [&] {
    std::vector<const ar::SensorFrame*> views;
    for (const ar::SensorFrame& f : frames) views.push_back(&f);
    return ar::estimate_depth_shift(views);
  });
  for (ar::SensorFrame& f : frames) f.depth = ar::shift_depth(f.depth, shift);
  std::unique_ptr<ar::FusedRoom> room;
  double fuse_s = 0.0;
  if (opt.fuse) {
    ar::FrameList list(frames, "the noisy synthetic recording");
    io::FusionStats fs;
    io::FusionOptions fo = opt.fusion;
    room = std::make_unique<ar::FusedRoom>(io::fuse_recording(list, fo, &fs));
    fuse_s = fs.seconds;
  }
  struct Figures {
    std::vector<double> iou, boundary, outline, jitter, ms;
    int over_1px = 0;
    std::vector<uint8_t> prev_truth, prev_covered;
    std::vector<float> prev_alpha;
  };
  Figures sensor, fused;
  auto judge = [&](Figures& fig, const std::vector<float>& alpha, const std::vector<uint8_t>& truth, const std::vector<uint8_t>& covered, double ms) {
    fig.ms.push_back(ms);
    const ar::MaskScore s = ar::score_mask(alpha, truth, covered, opt.width, opt.height);
    fig.iou.push_back(s.iou);
    fig.outline.push_back(s.outline_boundary_px);
    if (s.boundary_pixels > 0) {
      fig.boundary.push_back(s.boundary_px);
      fig.over_1px += s.boundary_px > 1.0;
    }
    if (!fig.prev_truth.empty()) {
      if (const auto j = ar::occlusion_jitter(fig.prev_alpha, alpha, fig.prev_truth, truth, fig.prev_covered, covered, opt.width, opt.height)) {
        fig.jitter.push_back(*j);
      }
    }
    fig.prev_truth = truth;
    fig.prev_alpha = alpha;
    fig.prev_covered = covered;
    return s;
  };
  for (int k = 0; k < opt.frames; ++k) {
    const ar::SensorFrame& truth_frame = truth_frames[static_cast<size_t>(k)];
    const ar::SensorFrame& f = frames[static_cast<size_t>(k)];
    const core::Camera cam = ar::make_camera(f.color_intrinsics, *f.world_from_camera);
    std::vector<float> zv(static_cast<size_t>(opt.width) * opt.height, std::numeric_limits<float>::infinity());
    core::for_each_tile(opt.width, opt.height, opt.threads, [&](const core::Tile& t) {
      for (int y = t.y0; y < t.y1; ++y)
        for (int x = t.x0; x < t.x1; ++x) {
          const core::Hit h = virt.intersect(cam.ray(x + 0.5f, y + 0.5f));
          if (h.valid()) zv[static_cast<size_t>(y) * opt.width + x] = h.t;
        }
    });
    const std::vector<uint8_t> truth = ar::exact_visibility(truth_frame.depth, zv);
    const std::vector<uint8_t> covered = ar::covered_pixels(zv);
    auto t0 = std::chrono::steady_clock::now();
    std::vector<float> alpha = ar::occlusion_alpha(f.depth, f.color, zv, opt.occlusion);
    ar::MaskScore s = judge(sensor, alpha, truth, covered, ms_since(t0));
    if (room) {
      t0 = std::chrono::steady_clock::now();
      ar::CompositeOptions co;
      co.room = room.get();
      co.threads = opt.threads;
      const ar::DepthImage clean = ar::clean_depth(f, co, 0, 0, opt.width, opt.height);
      alpha = ar::occlusion_alpha(clean, f.color, zv, opt.occlusion);  // the picture shows this one
      s = judge(fused, alpha, truth, covered, ms_since(t0));
    }
    if (!opt.debug_png.empty() && k == (opt.debug_frame >= 0 ? opt.debug_frame : opt.frames / 2)) {
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
  }
  auto worst = [](const std::vector<double>& v) { return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()); };
  auto figures = [&](const Figures& f) {
    return nlohmann::json{{"iou", median(f.iou)}, {"iou_min", f.iou.empty() ? 0.0 : *std::min_element(f.iou.begin(), f.iou.end())},
                          {"boundary_px", median(f.boundary)}, {"boundary_px_worst", worst(f.boundary)},
                          {"boundary_frames", f.boundary.size()}, {"boundary_frames_over_1px", f.over_1px},
                          {"jitter_px", median(f.jitter)}, {"jitter_px_worst", worst(f.jitter)},
                          {"outline_boundary_px", median(f.outline)}, {"occlusion_ms_median", median(f.ms)},
                          {"per_frame_iou", f.iou}, {"per_frame_boundary_px", f.boundary}};
  };
  auto print = [&](const char* what, const Figures& f) {
    std::printf("  %s: IoU %.4f (min %.4f), occlusion boundary %.3f px (worst frame %.3f; %d of %zu frames over 1 px), "
                "jitter %.3f px (worst %.3f), earlier outline-inclusive figure %.3f px, %.2f ms/frame\n",
                what, median(f.iou), f.iou.empty() ? 0.0 : *std::min_element(f.iou.begin(), f.iou.end()), median(f.boundary), worst(f.boundary),
                f.over_1px, f.boundary.size(), median(f.jitter), worst(f.jitter), median(f.outline), median(f.ms));
  };
  nlohmann::json out{{"scene", opt.scene}, {"frames", opt.frames}, {"width", opt.width}, {"height", opt.height},
                     {"depth_shift", {shift.dx, shift.dy}}, {"sensor_depth", figures(sensor)}};
  std::printf("bench-occlusion %s, %d frames %dx%d, Kinect-like depth (medians over frames; boundary on the occlusion boundary only, "
              "symmetric; jitter per pixel of true occlusion boundary), depth shifted %+d,%+d px:\n", opt.scene.c_str(), opt.frames, opt.width, opt.height,
              shift.dx, shift.dy);
  print("sensor depth", sensor);
  if (room) {
    out["fused_room"] = figures(fused);
    out["fuse_seconds"] = fuse_s;
    print("with the fused room", fused);
  }
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
  cmd->add_option("--debug-png", opt->debug_png, "write the mask errors of a frame (the middle one, or --debug-frame) as a picture");
  cmd->add_option("--debug-frame", opt->debug_frame, "the frame --debug-png shows")->check(CLI::Range(0, 100000));
  cmd->add_option("--guide-radius", opt->occlusion.guide_radius, "colour-guided refinement: window radius (pixels)")
      ->capture_default_str()
      ->check(CLI::Range(0, 16));
  cmd->add_option("--guide-sigma-color", opt->occlusion.guide_sigma_color, "colour-guided refinement: colour sigma (8-bit levels)")
      ->capture_default_str()
      ->check(finite_range(0.1, 1000.0));
  cmd->add_option("--guide-sigma-space", opt->occlusion.guide_sigma_space, "colour-guided refinement: spatial sigma (pixels)")
      ->capture_default_str()
      ->check(finite_range(0.1, 100.0));
  cmd->add_option("--voxel", opt->fusion.voxel_m, "--fuse: voxel edge (m)")->capture_default_str()->check(finite_range(0.001, 1.0));
  cmd->add_option("--truncation", opt->fusion.truncation_m, "--fuse: TSDF truncation (m)")->capture_default_str()->check(finite_range(0.002, 5.0));
  add_depth_shift_option(cmd, opt->depth_shift);
  cmd->add_flag("--fuse", opt->fuse, "also measure with the room fused from the noisy frames (artrace fuse) cleaning the depth");
  cmd->callback([opt] { run(*opt); });
}

}  // namespace artrace::tools
