#include "artrace/io/atomic_file.h"

#include <opencv2/imgcodecs.hpp>

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
