// The subcommands of the artrace program; each registers its options and its callback.
#pragma once

#include <CLI/CLI.hpp>

#include "outputs.h"

#include "artrace/core/renderer.h"

#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>

namespace artrace::tools {

void add_render_command(CLI::App& app);
void add_bench_core_command(CLI::App& app);
void add_bench_dynamic_command(CLI::App& app);
void add_recording_commands(CLI::App& app);
void add_bench_occlusion_command(CLI::App& app);
void add_export_command(CLI::App& app);
void add_replay_command(CLI::App& app);
void add_bench_bart_command(CLI::App& app);
void add_bench_ar_command(CLI::App& app);
void add_join_command(CLI::App& app);
void add_batch_command(CLI::App& app);

/// A number that is finite and within [lo, hi]. CLI::Range lets NaN through (NaN fails no
/// comparison), and "nan" or "inf" parse as numbers.
inline CLI::Validator finite_range(double lo, double hi) {
  std::ostringstream desc;
  desc << "FLOAT in [" << lo << " - " << hi << "]";
  return CLI::Validator(
      [lo, hi](std::string& s) {
        char* end = nullptr;
        const double v = std::strtod(s.c_str(), &end);
        if (end == s.c_str() || *end != '\0') return "Value " + s + " is not a number";
        if (v >= lo && v <= hi) return std::string();
        std::ostringstream m;
        m << "Value " << s << " not in range " << lo << " to " << hi;
        return m.str();
      },
      desc.str());
}

/// --threads, 0 (every core) to 1024.
inline void add_threads_option(CLI::App* cmd, int& threads) {
  cmd->add_option("--threads", threads, "worker threads (0 = all cores)")->capture_default_str()->check(CLI::Range(0, 1024));
}

/// Options of the commands that play a BART animation.
struct AnimationOptions {
  std::string scene, config = "kdtree+bvh";
  int frames = 800, width = 512, height = 400, threads = 0;
};

/// --scene, --frames, --width, --height, --threads, --config.
inline void add_animation_options(CLI::App* cmd, AnimationOptions& o) {
  cmd->add_option("--scene", o.scene, "BART .aff scene")->required()->check(CLI::ExistingFile);
  cmd->add_option("--frames", o.frames, "frames to render (spread over the animation)")->capture_default_str()->check(CLI::Range(1, 100000));
  cmd->add_option("--width", o.width, "image width")->capture_default_str()->check(CLI::Range(8, 16384));
  cmd->add_option("--height", o.height, "image height")->capture_default_str()->check(CLI::Range(8, 16384));
  add_threads_option(cmd, o.threads);
  cmd->add_option("--config", o.config, "bvh or kdtree+bvh")->capture_default_str()->check(CLI::IsMember({"bvh", "kdtree+bvh"}));
}

/// Writes an image as 8-bit PNG (sRGB-encoded) via a temporary file renamed into place, so an
/// interrupted run never leaves a half-written file under the final name. Throws on failure.
void write_png(const core::Image& img, const std::filesystem::path& path);

}  // namespace artrace::tools
