// artrace bench-bart: the paper's Table 1 experiment. Plays a BART animation through the update
// API and renders every frame with Whitted shading in one of the four modes, timing each frame
// and splitting it into update, primary, shadow, secondary and shading time.
// artrace report-bart: runs all 16 cells (2 scenes x 2 configurations x 4 modes), prints a table
// laid out like Table 1 with the paper's times beside ours, and draws Figures 2 and 3.
#include "bench_util.h"
#include "commands.h"
#include "plot.h"

#include "artrace/core/simd_level.h"
#include "artrace/io/atomic_file.h"
#include "artrace/io/bart_shading.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <tbb/task_arena.h>

#include <cstdio>
#include <memory>

namespace artrace::tools {
namespace {

struct Options : AnimationOptions {
  std::string json, mode = "all", frames_dir, secondary = "packets", simd = "auto";
  int every = 1;
  float min_weight = 0.0f;
  bool quiet = false;
};

struct FrameTimes {
  double t, update, render, primary, shadow, secondary, shade;
  double total() const { return update + render; }
};

struct CellResult {
  std::vector<FrameTimes> frames;
  core::WhittedStats rays;  ///< summed over the frames
  double total_s = 0;
  nlohmann::json json;
};

CellResult run_cell(const Options& opt, const io::AffScene& aff) {
  const int threads = opt.threads > 0 ? opt.threads : tbb::this_task_arena::max_concurrency();
  tbb::task_arena arena(threads);
  const auto config = core::TwoLevelScene::parse_config(opt.config);
  io::BartAnimation anim(aff, config);
  io::BartSurfaces surfaces(anim);
  const core::ShadingScene shading = io::make_shading_scene(anim, surfaces);
  core::WhittedOptions wopt;
  wopt.mode = core::parse_shading_mode(opt.mode);
  wopt.threads = threads;
  wopt.min_weight = opt.min_weight;
  wopt.secondary_packets = opt.secondary == "packets";

  const int total = std::max(1, aff.anim_frames);
  const int n = std::max(1, std::min(opt.frames, total));
  auto frame_index = [&](int k) { return n == 1 ? 0 : static_cast<int>(static_cast<long>(k) * (total - 1) / (n - 1)); };
  CellResult r;
  nlohmann::json per_frame = nlohmann::json::array();
  const auto start = std::chrono::steady_clock::now();
  for (int k = 0; k < n; ++k) {
    const double t = aff.frame_time(frame_index(k));
    const double up = arena.execute([&] { return anim.set_time(t); });
    const core::Camera cam = aff.camera_at(t, opt.width, opt.height);
    core::WhittedStats st;
    const core::Image img = core::render_whitted(shading, cam, wopt, &st);
    // thread time of each part, scaled to the frame's wall time
    const double thread_ms = std::max(1e-9, st.primary_ms + st.shadow_ms + st.secondary_ms + st.shade_ms);
    const double f = st.wall_ms / thread_ms;
    FrameTimes ft{t, up, st.wall_ms, st.primary_ms * f, st.shadow_ms * f, st.secondary_ms * f, st.shade_ms * f};
    r.frames.push_back(ft);
    r.rays.primary_rays += st.primary_rays;
    r.rays.shadow_rays += st.shadow_rays;
    r.rays.secondary_rays += st.secondary_rays;
    r.rays.transmission_rays += st.transmission_rays;
    per_frame.push_back({{"t", t},
                         {"frame_ms", ft.total()},
                         {"update_ms", up},
                         {"primary_ms", ft.primary},
                         {"shadow_ms", ft.shadow},
                         {"secondary_ms", ft.secondary},
                         {"shade_ms", ft.shade}});
    if (!opt.frames_dir.empty() && k % std::max(1, opt.every) == 0) {
      char name[64];
      std::snprintf(name, sizeof(name), "frame_%04d.png", frame_index(k));
      write_png(img, std::filesystem::path(opt.frames_dir) / name);
    }
    if (!opt.quiet) std::fprintf(stderr, "\r%s %s %s: frame %d/%d  %.1f ms   ", aff.file.filename().string().c_str(), opt.config.c_str(), opt.mode.c_str(), k + 1, n, ft.total());
  }
  if (!opt.quiet) std::fprintf(stderr, "\n");
  const double wall_s = ms_since(start) / 1000.0;
  double total_ms = 0;
  std::vector<double> frame_ms, up, pr, sh, se, sd;
  for (const FrameTimes& ft : r.frames) {
    total_ms += ft.total();
    frame_ms.push_back(ft.total());
    up.push_back(ft.update);
    pr.push_back(ft.primary);
    sh.push_back(ft.shadow);
    se.push_back(ft.secondary);
    sd.push_back(ft.shade);
  }
  auto sum = [](const std::vector<double>& v) { double s = 0; for (double x : v) s += x; return s / 1000.0; };
  r.total_s = total_ms / 1000.0;
  r.json = {{"scene", aff.file.string()},
            {"config", opt.config},
            {"mode", opt.mode},
            {"frames", n},
            {"width", opt.width},
            {"height", opt.height},
            {"threads", threads},
            {"simd", core::to_string(core::simd_level())},
            {"secondary", opt.secondary},
            {"min_weight", opt.min_weight},
            {"total_s", r.total_s},
            {"wall_s", wall_s},
            {"frame_ms_median", median(frame_ms)},
            {"split_s", {{"update", sum(up)}, {"primary", sum(pr)}, {"shadow", sum(sh)}, {"secondary", sum(se)}, {"shade", sum(sd)}}},
            {"rays", {{"primary", r.rays.primary_rays},
                      {"shadow", r.rays.shadow_rays},
                      {"secondary", r.rays.secondary_rays},
                      {"shadow_transmission_walk", r.rays.transmission_rays}}},
            {"per_frame", per_frame}};
  return r;
}

void print_cell(const CellResult& r) {
  const auto& j = r.json;
  const auto& s = j["split_s"];
  std::printf("bench-bart %s, %s, %s, %d frames at %dx%d, %d threads (%s), secondary rays as %s\n",
              j["scene"].get<std::string>().c_str(), j["config"].get<std::string>().c_str(), j["mode"].get<std::string>().c_str(),
              j["frames"].get<int>(), j["width"].get<int>(), j["height"].get<int>(), j["threads"].get<int>(),
              j["simd"].get<std::string>().c_str(), j["secondary"].get<std::string>().c_str());
  std::printf("  total %.2f s (median frame %.2f ms): update %.2f s, primary %.2f s, shadow %.2f s, secondary %.2f s, shading %.2f s\n",
              r.total_s, j["frame_ms_median"].get<double>(), s["update"].get<double>(), s["primary"].get<double>(),
              s["shadow"].get<double>(), s["secondary"].get<double>(), s["shade"].get<double>());
  const auto& rays = j["rays"];
  std::printf("  rays: %llu primary, %llu shadow (+%llu walking transmissive surfaces), %llu secondary\n",
              static_cast<unsigned long long>(rays["primary"].get<uint64_t>()), static_cast<unsigned long long>(rays["shadow"].get<uint64_t>()),
              static_cast<unsigned long long>(rays["shadow_transmission_walk"].get<uint64_t>()),
              static_cast<unsigned long long>(rays["secondary"].get<uint64_t>()));
}

// ---- report: all 16 cells, Table 1 and Figures 2-3 ----

struct ReportOptions {
  std::string kitchen, robots, out = "docs/table1";
  int frames = 800, width = 512, height = 400, threads = 0;
  float min_weight = 0.0f;
};

/// The paper's all-effects times in seconds for 800 frames, Table 1 (d).
double paper_seconds(const std::string& scene, const std::string& config) {
  if (config == "kdtree+bvh") return scene == "kitchen" ? 380.06 : 509.00;
  return scene == "kitchen" ? 966.10 : 3275.54;
}

void run_report(const ReportOptions& ro) {
  // (d) full Whitted, and (d') the paper's workload (shadow rays at the camera rays' hits only),
  // which the paper's own figures imply: its (d) equals (b) + (c) - (a) to within 1% in every row
  const char* modes[] = {"diffuse", "shadows", "reflect", "all", "paper"};
  constexpr int kModes = 5;
  const char* configs[] = {"bvh", "kdtree+bvh"};
  nlohmann::json all = nlohmann::json::array();
  std::string table =
      "| scene | configuration | (a) diffuse | (b) + shadows | (c) + reflection, refraction | (d) all effects, full Whitted "
      "| (d') all effects, the paper's workload | paper (d) | speedup, like for like (d') | speedup, full Whitted (d) |\n"
      "|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& [name, path] : {std::pair<std::string, std::string>{"kitchen", ro.kitchen}, {"robots", ro.robots}}) {
    if (path.empty()) continue;
    const io::AffScene aff = io::load_aff(path);
    std::vector<double> per_mode_frames[kModes];  // kdtree+bvh per-frame ms, for the figures
    for (const char* config : configs) {
      std::string row = "| " + name + " | " + config + " |";
      double seconds[kModes] = {};
      for (int m = 0; m < kModes; ++m) {
        Options o;
        o.config = config;
        o.mode = modes[m];
        o.frames = ro.frames;
        o.width = ro.width;
        o.height = ro.height;
        o.threads = ro.threads;
        o.min_weight = ro.min_weight;
        const CellResult r = run_cell(o, aff);
        print_cell(r);
        nlohmann::json cell = r.json;
        cell.erase("per_frame");
        cell["scene_name"] = name;
        all.push_back(cell);
        char buf[64];
        std::snprintf(buf, sizeof(buf), " %.2f s |", r.total_s);
        row += buf;
        seconds[m] = r.total_s;
        if (std::string(config) == "kdtree+bvh") {
          for (const FrameTimes& f : r.frames) per_mode_frames[m].push_back(f.total());
        }
      }
      const double paper = paper_seconds(name, config);
      char buf[128];
      if (ro.frames != 800) {
        // the paper's time is for all 800 frames: no ratio against a shorter run
        std::snprintf(buf, sizeof(buf), " %.2f s (800 frames) | - | - |", paper);
      } else {
        std::snprintf(buf, sizeof(buf), " %.2f s | %.1fx | %.1fx |", paper, paper / seconds[4], paper / seconds[3]);
      }
      table += row + buf + "\n";
    }
    // Figures 2 (kitchen) and 3 (robots): t_diffuse = t(a), t_shadows = t(b) - t(a),
    // t_reflections+refractions = t(c) - t(a), per frame, kdtree+bvh
    std::vector<double> diffuse = per_mode_frames[0], shadows, refl;
    for (size_t i = 0; i < diffuse.size(); ++i) {
      shadows.push_back(std::max(0.0, per_mode_frames[1][i] - diffuse[i]));
      refl.push_back(std::max(0.0, per_mode_frames[2][i] - diffuse[i]));
    }
    const std::string fig = name == "kitchen" ? "figure2_kitchen.png" : "figure3_robots.png";
    plot(name + " (kdtree+bvh, " + std::to_string(ro.width) + "x" + std::to_string(ro.height) + "): time per frame",
         {{"t_diffuse", diffuse}, {"t_shadows", shadows}, {"t_reflections+refractions", refl}, {"t_all", per_mode_frames[3]}, {"t_all, paper's workload", per_mode_frames[4]}},
         std::filesystem::path(ro.out) / fig);
  }
  std::printf("\n%s", table.c_str());
  std::filesystem::create_directories(ro.out);
  io::write_file_atomically(std::filesystem::path(ro.out) / "table1.md", table);
  write_json((std::filesystem::path(ro.out) / "table1.json").string(), all);
}

}  // namespace

