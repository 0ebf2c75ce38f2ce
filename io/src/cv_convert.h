// OpenCV images to the frame types. Internal to io.
#pragma once

#include "artrace/ar/sensor_frame.h"

#include <opencv2/core.hpp>

namespace artrace::io {

/// 8-bit BGR (OpenCV's order) to RGB.
ar::ColorImage color_from_bgr(const cv::Mat& bgr);
/// 16-bit depth in `per_metre` units to metres; 0 and 65535 (saturated) become "no reading".
ar::DepthImage depth_from_u16(const cv::Mat& raw, double per_metre);

}  // namespace artrace::io
