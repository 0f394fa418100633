#pragma once
// Errors minemap reports to users. Every input problem names the file and the line (text formats)
// or byte offset (binary formats) where it was found, so a user can open the file and look.
#include <cstdint>
#include <stdexcept>
#include <string>

namespace minemap {

/// Process exit codes of the `minemap` program; each failure class has its own code so scripts that
/// reprocess surveys unattended can tell them apart. Codes 3 and 7..12 are input problems
/// (InputProblem, exit_code_for); every one of them is found before the output folder is touched.
/// docs/bad-input.md lists which case gets which code, per reader.
enum class ExitCode : int {
  kOk = 0,
  kInternal = 1,             ///< a bug or an unexpected exception
  kUsage = 2,                ///< bad command line
  kInputError = 3,           ///< malformed or unreadable input: bad syntax, binary garbage, a missing file
  kRegistrationFailed = 4,   ///< a scan could not be registered (no overlap, too few pairs, NaN); nothing is
                             ///< written unless --write-unregistered
  kOutputError = 5,          ///< the output folder could not be written
  kBackendUnavailable = 6,   ///< --backend opencl was asked for and no usable OpenCL device exists
  kTruncatedInput = 7,       ///< a file ends before the data its header or its last line promises
  kNonFiniteInput = 8,       ///< an infinite coordinate or pose value, or a scan whose points are all NaN
  kEmptyInput = 9,           ///< an empty file, a scan with fewer than 3 points, a folder without scans
  kInconsistentSurvey = 10,  ///< duplicate scans, a missing pose file, pose and scan counts that differ
  kCountBeyondLimits = 11,   ///< a header count beyond the limits (ReadSettings::max_points), checked before allocating
  kSuspiciousUnits = 12,     ///< the survey looks like metres read as cm: map it with --unit m (or --unit cm)
  kInterrupted = 130,        ///< SIGINT: finished outputs are kept, temp files removed
};

/// What is wrong with an input, carried by InputError; each kind has its own exit code.
enum class InputProblem {
  kMalformed,           ///< bad syntax, binary garbage, unreadable or missing file (exit 3)
  kTruncated,           ///< the file ends early (exit 7)
  kNonFinite,           ///< inf / NaN where no value can be dropped, all points NaN (exit 8)
  kEmpty,               ///< nothing, or too little, to work with (exit 9)
  kInconsistentSurvey,  ///< the survey's files do not fit together (exit 10)
  kCountBeyondLimits,   ///< a header claims more than the limits allow (exit 11)
  kSuspiciousUnits,     ///< the coordinates look like another unit than the one read (exit 12)
};

/// The exit code of the `minemap` program for an input problem.
constexpr ExitCode exit_code_for(InputProblem problem) {
  switch (problem) {
    case InputProblem::kMalformed: return ExitCode::kInputError;
    case InputProblem::kTruncated: return ExitCode::kTruncatedInput;
    case InputProblem::kNonFinite: return ExitCode::kNonFiniteInput;
    case InputProblem::kEmpty: return ExitCode::kEmptyInput;
    case InputProblem::kInconsistentSurvey: return ExitCode::kInconsistentSurvey;
    case InputProblem::kCountBeyondLimits: return ExitCode::kCountBeyondLimits;
    case InputProblem::kSuspiciousUnits: return ExitCode::kSuspiciousUnits;
  }
  return ExitCode::kInputError;
}

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

/// Registration produced no trustworthy pose (too few pairs, NaN, divergence).
class RegistrationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Writing an output failed (disk full, permissions); the previous file content is untouched.
class OutputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace minemap
