// Camera trajectories: timestamped world-from-camera poses, interpolated between samples.
#pragma once

#include <Eigen/Geometry>

#include <optional>
#include <utility>
#include <vector>

namespace artrace::ar {

struct PoseSample {
  double time_s = 0.0;
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();  ///< unit
};

class Trajectory {
 public:
  Trajectory() = default;
  /// Samples sorted by strictly increasing time, unit quaternions (checked: throws
  /// std::invalid_argument naming the sample).
  explicit Trajectory(std::vector<PoseSample> samples);

  bool empty() const { return samples_.empty(); }
  size_t size() const { return samples_.size(); }
  const std::vector<PoseSample>& samples() const { return samples_; }

  /// The pose at time t: linear in translation, slerp in rotation between the two samples around t.
  /// Empty outside [first, last] or where the two samples are more than `max_gap_s` apart.
  std::optional<Eigen::Isometry3d> at(double t, double max_gap_s = 0.1) const;
  /// The first and last samples' times; empty for an empty trajectory.
  std::optional<std::pair<double, double>> span() const {
    if (samples_.empty()) return std::nullopt;
    return std::make_pair(samples_.front().time_s, samples_.back().time_s);
  }

 private:
  std::vector<PoseSample> samples_;
};

}  // namespace artrace::ar
