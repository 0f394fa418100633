#pragma once
// Internal to src/minemap/io: the pieces every reader shares, so that line numbers, byte offsets and
// number parsing are written once.
//  - read_file_bytes: the whole file in memory in one read (fast, and binary formats can check the
//    sizes a header claims against the real file size before allocating anything).
//  - LineReader: splits text into lines with 1-based numbers ('\n' or "\r\n"), for error messages.
//  - split_tokens / parse_double / parse_uint64: whitespace tokens and std::from_chars numbers, which
//    are locale-independent (strtod would read "1,5" in a German locale and "1.5" not at all).
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "minemap/core/error.hpp"

namespace minemap::io::detail {

/// The file's bytes. InputError naming the file when it is missing, a folder or unreadable.
std::string read_file_bytes(const std::filesystem::path& path);
/// The same into `bytes`, replacing its contents and keeping its capacity.
void read_file_bytes_into(const std::filesystem::path& path, std::string& bytes);

/// Asks the kernel to start reading `path` into the page cache now (POSIX_FADV_WILLNEED) and returns
/// at once: a survey read in parts asks for the next part's files before the current part is
/// matched, so the disk works while the cores do. Best effort: any failure is ignored (the read
/// that follows reports it).
void prefetch_file(const std::filesystem::path& path);

/// A scan file's bytes in a buffer that the calling thread reuses from scan to scan. A survey is
/// read one scan per task; a fresh buffer per scan costs an allocation and the first touch of every
/// page, which is what kept reading from scaling across cores (docs/benchmarks.md). Holds the
/// thread's buffer while alive: a second one alive in the same thread gets a buffer of its own.
/// Buffers above kKeepBytes are released afterwards, so a huge scan does not pin its size.
class ScanFileBytes {
 public:
  explicit ScanFileBytes(const std::filesystem::path& path);
  ~ScanFileBytes();
  ScanFileBytes(const ScanFileBytes&) = delete;
  ScanFileBytes& operator=(const ScanFileBytes&) = delete;
  const std::string& bytes() const { return *bytes_; }

  static constexpr std::size_t kKeepBytes = std::size_t{64} << 20;

 private:
  std::string own_;            ///< used when the thread's buffer is already taken
  std::string* bytes_;         ///< the thread's buffer or own_
  bool holds_thread_buffer_ = false;
};

/// Throw InputError at a place in the file; `problem` picks the kind (and the exit code).
[[noreturn]] void fail_in_file(const std::string& path, const std::string& message,
                               InputProblem problem = InputProblem::kMalformed);
[[noreturn]] void fail_at_line(const std::string& path, std::int64_t line, const std::string& message,
                               InputProblem problem = InputProblem::kMalformed);
[[noreturn]] void fail_at_byte(const std::string& path, std::uint64_t byte_offset, const std::string& message,
                               InputProblem problem = InputProblem::kMalformed);

/// Walks `text` line by line. Lines are returned without their terminator ('\n', "\r\n").
class LineReader {
 public:
  LineReader(std::string_view text, std::string path) : text_(text), path_(std::move(path)) {}

  /// The next line, or false at the end of the text.
  bool next(std::string_view& line) {
    if (offset_ >= text_.size()) return false;
    const std::size_t end = text_.find('\n', offset_);
    const std::size_t line_end = end == std::string_view::npos ? text_.size() : end;
    line = text_.substr(offset_, line_end - offset_);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    offset_ = end == std::string_view::npos ? text_.size() : end + 1;
    ++line_number_;
    return true;
  }

  /// 1-based number of the line last returned by next() (0 before the first).
  std::int64_t line_number() const { return line_number_; }
  /// Byte offset just past the last returned line: where binary data after a text header starts.
  std::size_t offset() const { return offset_; }
  const std::string& path() const { return path_; }

  /// InputError at the line last returned.
  [[noreturn]] void fail(const std::string& message, InputProblem problem = InputProblem::kMalformed) const {
    fail_at_line(path_, line_number_, message, problem);
  }

  /// Whether the line last returned is the file's last and has no line end: a file cut off in the
  /// middle of a line (a copy that stopped early) looks like this.
  bool at_unterminated_end() const {
    return line_number_ > 0 && offset_ == text_.size() && !text_.empty() && text_.back() != '\n';
  }

  /// For a line with too few values: a truncated file (kTruncated) when the line is the unterminated
  /// last one, else a malformed line.
  [[noreturn]] void fail_short_line(const std::string& message) const {
    if (at_unterminated_end()) fail("file ends inside this line (truncated): " + message, InputProblem::kTruncated);
    fail(message);
  }

 private:
  std::string_view text_;
  std::string path_;
  std::size_t offset_ = 0;
  std::int64_t line_number_ = 0;
};

inline bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

inline std::string_view trim(std::string_view text) {
  while (!text.empty() && is_space(text.front())) text.remove_prefix(1);
  while (!text.empty() && is_space(text.back())) text.remove_suffix(1);
  return text;
}

/// The line up to a '#' (a comment runs to the end of the line, as in 3DTK and TUM files).
inline std::string_view strip_comment(std::string_view line) {
  const std::size_t hash = line.find('#');
  return hash == std::string_view::npos ? line : line.substr(0, hash);
}

inline bool is_blank(std::string_view line) { return trim(line).empty(); }

/// Splits `line` at whitespace (and, with `commas`, at commas too: CSV pose files; with
/// `semicolons`, at those too: ASCII point exports) into `out`.
/// Returns the number of tokens on the line, which may be more than out.size() (the extra tokens are
/// counted but not stored), so callers can report "found N".
inline std::size_t split_tokens(std::string_view line, std::span<std::string_view> out, bool commas = false,
                                bool semicolons = false) {
  const auto separates = [commas, semicolons](char c) {
    return is_space(c) || (commas && c == ',') || (semicolons && c == ';');
  };
  std::size_t count = 0;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && separates(line[i])) ++i;
    if (i >= line.size()) break;
    const std::size_t start = i;
    while (i < line.size() && !separates(line[i])) ++i;
    if (count < out.size()) out[count] = line.substr(start, i - start);
    ++count;
  }
  return count;
}

/// All whitespace tokens of `line` into `out` (resized); for lines whose length is not known ahead.
inline void split_all_tokens(std::string_view line, std::vector<std::string_view>& out) {
  out.resize(split_tokens(line, {}));
  split_tokens(line, out);
}

enum class NumberStatus { kOk, kNotANumber, kOutOfRange };

/// A whole token as a double, C locale: decimal or exponent form, an optional leading '+' (strtod
/// accepts it), "nan" and "inf" (callers decide whether those are allowed). Hex floats are refused.
NumberStatus parse_double(std::string_view token, double& value);

/// A whole token as a non-negative decimal integer (an optional leading '+'; no sign '-', no spaces).
bool parse_uint64(std::string_view token, std::uint64_t& value);
bool parse_int64(std::string_view token, std::int64_t& value);

/// Quotes a token for an error message, shortened so a binary blob does not flood the terminal.
std::string quoted(std::string_view token);

/// Parses tokens[i] into values[i] as finite doubles; fails at the reader's line otherwise (a value
/// that is not a number: kMalformed; inf, NaN or beyond double range: kNonFinite).
/// `what` names the values for the message ("pose", "point").
void parse_finite_values(const LineReader& reader, std::span<const std::string_view> tokens, std::span<double> values,
                         std::string_view what);

}  // namespace minemap::io::detail
