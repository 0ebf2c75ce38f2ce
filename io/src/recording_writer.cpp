#include "artrace/io/recording_writer.h"
#include "artrace/io/atomic_file.h"
#include "artrace/io/file_name.h"
#include "artrace/io/oni_writer.h"
#include "artrace/io/tum_reader.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <iomanip>
#include <sstream>

namespace artrace::io {
namespace {

std::vector<uint16_t> depth_units(const ar::DepthImage& d, double per_metre) {
  std::vector<uint16_t> out(d.depth_m.size());
  for (size_t i = 0; i < out.size(); ++i) {
    const double v = std::round(d.depth_m[i] * per_metre);
    out[i] = (d.depth_m[i] > 0.0f && v >= 1.0 && v < 65535.0) ? static_cast<uint16_t>(v) : 0;  // out of range: no reading
  }
  return out;
}

void add_pose(std::vector<ar::PoseSample>& poses, const ar::SensorFrame& f) {
  if (!f.world_from_camera) return;
  ar::PoseSample s;
  s.time_s = f.color_time_s;
  s.translation = f.world_from_camera->translation();
  s.rotation = Eigen::Quaterniond(f.world_from_camera->rotation()).normalized();
  poses.push_back(s);
}

class TumWriter : public RecordingWriter {
 public:
  explicit TumWriter(const std::filesystem::path& dir)
      : dir_(dir), claim_(dir.string() + ".partial", PartialOutput::Kind::folder, dir.string()), tmp_(claim_.path()) {
    std::filesystem::create_directories(tmp_ / "rgb");
    std::filesystem::create_directories(tmp_ / "depth");
    rgb_ << "# color images\n# timestamp filename\n" << std::fixed << std::setprecision(6);
    depth_ << "# depth maps (16-bit PNG, 5000 per metre, 0 = no reading)\n# timestamp filename\n" << std::fixed
           << std::setprecision(6);
  }
  ~TumWriter() override {
    if (!closed_) {
      std::error_code ec;
      std::filesystem::remove_all(tmp_, ec);
    }
  }
  void write(const ar::SensorFrame& f) override {
    ar::require_depth_at_colour_size(f, dir_.string(), "a TUM folder's depth is registered to its colour (convert to .oni instead)");
    char name[64];
    std::snprintf(name, sizeof(name), "%.6f.png", f.color_time_s);
    const cv::Mat rgb(f.color.height, f.color.width, CV_8UC3, const_cast<uint8_t*>(f.color.rgb.data()));
    cv::Mat bgr;
    cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
    write_png(tmp_ / "rgb" / name, bgr, /*atomically=*/false);  // the folder is partial until close
    std::vector<uint16_t> d = depth_units(f.depth, 5000.0);
    const cv::Mat dm(f.depth.height, f.depth.width, CV_16UC1, d.data());
    std::snprintf(name, sizeof(name), "%.6f.png", f.depth_time_s);
    write_png(tmp_ / "depth" / name, dm, /*atomically=*/false);
    rgb_ << f.color_time_s << " rgb/" << std::setprecision(6) << f.color_time_s << ".png\n";
    depth_ << f.depth_time_s << " depth/" << f.depth_time_s << ".png\n";
    add_pose(poses_, f);
    intrinsics_ = f.color_intrinsics;
  }
  void close() override {
    write_file(tmp_ / "rgb.txt", rgb_.str());
    write_file(tmp_ / "depth.txt", depth_.str());
    if (!poses_.empty()) write_tum_trajectory(tmp_ / "groundtruth.txt", ar::Trajectory(poses_));
    std::ostringstream k;
    k << "# fx fy cx cy width height (pixels)\n"
      << std::setprecision(10) << intrinsics_.fx << ' ' << intrinsics_.fy << ' ' << intrinsics_.cx << ' '
      << intrinsics_.cy << ' ' << intrinsics_.width << ' ' << intrinsics_.height << '\n';
    write_file(tmp_ / "intrinsics.txt", k.str());
    std::filesystem::remove_all(dir_);
    std::filesystem::rename(tmp_, dir_);
    closed_ = true;
  }

 private:
  std::filesystem::path dir_;
  PartialOutput claim_;  ///< the partial folder, held while it is written
  std::filesystem::path tmp_;
  std::ostringstream rgb_, depth_;  ///< rgb.txt and depth.txt, written at close
  std::vector<ar::PoseSample> poses_;
  ar::PinholeIntrinsics intrinsics_;
  bool closed_ = false;
};

class OniRecordingWriter : public RecordingWriter {
 public:
  OniRecordingWriter(const std::filesystem::path& path, int fps) : path_(path), fps_(fps) {}
  void write(const ar::SensorFrame& f) override {
    if (!writer_) {
      auto fmt = [&](const ar::PinholeIntrinsics& k, int w, int h) {
        OniStreamFormat s;
        s.width = w;
        s.height = h;
        s.fps = fps_;
        if (k.fx > 0.0) s.fov_x_rad = 2.0 * std::atan(0.5 * w / k.fx);
        if (k.fy > 0.0) s.fov_y_rad = 2.0 * std::atan(0.5 * h / k.fy);
        return s;
      };
      writer_ = std::make_unique<OniWriter>(path_, fmt(f.depth_intrinsics, f.depth.width, f.depth.height),
                                            fmt(f.color_intrinsics, f.color.width, f.color.height));
    }
    const std::vector<uint16_t> d = depth_units(f.depth, 1000.0);
    writer_->write(d.data(), f.color.rgb.data(), static_cast<uint64_t>(std::llround(f.depth_time_s * 1e6)),
                   static_cast<uint64_t>(std::llround(f.color_time_s * 1e6)));
    add_pose(poses_, f);
  }
  void close() override {
    if (!writer_) throw std::runtime_error(path_.string() + ": no frames written");
    writer_->close();
    if (!poses_.empty()) write_tum_trajectory(path_.string() + ".trajectory.txt", ar::Trajectory(poses_));
  }

 private:
  std::filesystem::path path_;
  int fps_;
  std::unique_ptr<OniWriter> writer_;
  std::vector<ar::PoseSample> poses_;
};

}  // namespace

std::unique_ptr<RecordingWriter> make_recording_writer(const std::filesystem::path& path, int fps) {
  if (lower_extension(path) == ".oni") return std::make_unique<OniRecordingWriter>(path, fps);
  return std::make_unique<TumWriter>(path);
}

}  // namespace artrace::io
