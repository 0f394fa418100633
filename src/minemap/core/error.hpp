#pragma once
// Errors minemap reports to users. Every input problem names the file and the line (text formats)
// or byte offset (binary formats) where it was found, so a user can open the file and look.
#include <cstdint>
#include <stdexcept>
#include <string>

namespace minemap {

/// Process exit codes of the `minemap` program; each failure class has its own code so scripts that
/// reprocess surveys unattended can tell them apart.
enum class ExitCode : int {
  kOk = 0,
  kInternal = 1,            ///< a bug or an unexpected exception
  kUsage = 2,               ///< bad command line
  kInputError = 3,          ///< a malformed, truncated or unreadable input file
  kRegistrationFailed = 4,  ///< too few pairs, divergence, NaN: no pose is returned silently
  kOutputError = 5,         ///< the output folder could not be written
  kBackendUnavailable = 6,  ///< --backend opencl was asked for and no usable OpenCL device exists
  kInterrupted = 130,       ///< SIGINT: finished outputs are kept, temp files removed
};

/// Where in a file an error was found: a 1-based line for text, a byte offset for binary data.
struct FileLocation {
  std::string path;
  std::int64_t line = 0;         ///< 1-based; 0 when unknown or binary
  std::int64_t byte_offset = -1; ///< >= 0 for binary data
};

/// A problem with an input file. what() reads "path:line: message" or "path@byte N: message".
class InputError : public std::runtime_error {
 public:
  InputError(FileLocation where, const std::string& message);
  const FileLocation& where() const noexcept { return where_; }
  const std::string& message() const noexcept { return message_; }

 private:
  FileLocation where_;
  std::string message_;
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
