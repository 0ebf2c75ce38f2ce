#include "artrace/ar/trajectory.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace artrace::ar {

Trajectory::Trajectory(std::vector<PoseSample> samples) : samples_(std::move(samples)) {
  for (size_t i = 0; i < samples_.size(); ++i) {
    const PoseSample& s = samples_[i];
    if (!std::isfinite(s.time_s) || !s.translation.allFinite() || !s.rotation.coeffs().allFinite()) {
      throw std::invalid_argument("pose " + std::to_string(i) + " has a non-finite value");
    }
    if (std::fabs(s.rotation.norm() - 1.0) > 1e-3) {
      throw std::invalid_argument("pose " + std::to_string(i) + " has a non-unit quaternion (norm " +
                                  std::to_string(s.rotation.norm()) + ")");
    }
    samples_[i].rotation.normalize();
    if (i > 0 && !(s.time_s > samples_[i - 1].time_s)) {
      throw std::invalid_argument("pose " + std::to_string(i) + " at t=" + std::to_string(s.time_s) +
                                  " does not come after the previous one");
    }
  }
}

std::optional<Eigen::Isometry3d> Trajectory::at(double t, double max_gap_s) const {
  if (samples_.empty() || t < samples_.front().time_s || t > samples_.back().time_s) return std::nullopt;
  const auto it = std::lower_bound(samples_.begin(), samples_.end(), t,
                                   [](const PoseSample& s, double v) { return s.time_s < v; });
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  if (it->time_s == t) {
    pose.linear() = it->rotation.toRotationMatrix();
    pose.translation() = it->translation;
    return pose;
  }
  const PoseSample& b = *it;
  const PoseSample& a = *(it - 1);
  if (b.time_s - a.time_s > max_gap_s) return std::nullopt;
  const double s = (t - a.time_s) / (b.time_s - a.time_s);
  pose.linear() = a.rotation.slerp(s, b.rotation).toRotationMatrix();
  pose.translation() = (1.0 - s) * a.translation + s * b.translation;
  return pose;
}

}  // namespace artrace::ar
