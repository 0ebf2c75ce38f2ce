// The whole of a text input (trajectories, frame lists, intrinsics, AR scenes, AFF scenes,
// manifests), read with the checks a text file passes: no NUL byte and a bounded size. Without
// them /dev/zero, or a binary file given by mistake, was read as one endless line: a hang, then
// memory exhausted.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>

namespace artrace::io {

/// Text files above this many bytes are refused (256 MiB: a trajectory of hours at 1 kHz is a
/// tenth of it).
constexpr std::size_t kMaxTextBytes = std::size_t{256} << 20;

/// The bytes of `path`. Throws ParseError naming the file: it cannot be opened; it holds a NUL byte
/// (with the line and byte); it runs past `max_bytes`.
std::string read_text_file(const std::filesystem::path& path, std::size_t max_bytes = kMaxTextBytes);

}  // namespace artrace::io
