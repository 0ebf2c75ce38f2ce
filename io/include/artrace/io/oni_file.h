// Structure check of ONI files before OpenNI2 sees them: OpenNI2's player crashes on some corrupt
// files (a node without StateReady, codec 0, a property name with a byte above 127), so every
// record is walked here first.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace artrace::io {

struct OniNodeInfo {
  uint32_t id = 0;
  std::string name;
  uint32_t type = 0;   ///< 2 depth, 3 image, 5 IR
  uint32_t codec = 0;  ///< four characters, little-endian
  uint32_t frames = 0;
  int width = 0, height = 0, fps = 0;
  uint32_t data_records = 0;
  bool has_mode = false, has_cropping = false;  ///< xnMapOutputMode and xnCropping seen
};

struct OniFileInfo {
  uint64_t end_offset = 0;  ///< the End record (files may be padded after it)
  std::vector<OniNodeInfo> nodes;
};

/// Walks every record up to End; throws ParseError ("file @ byte N: problem") on anything the
/// player would choke on or that is not a well-formed recording.
OniFileInfo inspect_oni(const std::filesystem::path& path);

}  // namespace artrace::io
