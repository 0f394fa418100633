#pragma once
// One table of names per enum: to_string, parsing and the command line's list of choices all read
// it, so a name is written once. Each enum's table sits beside the enum (kMatchingModeNames,
// kSearchMethodNames, kBackendNames, ...).
//
// Thread-safety: constexpr tables and pure functions.
#include <array>
#include <cstddef>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace minemap {

template <typename Enum>
struct EnumName {
  Enum value;
  const char* name;
};

/// The name of `value` in `table` ("?" when the table lacks it).
template <typename Enum, std::size_t N>
constexpr const char* name_in(const std::array<EnumName<Enum>, N>& table, Enum value) {
  for (const auto& entry : table) {
    if (entry.value == value) return entry.name;
  }
  return "?";
}

/// The value named `text` in `table`, if any.
template <typename Enum, std::size_t N>
constexpr std::optional<Enum> value_named(const std::array<EnumName<Enum>, N>& table, std::string_view text) {
  for (const auto& entry : table) {
    if (text == entry.name) return entry.value;
  }
  return std::nullopt;
}

/// The table's names in order ({"pairwise", "incremental", "simultaneous"}).
template <typename Enum, std::size_t N>
std::vector<std::string> names_in(const std::array<EnumName<Enum>, N>& table) {
  std::vector<std::string> names;
  for (const auto& entry : table) names.emplace_back(entry.name);
  return names;
}

/// value_named, or std::invalid_argument "unknown WHAT 'text' (expected a, b or c)".
template <typename Enum, std::size_t N>
Enum parse_named(const std::array<EnumName<Enum>, N>& table, const std::string& text, const char* what) {
  if (const auto value = value_named(table, text)) return *value;
  std::string expected;
  for (std::size_t i = 0; i < N; ++i) {
    expected += (i == 0 ? "" : (i + 1 == N ? " or " : ", ")) + std::string(table[i].name);
  }
  throw std::invalid_argument("unknown " + std::string(what) + " '" + text + "' (expected " + expected + ")");
}

}  // namespace minemap
