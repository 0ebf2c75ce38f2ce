// Opens any supported recording by what it is: a folder in the TUM RGB-D layout, or an ONI file.
#pragma once

#include "artrace/ar/sensor_frame.h"

#include <filesystem>
#include <memory>

namespace artrace::io {

/// Throws ParseError naming the path when it is neither, or when the reader refuses it.
std::unique_ptr<ar::FrameSource> open_recording(const std::filesystem::path& path);

}  // namespace artrace::io
