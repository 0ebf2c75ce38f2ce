#include "artrace/io/intrinsics_file.h"
#include "artrace/io/file_name.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/text_file.h"
#include "artrace/io/tum_reader.h"

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include <cmath>
#include <sstream>

namespace artrace::io {
namespace {

/// The same bounds as read_intrinsics: focal lengths in (0, 1e6], principal point within +-1e6,
/// sizes 1..100000 (0: not given).
void check(const CameraFile& c) {
  const ar::PinholeIntrinsics& k = c.intrinsics;
  auto bad = [&](const char* what, double v, const char* range) {
    std::ostringstream m;
    m << what << " " << v << " is not in " << range;
    throw ParseError(c.file.string(), 0, 0, m.str());
  };
  if (!(k.fx > 0.0 && k.fx <= 1e6)) bad("fx", k.fx, "(0, 1e6]");
  if (!(k.fy > 0.0 && k.fy <= 1e6)) bad("fy", k.fy, "(0, 1e6]");
  if (!(std::fabs(k.cx) <= 1e6)) bad("cx", k.cx, "-1e6..1e6");
  if (!(std::fabs(k.cy) <= 1e6)) bad("cy", k.cy, "-1e6..1e6");
  if (k.width < 0 || k.width > 100000) bad("the width", k.width, "1..100000");
  if (k.height < 0 || k.height > 100000) bad("the height", k.height, "1..100000");
  for (const double d : c.distortion) {
    if (!std::isfinite(d) || std::fabs(d) > 1e3) bad("a distortion coefficient", d, "-1e3..1e3");
  }
}

/// fx, fy, cx, cy from a row-major 3x3 matrix.
void from_row_major(CameraFile& c, const std::vector<double>& m, const std::string& key) {
  if (m.size() != 9) throw ParseError(c.file.string(), 0, 0, key + ": expected 9 numbers (a 3x3 matrix), got " + std::to_string(m.size()));
  if (m[1] != 0.0 || m[3] != 0.0 || m[6] != 0.0 || m[7] != 0.0 || m[8] != 1.0) {
    throw ParseError(c.file.string(), 0, 0, key + ": not a pinhole camera matrix [fx 0 cx; 0 fy cy; 0 0 1] (skew or a wrong layout)");
  }
  c.intrinsics.fx = m[0];
  c.intrinsics.fy = m[4];
  c.intrinsics.cx = m[2];
  c.intrinsics.cy = m[5];
}

/// An image width or height as a file gives it: a whole number in 0..100000 (checked before the
/// conversion, which is undefined for values beyond int).
int image_size(const std::filesystem::path& path, const char* key, double v) {
  if (!(v >= 0.0 && v <= 100000.0) || v != std::floor(v)) {
    std::ostringstream m;
    m << key << " " << v << " is not a whole number in 0..100000";
    throw ParseError(path.string(), 0, 0, m.str());
  }
  return static_cast<int>(v);
}

CameraFile read_json(const std::filesystem::path& path) {
  CameraFile c;
  c.file = path;
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(read_text_file(path));
  } catch (const nlohmann::json::parse_error& e) {
    throw ParseError(path.string(), 0, 0, std::string("not valid JSON: ") + e.what());
  }
  if (!j.is_object() || !j.contains("intrinsic_matrix")) {
    throw ParseError(path.string(), 0, 0, "expected Open3D's PinholeCameraIntrinsic: an object with \"intrinsic_matrix\", \"width\" and \"height\"");
  }
  std::vector<double> m;
  try {
    m = j.at("intrinsic_matrix").get<std::vector<double>>();
    if (j.contains("width")) c.intrinsics.width = image_size(path, "width", j.at("width").get<double>());
    if (j.contains("height")) c.intrinsics.height = image_size(path, "height", j.at("height").get<double>());
  } catch (const nlohmann::json::exception& e) {
    throw ParseError(path.string(), 0, 0, std::string("intrinsic_matrix, width and height must be numbers: ") + e.what());
  }
  if (m.size() != 9) throw ParseError(path.string(), 0, 0, "intrinsic_matrix: expected 9 numbers, got " + std::to_string(m.size()));
  // Open3D stores the matrix column-major: [fx, 0, 0, 0, fy, 0, cx, cy, 1]
  from_row_major(c, {m[0], m[3], m[6], m[1], m[4], m[7], m[2], m[5], m[8]}, "intrinsic_matrix");
  return c;
}

/// A YAML node as numbers: an OpenCV matrix, a ROS {rows, cols, data} map, or a plain sequence.
std::vector<double> numbers(const cv::FileNode& n) {
  std::vector<double> out;
  if (n.isMap()) {
    // the numbers are read from `data` itself, never through OpenCV's matrix reader: that one
    // allocates rows x cols as declared before it looks at the data (found by fuzz_intrinsics: a
    // camera matrix with "rows: +" and a data string asked for 48 GB); a map without a data
    // sequence gives no numbers, which the caller reports
    const cv::FileNode data = n["data"];
    if (!data.empty() && data.isSeq()) {
      for (const auto& v : data) out.push_back(v.real());
    }
    return out;
  }
  if (n.isSeq()) {
    for (const auto& v : n) out.push_back(v.real());
  }
  return out;
}

CameraFile read_yaml(const std::filesystem::path& path) {
  CameraFile c;
  c.file = path;
  cv::FileStorage fs;
  try {
    // OpenCV's parser wants its "%YAML:1.0" header, which ROS camera files do not carry
    std::string text = read_text_file(path);
    if (text.rfind("%YAML", 0) != 0) text = "%YAML:1.0\n---\n" + text;
    if (!fs.open(text, cv::FileStorage::READ | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML)) {
      throw ParseError(path.string(), 0, 0, "not a readable YAML camera file");
    }
    const char* matrix_key = !fs["camera_matrix"].empty() ? "camera_matrix" : !fs["K"].empty() ? "K" : nullptr;
    if (!matrix_key) throw ParseError(path.string(), 0, 0, "has neither camera_matrix nor K (an OpenCV or ROS camera file)");
    from_row_major(c, numbers(fs[matrix_key]), matrix_key);
    for (const char* key : {"distortion_coefficients", "D"}) {
      if (!fs[key].empty()) {
        c.distortion = numbers(fs[key]);
        break;
      }
    }
    for (const auto& [wk, hk] : {std::pair{"image_width", "image_height"}, std::pair{"width", "height"}}) {
      if (!fs[wk].empty() && !fs[hk].empty()) {
        c.intrinsics.width = image_size(path, wk, fs[wk].real());
        c.intrinsics.height = image_size(path, hk, fs[hk].real());
        break;
      }
    }
  } catch (const cv::Exception& e) {
    throw ParseError(path.string(), 0, 0, std::string("not a readable YAML camera file: ") + e.err);
  }
  return c;
}

}  // namespace

CameraFile read_camera_file(const std::filesystem::path& path) {
  const std::string ext = lower_extension(path);
  CameraFile c;
  if (ext == ".json") {
    c = read_json(path);
  } else if (ext == ".yaml" || ext == ".yml") {
    c = read_yaml(path);
  } else {
    c.file = path;
    c.intrinsics = read_intrinsics(path);
  }
  check(c);
  return c;
}

std::optional<std::filesystem::path> find_camera_file(const std::filesystem::path& folder) {
  for (const char* name : {"intrinsics.txt", "intrinsics.json", "camera_intrinsic.json", "camera.yaml", "camera_info.yaml", "calibration.yaml"}) {
    if (std::filesystem::exists(folder / name)) return folder / name;
  }
  return std::nullopt;
}

}  // namespace artrace::io
