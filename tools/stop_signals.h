// Stopping an output that is being written: Ctrl-C's SIGINT, SIGTERM (kill's default, and what
// Slurm sends a job at its time limit or when it is cancelled, before SIGKILL) and SIGHUP (the
// terminal closed) are caught while a StopSignals lives, and the writing loop asks
// throw_if_stopped() after each frame. Its exception unwinds to the code that removes the partial
// output, so a stopped export or join leaves nothing behind, under the final name or a partial one.
#pragma once

#include <atomic>
#include <csignal>
#include <filesystem>
#include <stdexcept>
#include <string>

namespace artrace::tools {

namespace detail {
inline std::atomic<int> g_stop_signal{0};
extern "C" inline void on_stop_signal(int s) { g_stop_signal = s; }
}  // namespace detail

class StopSignals {
 public:
  StopSignals() {
    detail::g_stop_signal = 0;
    for (int i = 0; i < 3; ++i) previous_[i] = std::signal(kSignals[i], detail::on_stop_signal);
  }
  ~StopSignals() {
    for (int i = 0; i < 3; ++i) std::signal(kSignals[i], previous_[i]);
  }
  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;

  /// Throws "stopped by SIGTERM: OUT was not written" (or SIGINT, SIGHUP) once one has come.
  static void throw_if_stopped(const std::filesystem::path& out) {
    const int s = detail::g_stop_signal;
    if (s == 0) return;
    const char* name = s == SIGINT ? "SIGINT" : s == SIGTERM ? "SIGTERM" : "SIGHUP";
    throw std::runtime_error(std::string("stopped by ") + name + ": " + out.string() + " was not written");
  }

 private:
  static constexpr int kSignals[3] = {SIGINT, SIGTERM, SIGHUP};
  using Handler = void (*)(int);
  Handler previous_[3];
};

}  // namespace artrace::tools
