// The one error type of the io library: a malformed input, with where it was found.
#pragma once

#include <stdexcept>
#include <string>
#include <string_view>

namespace artrace::io {

/// "file:line:col: message" (line and column 1-based; 0 when not known).
class ParseError : public std::runtime_error {
 public:
  ParseError(std::string file, int line, int column, const std::string& message);
  const std::string& file() const { return file_; }
  int line() const { return line_; }
  int column() const { return column_; }

 private:
  std::string file_;
  int line_;
  int column_;
};

/// `token` in double quotes for an error message: bytes outside printable ASCII as \xNN, and at most
/// 40 characters of it followed by "..." (a corrupt file's token may be binary, or megabytes long).
std::string quote_token(std::string_view token);

}  // namespace artrace::io
