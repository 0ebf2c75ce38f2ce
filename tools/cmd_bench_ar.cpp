// artrace bench-ar: the AR path end to end, as replay runs it: frames read and decoded on a thread
// of their own, one ahead, while the previous one is composited; no encoding, no window. Reports
// frames per second over the wall time and the median of each stage; optionally how steady the
// occlusion is where the models touch the surfaces they are anchored on.
#include "ar_session.h"
#include "commands.h"
#include "soak.h"

#include <cstdio>
#include <numeric>

namespace artrace::tools {
namespace {

struct Options {
  std::string recording, json, soak;
  int soak_every = 200;
  ArArgs ar;
  int frames = 0;
  bool contact = false, no_occlusion = false, no_shadows = false;
};

/// Pixels of the virtual objects within `band` metres of a support plane: where they touch it.
std::vector<uint8_t> contact_pixels(const ar::SensorFrame& f, const std::vector<float>& zv, const std::vector<ar::Plane>& planes, double band) {
  std::vector<uint8_t> out(zv.size(), 0);
  const ar::PinholeIntrinsics& k = f.color_intrinsics;
  const Eigen::Isometry3d pose = f.world_from_camera.value_or(Eigen::Isometry3d::Identity());
  for (size_t i = 0; i < zv.size(); ++i) {
    if (!std::isfinite(zv[i])) continue;
    const int u = static_cast<int>(i % static_cast<size_t>(f.color.width)), v = static_cast<int>(i / static_cast<size_t>(f.color.width));
    const Eigen::Vector3d p = pose * Eigen::Vector3d((u - k.cx) / k.fx * zv[i], (v - k.cy) / k.fy * zv[i], zv[i]);
    for (const ar::Plane& pl : planes) out[i] = out[i] || std::fabs(pl.distance(p)) < band;
  }
  return out;
}

void run(const Options& opt) {
  std::vector<Output> outputs = SoakLog::outputs(opt.soak);
  outputs.push_back({opt.json});
  check_outputs(outputs, ar_inputs(opt.recording, opt.ar));
  ArSession session(opt.recording, opt.ar);
  ar::CompositeOptions& copt = session.options();
  copt.occlusion = !opt.no_occlusion;
  copt.shadows = !opt.no_shadows;
  copt.keep_visibility = opt.contact;
  if (opt.contact && copt.support_planes.empty()) throw std::invalid_argument("--contact needs anchored models (their support planes)");
  ar::FrameSource& source = session.source();
  const int64_t count = source.frame_count().value_or(0);
  if (count <= 0) throw std::runtime_error(opt.recording + ": no frames");
  const int64_t total = opt.frames > 0 ? opt.frames : count;
  // warm-up: the first frame once (lazy BVH builds, page faults), not timed
  {
    ar::SensorFrame f;
    source.seek(0);
    if (source.next(f)) session.composite(f, nullptr);
    source.seek(0);
  }
  std::vector<double> frame_ms, read_ms, update_ms, real_ms, trace_ms, shadow_ms, occlusion_ms, blend_ms;
  std::vector<double> flips;
  SoakLog soak(opt.soak, opt.soak_every);
  std::vector<uint8_t> prev_vis, prev_contact;
  double contact_hidden = 0.0, contact_pixels_total = 0.0;
  FrameReader reader(source);
  ar::SensorFrame f;
  const int64_t unposed_before = session.frames_without_pose();  // the warm-up's
  const auto start = std::chrono::steady_clock::now();
  for (int64_t k = 0; k < total; ++k) {
    double rm = 0.0;
    if (!reader.next(f, &rm)) {  // loop the recording for more frames than it has
      reader.seek(0);
      prev_vis.clear();
      if (!reader.next(f, &rm)) throw std::runtime_error(opt.recording + ": no frames");
    }
    read_ms.push_back(rm);
    const auto t0 = std::chrono::steady_clock::now();
    ar::CompositeStats st;
    double um = 0.0;
    session.composite(f, &st, &um);
    frame_ms.push_back(ms_since(t0));
    update_ms.push_back(um);
    real_ms.push_back(st.proxy_ms + st.real_depth_ms);
    trace_ms.push_back(st.trace_ms);
    shadow_ms.push_back(st.real_shadow_ms);
    occlusion_ms.push_back(st.occlusion_ms);
    blend_ms.push_back(st.composite_ms);
    soak.add(frame_ms.back());
    if (opt.contact && !st.visibility.empty()) {
      const std::vector<uint8_t> near = contact_pixels(f, st.virtual_depth, copt.support_planes, 0.02);
      std::vector<uint8_t> vis(st.visibility.size());
      for (size_t i = 0; i < vis.size(); ++i) vis[i] = st.visibility[i] >= 0.5f;
      for (size_t i = 0; i < near.size(); ++i) {
        contact_pixels_total += near[i];
        contact_hidden += near[i] && !vis[i];
      }
      if (!prev_vis.empty()) {
        int both = 0, changed = 0;
        for (size_t i = 0; i < vis.size(); ++i) {
          if (!near[i] || !prev_contact[i]) continue;
          ++both;
          changed += vis[i] != prev_vis[i];
        }
        if (both > 0) flips.push_back(static_cast<double>(changed) / both);
      }
      prev_vis = vis;
      prev_contact = near;
    }
  }
  const double wall_s = ms_since(start) / 1000.0;
  const double fps = total / std::max(wall_s, 1e-9);
  nlohmann::json stages{{"read", median(read_ms)},         {"update", median(update_ms)},         {"real_scene", median(real_ms)},
                        {"trace", median(trace_ms)},       {"real_shadows", median(shadow_ms)}, {"occlusion", median(occlusion_ms)},
                        {"blend", median(blend_ms)}};
  std::printf("bench-ar %s --scene %s%s: %lld frames, %d threads: %.1f frames/s (wall), %.2f ms median a frame composited\n",
              opt.recording.c_str(), opt.ar.scene.c_str(), session.room() ? " (fused room)" : "", static_cast<long long>(total), opt.ar.threads,
              fps, median(frame_ms));
  std::printf("  read (own thread, overlapped)  %7.2f ms\n", median(read_ms));
  std::printf("  update                         %7.2f ms\n", median(update_ms));
  std::printf("  real scene                     %7.2f ms\n", median(real_ms));
  std::printf("  trace                          %7.2f ms\n", median(trace_ms));
  std::printf("  shadows on real surfaces       %7.2f ms\n", median(shadow_ms));
  std::printf("  occlusion                      %7.2f ms\n", median(occlusion_ms));
  std::printf("  blend                          %7.2f ms\n", median(blend_ms));
  const int64_t unposed = session.frames_without_pose() - unposed_before;
  if (unposed > 0) {
    std::printf("warning: %lld of %lld frames had no camera pose and were passed through as recorded: the figures above "
                "are not all the compositor's\n",
                static_cast<long long>(unposed), static_cast<long long>(total));
  }
  nlohmann::json out{{"recording", opt.recording}, {"scene", opt.ar.scene},     {"frames", total},   {"threads", opt.ar.threads},
                     {"fps", fps},                 {"frame_ms_median", median(frame_ms)}, {"stages", stages}, {"room", !opt.ar.room.empty() || session.room()},
                     {"frames_without_pose", unposed}};
  if (opt.contact) {
    const double share_hidden = contact_pixels_total > 0 ? contact_hidden / contact_pixels_total : 0.0;
    std::printf("  contact: %.4f of the pixels touching a support plane flip between frames (median), %.4f hidden\n", median(flips), share_hidden);
    out["contact"] = {{"flip_rate_median", median(flips)}, {"flip_rate_mean", flips.empty() ? 0.0 : std::accumulate(flips.begin(), flips.end(), 0.0) / flips.size()},
                      {"hidden_share", share_hidden}};
  }
  if (soak.on()) out["soak"] = soak.report();
  write_json(opt.json, out);
}

}  // namespace

void add_bench_ar_command(CLI::App& app) {
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("bench-ar", "Time the AR path end to end as replay runs it (reading overlapped, no encoding)");
  cmd->add_option("recording", opt->recording, "TUM folder, image folder or .oni file")->required();
  add_ar_options(cmd, opt->ar);
  cmd->add_option("--frames", opt->frames, "frames to composite (0: the recording's; more loop it)")->capture_default_str()->check(CLI::Range(0, 100000000));
  cmd->add_option("--json", opt->json, "write fps, frame_ms_median and the stages' medians as JSON");
  cmd->add_flag("--contact", opt->contact, "also measure how steady the occlusion is where anchored models touch their planes");
  cmd->add_option("--soak", opt->soak, "a long run: sample resident memory and frame time into PREFIX.csv, PREFIX_memory.png and PREFIX_frame_time.png");
  cmd->add_option("--soak-every", opt->soak_every, "frames between --soak samples")->capture_default_str()->check(CLI::Range(1, 1000000));
  cmd->add_flag("--no-occlusion", opt->no_occlusion, "draw the virtual objects over everything");
  cmd->add_flag("--no-shadows", opt->no_shadows, "no shadow rays");
  cmd->callback([opt] { run(*opt); });
}

}  // namespace artrace::tools
