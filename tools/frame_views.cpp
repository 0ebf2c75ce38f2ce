#include "frame_views.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>

namespace artrace::tools {

cv::Mat to_bgr(const ar::ColorImage& c) {
  cv::Mat rgb(c.height, c.width, CV_8UC3, const_cast<uint8_t*>(c.rgb.data()));
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  return bgr;
}

cv::Mat depth_view(const ar::DepthImage& d, int w, int h) {
  cv::Mat gray(d.height, d.width, CV_8UC1);
  for (int y = 0; y < d.height; ++y) {
    for (int x = 0; x < d.width; ++x) {
      const float z = d.at(x, y);
      gray.at<uint8_t>(y, x) = z > 0.0f ? static_cast<uint8_t>(std::clamp(255.0f * (1.0f - z / 8.0f), 1.0f, 255.0f)) : 0;
    }
  }
  cv::Mat colour;
  cv::applyColorMap(gray, colour, cv::COLORMAP_TURBO);
  colour.setTo(cv::Scalar(0, 0, 0), gray == 0);
  if (colour.cols != w || colour.rows != h) cv::resize(colour, colour, cv::Size(w, h), 0, 0, cv::INTER_NEAREST);
  return colour;
}

}  // namespace artrace::tools
