// What a command's output may replace, checked before any work. A folder output (export's and
// join's numbered PNGs, convert's and synth's TUM layout) replaces the whole folder under its name,
// and a file output the file: neither may take an input with it, nor a folder of someone else's
// files.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace artrace::tools {

enum class OutputKind {
  file,          ///< a clip, an .oni recording, a trajectory, a mesh, an image, a JSON report
  frame_folder,  ///< numbered PNGs (frame_000000.png, ...) and shard.json: export's and join's
  tum_folder,    ///< rgb/, depth/, rgb.txt, depth.txt, groundtruth.txt, intrinsics.txt: convert's and synth's
};

struct Output {
  std::string path;  ///< "" when the output was not asked for
  OutputKind kind = OutputKind::file;
};

/// Throws std::invalid_argument naming the output and why, when writing it would replace
/// - one of `inputs` (the same path once links and "." and ".." are resolved), or a folder holding one;
/// - what the readers read inside an input folder (a recording's rgb.txt, groundtruth.txt, rgb/ or
///   intrinsics, a shard's frames; other names there are fine, new or not);
/// - a folder that holds an entry this kind of output does not write (checked one level down
///   for a TUM folder's rgb/ and depth/): the folder is someone else's;
/// - a file where a folder goes, or a folder where a file goes;
/// or when two of `outputs` are the same path. Empty paths in either list are skipped. A link
/// under an output's name is replaced itself, not what it points to, so only its target's being an
/// input counts against it.
void check_outputs(const std::vector<Output>& outputs, const std::vector<std::string>& inputs);

/// The kind of output a clip-or-folder name gives (export, join): a file for a clip name, else a
/// folder of frames.
OutputKind clip_or_frames(const std::filesystem::path& out);
/// The kind of output a recording name gives (convert, synth): a file for .oni, else a TUM folder;
/// with an .oni its poses' sidecar "<file>.trajectory.txt" is an output too.
std::vector<Output> recording_outputs(const std::string& out);
/// A recording's paths as inputs: the recording, an .oni's poses' sidecar where there is one, and
/// the intrinsics and trajectory files its options name.
std::vector<std::string> recording_inputs(const std::string& recording, const std::string& intrinsics = "",
                                          const std::string& trajectory = "");

}  // namespace artrace::tools
