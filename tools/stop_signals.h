// Stopping a command that writes outputs: Ctrl-C's SIGINT, SIGTERM (kill's default, and what Slurm
// sends a job at its time limit or when it is cancelled, before SIGKILL) and SIGHUP (the terminal
// closed) are caught while a StopSignals lives. Export and join ask throw_if_stopped() after each
// frame, and convert and synth before each frame they write (StoppableRecordingWriter); its
// exception unwinds to the code that removes the partial output, so a stopped command leaves
// nothing behind, under the final name or a partial one. Batch passes the signal on to its jobs.
#pragma once

#include <signal.h>

#include "artrace/io/recording_writer.h"

#include <csignal>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>

namespace artrace::tools {

namespace detail {
inline volatile std::sig_atomic_t g_stop_signal = 0;
extern "C" inline void on_stop_signal(int s) { g_stop_signal = s; }
}  // namespace detail

class StopSignals {
 public:
  /// `restart` false: a blocking call such as wait() returns at once (EINTR) when one comes, rather
  /// than going on waiting.
  explicit StopSignals(bool restart = true) {
    detail::g_stop_signal = 0;
    struct sigaction sa = {};
    sa.sa_handler = detail::on_stop_signal;
    sa.sa_flags = restart ? SA_RESTART : 0;
    sigemptyset(&sa.sa_mask);
    for (int i = 0; i < 3; ++i) sigaction(kSignals[i], &sa, &previous_[i]);
  }
  ~StopSignals() {
    for (int i = 0; i < 3; ++i) sigaction(kSignals[i], &previous_[i], nullptr);
  }
  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;

  /// The signal that asked to stop, or 0.
  static int caught() { return detail::g_stop_signal; }
  static const char* name(int s) { return s == SIGINT ? "SIGINT" : s == SIGTERM ? "SIGTERM" : "SIGHUP"; }

  /// Throws "stopped by SIGTERM: OUT was not written" (or SIGINT, SIGHUP) once one has come.
  static void throw_if_stopped(const std::filesystem::path& out) {
    if (const int s = caught()) throw std::runtime_error(std::string("stopped by ") + name(s) + ": " + out.string() + " was not written");
  }

 private:
  static constexpr int kSignals[3] = {SIGINT, SIGTERM, SIGHUP};
  struct sigaction previous_[3];
};

/// A recording writer that stops, before writing the next frame, once a stop signal has come: the
/// exception unwinds through the writer it wraps, whose destructor removes its partial output.
/// The signals are caught from construction to close().
class StoppableRecordingWriter : public io::RecordingWriter {
 public:
  StoppableRecordingWriter(std::unique_ptr<io::RecordingWriter> inner, std::filesystem::path out)
      : inner_(std::move(inner)), out_(std::move(out)), stop_(std::make_unique<StopSignals>()) {}
  void write(const ar::SensorFrame& frame) override {
    StopSignals::throw_if_stopped(out_);
    inner_->write(frame);
  }
  void close() override {
    StopSignals::throw_if_stopped(out_);
    inner_->close();
    stop_.reset();
  }

 private:
  std::unique_ptr<io::RecordingWriter> inner_;
  std::filesystem::path out_;
  std::unique_ptr<StopSignals> stop_;
};

}  // namespace artrace::tools
