#pragma once
// Errors minemap reports to users. Every input problem names the file and the line (text formats)
// or byte offset (binary formats) where it was found, so a user can open the file and look.
#include <cstdint>
#include <stdexcept>
#include <string>

namespace minemap {

/// What is wrong with an input, carried by InputError; each kind has its own exit code in the
/// `minemap` program (cli/exit_codes.hpp).
enum class InputProblem {
  kMalformed,           ///< bad syntax, binary garbage, unreadable or missing file (exit 3)
  kTruncated,           ///< the file ends early (exit 7)
  kNonFinite,           ///< inf / NaN where no value can be dropped, all points NaN (exit 8)
  kEmpty,               ///< nothing, or too little, to work with (exit 9)
  kInconsistentSurvey,  ///< the survey's files do not fit together (exit 10)
  kCountBeyondLimits,   ///< a header claims more than the limits allow (exit 11)
  kSuspiciousUnits,     ///< the coordinates look like another unit than the one read (exit 12)
};

/// "malformed", "truncated", "non-finite", "empty", "inconsistent survey", "count beyond limits",
/// "suspicious units".
const char* to_string(InputProblem problem);

/// Where in a file an error was found: a 1-based line for text, a byte offset for binary data.
struct FileLocation {
  std::string path;
  std::int64_t line = 0;         ///< 1-based; 0 when unknown or binary
  std::int64_t byte_offset = -1; ///< >= 0 for binary data
};

/// A problem with an input file. what() reads "path:line: message" or "path@byte N: message";
/// problem() says which kind it is (the exit code), kMalformed unless the thrower knows better.
class InputError : public std::runtime_error {
 public:
  InputError(FileLocation where, const std::string& message, InputProblem problem = InputProblem::kMalformed);
  const FileLocation& where() const noexcept { return where_; }
  const std::string& message() const noexcept { return message_; }
  InputProblem problem() const noexcept { return problem_; }

 private:
  FileLocation where_;
  std::string message_;
  InputProblem problem_;
};

/// Writing an output failed (disk full, permissions); the previous file content is untouched.
class OutputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace minemap
