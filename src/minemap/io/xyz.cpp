// ASCII point clouds as CloudCompare, PDAL's text writer and most scanner software export them:
// one point a line, x y z and optional columns, in metres, right-handed z up (as PLY and PCD).
//
// Choices:
//  - Separators: spaces, tabs, commas and semicolons (CloudCompare's export dialog offers all four).
//  - A header line of column names (CloudCompare's "//X,Y,Z,R,G,B,scalar_Intensity", PDAL's
//    "X,Y,Z,Intensity") names the columns: x y z (required), red green blue (R G B), intensity
//    (I, scalar_intensity, reflectance); other columns (normals, scalar fields) are skipped.
//  - Without a header the count of the first point line says: 3 x y z; 4 x y z intensity; 6 x y z
//    and red green blue when the three are whole numbers 0-255, else (normals) skipped; 7 x y z,
//    colour, intensity (CloudCompare's order). Other counts: x y z and the rest skipped.
//  - Every point line has the first point line's count (a wrong count is reported at its line, not
//    shifted into the next point); '#' starts a comment; up to 10 unparsable lines before the first
//    point are taken as a header, as in uos.
//  - NaN drops the point and is counted (formats.hpp); inf is an InputError at its line.
#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include "minemap/io/formats.hpp"
#include "minemap/io/scan_builder.hpp"
#include "minemap/io/text_reader.hpp"

