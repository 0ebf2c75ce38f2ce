// Long runs (soaks): resident memory and the time of each frame sampled every so many frames, then
// a CSV, two plots and a verdict: how much memory grew after the warm-up and how the frame time
// drifted. bench-ar and replay take --soak PREFIX; scripts/soak.sh runs one and judges it.
#pragma once

#include "outputs.h"

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace artrace::tools {

/// Resident memory of this process in MB (/proc/self/statm).
double resident_mb();

class SoakLog {
 public:
  /// Samples are written to PREFIX.csv, PREFIX_memory.png and PREFIX_frame_time.png; `unit` names
  /// what is counted ("frame", "view").
  SoakLog(std::string prefix, int every, std::string unit = "frame") : prefix_(std::move(prefix)), every_(every), unit_(std::move(unit)) {}

  bool on() const { return !prefix_.empty(); }
  /// The files a soak with this prefix writes (none without one), for check_outputs.
  static std::vector<Output> outputs(const std::string& prefix) {
    if (prefix.empty()) return {};
    return {{prefix + ".csv"}, {prefix + "_memory.png"}, {prefix + "_frame_time.png"}};
  }
  /// Records the time of one more frame; every `every` frames, a sample: the frame count, resident
  /// memory and the median time of those frames.
  void add(double frame_ms);

  /// Writes the CSV and the plots and prints the verdict: memory growth after the warm-up (the first
  /// tenth of the samples) and the drift of the frame time (the median of the last quarter's samples
  /// against the first quarter's after the warm-up). Throws with fewer than 8 samples.
  nlohmann::json report() const;

 private:
  std::string prefix_;
  int every_;
  std::string unit_;
  std::vector<double> recent_;
  double count_ = 0;
  std::vector<double> frame_, rss_, ms_;
};

}  // namespace artrace::tools