void add_bench_bart_command(CLI::App& app) {
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("bench-bart", "Render a BART animation with Whitted shading and time every frame (Table 1)");
  add_animation_options(cmd, *opt);
  cmd->add_option("--mode", opt->mode,
                  "diffuse, shadows, reflect, all (full Whitted: shadow rays at every hit) or paper (the paper's workload: "
                  "shadow rays at the camera rays' hits only)")
      ->capture_default_str()
      ->check(CLI::IsMember({"diffuse", "shadows", "reflect", "all", "paper"}));
  cmd->add_option("--secondary", opt->secondary, "trace reflection/refraction rays regrouped into packets or as single rays")
      ->capture_default_str()
      ->check(CLI::IsMember({"packets", "single"}));
  cmd->add_option("--min-weight", opt->min_weight, "no secondary ray whose weight is below this (0: every ray)")->capture_default_str()->check(finite_range(0, 1));
  cmd->add_option("--write-frames", opt->frames_dir, "folder to write rendered frames to as PNG");
  cmd->add_option("--every", opt->every, "with --write-frames: every n-th frame")->capture_default_str()->check(CLI::Range(1, 100000));
  cmd->add_option("--json", opt->json, "write the results (with per-frame times) as JSON");
  cmd->add_option("--simd", opt->simd, "packet kernels: auto, scalar, sse, avx2, avx512")->capture_default_str();
  cmd->add_flag("-q,--quiet", opt->quiet, "no progress line");
  cmd->callback([opt] {
    check_outputs({{opt->json}}, {opt->scene});
    core::set_simd_level(core::parse_simd_level(opt->simd));
    const io::AffScene aff = io::load_aff(opt->scene);
    const CellResult r = run_cell(*opt, aff);
    print_cell(r);
    write_json(opt->json, r.json);
  });

  auto ro = std::make_shared<ReportOptions>();
  CLI::App* rep = app.add_subcommand("report-bart", "All 20 cells of Table 1 (2 scenes x 2 configurations x 4 modes, and the paper's all-effects workload) and Figures 2-3");
  rep->add_option("--kitchen", ro->kitchen, "BART kitchen .aff")->check(CLI::ExistingFile);
  rep->add_option("--robots", ro->robots, "BART robots .aff")->check(CLI::ExistingFile);
  rep->add_option("--frames", ro->frames, "frames per cell")->capture_default_str()->check(CLI::Range(1, 100000));
  rep->add_option("--width", ro->width, "image width")->capture_default_str()->check(CLI::Range(8, 16384));
  rep->add_option("--height", ro->height, "image height")->capture_default_str()->check(CLI::Range(8, 16384));
  add_threads_option(rep, ro->threads);
  rep->add_option("--min-weight", ro->min_weight, "no secondary ray whose weight is below this")->capture_default_str()->check(finite_range(0, 1));
  rep->add_option("-o,--out", ro->out, "folder for table1.md, table1.json and the figures")->capture_default_str();
  rep->callback([ro] {
    if (ro->kitchen.empty() && ro->robots.empty()) throw std::invalid_argument("report-bart: give --kitchen and/or --robots");
    run_report(*ro);
  });
}

}  // namespace artrace::tools
