#include "artrace/io/tum_reader.h"
#include "artrace/io/atomic_file.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/text_file.h"
#include "cv_convert.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <sstream>

namespace artrace::io {
namespace {

/// Splits a line into white-space separated words; empty for blank and '#' comment lines.
std::vector<std::string> words(const std::string& line) {
  std::vector<std::string> out;
  std::istringstream in(line);
  std::string w;
  while (in >> w) {
    if (w[0] == '#') break;
    out.push_back(w);
  }
  return out;
}

double parse_number(const std::string& s, const std::filesystem::path& file, int line, const char* what) {
  size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != s.size() || !std::isfinite(v)) {
    throw ParseError(file.string(), line, 0, std::string("expected ") + what + ", got " + quote_token(s));
  }
  return v;
}

/// The file's text as a stream of lines, read with a text file's checks (read_text_file).
std::istringstream open_text(const std::filesystem::path& path) { return std::istringstream(read_text_file(path)); }

}  // namespace

std::vector<TimedFile> read_tum_list(const std::filesystem::path& path) {
  std::istringstream in = open_text(path);
  std::vector<TimedFile> out;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    const auto w = words(line);
    if (w.empty()) continue;
    if (w.size() != 2) {
      throw ParseError(path.string(), n, 0, "expected 'timestamp filename', got " + std::to_string(w.size()) + " words");
    }
    const double t = parse_number(w[0], path, n, "a timestamp");
    if (!out.empty() && !(t > out.back().time_s)) {
      throw ParseError(path.string(), n, 0, "timestamp " + w[0] + " does not come after the previous one");
    }
    out.push_back({t, w[1]});
  }
  return out;
}

ar::Trajectory read_tum_trajectory(const std::filesystem::path& path) {
  std::istringstream in = open_text(path);
  std::vector<ar::PoseSample> samples;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    const auto w = words(line);
    if (w.empty()) continue;
    if (w.size() != 8) {
      throw ParseError(path.string(), n, 0, "expected 'timestamp tx ty tz qx qy qz qw', got " + std::to_string(w.size()) + " words");
    }
    double v[8];
    for (int i = 0; i < 8; ++i) v[i] = parse_number(w[i], path, n, "a number");
    ar::PoseSample s;
    s.time_s = v[0];
    s.translation = {v[1], v[2], v[3]};
    s.rotation = Eigen::Quaterniond(v[7], v[4], v[5], v[6]);
    if (std::fabs(s.rotation.norm() - 1.0) > 1e-3) {
      throw ParseError(path.string(), n, 0, "quaternion has norm " + std::to_string(s.rotation.norm()) + ", not 1");
    }
    // metres: a camera 1,000 km away is a broken file, and beyond float range (the renderer's
    // camera) it would be infinite
    for (int i = 1; i <= 3; ++i) {
      if (!(std::fabs(v[i]) <= 1e6)) throw ParseError(path.string(), n, 0, "translation " + quote_token(w[i]) + " is beyond +-1e6 m");
    }
    if (!samples.empty() && !(s.time_s > samples.back().time_s)) {
      throw ParseError(path.string(), n, 0, "timestamp " + w[0] + " does not come after the previous one");
    }
    samples.push_back(s);
  }
  // an empty trajectory would leave every frame without a camera (or, for .oni files, with a
  // fixed one) and say nothing
  if (samples.empty()) throw ParseError(path.string(), 0, 0, "holds no pose (lines 'timestamp tx ty tz qx qy qz qw')");
  return ar::Trajectory(std::move(samples));
}

ar::PinholeIntrinsics read_intrinsics(const std::filesystem::path& path) {
  std::istringstream in = open_text(path);
  std::string line;
  std::vector<std::string> w;
  int n = 0;
  while (w.empty() && std::getline(in, line)) {
    ++n;
    w = words(line);
  }
  if (w.size() != 4 && w.size() != 6) throw ParseError(path.string(), n, 0, "expected 'fx fy cx cy [width height]'");
  auto value = [&](int i, const char* what, double lo, double hi) {
    const double v = parse_number(w[i], path, n, what);
    if (!(v >= lo && v <= hi)) {
      std::ostringstream m;
      m << what << " " << quote_token(w[i]) << " is not in " << lo << ".." << hi;
      throw ParseError(path.string(), n, 0, m.str());
    }
    return v;
  };
  ar::PinholeIntrinsics k;
  k.fx = value(0, "fx", 1e-6, 1e6);
  k.fy = value(1, "fy", 1e-6, 1e6);
  k.cx = value(2, "cx", -1e6, 1e6);
  k.cy = value(3, "cy", -1e6, 1e6);
  if (w.size() == 6) {
    k.width = static_cast<int>(value(4, "the width", 1, 100000));
    k.height = static_cast<int>(value(5, "the height", 1, 100000));
  }
  return k;
}

