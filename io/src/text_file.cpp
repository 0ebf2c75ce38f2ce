#include "artrace/io/text_file.h"
#include "artrace/io/parse_error.h"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>

namespace artrace::io {

std::string read_text_file(const std::filesystem::path& path, std::size_t max_bytes) {
  const std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!f) throw ParseError(path.string(), 0, 0, std::string("cannot open file: ") + std::strerror(errno));
  std::string text;
  char chunk[1 << 16];
  for (;;) {
    const std::size_t n = std::fread(chunk, 1, sizeof(chunk), f.get());
    if (const void* nul = std::memchr(chunk, '\0', n)) {
      const std::size_t at = text.size() + static_cast<std::size_t>(static_cast<const char*>(nul) - chunk);
      text.append(chunk, static_cast<const char*>(nul) - chunk);
      const int line = 1 + static_cast<int>(std::count(text.begin(), text.end(), '\n'));
      throw ParseError(path.string(), line, 0, "a NUL byte at byte " + std::to_string(at) + ": not a text file");
    }
    if (text.size() + n > max_bytes) {
      throw ParseError(path.string(), 0, 0, "runs past " + std::to_string(max_bytes) + " bytes: too large for a text file of this kind");
    }
    text.append(chunk, n);
    if (n < sizeof(chunk)) break;
  }
  if (std::ferror(f.get())) throw ParseError(path.string(), 0, 0, "cannot read file");
  return text;
}

}  // namespace artrace::io
