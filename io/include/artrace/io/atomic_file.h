// Files written whole or not at all. A full disk shows only when buffered bytes reach it, at a
// flush or a close that streams and some libraries do not check: OpenCV's imwrite, tinygltf and
// Open3D's PLY writer each left an empty or cut file on a full disk and reported success. Here
// every step is checked, and the system's reason is given.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

namespace cv {
class Mat;
}

namespace artrace::io {

/// Writes `bytes` as the whole of `path`: opened, written, flushed and closed, each step checked.
/// Throws std::runtime_error "PATH: cannot write: REASON" (the system's, "No space left on device"
/// say); a regular file cut short is then removed.
void write_file(const std::filesystem::path& path, std::string_view bytes);

/// write_file() into PATH.partial, renamed over `path` once complete: on failure nothing appears
/// under `path` (an earlier file of that name stays) and PATH.partial is removed. Creates the
/// parent folders.
void write_file_atomically(const std::filesystem::path& path, std::string_view bytes);

/// The ".partial" file or folder a long write (a clip, a folder of frames, a recording) goes into
/// before it is renamed into place, held by this process under an advisory lock (flock) for as long
/// as the object lives. A second writer of the same output is refused, "OUT: is being written by
/// another process (PARTIAL is in use)", instead of removing the first one's partial output from
/// under it or mixing its own into it; a partial left by a process that died (its lock went with
/// it) is removed. The claimed partial is new and empty: made under a unique name, locked, then
/// renamed to its own without replacing anything. The writer removes or renames it; the destructor
/// only lets the lock go.
class PartialOutput {
 public:
  enum class Kind { file, folder };
  /// `out`: the output's name, for messages. Creates the parent folders.
  PartialOutput(std::filesystem::path partial, Kind kind, std::string out);
  ~PartialOutput();
  PartialOutput(PartialOutput&& other) noexcept;
  PartialOutput& operator=(PartialOutput&&) = delete;
  PartialOutput(const PartialOutput&) = delete;
  PartialOutput& operator=(const PartialOutput&) = delete;

  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
  int fd_ = -1;
};

/// `image` (8-bit BGR or grey, or 16-bit grey) encoded as PNG in memory, then written by
/// write_file_atomically(), or by write_file() (`atomically` false: into a folder that is itself
/// still partial). OpenCV's imwrite reports success on a full disk.
void write_png(const std::filesystem::path& path, const cv::Mat& image, bool atomically = true);

}  // namespace artrace::io
