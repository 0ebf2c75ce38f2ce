// artrace export: composites an AR scene into a recording and writes a clip (video through
// FFmpeg's libraries, see clip_writer.h: H.264 where available, MPEG-4 otherwise, Motion JPEG in
// .avi; or numbered PNGs with a shard.json naming the frames, which artrace join puts together).
// The output appears under its final name only when complete; Ctrl-C stops cleanly and leaves
// nothing behind.
#include "bench_util.h"
#include "commands.h"
#include "frame_views.h"
#include "ar_session.h"
#include "clip_writer.h"
#include "shards.h"
#include "stop_signals.h"

#include "artrace/ar/compositor.h"
#include "artrace/io/ar_scene.h"
#include "artrace/io/atomic_file.h"
#include "artrace/io/recording.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>

namespace artrace::tools {
namespace {

struct Options {
  std::string recording, output, frames;
  ArArgs ar;
  int first = 0, last = -1;
  bool side_by_side = false, no_occlusion = false, no_shadows = false, quiet = false;
  ClipOptions clip{0.0};  ///< and the frame rate a shard records; 0: the recording's
};

/// What makes a shard's frames besides their numbers: join refuses shards that differ in any.
nlohmann::json settings(const Options& opt) {
  std::error_code ec;
  const std::filesystem::path recording = std::filesystem::weakly_canonical(opt.recording, ec);
  return {{"recording", ec ? opt.recording : recording.string()},
          {"scene", file_digest(opt.ar.scene)},
          {"room", file_digest(opt.ar.room)},
          {"trajectory", file_digest(opt.ar.rec.trajectory)},
          {"intrinsics", file_digest(opt.ar.rec.intrinsics)},
          {"depth_scale", opt.ar.rec.depth_scale},
          {"depth_shift", opt.ar.rec.depth_shift},
          {"no_occlusion", opt.no_occlusion},
          {"no_shadows", opt.no_shadows},
          {"side_by_side", opt.side_by_side}};
}

void run(const Options& opt) {
  check_output_name(opt.output);
  check_outputs({{opt.output, clip_or_frames(opt.output)}}, ar_inputs(opt.recording, opt.ar));
  ArSession session(opt.recording, opt.ar, opt.quiet);
  ar::FrameSource& source = session.source();
  const int64_t count = source.frame_count().value_or(0);
  int64_t first = opt.first, last = opt.last;
  if (!opt.frames.empty()) {
    const FrameRange r = parse_frame_range(opt.frames);
    first = r.first;
    last = r.end >= 0 ? r.end - 1 : -1;
    if (r.end > count) {
      throw std::invalid_argument("frame range " + opt.frames + ": " + opt.recording + " has " + std::to_string(count) + " frames");
    }
  }
  last = last >= 0 ? std::min<int64_t>(last, count - 1) : count - 1;
  if (first < 0 || first > last) throw std::invalid_argument("frame range " + std::to_string(first) + ".." + std::to_string(last) + " is empty");
  ClipOptions clip = opt.clip;
  if (clip.fps <= 0.0) clip.fps = recording_rate(count, session.frame_span());
  source.seek(first);

  const std::filesystem::path out(opt.output);
  const bool video = is_video_path(out);
  const io::PartialOutput claim = prepare_partial(out);  // held until the output is in place
  const std::filesystem::path& partial = claim.path();
  std::unique_ptr<ClipWriter> writer;
  auto cleanup = [&] {
    writer.reset();
    std::error_code ec;
    std::filesystem::remove_all(partial, ec);
  };

  ar::CompositeOptions& copt = session.options();
  copt.occlusion = !opt.no_occlusion;
  copt.shadows = !opt.no_shadows;
  auto stop = std::make_unique<StopSignals>();  // until the frames are written
  const int64_t total = last - first + 1;
  const auto start = std::chrono::steady_clock::now();
  std::vector<double> real_rays;
  int width = 0, height = 0;
  std::vector<double> frame_ms, read_ms, update_ms, proxy_ms, trace_ms, shadow_ms, occlusion_ms, blend_ms, write_ms;
  try {
    // the next frame is read (decoded) on another thread while this one is composited
    FrameReader reader(source);
    ar::SensorFrame f;
    for (int64_t k = 0; k < total; ++k) {
      StopSignals::throw_if_stopped(out);
      double rm = 0.0;
      if (!reader.next(f, &rm)) throw std::runtime_error(opt.recording + ": ended at frame " + std::to_string(first + k));
      read_ms.push_back(rm);
      const auto t0 = std::chrono::steady_clock::now();
      ar::CompositeStats st;
      double um = 0.0;
      const ar::ColorImage c = session.composite(f, &st, &um);
      update_ms.push_back(um);
      proxy_ms.push_back(st.proxy_ms + st.real_depth_ms);
      trace_ms.push_back(st.trace_ms);
      shadow_ms.push_back(st.real_shadow_ms);
      real_rays.push_back(st.shadow_rays_real);
      occlusion_ms.push_back(st.occlusion_ms);
      blend_ms.push_back(st.composite_ms);
      cv::Mat img = to_bgr(c);
      if (opt.side_by_side) cv::hconcat(std::vector<cv::Mat>{img, to_bgr(f.color), depth_view(f.depth, c.width, c.height)}, img);
      frame_ms.push_back(ms_since(t0));
      const auto tw = std::chrono::steady_clock::now();
      if (video) {
        if (!writer) writer = std::make_unique<ClipWriter>(partial, out.string(), img.size(), clip);
        writer->write(img);
      } else {
        io::write_png(frame_png(partial, first + k), img, /*atomically=*/false);  // the folder is partial until the end
        width = img.cols;
        height = img.rows;
      }
      write_ms.push_back(ms_since(tw));
      if (!opt.quiet) {
        const double s = ms_since(start) / 1000.0, fps = (k + 1) / std::max(s, 1e-9);
        std::fprintf(stderr, "\rframe %lld/%lld  %.1f frames/s  %.0f s left   ", static_cast<long long>(k + 1),
                     static_cast<long long>(total), fps, (total - k - 1) / fps);
      }
    }
    if (writer) writer->finish();
  } catch (...) {
    stop.reset();
    if (!opt.quiet) std::fprintf(stderr, "\n");
    cleanup();
    throw;
  }
  stop.reset();
  if (!video) {
    // a folder of frames is a shard: it says which frames of which recording it holds, for join
    try {
      write_shard_info({partial, opt.recording, first, last + 1, count, width, height, clip.fps, settings(opt)});
    } catch (...) {
      cleanup();
      throw;
    }
  }
  std::filesystem::remove_all(out);
  std::filesystem::rename(partial, out);
  const double s = ms_since(start) / 1000.0;
  if (!opt.quiet) std::fprintf(stderr, "\n");
  std::printf("%s: %lld frames in %.2f s (%.1f frames/s, %.1f ms median per frame)\n", out.string().c_str(),
              static_cast<long long>(total), s, total / std::max(s, 1e-9), median(frame_ms));
  if (!opt.quiet) {
    std::printf("  medians: read %.1f, update %.1f, real scene %.1f, trace %.1f, shadows on real surfaces %.1f, occlusion %.1f, "
                "blend %.1f, encode %.1f ms; %.0f shadow rays from real points\n",
                median(read_ms), median(update_ms), median(proxy_ms), median(trace_ms), median(shadow_ms), median(occlusion_ms),
                median(blend_ms), median(write_ms), median(real_rays));
  }
  if (session.frames_without_pose() > 0) {
    std::fprintf(stderr, "warning: %lld of %lld frames had no camera pose and are as recorded, without the virtual objects\n",
                 static_cast<long long>(session.frames_without_pose()), static_cast<long long>(total));
  }
  if (const int64_t posed = total - session.frames_without_pose(); posed > 0 && session.frames_in_view() == 0) {
    std::fprintf(stderr,
                 "warning: no virtual object came into view in any of the %lld frames: check the models' positions against the "
                 "recording's world (artrace info REC --planes lists a frame's large surfaces in it)\n",
                 static_cast<long long>(posed));
  }
}

}  // namespace

void add_export_command(CLI::App& app) {
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("export", "Composite an AR scene into a recording and write a clip");
  cmd->add_option("recording", opt->recording, "TUM folder, image folder or .oni file")->required();
  add_ar_options(cmd, opt->ar);
  cmd->add_option("-o,--output", opt->output, "clip.mp4 (or .mkv, .mov, .avi), or a folder for numbered PNGs")->required();
  cmd->add_option("--frames", opt->frames,
                  "frames A:B (A to B-1; A: to the end): a shard, the same frames as a whole export gives; into a folder, "
                  "for artrace join");
  cmd->add_option("--first", opt->first, "first frame")->capture_default_str()->check(CLI::Range(0, 100000000));
  cmd->add_option("--last", opt->last, "last frame (-1: to the end)")->capture_default_str()->check(CLI::Range(-1, 100000000));
  cmd->add_flag("--side-by-side", opt->side_by_side, "composite, original and depth side by side");
  cmd->add_option("--fps", opt->clip.fps, "frame rate of a video clip (default: the recording's, its frames over their time span)")
      ->check(finite_range(1.0, 1000.0));
  add_clip_options(cmd, opt->clip);
  cmd->add_flag("--no-occlusion", opt->no_occlusion, "draw the virtual objects over everything");
  cmd->add_flag("--no-shadows", opt->no_shadows, "no shadow rays");
  cmd->add_flag("-q,--quiet", opt->quiet, "no progress line");
  cmd->callback([opt] { run(*opt); });

  auto dir = std::make_shared<std::string>();
  CLI::App* models = app.add_subcommand("make-models", "Write the project's own glTF models (a spinning box, a glass sphere, a bending skinned tube)");
  models->add_option("folder", *dir, "where to write them")->required();
  models->callback([dir] {
    io::write_gltf(io::make_spinning_box(0.2f, {0.85f, 0.25f, 0.1f}), std::filesystem::path(*dir) / "spinning_box.gltf");
    io::write_gltf(io::make_glass_sphere(io::kShippedGlassSphereRadius), std::filesystem::path(*dir) / "glass_sphere.gltf");
    io::write_gltf(io::make_bending_tube(0.6f, 0.08f, {0.2f, 0.7f, 0.3f}), std::filesystem::path(*dir) / "bending_tube.gltf");
    std::printf("%s: spinning_box.gltf, glass_sphere.gltf, bending_tube.gltf\n", dir->c_str());
  });
}

}  // namespace artrace::tools
