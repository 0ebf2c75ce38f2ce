#include "artrace/io/atomic_file.h"

#include <opencv2/imgcodecs.hpp>

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

namespace artrace::io {
namespace {

/// Writes `bytes` as the whole of `file`; 0, or the errno of the first step that failed. A failed
/// regular file (or link) is removed; a device (/dev/full) is left alone.
int write_checked(const std::filesystem::path& file, std::string_view bytes) {
  std::FILE* f = std::fopen(file.c_str(), "wb");
  if (!f) return errno != 0 ? errno : EIO;
  errno = 0;
  int err = 0;
  if (std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size() || std::fflush(f) != 0) err = errno != 0 ? errno : EIO;
  if (std::fclose(f) != 0 && err == 0) err = errno != 0 ? errno : EIO;
  if (err != 0) {
    std::error_code ec;
    const auto type = std::filesystem::symlink_status(file, ec).type();
    if (type == std::filesystem::file_type::regular || type == std::filesystem::file_type::symlink) std::filesystem::remove(file, ec);
  }
  return err;
}

/// The process's file mode creation mask, read without changing it (/proc/self/status), else by
/// setting it and back.
mode_t creation_mask() {
  if (std::FILE* f = std::fopen("/proc/self/status", "r")) {
    char line[256];
    unsigned mask = 0;
    bool found = false;
    while (!found && std::fgets(line, sizeof line, f)) found = std::sscanf(line, "Umask: %o", &mask) == 1;
    std::fclose(f);
    if (found) return static_cast<mode_t>(mask);
  }
  const mode_t mask = ::umask(022);
  ::umask(mask);
  return mask;
}

/// Gives `made` the name `path` unless something has it: 0, or the errno (EEXIST when taken).
int take_name(const std::string& made, const std::filesystem::path& path, PartialOutput::Kind kind) {
  if (renameat2(AT_FDCWD, made.c_str(), AT_FDCWD, path.c_str(), RENAME_NOREPLACE) == 0) return 0;
  if (errno != EINVAL && errno != ENOSYS) return errno;
  // a filesystem without RENAME_NOREPLACE: a file's link is refused when the name is taken; a
  // folder's name is looked at first
  if (kind == PartialOutput::Kind::file) {
    if (::link(made.c_str(), path.c_str()) != 0) return errno;
    ::unlink(made.c_str());
    return 0;
  }
  std::error_code ec;
  if (std::filesystem::exists(std::filesystem::symlink_status(path, ec))) return EEXIST;
  return ::rename(made.c_str(), path.c_str()) == 0 ? 0 : errno;
}

[[noreturn]] void cannot_write(const std::filesystem::path& path, int err) {
  throw std::runtime_error(path.string() + ": cannot write: " + std::strerror(err));
}

}  // namespace

void write_file(const std::filesystem::path& path, std::string_view bytes) {
  if (const int err = write_checked(path, bytes)) cannot_write(path, err);
}

void write_file_atomically(const std::filesystem::path& path, std::string_view bytes) {
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  const std::filesystem::path partial = path.string() + ".partial";
  if (const int err = write_checked(partial, bytes)) cannot_write(path, err);
  std::error_code ec;
  std::filesystem::rename(partial, path, ec);  // fails where `path` is a folder, say
  if (ec) {
    std::filesystem::remove(partial);
    throw std::runtime_error(path.string() + ": cannot write: " + ec.message());
  }
}

PartialOutput::PartialOutput(std::filesystem::path partial, Kind kind, std::string out) : path_(std::move(partial)) {
  if (path_.has_parent_path()) std::filesystem::create_directories(path_.parent_path());
  auto fail = [&](const std::string& what, int err) {
    throw std::runtime_error(out + ": cannot create " + path_.string() + ": " + what + std::strerror(err));
  };
  for (int attempt = 0;; ++attempt) {
    // a new one under a unique name, locked before it takes the partial's name
    std::string made = path_.string() + ".XXXXXX";
    int fd = -1;
    if (kind == Kind::folder) {
      if (!mkdtemp(made.data())) fail("", errno);
      fd = ::open(made.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    } else {
      fd = mkostemp(made.data(), O_CLOEXEC);
    }
    // mkstemp and mkdtemp make them the owner's alone; an output gets what open() and mkdir() give
    const mode_t mode = (kind == Kind::folder ? 0777 : 0666) & ~creation_mask();
    if (fd < 0 || ::fchmod(fd, mode) != 0 || flock(fd, LOCK_EX | LOCK_NB) != 0) {
      const int err = errno;
      std::error_code ec;
      std::filesystem::remove(made, ec);
      if (fd >= 0) ::close(fd);
      fail("", err);
    }
    const int err = take_name(made, path_, kind);
    if (err == 0) {
      fd_ = fd;
      return;
    }
    std::error_code ec;
    std::filesystem::remove(made, ec);
    ::close(fd);
    if (err != EEXIST || attempt > 0) fail("", err);
    // a partial is there already: another process's, in use, or one left by a process that died
    const int held = ::open(path_.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (held >= 0 && flock(held, LOCK_EX | LOCK_NB) != 0) {
      const int busy = errno;
      ::close(held);
      if (busy == EWOULDBLOCK) {
        throw std::runtime_error(out + ": is being written by another process (" + path_.string() + " is in use)");
      }
      fail("", busy);
    }
    std::filesystem::remove_all(path_, ec);
    if (held >= 0) ::close(held);
    if (ec) fail("the one left there cannot be removed: ", ec.value());
  }
}

PartialOutput::~PartialOutput() {
  if (fd_ >= 0) ::close(fd_);
}

PartialOutput::PartialOutput(PartialOutput&& other) noexcept : path_(std::move(other.path_)), fd_(other.fd_) { other.fd_ = -1; }

void write_png(const std::filesystem::path& path, const cv::Mat& image, bool atomically) {
  std::vector<uchar> bytes;
  if (!cv::imencode(".png", image, bytes)) throw std::runtime_error(path.string() + ": cannot encode PNG");
  const std::string_view view(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  if (atomically) {
    write_file_atomically(path, view);
  } else {
    write_file(path, view);
  }
}

}  // namespace artrace::io
