#include "soak.h"

#include "bench_util.h"
#include "plot.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <stdexcept>

namespace artrace::tools {

double resident_mb() {
  long pages = 0, resident = 0;
  if (FILE* f = std::fopen("/proc/self/statm", "r")) {
    if (std::fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = 0;
    std::fclose(f);
  }
  return static_cast<double>(resident) * static_cast<double>(sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0);
}

void SoakLog::add(double frame_ms) {
  if (!on()) return;
  ++count_;
  recent_.push_back(frame_ms);
  if (static_cast<int>(recent_.size()) < every_) return;
  frame_.push_back(count_);
  rss_.push_back(resident_mb());
  ms_.push_back(median(recent_));
  recent_.clear();
}

nlohmann::json SoakLog::report() const {
  if (frame_.size() < 8) throw std::invalid_argument("--soak: fewer than 8 samples; run more " + unit_ + "s or lower --soak-every");
  const std::filesystem::path prefix(prefix_);
  if (prefix.has_parent_path()) std::filesystem::create_directories(prefix.parent_path());
  {
    std::string csv = unit_ + ",resident_mb," + unit_ + "_ms_median\n";
    char line[96];
    for (size_t i = 0; i < frame_.size(); ++i) {
      std::snprintf(line, sizeof(line), "%.0f,%.2f,%.3f\n", frame_[i], rss_[i], ms_[i]);
      csv += line;
    }
    io::write_file_atomically(prefix_ + ".csv", csv);
  }
  const size_t warm = std::max<size_t>(1, frame_.size() / 10);
  const size_t n = frame_.size() - warm, quarter = std::max<size_t>(1, n / 4);
  const double rss_warm = rss_[warm], rss_max = *std::max_element(rss_.begin() + warm, rss_.end()), rss_end = rss_.back();
  const double ms_first = median(std::vector<double>(ms_.begin() + warm, ms_.begin() + warm + quarter));
  const double ms_last = median(std::vector<double>(ms_.end() - quarter, ms_.end()));
  const double growth = rss_warm > 0 ? (rss_max - rss_warm) / rss_warm : 0.0, drift = ms_first > 0 ? (ms_last - ms_first) / ms_first : 0.0;
  plot("resident memory (" + std::to_string(static_cast<long long>(frame_.back())) + " " + unit_ + "s)", {{"resident MB", rss_}},
       prefix_ + "_memory.png", "MB", frame_);
  plot("time a " + unit_ + ", median of every " + std::to_string(every_) + " " + unit_ + "s", {{"ms a " + unit_, ms_}}, prefix_ + "_frame_time.png", "ms", frame_);
  std::printf("  soak: resident %.1f MB after warm-up (%s %.0f), at most %.1f MB after it (%+.2f%%), %.1f MB at the end; "
              "time %.2f ms in the first quarter after warm-up, %.2f ms in the last (%+.2f%%); %s.csv and the plots\n",
              rss_warm, unit_.c_str(), frame_[warm], rss_max, 100.0 * growth, rss_end, ms_first, ms_last,
              100.0 * drift, prefix_.c_str());
  return {{"samples", frame_.size()}, {"every", every_}, {"warmup_frames", frame_[warm]}, {"resident_mb_after_warmup", rss_warm},
          {"resident_mb_max_after_warmup", rss_max}, {"resident_mb_end", rss_end}, {"memory_growth", growth},
          {"frame_ms_first_quarter", ms_first}, {"frame_ms_last_quarter", ms_last}, {"frame_time_drift", drift}};
}

}  // namespace artrace::tools
