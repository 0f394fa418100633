// Shared reading helpers of src/minemap/io: whole-file reads, error locations, locale-free numbers.
#include "minemap/io/text_reader.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>

namespace minemap::io::detail {

std::string read_file_bytes(const std::filesystem::path& path) {
  std::string bytes;
  read_file_bytes_into(path, bytes);
  return bytes;
}

namespace {
thread_local std::string t_scan_buffer;
thread_local bool t_scan_buffer_taken = false;
}  // namespace

ScanFileBytes::ScanFileBytes(const std::filesystem::path& path) : bytes_(&own_) {
  if (!t_scan_buffer_taken) {
    t_scan_buffer_taken = holds_thread_buffer_ = true;
    bytes_ = &t_scan_buffer;
  }
  try {
    read_file_bytes_into(path, *bytes_);
  } catch (...) {
    if (holds_thread_buffer_) t_scan_buffer_taken = false;
    throw;
  }
}

ScanFileBytes::~ScanFileBytes() {
  if (!holds_thread_buffer_) return;
  if (t_scan_buffer.capacity() > kKeepBytes) std::string().swap(t_scan_buffer);
  t_scan_buffer_taken = false;
}

void read_file_bytes_into(const std::filesystem::path& path, std::string& bytes) {
  bytes.clear();
  const std::string name = path.string();
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) fail_in_file(name, std::string("cannot open: ") + std::strerror(errno));
  struct FdCloser {
    int fd;
    ~FdCloser() { ::close(fd); }
  } closer{fd};
  struct stat info {};
  if (::fstat(fd, &info) != 0) fail_in_file(name, std::string("cannot read: ") + std::strerror(errno));
  if (S_ISDIR(info.st_mode)) fail_in_file(name, "is a folder, not a file");
  // Regular files: one allocation of the real size. Pipes and the like report 0 and grow as read.
  if (S_ISREG(info.st_mode) && info.st_size > 0) bytes.reserve(static_cast<std::size_t>(info.st_size));
  char buffer[1 << 16];
  for (;;) {
    const ssize_t got = ::read(fd, buffer, sizeof buffer);
    if (got == 0) break;
    if (got < 0) {
      if (errno == EINTR) continue;
      fail_in_file(name, std::string("cannot read: ") + std::strerror(errno));
    }
    bytes.append(buffer, static_cast<std::size_t>(got));
  }
}

void prefetch_file(const std::filesystem::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return;
  ::posix_fadvise(fd, 0, 0, POSIX_FADV_WILLNEED);
  ::close(fd);
}

void fail_in_file(const std::string& path, const std::string& message, InputProblem problem) {
  throw InputError(FileLocation{path}, message, problem);
}

void fail_at_line(const std::string& path, std::int64_t line, const std::string& message, InputProblem problem) {
  throw InputError(FileLocation{path, line, -1}, message, problem);
}

void fail_at_byte(const std::string& path, std::uint64_t byte_offset, const std::string& message, InputProblem problem) {
  throw InputError(FileLocation{path, 0, static_cast<std::int64_t>(byte_offset)}, message, problem);
}

