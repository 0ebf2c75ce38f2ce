#include "artrace/io/oni_reader.h"
#include "artrace/io/oni_codecs.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/tum_reader.h"

#include <cmath>
#include <cstring>

namespace artrace::io {
namespace {

/// A stream's frames as TUM-style timed entries, for pairing by time.
std::vector<TimedFile> times_of(const OniNode& n) {
  std::vector<TimedFile> out;
  out.reserve(n.frames.size());
  for (const OniFrameRecord& f : n.frames) out.push_back({static_cast<double>(f.timestamp_us) * 1e-6, std::string()});
  return out;
}

std::vector<OniGap> gaps_of(const OniNode& n, const char* stream) {
  std::vector<OniGap> out;
  if (n.fps <= 0) return out;
  const double period_ms = 1000.0 / n.fps;
  for (size_t k = 1; k < n.frames.size(); ++k) {
    const double dt = (static_cast<double>(n.frames[k].timestamp_us) - static_cast<double>(n.frames[k - 1].timestamp_us)) * 1e-3;
    if (dt > 1.5 * period_ms) out.push_back({stream, k - 1, dt, static_cast<int>(std::lround(dt / period_ms)) - 1});
  }
  return out;
}

// Per-pixel loops without a branch on the data are kept out of libFuzzer's coverage tracing
// (tests/fuzz): traced, the two below were most of the ONI harness's time, and they have no path
// for it to find. Not inlined, since inlined they would be traced as part of their caller.
#if defined(__clang__)
#define ARTRACE_NO_COVERAGE __attribute__((no_sanitize("coverage"), noinline))
#else
#define ARTRACE_NO_COVERAGE
#endif

/// The metres of every stored depth value.
ARTRACE_NO_COVERAGE void fill_metres(double units_per_metre, float* table) {
  for (uint32_t v = 0; v < 65536; ++v) table[v] = ar::depth_metres(v, units_per_metre);
}

/// Stored depth values to metres through the table (0 stays 0: no reading).
ARTRACE_NO_COVERAGE void to_metres(const uint16_t* raw, size_t n, const float* table, float* out) {
  for (size_t k = 0; k < n; ++k) out[k] = table[raw[k]];
}

}  // namespace

OniReader::OniReader(const std::filesystem::path& path, const OniOptions& options)
    : path_(path), options_(options), file_(path) {
  warnings_ = file_.warnings();
  depth_ = file_.find(kOniDepth);
  color_ = file_.find(kOniImage);
  if (!depth_ || !color_) {
    std::string streams;
    for (const OniNode& n : file_.nodes()) streams += (streams.empty() ? "" : ", ") + n.name + " (type " + std::to_string(n.type) + ")";
    throw ParseError(path.string(), 0, 0, std::string("needs a depth and a colour stream; it holds ") + (streams.empty() ? "no stream" : streams));
  }
  for (const OniNode* n : {depth_, color_}) {
    const bool depth = n == depth_;
    const bool known = depth ? (n->codec == "NONE" || n->codec == "16zP" || n->codec == "16zT") : (n->codec == "NONE" || n->codec == "JPEG");
    if (!known) {
      throw ParseError(path.string(), 0, 0, std::string(depth ? "depth" : "colour") + " stream '" + n->name + "' has codec " + quote_token(n->codec) +
                                                ", which this reader does not decode (depth: NONE, 16zP, 16zT; colour: NONE, JPEG)");
    }
  }
  if (depth_->frames.empty() || color_->frames.empty()) {
    throw ParseError(path.string(), 0, 0, "holds no frames (" + std::to_string(depth_->frames.size()) + " depth, " +
                                              std::to_string(color_->frames.size()) + " colour): a recording stopped before its first frame?");
  }
  // pair by time, each frame once, within half the slower stream's period
  const int fps = std::max(1, std::min(depth_->fps > 0 ? depth_->fps : 30, color_->fps > 0 ? color_->fps : 30));
  pairs_ = associate(times_of(*depth_), times_of(*color_), 0.5 / fps);
  if (pairs_.size() < std::max(depth_->frames.size(), color_->frames.size())) {
    warnings_.push_back(path.string() + ": " + std::to_string(depth_->frames.size() - pairs_.size()) + " depth and " +
                        std::to_string(color_->frames.size() - pairs_.size()) + " colour frames have no partner within " +
                        std::to_string(std::lround(500.0 / fps)) + " ms and are skipped");
  }
  if (pairs_.empty()) throw ParseError(path.string(), 0, 0, "no depth frame lies within half a frame period of a colour frame");
  for (const char* s : {"depth", "colour"}) {
    for (const OniGap& g : gaps_of(s[0] == 'd' ? *depth_ : *color_, s)) gaps_.push_back(g);
  }

  // depth unit
  if (options.depth_units_per_metre) {
    depth_units_ = *options.depth_units_per_metre;
  } else if (depth_->int_property("oniPixelFormat").value_or(100) == 101) {
    depth_units_ = 10000.0;  // OpenNI2's DEPTH_100_UM
  }
  metres_.resize(65536);
  fill_metres(depth_units_, metres_.data());
  // registration
  if (const auto avp = depth_->int_property("AlternativeViewPoint")) {
    registered_ = *avp != 0;
    if (!*registered_) {
      warnings_.push_back(path.string() + ": the depth is not registered to the colour camera (AlternativeViewPoint 0): occlusion and "
                          "shadows are offset by the distance between the two cameras");
    }
  }
  // intrinsics
  // xnFOV (radians): OpenNI 1.x records it on the depth node, OpenNI2 and the project's writer on
  // both; registered depth shares the colour camera's
  auto fov_of = [](const OniNode& n, double fov[2]) {
    const auto it = n.properties.find("xnFOV");
    if (it == n.properties.end() || it->second.size() != 16) return false;
    std::memcpy(fov, it->second.data(), 16);
    return fov[0] > 0.0 && fov[0] < 3.1 && fov[1] > 0.0 && fov[1] < 3.1;
  };
  auto intrinsics_of = [&](const OniNode& n, const OniNode* fallback, const char* stream, ar::PinholeIntrinsics& k) {
    k.width = n.width;
    k.height = n.height;
    k.cx = 0.5 * n.width - 0.5;
    k.cy = 0.5 * n.height - 0.5;
    double fov[2];
    const OniNode* from = fov_of(n, fov) ? &n : (fallback && fov_of(*fallback, fov)) ? fallback : nullptr;
    if (from) {
      k.fx = 0.5 * n.width / std::tan(0.5 * fov[0]);
      k.fy = 0.5 * n.height / std::tan(0.5 * fov[1]);
      return std::string("the ") + (from == depth_ ? "depth" : "colour") + " stream's field of view (xnFOV)";
    }
    k.fx = k.fy = 525.0 * n.width / 640.0;
    warnings_.push_back(path.string() + ": the " + stream + " stream records no field of view: default intrinsics fx = fy = " +
                        std::to_string(k.fx) + ", cx = " + std::to_string(k.cx) + ", cy = " + std::to_string(k.cy) +
                        " (give the camera's own with --intrinsics)");
    return std::string("defaults (no xnFOV in the file)");
  };
  const bool registered = registered_.value_or(true);
  if (options.intrinsics) {
    color_k_ = depth_k_ = *options.intrinsics;
    color_k_.width = depth_k_.width = color_->width;
    color_k_.height = depth_k_.height = color_->height;
    intrinsics_source_ = "given";
  } else {
    intrinsics_source_ = intrinsics_of(*color_, registered ? depth_ : nullptr, "colour", color_k_);
    if (registered) {
      depth_k_ = color_k_;
      depth_k_.width = depth_->width;
      depth_k_.height = depth_->height;
    } else {
      intrinsics_of(*depth_, nullptr, "depth", depth_k_);
    }
  }
  const std::filesystem::path sidecar = path.string() + ".trajectory.txt";
  if (options.trajectory) trajectory_ = read_tum_trajectory(*options.trajectory);
  else if (std::filesystem::exists(sidecar)) trajectory_ = read_tum_trajectory(sidecar);
}

ar::SensorFrame OniReader::read(int64_t i) const {
  ar::SensorFrame frame;
  read_into(i, frame);
  return frame;
}

void OniReader::read_into(int64_t i, ar::SensorFrame& frame) const {
  if (i < 0 || i >= static_cast<int64_t>(pairs_.size())) throw std::out_of_range(path_.string() + ": no frame " + std::to_string(i));
  const OniFrameRecord& d = depth_->frames[pairs_[static_cast<size_t>(i)].first];
  const OniFrameRecord& c = color_->frames[pairs_[static_cast<size_t>(i)].second];
  frame.index = i;
  frame.world_from_camera.reset();
  frame.depth_time_s = static_cast<double>(d.timestamp_us) * 1e-6;
  frame.color_time_s = static_cast<double>(c.timestamp_us) * 1e-6;
  thread_local std::vector<uint8_t> payload;
  thread_local std::vector<uint16_t> raw;
  auto fail = [&](const OniFrameRecord& f, const char* stream, const DecodeError& e) -> ParseError {
    return ParseError(file_.where(f.data_offset + e.byte()), 0, 0,
                      std::string(stream) + " frame " + std::to_string(i) + " (" + (stream[0] == 'd' ? depth_ : color_)->codec + "): " + e.what());
  };
  // depth
  file_.read_payload(d, payload);
  const size_t pixels = static_cast<size_t>(d.width) * d.height;
  raw.resize(pixels);
  try {
    if (depth_->codec == "NONE") {
      if (payload.size() != 2 * pixels) {
        throw DecodeError(0, "an uncompressed " + std::to_string(d.width) + "x" + std::to_string(d.height) + " depth frame takes " +
                                 std::to_string(2 * pixels) + " bytes, this one has " + std::to_string(payload.size()));
      }
      std::memcpy(raw.data(), payload.data(), 2 * pixels);
    } else {
      decode_16z(payload.data(), payload.size(), depth_->codec == "16zT", pixels, raw.data());
    }
  } catch (const DecodeError& e) {
    throw fail(d, "depth", e);
  }
  frame.depth.width = d.width;
  frame.depth.height = d.height;
  frame.depth.depth_m.resize(pixels);
  to_metres(raw.data(), pixels, metres_.data(), frame.depth.depth_m.data());
  // colour
  file_.read_payload(c, payload);
  try {
    if (color_->codec == "JPEG") {
      decode_jpeg_rgb(payload.data(), payload.size(), c.width, c.height, frame.color.rgb);
    } else {
      decode_raw_rgb(payload.data(), payload.size(), static_cast<int>(color_->int_property("xnPixelFormat").value_or(1)), c.width, c.height,
                     frame.color.rgb);
    }
  } catch (const DecodeError& e) {
    throw fail(c, "colour", e);
  }
  frame.color.width = c.width;
  frame.color.height = c.height;
  frame.color_intrinsics = color_k_;
  frame.depth_intrinsics = depth_k_;
  if (!trajectory_.empty()) {
    if (auto pose = trajectory_.at(frame.color_time_s, options_.max_pose_gap_s)) frame.world_from_camera = *pose;
  } else {
    frame.world_from_camera = Eigen::Isometry3d::Identity();  // a fixed camera
  }
}

bool OniReader::next(ar::SensorFrame& frame) {
  if (cursor_ >= static_cast<int64_t>(pairs_.size())) return false;
  read_into(cursor_, frame);
  ++cursor_;
  return true;
}

void OniReader::seek(int64_t index) {
  if (index < 0 || index > static_cast<int64_t>(pairs_.size())) {
    throw std::out_of_range(path_.string() + ": cannot seek to frame " + std::to_string(index) + " of " + std::to_string(pairs_.size()));
  }
  cursor_ = index;
}

std::string OniReader::describe() const {
  return "ONI recording " + path_.string() + " (" + std::to_string(pairs_.size()) + " frames, depth " + depth_->codec + ", colour " +
         color_->codec + (file_.finalised() ? "" : ", never finalised") + (trajectory_.empty() ? ", fixed camera" : ", with trajectory") + ")";
}

}  // namespace artrace::io
