// What a file name's extension says, in any case: "clip.MP4" is a clip as "clip.mp4" is.
#pragma once

#include <cctype>
#include <filesystem>
#include <string>

namespace artrace::io {

/// The extension of `p` in lower case: ".mp4" for "clip.MP4", "" for none.
inline std::string lower_extension(const std::filesystem::path& p) {
  std::string ext = p.extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

}  // namespace artrace::io
