// artrace render SCENE.aff -o frame.png: one frame with eye-light shading.
#include "commands.h"
#include "shards.h"

#include "artrace/core/simd_level.h"
#include "artrace/io/aff_scene.h"

#include <chrono>
#include <iostream>
#include <memory>

namespace artrace::tools {

void add_render_command(CLI::App& app) {
  struct Options {
    std::string scene, output = "out/frame.png", simd = "auto";
    double time = 0.0;
    int frame = -1, width = 512, height = 400, threads = 0;
    bool single = false;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("render", "Render one frame of an AFF scene to PNG (eye-light shading)");
  cmd->add_option("scene", opt->scene, "BART .aff scene file")->required()->check(CLI::ExistingFile);
  cmd->add_option("-o,--output", opt->output, "PNG file to write")->capture_default_str();
  cmd->add_option("--time", opt->time, "scene time t")->capture_default_str()->check(finite_range(-1e6, 1e6));
  cmd->add_option("--frame", opt->frame, "frame index of the scene's animation (overrides --time)")->check(CLI::Range(0, 100000000));
  cmd->add_option("--width", opt->width, "image width")->capture_default_str()->check(CLI::Range(1, 16384));
  cmd->add_option("--height", opt->height, "image height")->capture_default_str()->check(CLI::Range(1, 16384));
  add_threads_option(cmd, opt->threads);
  cmd->add_option("--simd", opt->simd, "packet kernels: auto, scalar, sse, avx2, avx512")->capture_default_str();
  cmd->add_flag("--single", opt->single, "trace single rays instead of packets");
  cmd->callback([opt] {
    require_output_extension(opt->output, ".png", "PNG images");
    check_outputs({{opt->output}}, {opt->scene});
    core::set_simd_level(core::parse_simd_level(opt->simd));
    const auto t0 = std::chrono::steady_clock::now();
    const io::AffScene scene = io::load_aff(opt->scene);
    const double t = opt->frame >= 0 ? scene.frame_time(opt->frame) : opt->time;
    const core::KdTree tree(scene.triangles_at(t));
    const auto t1 = std::chrono::steady_clock::now();
    const core::Camera cam = scene.camera_at(t, opt->width, opt->height);
    const core::Image img = core::render_eye_light(tree, cam, {opt->threads, !opt->single});
    const auto t2 = std::chrono::steady_clock::now();
    write_png(img, opt->output);
    std::cout << opt->output << ": " << tree.triangles().size() << " triangles at t=" << t << ", load+build "
              << std::chrono::duration<double, std::milli>(t1 - t0).count() << " ms, render "
              << std::chrono::duration<double, std::milli>(t2 - t1).count() << " ms\n";
  });
}

}  // namespace artrace::tools