namespace minemap::io {
namespace {

using detail::LineReader;
using detail::NumberStatus;

constexpr int kMaxHeaderLines = 10;
constexpr std::size_t kMaxColumns = 32;

/// Spaces, tabs, commas and semicolons separate the values.
std::size_t split(std::string_view line, std::array<std::string_view, kMaxColumns>& out) {
  return detail::split_tokens(line, out, /*commas=*/true, /*semicolons=*/true);
}

std::string lower(std::string_view text) {
  std::string out(text);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

/// Where each kept value sits in a line; -1 where absent.
struct Columns {
  std::size_t count = 0;
  int x = 0, y = 1, z = 2;
  int red = -1, green = -1, blue = -1;
  int intensity = -1;
};

/// Columns from a header of names, or false when `tokens` do not name x, y and z.
bool columns_from_names(const std::array<std::string_view, kMaxColumns>& tokens, std::size_t count, Columns& columns) {
  Columns named;
  named.count = count;
  named.x = named.y = named.z = -1;
  for (std::size_t i = 0; i < std::min(count, kMaxColumns); ++i) {
    std::string name = lower(tokens[i]);
    while (!name.empty() && (name.front() == '/' || name.front() == '#')) name.erase(name.begin());
    if (name.rfind("scalar_", 0) == 0) name = name.substr(7);
    const int at = static_cast<int>(i);
    if (name == "x") named.x = at;
    if (name == "y") named.y = at;
    if (name == "z") named.z = at;
    if (name == "r" || name == "red") named.red = at;
    if (name == "g" || name == "green") named.green = at;
    if (name == "b" || name == "blue") named.blue = at;
    if (name == "i" || name == "intensity" || name == "reflectance") named.intensity = at;
  }
  if (named.x < 0 || named.y < 0 || named.z < 0) return false;
  if (named.red < 0 || named.green < 0 || named.blue < 0) named.red = named.green = named.blue = -1;
  columns = named;
  return true;
}

bool is_byte(double value) { return value >= 0.0 && value <= 255.0 && value == std::floor(value); }

/// Columns from the first point line's count and values (no header).
Columns columns_from_count(std::size_t count, const std::array<double, kMaxColumns>& values) {
  Columns columns;
  columns.count = count;
  if (count == 4) columns.intensity = 3;
  if ((count == 6 || count == 7) && is_byte(values[3]) && is_byte(values[4]) && is_byte(values[5])) {
    columns.red = 3;
    columns.green = 4;
    columns.blue = 5;
  }
  if (count == 7) columns.intensity = 6;
  return columns;
}

std::uint32_t colour_byte(double value) {
  return static_cast<std::uint32_t>(std::clamp(std::lround(value), 0L, 255L));
}

}  // namespace

Scan read_xyz(const fs::path& path, const ReadSettings& settings) {
  const detail::ScanFileBytes file(path);
  const std::string& text = file.bytes();
  LineReader reader(text, path.string());
  detail::ScanBuilder builder(path, settings, LengthUnit::kMetre);
  const auto lines = static_cast<std::uint64_t>(std::count(text.begin(), text.end(), '\n')) + 1;
  builder.reserve(static_cast<std::size_t>(std::min<std::uint64_t>(lines, settings.max_points)));

  std::optional<Columns> columns;  // fixed by a header of names, else by the first point line
  bool named = false;
  std::int64_t first_point_line = 0;
  int header_lines = 0;
  std::array<std::string_view, kMaxColumns> tokens;
  std::array<double, kMaxColumns> values{};
  std::string_view line;
  while (reader.next(line)) {
    std::string_view content = line;
    if (!(detail::trim(content).rfind("//", 0) == 0)) content = detail::strip_comment(line);
    if (detail::is_blank(content)) continue;
    const std::size_t count = split(content, tokens);
    std::string problem;
    if (count < 3) problem = "expected at least 3 values (x y z), found " + std::to_string(count);
    if (count > kMaxColumns) problem = "more than " + std::to_string(kMaxColumns) + " values";
    if (problem.empty() && columns && first_point_line != 0 && count != columns->count) {
      problem = "expected " + std::to_string(columns->count) + " values as on line " +
                std::to_string(first_point_line) + ", found " + std::to_string(count);
    }
    for (std::size_t i = 0; i < count && problem.empty(); ++i) {
      const NumberStatus status = detail::parse_double(tokens[i], values[i]);
      if (status == NumberStatus::kNotANumber) problem = detail::quoted(tokens[i]) + " is not a number";
      if (status == NumberStatus::kOutOfRange) {
        reader.fail(detail::quoted(tokens[i]) + " is out of range", InputProblem::kNonFinite);
      }
    }
    if (!problem.empty()) {
      if (first_point_line == 0) {  // before the first point: a header line
        if (!columns && columns_from_names(tokens, count, columns.emplace())) {
          named = true;
          continue;
        }
        if (!named) columns.reset();
        if (++header_lines > kMaxHeaderLines) {
          reader.fail(problem + " (more than " + std::to_string(kMaxHeaderLines) +
                      " unparsable lines before the first point)");
        }
        continue;
      }
      reader.fail(problem);
    }
    if (first_point_line == 0) {
      first_point_line = reader.line_number();
      if (!columns) columns = columns_from_count(count, values);
      if (columns->count != count) {
        reader.fail("expected " + std::to_string(columns->count) + " values as the header names, found " +
                    std::to_string(count));
      }
      builder.carries(static_cast<std::uint8_t>((columns->intensity >= 0 ? kIntensity : 0) |
                                                (columns->red >= 0 ? kColour : 0)));
    }
    const Columns& c = *columns;
    for (const int at : {c.x, c.y, c.z}) {
      if (std::isinf(values[at])) {
        reader.fail("value " + std::to_string(at + 1) + " " + detail::quoted(tokens[at]) + " is not finite",
                    InputProblem::kNonFinite);
      }
    }
    PointValues attributes;
    if (c.intensity >= 0) attributes.intensity = static_cast<float>(values[c.intensity]);
    if (c.red >= 0) {
      attributes.rgb = colour_byte(values[c.red]) << 16 | colour_byte(values[c.green]) << 8 | colour_byte(values[c.blue]);
    }
    const auto added = builder.add(values[c.x], values[c.y], values[c.z], attributes);
    if (added != detail::ScanBuilder::AddResult::kOk) reader.fail(builder.describe(added), builder.problem_of(added));
  }
  if (builder.size() == 0) {
    if (text.empty()) detail::fail_in_file(path.string(), "no points (empty file)", InputProblem::kEmpty);
    detail::fail_at_line(path.string(), reader.line_number(), builder.no_points_message(), builder.no_points_problem());
  }
  return builder.finish(/*split_unmarked=*/false);
}

bool looks_like_xyz_text(const fs::path& path) {
  std::ifstream in(path);
  std::string line;
  for (int i = 0; i < kMaxHeaderLines && std::getline(in, line); ++i) {
    if (detail::is_blank(line)) continue;
    std::array<std::string_view, kMaxColumns> tokens;
    const std::size_t count = split(line, tokens);
    Columns columns;
    if (count >= 3 && columns_from_names(tokens, count, columns)) return true;
    const std::string_view start = detail::trim(line);
    if (start.front() == '#' || start.rfind("//", 0) == 0) continue;  // a comment line
    double value = 0.0;
    if (count < 3) return false;
    for (std::size_t k = 0; k < 3; ++k) {
      if (detail::parse_double(tokens[k], value) != NumberStatus::kOk) return false;
    }
    return true;
  }
  return false;
}

}  // namespace minemap::io
