#include "artrace/io/recording.h"
#include "artrace/io/image_folder_reader.h"
#include "artrace/io/oni_reader.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/tum_reader.h"

namespace artrace::io {

std::unique_ptr<ar::FrameSource> open_recording(const std::filesystem::path& path) {
  if (std::filesystem::is_directory(path)) {
    if (std::filesystem::exists(path / "rgb.txt")) return std::make_unique<TumReader>(path);
    if (ImageFolderReader::accepts(path)) return std::make_unique<ImageFolderReader>(path);
    throw ParseError(path.string(), 0, 0,
                     "folder is neither a TUM RGB-D sequence (rgb.txt) nor a colour/depth image folder (color/ or color.mp4, and depth/)");
  }
  if (!std::filesystem::exists(path)) throw ParseError(path.string(), 0, 0, "no such file or folder");
  return std::make_unique<OniReader>(path);  // identified by content, as OpenNI2 does
}

}  // namespace artrace::io
