// What the libFuzzer harnesses share: a scratch folder of their own (one per process) to write an
// input into under the name a reader expects, with the files it may refer to beside it.
//
// A harness calls one reader on one input. Readers answer bad input by throwing (a message that
// names the file and what is wrong): that is a pass. A crash, a sanitizer report, a hang (libFuzzer's
// -timeout) or an exception not derived from std::exception is a finding.
#pragma once

#include <signal.h>
#include <unistd.h>

#include <cerrno>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

namespace artrace::fuzz {

/// A folder of this process's own, removed when the process ends normally. A crash leaves it
/// (with the inputs the reader saw); the next harness to start removes those of processes gone.
class ScratchDir {
 public:
  ScratchDir() {
    const std::filesystem::path base = std::filesystem::exists("/dev/shm") ? "/dev/shm" : std::filesystem::temp_directory_path();
    const std::string prefix = "artrace-fuzz-";
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(base, ec)) {
      const std::string name = e.path().filename().string();
      if (name.rfind(prefix, 0) != 0) continue;
      const std::string digits = name.substr(prefix.size());
      if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos || digits.size() > 9) continue;
      const pid_t pid = static_cast<pid_t>(std::stol(digits));
      if (kill(pid, 0) != 0 && errno == ESRCH) std::filesystem::remove_all(e.path(), ec);  // its process is gone
    }
    dir_ = base / (prefix + std::to_string(getpid()));
    std::filesystem::create_directories(dir_);
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  const std::filesystem::path& path() const { return dir_; }

 private:
  std::filesystem::path dir_;
};

/// This process's scratch folder, made once (in /dev/shm where it exists: no disk writes).
inline const std::filesystem::path& scratch() {
  static const ScratchDir dir;
  return dir.path();
}

/// Writes bytes to `name` in the scratch folder; returns its path.
inline std::filesystem::path put(const std::string& name, const uint8_t* data, size_t size) {
  const auto p = scratch() / name;
  std::ofstream(p, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  return p;
}
inline std::filesystem::path put(const std::string& name, std::string_view text) {
  return put(name, reinterpret_cast<const uint8_t*>(text.data()), text.size());
}

/// Copies a file of the source tree into the scratch folder (for readers that open references).
inline void provide(const std::filesystem::path& from_source, const std::string& as) {
  std::filesystem::copy_file(std::filesystem::path(ARTRACE_SOURCE_DIR) / from_source, scratch() / as,
                             std::filesystem::copy_options::overwrite_existing);
}

/// Runs a reader; exceptions derived from std::exception are its clean answers to bad input.
template <class Fn>
inline void expect_clean(Fn&& fn) {
  try {
    fn();
  } catch (const std::exception&) {
  }
}

}  // namespace artrace::fuzz
