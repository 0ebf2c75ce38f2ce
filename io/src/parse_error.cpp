#include "artrace/io/parse_error.h"

namespace artrace::io {
namespace {

std::string format(const std::string& file, int line, int column, const std::string& message) {
  std::string s = file;
  if (line > 0) s += ":" + std::to_string(line);
  if (line > 0 && column > 0) s += ":" + std::to_string(column);
  return s + ": " + message;
}

}  // namespace

std::string quote_token(std::string_view token) {
  constexpr size_t kMax = 40;
  static const char kHex[] = "0123456789abcdef";
  std::string s = "\"";
  for (size_t i = 0; i < token.size() && i < kMax; ++i) {
    const auto c = static_cast<unsigned char>(token[i]);
    if (c >= 0x20 && c < 0x7f) {
      s += static_cast<char>(c);
    } else {
      s += "\\x";
      s += kHex[c >> 4];
      s += kHex[c & 15];
    }
  }
  return s + (token.size() > kMax ? "\"..." : "\"");
}

ParseError::ParseError(std::string file, int line, int column, const std::string& message)
    : std::runtime_error(format(file, line, column, message)), file_(std::move(file)), line_(line), column_(column) {}

}  // namespace artrace::io
