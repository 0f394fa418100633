#include "minemap/core/error.hpp"

namespace minemap {
namespace {
std::string format_location(const FileLocation& where, const std::string& message) {
  std::string text = where.path;
  if (where.line > 0) {
    text += ':';
    text += std::to_string(where.line);
  } else if (where.byte_offset >= 0) {
    text += "@byte ";
    text += std::to_string(where.byte_offset);
  }
  text += ": ";
  text += message;
  return text;
}
}  // namespace

InputError::InputError(FileLocation where, const std::string& message)
    : std::runtime_error(format_location(where, message)), where_(std::move(where)), message_(message) {}

}  // namespace minemap
