// Shards of an export: a frame range rendered on its own into a folder of PNGs with a
// shard.json that says which range of which recording it holds. `artrace join` checks that a set
// of shards covers a range exactly once and encodes it in one go. Also the commands' checks of
// their output names, which choose what is written.
#pragma once

#include "artrace/io/atomic_file.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace artrace::tools {

/// A half-open frame range [first, end); end = -1: to the end of the recording.
struct FrameRange {
  int64_t first = 0, end = -1;
};

/// "A:B" (frames A to B - 1), "A:" (A to the end) or ":B". Throws std::invalid_argument naming
/// the text when it is anything else or empty (B <= A).
FrameRange parse_frame_range(const std::string& text);

/// What a complete shard folder holds, from its shard.json.
struct ShardInfo {
  std::filesystem::path folder;
  std::string recording;
  int64_t first = 0, end = 0;  ///< frames [first, end), one PNG each: frame_%06d.png
  int64_t recording_frames = 0;
  int width = 0, height = 0;
  double fps = 30.0;
  /// What makes the frames besides their numbers (the recording, digests of the scene and the
  /// other input files, the options that change a picture); empty in shards written without it.
  nlohmann::json settings = nlohmann::json::object();
};

/// A digest (64-bit FNV-1a, hexadecimal) of a file's bytes, "" for an empty path: whether two
/// shards were made from the same scene, room, trajectory or intrinsics file.
std::string file_digest(const std::string& path);
/// The first setting in which two shards' settings differ, as "KEY differs (A against B)"; ""
/// when they agree or either has none.
std::string settings_difference(const nlohmann::json& a, const nlohmann::json& b);

constexpr const char* kShardManifest = "shard.json";

/// The PNG of frame `index` in a shard or frame folder.
std::filesystem::path frame_png(const std::filesystem::path& folder, int64_t index);

/// Writes `folder`/shard.json (the folder being a finished shard's contents, before it is
/// renamed into place).
void write_shard_info(const ShardInfo& s);
/// Reads a shard folder's shard.json; throws naming the folder when it is not a complete shard
/// (no shard.json: an export that did not finish, or another folder) or the file is malformed.
ShardInfo read_shard_info(const std::filesystem::path& folder);

/// Problems with covering [first, end) by these shards exactly once, in words ("frames 40-59 are
/// missing", "frames 20-29 are in both a/ and b/"); empty when they tile it.
std::vector<std::string> coverage_problems(std::vector<ShardInfo> shards, int64_t first, int64_t end);

/// Whether a path names a video clip by its extension (.mp4, .avi, .mkv, .mov, in any case).
bool is_video_path(const std::filesystem::path& p);
/// An output name checked before any work: one with the extension of a video or image format that
/// is not written (.webm, .gif, .png, ...) is refused, since a folder of PNGs under that name is
/// surely not what was meant; one with any other extension becomes a folder of PNGs, and a note
/// on stderr says so. A name without an extension is a folder of PNGs, silently.
void check_output_name(const std::filesystem::path& out);
/// Refuses, before any work, an output name that does not end in `ext` (in any case): `what` is
/// what the command writes ("PNG images"), for the message.
void require_output_extension(const std::filesystem::path& out, const std::string& ext, const std::string& what);
/// A recording's output: an .oni file (in any case), else a TUM folder; a folder name with an
/// extension gets a note on stderr saying that it becomes a folder.
void note_recording_output(const std::filesystem::path& out);
/// Where an output is written before it is complete: "clip.partial.mp4" beside a clip (the
/// extension kept, so that the encoder is chosen by it), "folder.partial" for a folder of PNGs;
/// claimed for this process (io::PartialOutput: new and empty, and refused while another process
/// writes the same output). Makes the output's parent folder.
io::PartialOutput prepare_partial(const std::filesystem::path& out);

}  // namespace artrace::tools