void write_tum_trajectory(const std::filesystem::path& path, const ar::Trajectory& trajectory) {
  std::ostringstream out;
  out << "# timestamp tx ty tz qx qy qz qw\n" << std::setprecision(9);
  for (const ar::PoseSample& s : trajectory.samples()) {
    out << std::fixed << std::setprecision(6) << s.time_s << std::setprecision(9) << ' ' << s.translation.x() << ' '
        << s.translation.y() << ' ' << s.translation.z() << ' ' << s.rotation.x() << ' ' << s.rotation.y() << ' '
        << s.rotation.z() << ' ' << s.rotation.w() << '\n';
  }
  write_file_atomically(path, out.str());
}

std::vector<std::pair<size_t, size_t>> associate(const std::vector<TimedFile>& color,
                                                 const std::vector<TimedFile>& depth, double max_dt_s) {
  struct Candidate {
    double dt;
    size_t c, d;
  };
  std::vector<Candidate> cands;
  size_t lo = 0;
  for (size_t c = 0; c < color.size(); ++c) {
    while (lo < depth.size() && depth[lo].time_s < color[c].time_s - max_dt_s) ++lo;
    for (size_t d = lo; d < depth.size() && depth[d].time_s <= color[c].time_s + max_dt_s; ++d) {
      cands.push_back({std::fabs(depth[d].time_s - color[c].time_s), c, d});
    }
  }
  std::sort(cands.begin(), cands.end(), [](const Candidate& a, const Candidate& b) {
    return a.dt < b.dt || (a.dt == b.dt && (a.c < b.c || (a.c == b.c && a.d < b.d)));
  });
  std::vector<char> used_c(color.size(), 0), used_d(depth.size(), 0);
  std::vector<std::pair<size_t, size_t>> out;
  for (const Candidate& k : cands) {
    if (used_c[k.c] || used_d[k.d]) continue;
    used_c[k.c] = used_d[k.d] = 1;
    out.push_back({k.c, k.d});
  }
  std::sort(out.begin(), out.end());
  return out;
}

ar::PinholeIntrinsics freiburg_intrinsics(const std::string& name) {
  auto has = [&](const char* s) { return name.find(s) != std::string::npos; };
  if (has("freiburg1") || has("fr1")) return {640, 480, 517.3, 516.5, 318.6, 255.3};
  if (has("freiburg2") || has("fr2")) return {640, 480, 520.9, 521.0, 325.1, 249.7};
  if (has("freiburg3") || has("fr3")) return {640, 480, 535.4, 539.2, 320.1, 247.6};
  return {640, 480, 525.0, 525.0, 319.5, 239.5};
}

void check_intrinsics_size(const ar::PinholeIntrinsics& k, int width, int height, const std::string& where, const std::string& subject) {
  if ((k.width == 0 || k.width == width) && (k.height == 0 || k.height == height)) return;  // 0: not named
  throw ParseError(where, 0, 0, subject + " for " + std::to_string(k.width) + "x" + std::to_string(k.height) + " images, the recording's are " +
                                     std::to_string(width) + "x" + std::to_string(height));
}

