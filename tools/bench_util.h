// Small helpers shared by the benchmark commands.
#pragma once

#include "artrace/io/atomic_file.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace artrace::tools {

inline double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

inline double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

inline void write_json(const std::string& path, const nlohmann::json& j) {
  if (path.empty()) return;
  io::write_file_atomically(path, j.dump(2) + "\n");
}

}  // namespace artrace::tools
