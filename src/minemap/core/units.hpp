#pragma once
// Length units. minemap works in centimetres internally (the paper's thresholds are in cm); readers
// take the file's unit and convert on load, writers convert back.
#include <stdexcept>
#include <string>
#include <string_view>

namespace minemap {

enum class LengthUnit { kCentimetre, kMetre };

/// Factor that turns a length in `unit` into centimetres.
constexpr double centimetres_per(LengthUnit unit) { return unit == LengthUnit::kMetre ? 100.0 : 1.0; }

inline LengthUnit parse_length_unit(std::string_view text) {
  if (text == "cm") return LengthUnit::kCentimetre;
  if (text == "m") return LengthUnit::kMetre;
  throw std::invalid_argument("unknown length unit '" + std::string(text) + "' (expected m or cm)");
}

inline const char* to_string(LengthUnit unit) { return unit == LengthUnit::kMetre ? "m" : "cm"; }

}  // namespace minemap
