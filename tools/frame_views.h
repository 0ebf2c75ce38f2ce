// OpenCV views of sensor frames shared by export and replay.
#pragma once

#include "artrace/ar/sensor_frame.h"

#include <opencv2/core.hpp>

namespace artrace::tools {

/// An RGB colour image as a BGR cv::Mat (a copy).
cv::Mat to_bgr(const ar::ColorImage& c);

/// Depth as a false-colour image (near warm, far cold, no reading black), resized to w x h.
cv::Mat depth_view(const ar::DepthImage& d, int w, int h);

}  // namespace artrace::tools
