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

InputError::InputError(FileLocation where, const std::string& message, InputProblem problem)
    : std::runtime_error(format_location(where, message)), where_(std::move(where)), message_(message), problem_(problem) {}

const char* to_string(InputProblem problem) {
  switch (problem) {
    case InputProblem::kMalformed: return "malformed";
    case InputProblem::kTruncated: return "truncated";
    case InputProblem::kNonFinite: return "non-finite";
    case InputProblem::kEmpty: return "empty";
    case InputProblem::kInconsistentSurvey: return "inconsistent survey";
    case InputProblem::kCountBeyondLimits: return "count beyond limits";
    case InputProblem::kSuspiciousUnits: return "suspicious units";
  }
  return "?";
}

}  // namespace minemap
