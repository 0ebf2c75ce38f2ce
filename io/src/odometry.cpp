#include "artrace/io/odometry.h"

#include <opencv2/core/eigen.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/rgbd.hpp>

#include <cmath>
#include <stdexcept>

namespace artrace::io {
namespace {

struct Prepared {
  cv::Mat gray, depth, mask;
};

Prepared prepare(const ar::SensorFrame& f) {
  Prepared p;
  const cv::Mat rgb(f.color.height, f.color.width, CV_8UC3, const_cast<uint8_t*>(f.color.rgb.data()));
  cv::cvtColor(rgb, p.gray, cv::COLOR_RGB2GRAY);
  cv::Mat d(f.depth.height, f.depth.width, CV_32FC1, const_cast<float*>(f.depth.depth_m.data()));
  p.depth = d.clone();
  p.mask = p.depth > 0.0f;
  p.depth.setTo(std::numeric_limits<float>::quiet_NaN(), ~p.mask);
  return p;
}

}  // namespace

OdometryResult estimate_trajectory(ar::FrameSource& source, const OdometryOptions& options) {
  OdometryResult result;
  ar::SensorFrame frame;
  if (!source.next(frame)) throw std::runtime_error(source.describe() + ": no frame to track");
  const ar::PinholeIntrinsics& k = frame.color_intrinsics;
  const cv::Mat K = (cv::Mat_<float>(3, 3) << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
  cv::Ptr<cv::rgbd::Odometry> odo = cv::rgbd::Odometry::create(options.method);
  if (odo.empty()) throw std::invalid_argument("unknown odometry method '" + options.method + "'");
  odo->setCameraMatrix(K);
  std::vector<ar::PoseSample> poses;
  Eigen::Isometry3d world_from_cam = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d last_motion = Eigen::Isometry3d::Identity();
  auto push = [&](double t) {
    ar::PoseSample s;
    s.time_s = t;
    s.translation = world_from_cam.translation();
    s.rotation = Eigen::Quaterniond(world_from_cam.rotation()).normalized();
    poses.push_back(s);
  };
  std::vector<ar::PoseSample> given;
  bool all_given = true;
  auto remember = [&](const ar::SensorFrame& f) {
    if (!f.world_from_camera) {
      all_given = false;
      return;
    }
    ar::PoseSample s;
    s.time_s = f.color_time_s;
    s.translation = f.world_from_camera->translation();
    s.rotation = Eigen::Quaterniond(f.world_from_camera->rotation()).normalized();
    given.push_back(s);
  };
  const std::string need = "odometry needs depth registered to the colour";
  ar::require_depth_at_colour_size(frame, source.describe(), need);
  push(frame.color_time_s);
  remember(frame);
  Prepared prev = prepare(frame);
  int n = 1;
  while ((options.max_frames <= 0 || n < options.max_frames) && source.next(frame)) {
    ar::require_depth_at_colour_size(frame, source.describe(), need);
    Prepared cur = prepare(frame);
    cv::Mat rt;
    // Rt maps points of the source (previous) frame into the destination (current) frame.
    const bool ok = odo->compute(prev.gray, prev.depth, prev.mask, cur.gray, cur.depth, cur.mask, rt);
    if (ok && !rt.empty()) {
      Eigen::Matrix4d m;
      cv::cv2eigen(rt, m);
      Eigen::Isometry3d cur_from_prev(m);
      last_motion = cur_from_prev.inverse();  // prev_from_cur
    } else {
      ++result.failures;  // keep moving as before
    }
    world_from_cam = world_from_cam * last_motion;
    push(frame.color_time_s);
    remember(frame);
    prev = std::move(cur);
    ++n;
  }
  result.trajectory = ar::Trajectory(std::move(poses));
  if (all_given) result.reference = ar::Trajectory(std::move(given));
  return result;
}

DriftReport compare_trajectories(const ar::Trajectory& estimate, const ar::Trajectory& reference) {
  DriftReport r;
  if (estimate.empty() || reference.empty()) return r;
  const auto ref0 = reference.at(estimate.samples().front().time_s, 1e9);
  if (!ref0) return r;
  // estimate poses are relative to its first frame: express the reference the same way
  const Eigen::Isometry3d ref0_inv = ref0->inverse();
  double sum = 0.0;
  for (const ar::PoseSample& s : estimate.samples()) {
    const auto ref = reference.at(s.time_s, 1e9);
    if (!ref) continue;
    const Eigen::Isometry3d rel = ref0_inv * *ref;
    const double e = (rel.translation() - s.translation).norm();
    sum += e * e;
    ++r.compared;
    r.final_m = e;
    const Eigen::AngleAxisd d(rel.rotation().transpose() * s.rotation.toRotationMatrix());
    r.final_deg = std::fabs(d.angle()) * 180.0 / M_PI;
  }
  r.rms_m = r.compared ? std::sqrt(sum / r.compared) : 0.0;
  return r;
}

}  // namespace artrace::io
