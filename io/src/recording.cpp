#include "artrace/io/recording.h"
#include "artrace/io/image_folder_reader.h"
#include "artrace/io/intrinsics_file.h"
#include "artrace/io/oni_reader.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/tum_reader.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>

namespace artrace::io {
namespace {

/// A reader's frames with the intrinsics of a camera file, undistorted where it gives distortion:
/// colour bilinearly, depth by nearest neighbour (depths are not averaged across edges), both to
/// the same camera matrix.
class CameraFileSource : public ar::FrameSource {
 public:
  CameraFileSource(std::unique_ptr<ar::FrameSource> inner, CameraFile camera) : inner_(std::move(inner)), camera_(std::move(camera)) {
    distorted_ = std::any_of(camera_.distortion.begin(), camera_.distortion.end(), [](double d) { return d != 0.0; });
  }
  std::optional<int64_t> frame_count() const override { return inner_->frame_count(); }
  bool next(ar::SensorFrame& f) override {
    if (!inner_->next(f)) return false;
    const ar::PinholeIntrinsics& k = camera_.intrinsics;
    check_intrinsics_size(k, f.color.width, f.color.height, camera_.file.string());
    for (ar::PinholeIntrinsics* out : {&f.color_intrinsics, &f.depth_intrinsics}) {
      *out = k;
      out->width = f.color.width;
      out->height = f.color.height;
    }
    if (distorted_) undistort(f);
    return true;
  }
  void seek(int64_t index) override { inner_->seek(index); }
  std::string describe() const override { return inner_->describe(); }
  double depth_units_per_metre() const override { return inner_->depth_units_per_metre(); }
  std::string intrinsics_source() const override {
    return camera_.file.string() + (distorted_ ? " (frames undistorted with its distortion coefficients)" : "");
  }
  std::optional<std::pair<double, double>> trajectory_span() const override { return inner_->trajectory_span(); }
  std::vector<std::string> warnings() const override {
    std::vector<std::string> w;
    for (const std::string& s : inner_->warnings()) {
      if (s.find("default intrinsics") == std::string::npos) w.push_back(s);  // the camera file replaced them
    }
    return w;
  }

 private:
  void undistort(ar::SensorFrame& f) {
    if (map_x_.cols != f.color.width || map_x_.rows != f.color.height) {
      const cv::Matx33d K(camera_.intrinsics.fx, 0.0, camera_.intrinsics.cx, 0.0, camera_.intrinsics.fy, camera_.intrinsics.cy, 0.0, 0.0, 1.0);
      cv::initUndistortRectifyMap(K, camera_.distortion, cv::noArray(), K, cv::Size(f.color.width, f.color.height), CV_32FC1, map_x_, map_y_);
    }
    const cv::Mat rgb(f.color.height, f.color.width, CV_8UC3, f.color.rgb.data());
    cv::Mat rgb_out;
    cv::remap(rgb, rgb_out, map_x_, map_y_, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
    std::copy(rgb_out.data, rgb_out.data + f.color.rgb.size(), f.color.rgb.begin());
    if (f.depth.width == f.color.width && f.depth.height == f.color.height) {
      const cv::Mat d(f.depth.height, f.depth.width, CV_32FC1, f.depth.depth_m.data());
      cv::Mat d_out;
      cv::remap(d, d_out, map_x_, map_y_, cv::INTER_NEAREST, cv::BORDER_CONSTANT, cv::Scalar(0.0));
      std::copy(d_out.ptr<float>(), d_out.ptr<float>() + f.depth.depth_m.size(), f.depth.depth_m.begin());
    }
  }

  std::unique_ptr<ar::FrameSource> inner_;
  CameraFile camera_;
  bool distorted_ = false;
  cv::Mat map_x_, map_y_;
};

}  // namespace

std::unique_ptr<ar::FrameSource> open_recording(const std::filesystem::path& path, const RecordingOptions& options) {
  std::unique_ptr<ar::FrameSource> source;
  std::optional<std::filesystem::path> camera = options.intrinsics;
  if (std::filesystem::is_directory(path)) {
    // intrinsics.txt is read by the readers themselves; the other formats come through a CameraFile
    if (!camera) {
      if (const auto found = find_camera_file(path); found && found->filename() != "intrinsics.txt") camera = found;
    }
    if (std::filesystem::exists(path / "rgb.txt")) {
      TumOptions o;
      if (options.depth_units_per_metre) o.depth_scale = *options.depth_units_per_metre;
      o.trajectory = options.trajectory;
      source = std::make_unique<TumReader>(path, o);
    } else if (ImageFolderReader::accepts(path)) {
      ImageFolderOptions o;
      if (options.depth_units_per_metre) o.depth_per_metre = *options.depth_units_per_metre;
      o.trajectory = options.trajectory;
      source = std::make_unique<ImageFolderReader>(path, o);
    } else {
      throw ParseError(path.string(), 0, 0,
                       "folder is neither a TUM RGB-D sequence (rgb.txt) nor a colour/depth image folder (color/ or color.mp4, and depth/)");
    }
  } else {
    if (!std::filesystem::exists(path)) throw ParseError(path.string(), 0, 0, "no such file or folder");
    OniOptions o;
    o.depth_units_per_metre = options.depth_units_per_metre;
    o.trajectory = options.trajectory;
    source = std::make_unique<OniReader>(path, o);  // identified by content
  }
  if (camera) return std::make_unique<CameraFileSource>(std::move(source), read_camera_file(*camera));
  return source;
}

}  // namespace artrace::io
