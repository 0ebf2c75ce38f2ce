#include "commands.h"

#include <opencv2/imgcodecs.hpp>

#include <cmath>
#include <stdexcept>

namespace artrace::tools {
namespace {

uint8_t to_srgb8(float linear) {
  const float c = std::fmin(std::fmax(linear, 0.0f), 1.0f);
  const float s = c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.0f / 2.4f) - 0.055f;
  return static_cast<uint8_t>(std::lround(s * 255.0f));
}

}  // namespace

void write_png(const core::Image& img, const std::filesystem::path& path) {
  cv::Mat mat(img.height, img.width, CV_8UC3);
  for (int y = 0; y < img.height; ++y) {
    for (int x = 0; x < img.width; ++x) {
      const glm::vec3& c = img.at(x, y);
      mat.at<cv::Vec3b>(y, x) = cv::Vec3b(to_srgb8(c.b), to_srgb8(c.g), to_srgb8(c.r));
    }
  }
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  const std::filesystem::path tmp = path.string() + ".partial.png";
  if (!cv::imwrite(tmp.string(), mat)) {
    std::filesystem::remove(tmp);
    throw std::runtime_error(path.string() + ": cannot write PNG");
  }
  std::filesystem::rename(tmp, path);
}

}  // namespace artrace::tools
