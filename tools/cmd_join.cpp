// artrace join: puts the shards of an export (folders of PNGs from export --frames) together into
// one clip, encoded in one go, or one folder of frames. It refuses, naming the frames, when the
// shards leave a gap or overlap, and writes nothing under the final name until it is complete.
#include "bench_util.h"
#include "clip_writer.h"
#include "commands.h"
#include "outputs.h"
#include "shards.h"
#include "stop_signals.h"

#include <opencv2/imgcodecs.hpp>

#include <cstdio>
#include <memory>

namespace artrace::tools {
namespace {

struct JoinOptions {
  std::vector<std::string> shards;
  std::string output, frames;
  double fps = 0.0;
  bool quiet = false;
  ClipOptions clip;
};

void run_join(const JoinOptions& opt) {
  check_output_name(opt.output);
  check_outputs({{opt.output, clip_or_frames(opt.output)}}, opt.shards);
  std::vector<ShardInfo> shards;
  for (const std::string& s : opt.shards) shards.push_back(read_shard_info(s));
  const ShardInfo& a = shards.front();
  for (const ShardInfo& s : shards) {
    if (const std::string d = settings_difference(a.settings, s.settings); !d.empty()) {
      throw std::runtime_error(s.folder.string() + " is not a shard of the same export as " + a.folder.string() + ": its " + d);
    }
    if (s.recording_frames != a.recording_frames || s.width != a.width || s.height != a.height) {
      throw std::runtime_error(s.folder.string() + " is not a shard of the same export as " + a.folder.string() + " (" +
                               std::to_string(s.recording_frames) + " frames of " + std::to_string(s.width) + "x" +
                               std::to_string(s.height) + " against " + std::to_string(a.recording_frames) + " of " +
                               std::to_string(a.width) + "x" + std::to_string(a.height) + ")");
    }
  }
  FrameRange range{0, a.recording_frames};
  if (!opt.frames.empty()) {
    range = parse_frame_range(opt.frames);
    if (range.end < 0) range.end = a.recording_frames;
  }
  const std::vector<std::string> problems = coverage_problems(shards, range.first, range.end);
  if (!problems.empty()) {
    std::string msg = "cannot join: ";
    for (size_t i = 0; i < problems.size(); ++i) msg += (i ? "; " : "") + problems[i];
    throw std::runtime_error(msg + " (nothing written)");
  }
  // which shard holds each frame: the shards tile the range
  std::vector<const ShardInfo*> holder(static_cast<size_t>(range.end - range.first), nullptr);
  for (const ShardInfo& s : shards) {
    for (int64_t k = std::max(s.first, range.first); k < std::min(s.end, range.end); ++k) holder[k - range.first] = &s;
  }

  const std::filesystem::path out(opt.output);
  const bool video = is_video_path(out);
  const io::PartialOutput claim = prepare_partial(out);  // held until the output is in place
  const std::filesystem::path& partial = claim.path();
  std::unique_ptr<ClipWriter> writer;
  const double fps = opt.fps > 0.0 ? opt.fps : a.fps;
  ClipOptions clip = opt.clip;
  clip.fps = fps;
  auto stop = std::make_unique<StopSignals>();  // until the frames are written
  const auto start = std::chrono::steady_clock::now();
  try {
    for (int64_t k = range.first; k < range.end; ++k) {
      StopSignals::throw_if_stopped(out);
      const std::filesystem::path src = frame_png(holder[k - range.first]->folder, k);
      if (video) {
        const cv::Mat img = cv::imread(src.string(), cv::IMREAD_COLOR);
        if (img.empty()) throw std::runtime_error(src.string() + ": missing or not a PNG (frame " + std::to_string(k) + ")");
        if (img.cols != a.width || img.rows != a.height) {
          throw std::runtime_error(src.string() + ": " + std::to_string(img.cols) + "x" + std::to_string(img.rows) +
                                   ", the shard says " + std::to_string(a.width) + "x" + std::to_string(a.height));
        }
        if (!writer) writer = std::make_unique<ClipWriter>(partial, out.string(), img.size(), clip);
        writer->write(img);
      } else {
        // the frames as they are (a link where the filesystem allows it, else a copy)
        std::error_code ec;
        const std::filesystem::path dst = frame_png(partial, k);
        std::filesystem::create_hard_link(src, dst, ec);
        if (ec) std::filesystem::copy_file(src, dst, ec);
        if (ec) throw std::runtime_error(src.string() + ": " + ec.message() + " (frame " + std::to_string(k) + ")");
      }
      if (!opt.quiet) std::fprintf(stderr, "\rframe %lld/%lld   ", static_cast<long long>(k - range.first + 1), static_cast<long long>(range.end - range.first));
    }
    if (writer) writer->finish();
    if (!video) write_shard_info({partial, a.recording, range.first, range.end, a.recording_frames, a.width, a.height, fps, a.settings});
  } catch (...) {
    stop.reset();
    if (!opt.quiet) std::fprintf(stderr, "\n");
    writer.reset();
    std::error_code ec;
    std::filesystem::remove_all(partial, ec);
    throw;
  }
  stop.reset();
  std::filesystem::remove_all(out);
  std::filesystem::rename(partial, out);
  const double ms = ms_since(start);
  if (!opt.quiet) std::fprintf(stderr, "\n");
  const int64_t n = range.end - range.first;
  std::printf("%s: %lld frames from %zu shards in %.2f s (%.2f ms a frame)\n", out.string().c_str(), static_cast<long long>(n),
              shards.size(), ms / 1000.0, ms / static_cast<double>(n));
}

}  // namespace

void add_join_command(CLI::App& app) {
  auto opt = std::make_shared<JoinOptions>();
  CLI::App* cmd = app.add_subcommand("join", "Join the shards of an export (folders from export --frames) into one clip or folder");
  cmd->add_option("shards", opt->shards, "shard folders, in any order")->required();
  cmd->add_option("-o,--output", opt->output, "clip.mp4 (or .mkv, .mov, .avi), or a folder of numbered PNGs")->required();
  cmd->add_option("--frames", opt->frames, "the frames the shards must cover, A:B (default: the whole recording)");
  cmd->add_option("--fps", opt->fps, "frame rate of a video clip (default: the shards')")->check(finite_range(1.0, 1000.0));
  add_clip_options(cmd, opt->clip);
  cmd->add_flag("-q,--quiet", opt->quiet, "no progress line");
  cmd->callback([opt] { run_join(*opt); });
}

}  // namespace artrace::tools
