// The subcommands of the artrace program; each registers its options and its callback.
#pragma once

#include <CLI/CLI.hpp>

#include "artrace/core/renderer.h"

#include <filesystem>
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

/// Writes an image as 8-bit PNG (sRGB-encoded) via a temporary file renamed into place, so an
/// interrupted run never leaves a half-written file under the final name. Throws on failure.
void write_png(const core::Image& img, const std::filesystem::path& path);

}  // namespace artrace::tools
