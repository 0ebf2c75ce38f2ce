#include "commands.h"

#include "artrace/core/srgb.h"
#include "artrace/io/atomic_file.h"

#include <opencv2/core.hpp>

#include <cmath>
#include <stdexcept>

namespace artrace::tools {
void write_png(const core::Image& img, const std::filesystem::path& path) {
  cv::Mat mat(img.height, img.width, CV_8UC3);
  for (int y = 0; y < img.height; ++y) {
    for (int x = 0; x < img.width; ++x) {
      const glm::vec3& c = img.at(x, y);
      mat.at<cv::Vec3b>(y, x) = cv::Vec3b(core::linear_to_srgb8(c.b), core::linear_to_srgb8(c.g), core::linear_to_srgb8(c.r));
    }
  }
  io::write_png(path, mat);
}

}  // namespace artrace::tools
