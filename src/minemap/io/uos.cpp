// 3DTK's "uos" survey files (facts: ../shared/notes/FORMATS-3DTK.md): scanNNN.3d points,
// scanNNN.pose (x y z, Euler angles in degrees) and scanNNN.frames (column-major 4x4 and a type).
#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

#include "minemap/core/atomic_file.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/io/pose_text.hpp"
#include "minemap/io/scan_builder.hpp"
#include "minemap/io/text_reader.hpp"
#include "minemap/io/text_writer.hpp"

namespace minemap::io {
namespace {

using detail::LineReader;
using detail::NumberStatus;

/// 3DTK's readASCII tolerates this many unparsable lines before the first point (a header such as
/// the old "w x b" resolution line); after the first point, one bad line fails the scan.
constexpr int kMaxHeaderLines = 10;

/// Whether a whole-line comment is minemap's slice marker "# slice N" (N a decimal integer).
bool is_slice_marker(std::string_view line) {
  line = detail::trim(line);
  if (line.empty() || line.front() != '#') return false;
  line = detail::trim(line.substr(1));
  constexpr std::string_view kKeyword = "slice";
  if (!line.starts_with(kKeyword)) return false;
  line.remove_prefix(kKeyword.size());
  if (line.empty() || !detail::is_space(line.front())) return false;
  std::uint64_t number = 0;
  return detail::parse_uint64(detail::trim(line), number);
}

/// Angles for a .pose file that EulerToMatrix4 turns back into `pose` exactly.
///
/// 3DTK's Matrix4ToEuler (core pose_to_euler) sets theta_x = 0 whenever |cos theta_y| <= 0.005, which
/// moves the rotation by up to about half a degree for poses near theta_y = +-90 deg. Any angles that
/// reproduce the matrix are a valid .pose, so the writer decomposes exactly (theta_y in [-90, 90])
/// and only sets theta_x = 0 when cos theta_y vanishes to rounding.
EulerPose exact_euler_for_pose_file(const Pose& m) {
  // EulerToMatrix4: m(0,0) = cy cz, m(0,1) = -cy sz, m(0,2) = sy, m(1,2) = -sx cy, m(2,2) = cx cy.
  const double cos_y = std::hypot(m(0, 0), m(0, 1));
  const double sin_y = std::clamp(m(0, 2), -1.0, 1.0);
  double theta_x = 0.0;
  double theta_y = 0.0;
  double theta_z = 0.0;
  if (cos_y > 1e-12) {
    theta_y = std::atan2(sin_y, cos_y);
    theta_x = std::atan2(-m(1, 2), m(2, 2));
    theta_z = std::atan2(-m(0, 1), m(0, 0));
  } else {
    // Gimbal lock: only theta_x + theta_z (sy = 1) or theta_z - theta_x (sy = -1) is defined.
    theta_y = sin_y > 0 ? std::numbers::pi / 2 : -std::numbers::pi / 2;
    theta_z = std::atan2(m(1, 0), m(1, 1));
  }
  EulerPose euler;
  euler.position_cm = m.block<3, 1>(0, 3);
  euler.angles_deg = Eigen::Vector3d(theta_x, theta_y, theta_z) * (180.0 / std::numbers::pi);
  return euler;
}

}  // namespace

// 3DTK's rules (readASCII / handle_line), with two deliberate differences: lines may be longer than
// 3DTK's 128-byte buffer (3DTK would stop reading there; minemap's own lines stay far below it), and
// a number that does not fit a double ("1e999") or a non-finite value fails at its line instead of
// becoming a point at infinity.
Scan read_uos_points(const fs::path& path, const ReadSettings& settings) {
  const detail::ScanFileBytes file(path);
  const std::string& text = file.bytes();
  LineReader reader(text, path.string());
  detail::ScanBuilder builder(path, settings, LengthUnit::kCentimetre);
  // One point per line at most: counting the lines (a fast scan) sizes the points once, so they
  // need neither growth nor a shrinking copy.
  const auto lines = static_cast<std::uint64_t>(std::count(text.begin(), text.end(), '\n')) + 1;
  builder.reserve(static_cast<std::size_t>(std::min<std::uint64_t>(lines, settings.max_points)));

  std::size_t columns = 0;  // 3 (x y z) or 4 (x y z reflectance), fixed by the first point line
  std::int64_t first_point_line = 0;
  int unparsable_header_lines = 0;
  std::array<std::string_view, 4> tokens;
  std::array<double, 4> values{};
  std::string_view line;
  while (reader.next(line)) {
    const std::string_view content = detail::strip_comment(line);
    if (detail::is_blank(content)) {
      if (content.size() != line.size() && is_slice_marker(line)) builder.begin_slice();
      continue;
    }
    const std::size_t count = detail::split_tokens(content, tokens);
    std::string problem;  // why the line is not a point line; empty when it is one
    bool cut_short = false;  // the problem is one a file cut off inside this line would show
    if (count < 3 || count > 4) {
      problem = "expected 3 values (x y z) or 4 (x y z reflectance), found " + std::to_string(count);
      cut_short = count < 3;
    } else if (columns != 0 && count != columns) {
      problem = "expected " + std::to_string(columns) + " values as on line " + std::to_string(first_point_line) +
                ", found " + std::to_string(count);
      cut_short = count < columns;
    } else {
      for (std::size_t i = 0; i < count && problem.empty(); ++i) {
        const NumberStatus status = detail::parse_double(tokens[i], values[i]);
        if (status == NumberStatus::kNotANumber) {
          problem = detail::quoted(tokens[i]) + " is not a number";
          cut_short = i + 1 == count;
        }
        // A number that strtod would read as +-inf or 0 is not a header line: it is a broken point.
        if (status == NumberStatus::kOutOfRange) {
          reader.fail(detail::quoted(tokens[i]) + " is out of range", InputProblem::kNonFinite);
        }
      }
    }
    if (!problem.empty()) {
      if (columns == 0) {
        if (++unparsable_header_lines > kMaxHeaderLines) {
          reader.fail(problem + " (more than " + std::to_string(kMaxHeaderLines) +
                      " unparsable lines before the first point)");
        }
        continue;
      }
      if (cut_short) reader.fail_short_line(problem);
      reader.fail(problem);
    }
    if (columns == 0) {
      columns = count;
      first_point_line = reader.line_number();
      if (columns == 4) builder.carries(kIntensity);  // the reflectance, kept as the intensity
    }
    // x y z: NaN drops the point (ScanBuilder), inf fails it.
    for (std::size_t i = 0; i < 3; ++i) {
      if (std::isinf(values[i])) {
        reader.fail("value " + std::to_string(i + 1) + " " + detail::quoted(tokens[i]) + " is not finite",
                    InputProblem::kNonFinite);
      }
    }
    PointValues attributes;
    attributes.intensity = static_cast<float>(values[3]);
    const auto added = builder.add(values[0], values[1], values[2], attributes);
    if (added != detail::ScanBuilder::AddResult::kOk) reader.fail(builder.describe(added), builder.problem_of(added));
  }
  if (builder.size() == 0) {
    if (text.empty()) detail::fail_in_file(path.string(), "no points (empty file)", InputProblem::kEmpty);
    detail::fail_at_line(path.string(), reader.line_number(), builder.no_points_message(), builder.no_points_problem());
  }
  return builder.finish(/*split_unmarked=*/true);
}

void write_uos_points(const fs::path& path, const Scan& scan, LengthUnit unit) {
  if (!scan.slice_offsets.empty()) {
    // Bad offsets would make the loop below read past the points: a caller's bug, refused up front.
    bool consistent = scan.slice_offsets.size() >= 2 && scan.slice_offsets.front() == 0 &&
                      scan.slice_offsets.back() == scan.size();
    for (std::size_t s = 1; consistent && s < scan.slice_offsets.size(); ++s) {
      consistent = scan.slice_offsets[s - 1] <= scan.slice_offsets[s];
    }
    if (!consistent) throw std::invalid_argument("write_uos_points: scan " + scan.name + " has inconsistent slice offsets");
  }
  const double divisor = centimetres_per(unit);
  std::string out;
  out.reserve(scan.size() * 32 + 128);
  out += "# minemap .3d: x y z in ";
  out += to_string(unit);
  out += scan.has_slices() ? "; '# slice N' starts slice N\n" : "\n";
  const auto append_point = [&](std::size_t i) {
    const Eigen::Vector3f& p = scan.points_cm[i];
    detail::append_coordinate(out, p.x(), scan.local_origin_cm.x(), divisor);
    out += ' ';
    detail::append_coordinate(out, p.y(), scan.local_origin_cm.y(), divisor);
    out += ' ';
    detail::append_coordinate(out, p.z(), scan.local_origin_cm.z(), divisor);
    out += '\n';
  };
  if (scan.has_slices()) {
    for (std::size_t s = 0; s < scan.num_slices(); ++s) {
      out += "# slice ";
      out += std::to_string(s);
      out += '\n';
      for (std::size_t i = scan.slice_offsets[s]; i < scan.slice_offsets[s + 1]; ++i) append_point(i);
    }
  } else {
    for (std::size_t i = 0; i < scan.size(); ++i) append_point(i);
  }
  write_file_atomically(path, out);
}

EulerPose read_uos_pose(const fs::path& path, LengthUnit unit) {
  const std::string text = detail::read_file_bytes(path);
  LineReader reader(text, path.string());
  // 3DTK reads six numbers with operator>>, so line breaks do not matter; frames2pose writes two
  // lines. '#' comments are a minemap allowance (3DTK's pose files have none).
  std::array<double, 6> values{};
  std::size_t found = 0;
  std::array<std::string_view, 7> tokens;
  std::string_view line;
  while (reader.next(line)) {
    const std::size_t count = detail::split_tokens(detail::strip_comment(line), tokens);
    if (found + count > values.size()) {
      reader.fail("more than 6 numbers; a .pose file holds x y z theta_x theta_y theta_z");
    }
    detail::parse_finite_values(reader, std::span(tokens).first(count), std::span(values).subspan(found, count), "pose");
    found += count;
  }
  if (found == 0) {
    detail::fail_at_line(path.string(), reader.line_number(),
                         std::string(text.empty() ? "empty file: " : "") +
                             "found 0 numbers, expected 6 (x y z theta_x theta_y theta_z)",
                         InputProblem::kEmpty);
  }
  if (found < values.size()) {
    detail::fail_at_line(path.string(), reader.line_number(),
                         "found " + std::to_string(found) + " numbers, expected 6 (x y z theta_x theta_y theta_z): the file ends early",
                         InputProblem::kTruncated);
  }
  EulerPose pose;
  pose.position_cm = Eigen::Vector3d(values[0], values[1], values[2]) * centimetres_per(unit);
  pose.angles_deg = Eigen::Vector3d(values[3], values[4], values[5]);
  if (!pose.position_cm.allFinite()) {
    detail::fail_at_line(path.string(), reader.line_number(), "position out of range", InputProblem::kNonFinite);
  }
  return pose;
}

void write_uos_pose(const fs::path& path, const Pose& pose_cm, LengthUnit unit) {
  const EulerPose euler = exact_euler_for_pose_file(pose_cm);
  const double divisor = centimetres_per(unit);
  std::string out;
  for (int i = 0; i < 3; ++i) {
    if (i > 0) out += ' ';
    detail::append_number(out, euler.position_cm[i] / divisor);
  }
  out += '\n';
  for (int i = 0; i < 3; ++i) {
    if (i > 0) out += ' ';
    detail::append_number(out, euler.angles_deg[i]);
  }
  out += '\n';
  write_file_atomically(path, out);
}

std::vector<FrameLine> read_uos_frames(const fs::path& path, LengthUnit unit) {
  const std::string text = detail::read_file_bytes(path);
  LineReader reader(text, path.string());
  const double scale_to_cm = centimetres_per(unit);
  std::vector<FrameLine> frames;
  std::array<std::string_view, 17> tokens;
  std::array<double, 16> values{};
  std::string_view line;
  while (reader.next(line)) {
    const std::string_view content = detail::strip_comment(line);
    if (detail::is_blank(content)) continue;
    const std::size_t count = detail::split_tokens(content, tokens);
    if (count != tokens.size()) {
      const std::string problem = "expected 16 matrix values and a type, found " + std::to_string(count) + " values";
      if (count < tokens.size()) reader.fail_short_line(problem);
      reader.fail(problem);
    }
    detail::parse_finite_values(reader, std::span(tokens).first(16), values, "matrix");
    std::int64_t type = 0;
    if (!detail::parse_int64(tokens[16], type) || type < 0 || type > 4) {
      reader.fail("frame type " + detail::quoted(tokens[16]) +
                  " is not 0..4 (INVALID, ICP, ICPINACTIVE, LUM, ELCH)");
    }
    // 3DTK's transMat is column-major (OpenGL): index = col * 4 + row, translation at 12..14.
    Pose raw;
    for (int col = 0; col < 4; ++col) {
      for (int row = 0; row < 4; ++row) raw(row, col) = values[static_cast<std::size_t>(col * 4 + row)];
    }
    raw.block<3, 1>(0, 3) *= scale_to_cm;
    frames.push_back(FrameLine{detail::checked_rigid_pose(raw, reader), static_cast<int>(type)});
  }
  if (frames.empty()) detail::fail_at_line(path.string(), reader.line_number(), "no frames", InputProblem::kEmpty);
  return frames;
}

void write_uos_frames(const fs::path& path, std::span<const FrameLine> frames, LengthUnit unit) {
  const double divisor = centimetres_per(unit);
  std::string out;
  out.reserve(frames.size() * 200);
  for (const FrameLine& frame : frames) {
    for (int col = 0; col < 4; ++col) {
      for (int row = 0; row < 4; ++row) {
        const double value = frame.pose_cm(row, col);
        detail::append_number(out, col == 3 && row < 3 ? value / divisor : value);
        out += ' ';
      }
    }
    out += std::to_string(frame.type);
    out += '\n';
  }
  write_file_atomically(path, out);
}

}  // namespace minemap::io
