// artrace bench-dynamic: plays a BART animation through the two-level scene's update API and
// times, per frame, the update of the dynamic structures and the tracing of an eye-light frame;
// then the same frames with one BVH over everything rebuilt every frame, for comparison.
#include "bench_util.h"
#include "commands.h"

#include "artrace/core/simd_level.h"
#include "artrace/io/bart_animation.h"

#include <tbb/task_arena.h>

#include <cstdio>
#include <iostream>
#include <memory>

namespace artrace::tools {
namespace {

struct Options : AnimationOptions {
  std::string json, frames_dir;
  int rebuild_frames = 0;
};

void run(const Options& opt) {
  check_outputs({{opt.json}}, {opt.scene});
  const int threads = opt.threads > 0 ? opt.threads : tbb::this_task_arena::max_concurrency();
  tbb::task_arena arena(threads);
  const io::AffScene aff = io::load_aff(opt.scene);
  const auto config = core::TwoLevelScene::parse_config(opt.config);
  auto t0 = std::chrono::steady_clock::now();
  io::BartAnimation anim(aff, config);
  const double setup_ms = ms_since(t0);

  const int total = std::max(1, aff.anim_frames);
  const int n = std::max(1, std::min(opt.frames, total));
  auto frame_index = [&](int k) { return n == 1 ? 0 : static_cast<int>(static_cast<long>(k) * (total - 1) / (n - 1)); };

  std::vector<double> update_ms, trace_ms, frame_ms;
  uint32_t first_frame_nodes = 0;
  nlohmann::json per_frame = nlohmann::json::array();
  const core::RenderOptions ropt{threads, true};
  for (int k = 0; k < n; ++k) {
    const double t = aff.frame_time(frame_index(k));
    const double up = arena.execute([&] { return anim.set_time(t); });
    const core::Camera cam = aff.camera_at(t, opt.width, opt.height);
    t0 = std::chrono::steady_clock::now();
    const core::Image img = core::render_eye_light(
        anim.scene(), [&](const core::Hit& h) { return anim.scene().world_triangle(h); }, cam, ropt);
    const double tr = ms_since(t0);
    update_ms.push_back(up);
    trace_ms.push_back(tr);
    frame_ms.push_back(up + tr);
    per_frame.push_back({{"t", t}, {"update_ms", up}, {"trace_ms", tr}});
    if (k == 0) first_frame_nodes = anim.scene().bvh_stats().nodes_built;
    if (!opt.frames_dir.empty()) {
      char name[64];
      std::snprintf(name, sizeof(name), "frame_%04d.png", frame_index(k));
      write_png(img, std::filesystem::path(opt.frames_dir) / name);
    }
  }
  const core::BvhStats lazy = anim.scene().bvh_stats();
  const core::BvhStats full_objects = anim.scene().bvh_stats_full();

  // Baseline: one BVH over the flattened scene, built in full every frame.
  const int nb = opt.rebuild_frames > 0 ? std::min(opt.rebuild_frames, n) : n;
  std::vector<double> rebuild_ms, rebuild_frame_ms;
  uint32_t full_nodes = 0;
  for (int k = 0; k < nb; ++k) {
    const int f = frame_index(static_cast<int>(static_cast<long>(k) * (n - 1) / std::max(1, nb - 1)));
    const double t = aff.frame_time(f);
    std::vector<core::Triangle> flat = aff.triangles_at(t);
    t0 = std::chrono::steady_clock::now();
    core::Bvh bvh;
    arena.execute([&] {
      bvh.rebuild(std::move(flat));
      bvh.build_all();
    });
    const double build = ms_since(t0);
    const core::Camera cam = aff.camera_at(t, opt.width, opt.height);
    const auto& tris = bvh.triangles();
    t0 = std::chrono::steady_clock::now();
    core::render_eye_light(bvh, [&](const core::Hit& h) { return tris[h.prim]; }, cam, ropt);
    const double tr = ms_since(t0);
    rebuild_ms.push_back(build);
    rebuild_frame_ms.push_back(build + tr);
    full_nodes = bvh.stats().nodes_built;
  }

  nlohmann::json out;
  out["scene"] = opt.scene;
  out["config"] = opt.config;
  out["frames"] = n;
  out["width"] = opt.width;
  out["height"] = opt.height;
  out["threads"] = threads;
  out["simd"] = core::to_string(core::simd_level());
  out["instances"] = anim.scene().instance_count();
  out["setup_ms"] = setup_ms;
  out["update_ms_median"] = median(update_ms);
  out["update_ms_max"] = *std::max_element(update_ms.begin(), update_ms.end());
  out["trace_ms_median"] = median(trace_ms);
  out["frame_ms_median"] = median(frame_ms);
  out["total_s"] = [&] { double s = 0; for (double v : frame_ms) s += v; return s / 1000.0; }();
  out["rebuild_frames"] = nb;
  out["rebuild_build_ms_median"] = median(rebuild_ms);
  out["rebuild_frame_ms_median"] = median(rebuild_frame_ms);
  out["bvh_nodes_built_first_frame"] = first_frame_nodes;
  out["bvh_nodes_full_build"] = full_objects.nodes_built;
  out["bvh_nodes_built_lazily"] = lazy.nodes_built;
  out["bvh_nodes_unbuilt"] = lazy.nodes_unbuilt;
  out["full_bvh_nodes_everything"] = full_nodes;
  out["per_frame"] = per_frame;
  std::printf("bench-dynamic %s, %s, %d frames at %dx%d, %d threads, %zu instances\n", opt.scene.c_str(),
              opt.config.c_str(), n, opt.width, opt.height, threads, anim.scene().instance_count());
  std::printf("  update %.3f ms (median; max %.3f), trace %.2f ms, frame %.2f ms; total %.2f s\n", median(update_ms),
              out["update_ms_max"].get<double>(), median(trace_ms), median(frame_ms), out["total_s"].get<double>());
  std::printf("  one BVH rebuilt every frame (%d frames): build %.2f ms, frame %.2f ms\n", nb, median(rebuild_ms),
              median(rebuild_frame_ms));
  std::printf("  object BVH nodes built lazily: %u for the first frame, %u over all frames; %u in a full build "
              "of the same BVHs (one BVH over everything: %u)\n",
              first_frame_nodes, lazy.nodes_built, full_objects.nodes_built, full_nodes);
  write_json(opt.json, out);
}

}  // namespace

void add_bench_dynamic_command(CLI::App& app) {
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("bench-dynamic", "Play a BART animation through the update API and time it");
  add_animation_options(cmd, *opt);
  cmd->add_option("--rebuild-frames", opt->rebuild_frames, "frames for the rebuild-everything baseline (0 = all)")->capture_default_str()->check(CLI::Range(0, 100000));
  cmd->add_option("--write-frames", opt->frames_dir, "folder to write every rendered frame to as PNG");
  cmd->add_option("--json", opt->json, "write the results as JSON");
  cmd->callback([opt] { run(*opt); });
}

}  // namespace artrace::tools