TumReader::TumReader(const std::filesystem::path& folder, const TumOptions& options)
    : folder_(folder), options_(options) {
  if (!std::filesystem::is_directory(folder)) throw ParseError(folder.string(), 0, 0, "not a folder");
  const auto color = read_tum_list(folder / "rgb.txt");
  const auto depth = read_tum_list(folder / "depth.txt");
  if (color.empty()) throw ParseError((folder / "rgb.txt").string(), 0, 0, "lists no frames");
  const auto pairs = associate(color, depth, options.max_dt_s);
  if (pairs.size() < color.size()) {
    std::ostringstream m;
    m << folder.string() << ": " << color.size() - pairs.size() << " colour frames have no depth frame within " << options.max_dt_s
      << " s and are skipped";
    warnings_.push_back(m.str());
  }
  size_t missing = 0;
  for (const auto& [c, d] : pairs) {
    if (!std::filesystem::exists(folder / color[c].file) || !std::filesystem::exists(folder / depth[d].file)) {
      if (++missing <= 3) {
        warnings_.push_back(folder.string() + ": frame " + color[c].file + " / " + depth[d].file + " is listed but missing, skipped");
      }
      continue;
    }
    frames_.push_back({color[c], depth[d]});
  }
  if (missing > 3) warnings_.push_back(folder.string() + ": " + std::to_string(missing) + " listed frames missing in all");
  if (frames_.empty()) throw ParseError(folder.string(), 0, 0, "no frame has both a colour and a depth image");

  if (options.trajectory) {
    trajectory_ = read_tum_trajectory(*options.trajectory);
  } else if (std::filesystem::exists(folder / "groundtruth.txt")) {
    trajectory_ = read_tum_trajectory(folder / "groundtruth.txt");
  }
  if (options.intrinsics) {
    intrinsics_ = *options.intrinsics;
    intrinsics_source_ = "given";
    intrinsics_where_ = folder;
    intrinsics_subject_ = "the intrinsics given are";
  } else if (std::filesystem::exists(folder / "intrinsics.txt")) {
    intrinsics_ = read_intrinsics(folder / "intrinsics.txt");
    intrinsics_source_ = intrinsics_where_ = folder / "intrinsics.txt";
  } else {
    const std::string name = std::filesystem::absolute(folder).lexically_normal().string();
    intrinsics_ = freiburg_intrinsics(name);
    const int fr = name.find("freiburg1") != std::string::npos || name.find("fr1") != std::string::npos   ? 1
                   : name.find("freiburg2") != std::string::npos || name.find("fr2") != std::string::npos ? 2
                   : name.find("freiburg3") != std::string::npos || name.find("fr3") != std::string::npos ? 3
                                                                                                        : 0;
    if (fr > 0) {
      intrinsics_source_ = "the TUM benchmark's Freiburg " + std::to_string(fr) + " intrinsics, chosen by the folder's name";
      intrinsics_where_ = folder;
      intrinsics_subject_ = intrinsics_source_ + ", are";
    } else {
      warnings_.push_back(folder.string() + ": no intrinsics.txt and no Freiburg sequence name: default intrinsics fx = fy = 525 px at "
                          "640 wide (scaled with the width), principal point at the centre (give the camera's own with --intrinsics)");
      intrinsics_source_ = "defaults";
      default_intrinsics_ = true;
    }
  }
}

ar::SensorFrame TumReader::read(int64_t i) const {
  if (i < 0 || i >= static_cast<int64_t>(frames_.size())) {
    throw std::out_of_range(folder_.string() + ": frame " + std::to_string(i) + " of " + std::to_string(frames_.size()));
  }
  const Entry& e = frames_[static_cast<size_t>(i)];
  ar::SensorFrame f;
  f.index = i;
  f.color_time_s = e.color.time_s;
  f.depth_time_s = e.depth.time_s;
  const std::filesystem::path cp = folder_ / e.color.file, dp = folder_ / e.depth.file;
  const cv::Mat bgr = read_image_file(cp, cv::IMREAD_COLOR);
  if (bgr.empty()) throw ParseError(cp.string(), 0, 0, "cannot decode the colour image (missing, truncated or not an image)");
  const cv::Mat raw = read_depth_png(dp, bgr);
  f.color = color_from_bgr(bgr);
  f.depth = depth_from_u16(raw, options_.depth_scale);
  if (default_intrinsics_) {
    const double focal = 525.0 * bgr.cols / 640.0;
    f.color_intrinsics = {bgr.cols, bgr.rows, focal, focal, 0.5 * bgr.cols - 0.5, 0.5 * bgr.rows - 0.5};
  } else {
    check_intrinsics_size(intrinsics_, bgr.cols, bgr.rows, intrinsics_where_.string(), intrinsics_subject_);
    f.color_intrinsics = intrinsics_;
    f.color_intrinsics.width = bgr.cols;
    f.color_intrinsics.height = bgr.rows;
  }
  f.depth_intrinsics = f.color_intrinsics;  // TUM depth is registered to colour
  if (!trajectory_.empty()) {
    if (auto pose = trajectory_.at(e.color.time_s, options_.max_pose_gap_s)) f.world_from_camera = *pose;
  }
  return f;
}

bool TumReader::next(ar::SensorFrame& frame) {
  if (cursor_ >= static_cast<int64_t>(frames_.size())) return false;
  frame = read(cursor_++);
  return true;
}

void TumReader::seek(int64_t index) {
  if (index < 0 || index > static_cast<int64_t>(frames_.size())) {
    throw std::out_of_range(folder_.string() + ": cannot seek to frame " + std::to_string(index) + " of " +
                            std::to_string(frames_.size()));
  }
  cursor_ = index;
}

std::string TumReader::describe() const {
  return "TUM RGB-D sequence " + folder_.string() + " (" + std::to_string(frames_.size()) + " frames" +
         (trajectory_.empty() ? ", no trajectory" : ", with trajectory") + ")";
}

}  // namespace artrace::io
