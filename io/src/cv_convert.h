// OpenCV images to the frame types. Internal to io.
#pragma once

#include "artrace/ar/sensor_frame.h"

#include <opencv2/core.hpp>

#include <cstddef>
#include <cstdint>
#include <optional>

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

}  // namespace artrace::io
