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

ParseError::ParseError(std::string file, int line, int column, const std::string& message)
    : std::runtime_error(format(file, line, column, message)), file_(std::move(file)), line_(line), column_(column) {}

}  // namespace artrace::io