namespace {

/// Clinger's fast path, for the decimals scan files are made of ("192.39798", "-5.890489e-15"): the
/// digits as an integer w <= 2^53 and a power of ten p with |p| <= 22 are both exact doubles, so
/// w * 10^p (or w / 10^-p) is one IEEE operation, rounded once: the correctly rounded value, which
/// is what from_chars returns too. Takes only [-]digits[.digits][(e|E)[+-]digits] of at most 19
/// digits, the whole token; false for anything else (from_chars then reads it). Parsing is a third
/// of reading a survey (docs/scaling.md), and from_chars' general path is the slower part of it.
bool fast_decimal(std::string_view token, double& value) {
  static constexpr double kPowers[] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                                       1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};
  const char* at = token.data();
  const char* const end = at + token.size();
  const bool negative = at != end && *at == '-';
  if (negative) ++at;
  std::uint64_t digits = 0;
  int count = 0;
  const auto digit = [](char c) { return static_cast<unsigned>(c - '0') <= 9u; };
  const char* const whole = at;
  for (; at != end && digit(*at); ++at, ++count) digits = digits * 10 + static_cast<unsigned>(*at - '0');
  if (at == whole) return false;  // ".5", "-", "inf": from_chars
  int power = 0;
  if (at != end && *at == '.') {
    const char* const fraction = ++at;
    for (; at != end && digit(*at); ++at, ++count) digits = digits * 10 + static_cast<unsigned>(*at - '0');
    if (at == fraction) return false;  // "5.": from_chars
    power = -static_cast<int>(at - fraction);
  }
  if (count > 19) return false;  // digits may have overflowed
  if (at != end && (*at == 'e' || *at == 'E')) {
    ++at;
    const bool down = at != end && *at == '-';
    if (at != end && (*at == '-' || *at == '+')) ++at;
    const char* const exponent = at;
    int e = 0;
    for (; at != end && digit(*at) && e < 1000; ++at) e = e * 10 + (*at - '0');
    if (at == exponent) return false;
    power += down ? -e : e;
  }
  if (at != end || digits > (std::uint64_t{1} << 53) || power < -22 || power > 22) return false;
  const double w = static_cast<double>(digits);
  value = power >= 0 ? w * kPowers[power] : w / kPowers[-power];
  if (negative) value = -value;
  return true;
}

}  // namespace

NumberStatus parse_double(std::string_view token, double& value) {
  if (token.empty()) return NumberStatus::kNotANumber;
  if (token.front() != '+' && fast_decimal(token, value)) return NumberStatus::kOk;
  // from_chars refuses a leading '+', strtod (3DTK, PCL) accepts it; "+-1" stays refused.
  if (token.front() == '+') {
    token.remove_prefix(1);
    if (token.empty() || token.front() == '-' || token.front() == '+') return NumberStatus::kNotANumber;
  }
  const char* first = token.data();
  const char* last = token.data() + token.size();
  const auto [end, error] = std::from_chars(first, last, value, std::chars_format::general);
  if (end != last) return NumberStatus::kNotANumber;
  if (error == std::errc::result_out_of_range) return NumberStatus::kOutOfRange;
  if (error != std::errc()) return NumberStatus::kNotANumber;
  return NumberStatus::kOk;
}

bool parse_uint64(std::string_view token, std::uint64_t& value) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty() || token.front() == '-' || token.front() == '+') return false;
  const auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), value);
  return error == std::errc() && end == token.data() + token.size();
}

bool parse_int64(std::string_view token, std::int64_t& value) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty() || token.front() == '+') return false;
  const auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), value);
  return error == std::errc() && end == token.data() + token.size();
}

std::string quoted(std::string_view token) {
  constexpr std::size_t kMaxShown = 40;
  std::string shown;
  for (const char c : token.substr(0, kMaxShown)) {
    const auto byte = static_cast<unsigned char>(c);
    shown += (byte >= 0x20 && byte < 0x7f) ? c : '?';
  }
  if (token.size() > kMaxShown) shown += "...";
  return "'" + shown + "'";
}

void parse_finite_values(const LineReader& reader, std::span<const std::string_view> tokens, std::span<double> values,
                         std::string_view what) {
  for (std::size_t i = 0; i < values.size(); ++i) {
    const NumberStatus status = parse_double(tokens[i], values[i]);
    const std::string which = std::string(what) + " value " + std::to_string(i + 1);
    if (status == NumberStatus::kNotANumber) {
      // A number cut off by the end of the file ("1.5e") is a truncation, not garbage.
      if (i + 1 == tokens.size() && reader.at_unterminated_end()) {
        reader.fail_short_line(which + " " + quoted(tokens[i]) + " is not a number");
      }
      reader.fail(which + " " + quoted(tokens[i]) + " is not a number");
    }
    if (status == NumberStatus::kOutOfRange) {
      reader.fail(which + " " + quoted(tokens[i]) + " is out of range", InputProblem::kNonFinite);
    }
    if (!std::isfinite(values[i])) reader.fail(which + " " + quoted(tokens[i]) + " is not finite", InputProblem::kNonFinite);
  }
}

}  // namespace minemap::io::detail
