#include "artrace/io/image_folder_reader.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/tum_reader.h"
#include "cv_convert.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <algorithm>

namespace artrace::io {
namespace {

const char* const kVideoExtensions[] = {".mp4", ".avi", ".mkv", ".mov"};

std::filesystem::path find_video(const std::filesystem::path& folder) {
  for (const char* ext : kVideoExtensions) {
    const auto p = folder / (std::string("color") + ext);
    if (std::filesystem::exists(p)) return p;
  }
  return {};
}

bool is_digit(char c) { return c >= '0' && c <= '9'; }

/// Names in natural order: runs of digits compare as numbers ("9" before "10"), the rest as text;
/// equal so far, the plain order decides ("01" and "1").
bool natural_less(const std::string& a, const std::string& b) {
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (is_digit(a[i]) && is_digit(b[j])) {
      size_t ei = i, ej = j;
      while (ei < a.size() && is_digit(a[ei])) ++ei;
      while (ej < b.size() && is_digit(b[ej])) ++ej;
      size_t si = i, sj = j;  // without leading zeros
      while (si + 1 < ei && a[si] == '0') ++si;
      while (sj + 1 < ej && b[sj] == '0') ++sj;
      if (ei - si != ej - sj) return ei - si < ej - sj;
      if (const int c = a.compare(si, ei - si, b, sj, ej - sj); c != 0) return c < 0;
      i = ei;
      j = ej;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  if (i < a.size() || j < b.size()) return j < b.size() && i == a.size();
  return a < b;
}

std::vector<std::filesystem::path> sorted_files(const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> out;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    if (e.is_regular_file() && e.path().filename().string()[0] != '.') out.push_back(e.path());
  }
  std::sort(out.begin(), out.end(), [](const std::filesystem::path& a, const std::filesystem::path& b) {
    return natural_less(a.filename().string(), b.filename().string());
  });
  return out;
}

/// The last run of digits in a file's stem, as a number without leading zeros; "" without one.
std::string last_number(const std::filesystem::path& p) {
  const std::string s = p.stem().string();
  size_t e = s.size();
  while (e > 0 && !is_digit(s[e - 1])) --e;
  size_t b = e;
  while (b > 0 && is_digit(s[b - 1])) --b;
  while (b + 1 < e && s[b] == '0') ++b;
  return s.substr(b, e - b);
}

}  // namespace

struct ImageFolderReader::Video {
  cv::VideoCapture cap;
  int64_t position = 0;
};

bool ImageFolderReader::accepts(const std::filesystem::path& folder) {
  return std::filesystem::is_directory(folder / "depth") &&
         (std::filesystem::is_directory(folder / "color") || !find_video(folder).empty());
}

ImageFolderReader::ImageFolderReader(const std::filesystem::path& folder, const ImageFolderOptions& options)
    : folder_(folder), options_(options) {
  if (!accepts(folder)) throw ParseError(folder.string(), 0, 0, "needs depth/ and color/ (or a color.mp4 video)");
  depth_files_ = sorted_files(folder / "depth");
  if (depth_files_.empty()) throw ParseError((folder / "depth").string(), 0, 0, "holds no depth image");
  if (!options_.depth_per_metre) {
    options_.depth_per_metre = 1000.0;
    warnings_.push_back(folder.string() + ": depth units not given: read as millimetres, 1000 a metre (what Kinect, "
                        "RealSense and Azure Kinect tools write; --depth-scale sets them)");
  }
  video_path_ = find_video(folder);
  if (std::filesystem::is_directory(folder / "color")) video_path_.clear();
  if (video_path_.empty()) {
    color_files_ = sorted_files(folder / "color");
    if (color_files_.size() != depth_files_.size()) {
      throw ParseError(folder.string(), 0, 0, "color/ has " + std::to_string(color_files_.size()) +
                                                  " images, depth/ " + std::to_string(depth_files_.size()));
    }
    for (size_t k = 0; k < color_files_.size(); ++k) {
      const std::string c = last_number(color_files_[k]), d = last_number(depth_files_[k]);
      if (!c.empty() && !d.empty() && c != d) {
        warnings_.push_back(color_files_[k].string() + " pairs with " + depth_files_[k].string() +
                            ": frames pair by their order in color/ and depth/, and these names' numbers differ");
        break;
      }
    }
  } else {
    video_ = std::make_unique<Video>();
    if (!video_->cap.open(video_path_.string())) throw ParseError(video_path_.string(), 0, 0, "OpenCV cannot open the video");
    const double fps = video_->cap.get(cv::CAP_PROP_FPS);
    if (fps > 0.0) options_.fps = fps;
  }
  if (options.trajectory) trajectory_ = read_tum_trajectory(*options.trajectory);
  else if (std::filesystem::exists(folder / "trajectory.txt")) trajectory_ = read_tum_trajectory(folder / "trajectory.txt");
  if (options.intrinsics) {
    intrinsics_ = options.intrinsics;
    intrinsics_source_ = "given";
  } else if (std::filesystem::exists(folder / "intrinsics.txt")) {
    intrinsics_ = read_intrinsics(folder / "intrinsics.txt");
    intrinsics_source_ = (folder / "intrinsics.txt").string();
  } else {
    intrinsics_source_ = "defaults";
    warnings_.push_back(folder.string() + ": no intrinsics file (intrinsics.txt, intrinsics.json, camera.yaml): default intrinsics fx = fy = "
                        "525 px at 640 wide (scaled with the width), principal point at the centre (give the camera's own with --intrinsics)");
  }
}

ImageFolderReader::~ImageFolderReader() = default;

bool ImageFolderReader::next(ar::SensorFrame& f) {
  if (cursor_ >= static_cast<int64_t>(depth_files_.size())) return false;
  cv::Mat bgr;
  std::string color_name;
  if (video_) {
    color_name = video_path_.string() + " frame " + std::to_string(cursor_);
    if (!video_->cap.read(bgr) || bgr.empty()) {
      throw ParseError(video_path_.string(), 0, 0, "video ends at frame " + std::to_string(cursor_) + ", before the depth images do");
    }
    ++video_->position;
  } else {
    color_name = color_files_[static_cast<size_t>(cursor_)].string();
    bgr = read_image_file(color_name, cv::IMREAD_COLOR);
    if (bgr.empty()) throw ParseError(color_name, 0, 0, "cannot decode the colour image");
  }
  const std::string depth_name = depth_files_[static_cast<size_t>(cursor_)].string();
  const cv::Mat raw = read_depth_png(depth_name, bgr);
  if (intrinsics_) check_intrinsics_size(*intrinsics_, bgr.cols, bgr.rows, intrinsics_source_, intrinsics_source_ == "given" ? "the intrinsics given are" : "is");
  f = ar::SensorFrame{};
  f.index = cursor_;
  f.color_time_s = f.depth_time_s = static_cast<double>(cursor_) / options_.fps;
  f.color = color_from_bgr(bgr);
  f.depth = depth_from_u16(raw, *options_.depth_per_metre);
  ar::PinholeIntrinsics k = intrinsics_.value_or(
      ar::PinholeIntrinsics{bgr.cols, bgr.rows, 525.0 * bgr.cols / 640.0, 525.0 * bgr.cols / 640.0, 0.5 * bgr.cols - 0.5, 0.5 * bgr.rows - 0.5});
  k.width = bgr.cols;
  k.height = bgr.rows;
  f.color_intrinsics = f.depth_intrinsics = k;
  if (!trajectory_.empty()) {
    if (auto pose = trajectory_.at(f.color_time_s)) f.world_from_camera = *pose;
  }
  ++cursor_;
  return true;
}

void ImageFolderReader::seek(int64_t index) {
  if (index < 0 || index > static_cast<int64_t>(depth_files_.size())) {
    throw std::out_of_range(folder_.string() + ": cannot seek to frame " + std::to_string(index));
  }
  if (video_) {
    // CAP_PROP_POS_FRAMES is not frame-accurate for every codec: reopen and step instead.
    if (index < video_->position) {
      video_->cap.open(video_path_.string());
      video_->position = 0;
    }
    cv::Mat skip;
    while (video_->position < index && video_->cap.grab()) ++video_->position;
  }
  cursor_ = index;
}

std::string ImageFolderReader::describe() const {
  return std::string(video_ ? "colour video + depth images " : "colour/depth image folder ") + folder_.string() +
         " (" + std::to_string(depth_files_.size()) + " frames)";
}

}  // namespace artrace::io
