#include "artrace/io/openni2_reader.h"
#include "artrace/io/oni_file.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/tum_reader.h"

#include <OpenNI.h>

#include <cmath>
#include <cstring>
#include <mutex>

namespace artrace::io {
namespace {

void initialize_openni() {
  static std::once_flag once;
  static openni::Status status = openni::STATUS_OK;
  std::call_once(once, [] { status = openni::OpenNI::initialize(); });
  if (status != openni::STATUS_OK) {
    throw std::runtime_error(std::string("OpenNI2 failed to initialise: ") + openni::OpenNI::getExtendedError());
  }
}

}  // namespace

struct OpenNi2Reader::Impl {
  openni::Device device;
  openni::VideoStream depth, color;
  ~Impl() {
    depth.stop();
    color.stop();
    depth.destroy();
    color.destroy();
    device.close();
  }
};

OpenNi2Reader::OpenNi2Reader(const std::filesystem::path& path, const OpenNi2Options& options) : path_(path), options_(options) {
  const OniContainer file(path);  // refuse what is not an ONI recording before OpenNI2 sees it
  if (!file.find(kOniDepth) || !file.find(kOniImage)) throw ParseError(path.string(), 0, 0, "needs a depth and a colour stream");
  const std::filesystem::path sidecar = path.string() + ".trajectory.txt";
  if (options.trajectory) trajectory_ = read_tum_trajectory(*options.trajectory);
  else if (std::filesystem::exists(sidecar)) trajectory_ = read_tum_trajectory(sidecar);
  open();
}

OpenNi2Reader::~OpenNi2Reader() = default;

void OpenNi2Reader::open() {
  initialize_openni();
  impl_.reset();
  auto impl = std::make_unique<Impl>();
  auto check = [&](openni::Status s, const char* what) {
    if (s != openni::STATUS_OK) {
      throw ParseError(path_.string(), 0, 0, std::string(what) + ": " + openni::OpenNI::getExtendedError());
    }
  };
  check(impl->device.open(path_.string().c_str()), "OpenNI2 cannot open the recording");
  check(impl->depth.create(impl->device, openni::SENSOR_DEPTH), "no depth stream");
  check(impl->color.create(impl->device, openni::SENSOR_COLOR), "no colour stream");
  openni::PlaybackControl* pc = impl->device.getPlaybackControl();
  if (!pc) throw ParseError(path_.string(), 0, 0, "not a playback device");
  // Manual mode (one frame per waitForAnyStream), set before the streams start. Repeat is on
  // although next() stops at the last frame: without it the player thread spins at the end of
  // the file, walking the driver's list of streams without its lock, and closing the reader (or
  // a backward seek, which reopens) while it spins frees a stream under it (SIGSEGV in libOniFile,
  // about one run in 20 of the round-trip test on a loaded machine). With repeat it rewinds and
  // waits for the next trigger instead (no crash in 500 runs).
  check(pc->setSpeed(-1.0f), "cannot set the playback speed");
  check(pc->setRepeatEnabled(true), "cannot turn on repeat");
  frames_ = std::min(pc->getNumberOfFrames(impl->depth), pc->getNumberOfFrames(impl->color));
  const openni::PixelFormat df = impl->depth.getVideoMode().getPixelFormat();
  if (df != openni::PIXEL_FORMAT_DEPTH_1_MM && df != openni::PIXEL_FORMAT_DEPTH_100_UM) {
    throw ParseError(path_.string(), 0, 0, "depth stream pixel format " + std::to_string(df) + " is not supported");
  }
  if (impl->color.getVideoMode().getPixelFormat() != openni::PIXEL_FORMAT_RGB888) {
    throw ParseError(path_.string(), 0, 0, "colour stream is not RGB888");
  }
  check(impl->depth.start(), "cannot start the depth stream");
  check(impl->color.start(), "cannot start the colour stream");
  impl_ = std::move(impl);
  cursor_ = 0;
}

bool OpenNi2Reader::next(ar::SensorFrame& frame) {
  if (cursor_ >= frames_) return false;
  openni::VideoFrameRef d, c;
  openni::VideoStream* streams[2] = {&impl_->depth, &impl_->color};
  const int want = static_cast<int>(cursor_ + 1);  // ONI frame numbers start at 1
  for (int guard = 0; (!d.isValid() || !c.isValid()) && guard < 64; ++guard) {
    int which = -1;
    if (openni::OpenNI::waitForAnyStream(streams, 2, &which, 5000) != openni::STATUS_OK || which < 0) {
      throw ParseError(path_.string(), 0, 0, "frame " + std::to_string(cursor_) + ": no data from OpenNI2 (" +
                                                 openni::OpenNI::getExtendedError() + ")");
    }
    openni::VideoFrameRef f;
    if (streams[which]->readFrame(&f) != openni::STATUS_OK) continue;
    if (f.getFrameIndex() != want) continue;
    (which == 0 ? d : c) = f;
  }
  if (!d.isValid() || !c.isValid()) throw ParseError(path_.string(), 0, 0, "frame " + std::to_string(cursor_) + " incomplete");

  frame = ar::SensorFrame{};
  frame.index = cursor_;
  frame.depth_time_s = static_cast<double>(d.getTimestamp()) * 1e-6;
  frame.color_time_s = static_cast<double>(c.getTimestamp()) * 1e-6;
  frame.depth.width = d.getWidth();
  frame.depth.height = d.getHeight();
  frame.depth.depth_m.resize(static_cast<size_t>(d.getWidth()) * d.getHeight());
  const double units = d.getVideoMode().getPixelFormat() == openni::PIXEL_FORMAT_DEPTH_100_UM ? 10000.0 : 1000.0;
  for (int y = 0; y < d.getHeight(); ++y) {
    const auto* row = reinterpret_cast<const uint16_t*>(static_cast<const uint8_t*>(d.getData()) + static_cast<size_t>(y) * d.getStrideInBytes());
    float* out = frame.depth.depth_m.data() + static_cast<size_t>(y) * d.getWidth();
    for (int x = 0; x < d.getWidth(); ++x) out[x] = ar::depth_metres(row[x], units);  // 0 stays 0: no reading
  }
  frame.color.width = c.getWidth();
  frame.color.height = c.getHeight();
  frame.color.rgb.resize(static_cast<size_t>(c.getWidth()) * c.getHeight() * 3);
  for (int y = 0; y < c.getHeight(); ++y) {
    std::memcpy(frame.color.rgb.data() + static_cast<size_t>(y) * c.getWidth() * 3,
                static_cast<const uint8_t*>(c.getData()) + static_cast<size_t>(y) * c.getStrideInBytes(),
                static_cast<size_t>(c.getWidth()) * 3);
  }
  auto from_fov = [](const openni::VideoStream& s, int w, int h) {
    ar::PinholeIntrinsics k;
    k.width = w;
    k.height = h;
    const float hf = s.getHorizontalFieldOfView(), vf = s.getVerticalFieldOfView();
    k.fx = hf > 0.0f ? 0.5 * w / std::tan(0.5 * hf) : 525.0 * w / 640.0;
    k.fy = vf > 0.0f ? 0.5 * h / std::tan(0.5 * vf) : 525.0 * h / 480.0;
    k.cx = 0.5 * w - 0.5;
    k.cy = 0.5 * h - 0.5;
    return k;
  };
  frame.color_intrinsics = options_.intrinsics ? *options_.intrinsics : from_fov(impl_->color, c.getWidth(), c.getHeight());
  frame.depth_intrinsics = options_.intrinsics ? *options_.intrinsics : from_fov(impl_->depth, d.getWidth(), d.getHeight());
  if (!trajectory_.empty()) {
    if (auto pose = trajectory_.at(frame.color_time_s, options_.max_pose_gap_s)) frame.world_from_camera = *pose;
  } else {
    frame.world_from_camera = Eigen::Isometry3d::Identity();  // a fixed camera
  }
  ++cursor_;
  return true;
}

void OpenNi2Reader::seek(int64_t index) {
  if (index < 0 || index > frames_) {
    throw std::out_of_range(path_.string() + ": cannot seek to frame " + std::to_string(index) + " of " + std::to_string(frames_));
  }
  if (index < cursor_) open();  // PlaybackControl::seek is broken in OpenNI2 2.2: reopen and step
  ar::SensorFrame skip;
  while (cursor_ < index) next(skip);
}

std::string OpenNi2Reader::describe() const {
  return "ONI recording " + path_.string() + " (" + std::to_string(frames_) + " frames" +
         (trajectory_.empty() ? ", fixed camera" : ", with trajectory") + ")";
}

}  // namespace artrace::io
