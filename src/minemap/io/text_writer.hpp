#pragma once
// Internal to src/minemap/io: number formatting shared by every text writer.
//
// Writers print numbers so that reading them back gives the same value: the shortest text that
// round-trips (std::to_chars), never 3DTK's default 6 significant digits, which would move a point
// 1 km from the origin by up to 5 cm. 3DTK reads these numbers fine: it parses with strtod and
// operator>>, which accept any decimal or exponent form, and our lines stay well under its 128-byte
// line buffer (3 numbers of at most 24 characters for .3d).
#include <charconv>
#include <string>

namespace minemap::io::detail {

/// Shortest text that reads back as exactly `value`.
inline void append_number(std::string& out, double value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
  out.append(buffer, result.ptr);
}

inline void append_number(std::string& out, float value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
  out.append(buffer, result.ptr);
}

/// A coordinate stored as float `local` relative to a whole-cm `origin`, written divided by `divisor`
/// (1 for cm, 100 for m). The text reads back to the same float:
///  - origin 0 and cm: the float's own shortest text;
///  - origin 0 and another unit: 9 significant digits, which carry any float through the scaling
///    (9 digits err by at most 5e-9 relative, a float's half-ulp is at least 6e-8 relative);
///  - otherwise the double sum needs its shortest round-trip text.
inline void append_coordinate(std::string& out, float local, double origin, double divisor) {
  if (origin == 0.0 && divisor == 1.0) {
    append_number(out, local);
    return;
  }
  const double value = (static_cast<double>(local) + origin) / divisor;
  if (origin == 0.0) {
    char buffer[32];
    const auto result = std::to_chars(buffer, buffer + sizeof buffer, value, std::chars_format::general, 9);
    out.append(buffer, result.ptr);
    return;
  }
  append_number(out, value);
}

}  // namespace minemap::io::detail
