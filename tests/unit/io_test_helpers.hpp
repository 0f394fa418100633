#pragma once
// Helpers shared by the tests/unit/test_io_*.cpp files: checking that a reader fails with an
// InputError that names the file and the place, and building scans to write.
#include <gtest/gtest.h>

#include <filesystem>
#include <initializer_list>
#include <string>

#include "minemap/core/error.hpp"
#include "minemap/core/scan.hpp"
#include "test_support.hpp"

namespace minemap::test {

/// "path:LINE:" as InputError::what() writes a text location.
inline std::string at_line(const std::filesystem::path& path, long line) {
  return path.string() + ":" + std::to_string(line) + ":";
}

/// "path@byte N:" as InputError::what() writes a binary location.
inline std::string at_byte(const std::filesystem::path& path, unsigned long long byte) {
  return path.string() + "@byte " + std::to_string(byte) + ":";
}

/// `text` with the first `from` replaced by `to` (the test must fail if `from` is absent).
inline std::string replace_once(const std::string& text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << "'" << from << "' not in the test input";
  if (at == std::string::npos) return text;
  return text.substr(0, at) + to + text.substr(at + from.size());
}

/// Calls `read`, which must throw InputError whose what() contains every string in `expected`.
/// Returns what() for further checks (empty when the expectation failed).
template <class Read>
std::string expect_input_error(Read&& read, std::initializer_list<std::string> expected) {
  try {
    read();
  } catch (const InputError& error) {
    const std::string what = error.what();
    for (const std::string& part : expected) {
      EXPECT_NE(what.find(part), std::string::npos) << "missing '" << part << "' in: " << what;
    }
    return what;
  } catch (const std::exception& error) {
    ADD_FAILURE() << "expected InputError, got another exception: " << error.what();
    return {};
  }
  ADD_FAILURE() << "expected InputError, nothing was thrown";
  return {};
}

/// A scan of `count` random points (fixed seed) in [lo, hi]^3 cm.
inline Scan random_scan(std::size_t count, float lo_cm, float hi_cm, std::uint32_t seed, const std::string& name = "scan") {
  Scan scan;
  scan.name = name;
  scan.points_cm = random_cloud(count, lo_cm, hi_cm, seed);
  return scan;
}

}  // namespace minemap::test
