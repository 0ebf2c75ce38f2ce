#include "cv_convert.h"

#include <opencv2/imgproc.hpp>

namespace artrace::io {

ar::ColorImage color_from_bgr(const cv::Mat& bgr) {
  ar::ColorImage c;
  c.width = bgr.cols;
  c.height = bgr.rows;
  c.rgb.resize(static_cast<size_t>(bgr.cols) * bgr.rows * 3);
  cv::Mat rgb(bgr.rows, bgr.cols, CV_8UC3, c.rgb.data());
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  return c;
}

ar::DepthImage depth_from_u16(const cv::Mat& raw, double per_metre) {
  ar::DepthImage d;
  d.width = raw.cols;
  d.height = raw.rows;
  d.depth_m.resize(static_cast<size_t>(raw.cols) * raw.rows);
  for (int y = 0; y < raw.rows; ++y) {
    const uint16_t* row = raw.ptr<uint16_t>(y);
    float* out = d.depth_m.data() + static_cast<size_t>(y) * raw.cols;
    for (int x = 0; x < raw.cols; ++x) out[x] = (row[x] == 0 || row[x] == 65535) ? 0.0f : ar::depth_metres(row[x], per_metre);
  }
  return d;
}

}  // namespace artrace::io
