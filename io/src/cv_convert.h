// OpenCV images to the frame types. Internal to io.
#pragma once

#include "artrace/ar/sensor_frame.h"

#include <opencv2/core.hpp>

#include <cstddef>
#include <filesystem>
#include <cstdint>
#include <optional>
#include <string>

namespace artrace::io {

/// 8-bit BGR (OpenCV's order) to RGB.
ar::ColorImage color_from_bgr(const cv::Mat& bgr);
/// 16-bit depth in `per_metre` units to metres; 0 and 65535 (saturated) become "no reading".
ar::DepthImage depth_from_u16(const cv::Mat& raw, double per_metre);

/// Width and height a PNG (IHDR), JPEG (first SOF marker) or WebP image declares, read from its header
/// without decoding it; nullopt for other or unreadable headers. Lets a reader refuse an image
/// whose declared size is absurd before OpenCV allocates for it.
struct ImageSize {
  uint32_t width = 0, height = 0;
};
std::optional<ImageSize> declared_image_size(const uint8_t* data, size_t size);
/// For a PNG: what is wrong with its chunk structure (a chunk whose length runs past the data,
/// which libpng would allocate for before reading), or "" when every chunk up to IEND fits. ""
/// for other formats.
std::string png_chunk_error(const uint8_t* data, size_t size);
/// The largest image side the readers take (GPUs' usual texture limit).
constexpr uint32_t kMaxImageSide = 16384;
/// The eight bytes a PNG file starts with.
inline constexpr uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
/// What is wrong with an image's header before OpenCV may decode it ("is a broken PNG: ..." for a
/// chunk running past the data, "declares WxH pixels ..." for a side of 0 or beyond kMaxImageSide);
/// "" when nothing is (including formats whose header this does not read).
std::string image_header_error(const uint8_t* data, size_t size);
/// An image file decoded by OpenCV (`flags` as cv::imread's), after its header is checked: a PNG
/// whose chunks run past the file, or a PNG or JPEG declaring more than 16384 pixels a side, is a
/// ParseError naming the file (OpenCV would allocate for the declared size first). Empty when the
/// file is missing or OpenCV cannot decode it; the caller says which image it was.
cv::Mat read_image_file(const std::filesystem::path& path, int flags);

/// A depth PNG read for the colour image `bgr` it pairs with: 16-bit, one channel, of the colour's
/// size; else a ParseError naming the file and what is wrong (undecodable, its type, both sizes).
cv::Mat read_depth_png(const std::filesystem::path& path, const cv::Mat& bgr);

}  // namespace artrace::io
