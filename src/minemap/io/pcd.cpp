// PCL's PCD v0.7 (https://pointclouds.org/documentation/tutorials/pcd_file_format.html): a text header
// (VERSION FIELDS SIZE TYPE COUNT WIDTH HEIGHT VIEWPOINT POINTS DATA), then ascii lines, binary
// records (array of structures) or binary_compressed (uint32 compressed size, uint32 uncompressed
// size, one LZF block that decompresses to a structure of arrays: each field's values for all points
// in turn).
//
// Choices, documented here because PCL leaves them open:
//  - x, y and z must be F4 or F8 with COUNT 1. The attributes minemap keeps (Scan::attributes),
//    each a field of COUNT 1: intensity (or i), rgb (or rgba: PCL packs 0xRRGGBB into a float's bits,
//    F4, or a U4), time (or t, timestamp; seconds) and ring. Every other field (any type, size,
//    count) is skipped.
//  - NaN points are dropped and counted (ReadReport). PCL marks "no return" with NaN x/y/z in
//    organized clouds (HEIGHT > 1), and a PCD file has no is_dense flag, so any PCD may hold them
//    legitimately (pcl::removeNaNFromPointCloud drops a point when x, y or z is NaN; so do we). An
//    infinite coordinate is never a PCL convention: it is an InputError at its line or byte.
//  - VIEWPOINT (tx ty tz qw qx qy qz), PCL's sensor origin and orientation, becomes Scan::pose_cm
//    (translation in cm): the initial guess T_world_file. Files written by PCL almost always carry
//    the identity; the writer stores pose_cm there, so a round trip keeps the pose.
//  - Bytes after the last point of binary data are ignored (as PCL does).
#include <lzf.h>

#include <array>
#include <cmath>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <string>
#include <vector>

#include "minemap/core/atomic_file.hpp"
#include "minemap/core/error.hpp"
#include "minemap/io/binary_data.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/io/pose_text.hpp"
#include "minemap/io/scan_builder.hpp"
#include "minemap/io/text_reader.hpp"
#include "minemap/io/text_writer.hpp"

namespace minemap::io {
namespace {

using detail::LineReader;

/// The most bytes one point may occupy; real files have tens of bytes (FPFH: 132).
constexpr std::uint64_t kMaxPointBytes = 1 << 20;
/// One LZF back-reference expands 3 bytes into at most 264, so no block decompresses to more.
constexpr std::uint64_t kLzfMaxExpansion = 88;

struct PcdField {
  std::string name;
  std::uint64_t size = 0;  ///< bytes per value
  char type = 0;           ///< 'I', 'U' or 'F'
  std::uint64_t count = 1;
  std::uint64_t byte_offset = 0;   ///< within a binary record (binary) or times POINTS (compressed)
  std::uint64_t first_value = 0;   ///< index of its first value on an ascii line
};

struct PcdHeader {
  std::vector<PcdField> fields;
  std::uint64_t width = 0;
  std::uint64_t height = 1;
  std::uint64_t points = 0;
  Pose viewpoint_cm = Pose::Identity();
  PcdEncoding encoding = PcdEncoding::kAscii;
  std::uint64_t point_bytes = 0;
  std::uint64_t values_per_point = 0;
  std::array<int, 3> xyz_fields{};  ///< indices into fields
  /// The attribute fields (indices into fields, -1: absent), by PointAttribute: intensity, colour,
  /// time, ring.
  int intensity_field = -1, rgb_field = -1, time_field = -1, ring_field = -1;
  std::uint8_t attributes() const {
    return static_cast<std::uint8_t>((intensity_field >= 0 ? kIntensity : 0) | (rgb_field >= 0 ? kColour : 0) |
                                     (time_field >= 0 ? kTime : 0) | (ring_field >= 0 ? kRing : 0));
  }
  std::size_t data_offset = 0;      ///< first byte after the DATA line
};

std::uint64_t parse_count(const LineReader& reader, std::string_view keyword, std::string_view token) {
  std::uint64_t value = 0;
  if (!detail::parse_uint64(token, value)) {
    reader.fail(std::string(keyword) + " value " + detail::quoted(token) + " is not a non-negative integer");
  }
  return value;
}

/// Reads the header up to and including the DATA line and checks it, before any data is touched.
PcdHeader read_header(LineReader& reader, const ReadSettings& settings, double scale_to_cm) {
  PcdHeader header;
  std::vector<std::string_view> names, sizes, types, counts;
  bool have_width = false, have_points = false, have_data = false;
  std::int64_t points_line = 0, width_line = 0;
  std::vector<std::string> seen;
  std::string_view line;
  while (!have_data && reader.next(line)) {
    const std::string_view content = detail::trim(line);
    if (content.empty() || content.front() == '#') continue;
    std::vector<std::string_view> tokens;
    detail::split_all_tokens(content, tokens);
    const std::string keyword(tokens.front());
    tokens.erase(tokens.begin());
    for (const auto& previous : seen) {
      if (previous == keyword) reader.fail("header keyword " + keyword + " appears twice");
    }
    seen.push_back(keyword);
    const auto require_values = [&](std::size_t expected) {
      if (tokens.size() != expected) {
        reader.fail(keyword + " expects " + std::to_string(expected) + " value(s), found " + std::to_string(tokens.size()));
      }
    };
    if (keyword == "VERSION") {
      // 0.7 in practice; earlier versions differ only in keywords we check anyway.
    } else if (keyword == "FIELDS") {
      if (tokens.empty()) reader.fail("FIELDS names no field");
      names = tokens;
    } else if (keyword == "SIZE") {
      sizes = tokens;
    } else if (keyword == "TYPE") {
      types = tokens;
    } else if (keyword == "COUNT") {
      counts = tokens;
    } else if (keyword == "WIDTH") {
      require_values(1);
      header.width = parse_count(reader, keyword, tokens[0]);
      have_width = true;
      width_line = reader.line_number();
    } else if (keyword == "HEIGHT") {
      require_values(1);
      header.height = parse_count(reader, keyword, tokens[0]);
    } else if (keyword == "VIEWPOINT") {
      require_values(7);
      std::array<double, 7> v{};
      detail::parse_finite_values(reader, tokens, v, "VIEWPOINT");
      const Eigen::Vector3d translation_cm = Eigen::Vector3d(v[0], v[1], v[2]) * scale_to_cm;
      header.viewpoint_cm = detail::pose_from_quaternion(translation_cm, v[3], v[4], v[5], v[6], reader);
      if (settings.right_handed_to_3dtk) header.viewpoint_cm = right_handed_pose_to_3dtk(header.viewpoint_cm, 1.0);
    } else if (keyword == "POINTS") {
      require_values(1);
      header.points = parse_count(reader, keyword, tokens[0]);
      have_points = true;
      points_line = reader.line_number();
    } else if (keyword == "DATA") {
      require_values(1);
      if (tokens[0] == "ascii") {
        header.encoding = PcdEncoding::kAscii;
      } else if (tokens[0] == "binary") {
        header.encoding = PcdEncoding::kBinary;
      } else if (tokens[0] == "binary_compressed") {
        header.encoding = PcdEncoding::kBinaryCompressed;
      } else {
        reader.fail("unknown DATA type " + detail::quoted(tokens[0]) + " (expected ascii, binary or binary_compressed)");
      }
      have_data = true;
    } else {
      reader.fail("unknown header keyword " + detail::quoted(keyword));
    }
  }
  if (!have_data) {
    if (reader.line_number() == 0) reader.fail("empty file, not a PCD", InputProblem::kEmpty);
    reader.fail("header has no DATA line (no point data): the file ends in the header", InputProblem::kTruncated);
  }
  header.data_offset = reader.offset();

  // Fields: from here on, messages point at the DATA line, where the header is complete.
  if (names.empty()) reader.fail("header has no FIELDS line");
  if (sizes.size() != names.size() || types.size() != names.size()) {
    reader.fail("FIELDS names " + std::to_string(names.size()) + " fields but SIZE has " + std::to_string(sizes.size()) +
                " and TYPE " + std::to_string(types.size()));
  }
  if (!counts.empty() && counts.size() != names.size()) {
    reader.fail("FIELDS names " + std::to_string(names.size()) + " fields but COUNT has " + std::to_string(counts.size()));
  }
  header.xyz_fields = {-1, -1, -1};
  for (std::size_t i = 0; i < names.size(); ++i) {
    PcdField field;
    field.name = std::string(names[i]);
    field.size = parse_count(reader, "SIZE", sizes[i]);
    field.count = counts.empty() ? 1 : parse_count(reader, "COUNT", counts[i]);
    if (types[i].size() != 1 || (types[i] != "I" && types[i] != "U" && types[i] != "F")) {
      reader.fail("field " + field.name + ": TYPE " + detail::quoted(types[i]) + " is not I, U or F");
    }
    field.type = types[i][0];
    const bool size_ok = field.type == 'F' ? (field.size == 4 || field.size == 8)
                                           : (field.size == 1 || field.size == 2 || field.size == 4 || field.size == 8);
    if (!size_ok) reader.fail("field " + field.name + ": SIZE " + std::to_string(field.size) + " is invalid for TYPE " + field.type);
    if (field.count == 0) reader.fail("field " + field.name + ": COUNT 0 is out of range");
    if (field.count > kMaxPointBytes) {
      reader.fail("field " + field.name + ": COUNT " + std::to_string(field.count) + " is out of range",
                  InputProblem::kCountBeyondLimits);
    }
    field.byte_offset = header.point_bytes;
    field.first_value = header.values_per_point;
    header.point_bytes += field.size * field.count;
    header.values_per_point += field.count;
    if (header.point_bytes > kMaxPointBytes) {
      reader.fail("a point of more than 1 MiB: FIELDS/SIZE/COUNT are not plausible", InputProblem::kCountBeyondLimits);
    }
    for (int axis = 0; axis < 3; ++axis) {
      if (field.name == std::string(1, static_cast<char>('x' + axis)) && header.xyz_fields[axis] < 0) {
        header.xyz_fields[axis] = static_cast<int>(i);
        if (field.type != 'F' || field.count != 1) {
          reader.fail("field " + field.name + " must be TYPE F (SIZE 4 or 8) with COUNT 1");
        }
      }
    }
    // An attribute minemap keeps: the first field of its names, with COUNT 1.
    const auto claim = [&](int& slot, std::initializer_list<const char*> aliases) {
      for (const char* alias : aliases) {
        if (field.name == alias && slot < 0 && field.count == 1) slot = static_cast<int>(i);
      }
    };
    claim(header.intensity_field, {"intensity", "i"});
    if (field.size == 4) claim(header.rgb_field, {"rgb", "rgba"});
    claim(header.time_field, {"time", "t", "timestamp"});
    claim(header.ring_field, {"ring"});
    header.fields.push_back(std::move(field));
  }
  for (int axis = 0; axis < 3; ++axis) {
    if (header.xyz_fields[axis] < 0) reader.fail(std::string("no field ") + static_cast<char>('x' + axis) + " in FIELDS");
  }

  // Counts: WIDTH * HEIGHT = POINTS, and never more than max_points (checked before any allocation).
  if (!have_width) reader.fail("header has no WIDTH line");
  if (header.height != 0 && header.width > std::numeric_limits<std::uint64_t>::max() / header.height) {
    detail::fail_at_line(reader.path(), width_line, "WIDTH x HEIGHT overflows", InputProblem::kCountBeyondLimits);
  }
  const std::uint64_t width_times_height = header.width * header.height;
  if (!have_points) {
    header.points = width_times_height;
    points_line = width_line;
  } else if (header.points != width_times_height) {
    detail::fail_at_line(reader.path(), points_line,
                         "POINTS " + std::to_string(header.points) + " differs from WIDTH x HEIGHT = " +
                             std::to_string(header.width) + " x " + std::to_string(header.height));
  }
  if (header.points == 0) detail::fail_at_line(reader.path(), points_line, "no points (POINTS 0)", InputProblem::kEmpty);
  if (header.points > settings.max_points) {
    detail::fail_at_line(reader.path(), points_line,
                         "claims " + std::to_string(header.points) + " points, more than max_points = " +
                             std::to_string(settings.max_points),
                         InputProblem::kCountBeyondLimits);
  }
  return header;
}

/// One binary value of `field` as a double (any TYPE and SIZE).
double load_value(const char* bytes, const PcdField& field) {
  switch (field.type) {
    case 'F': return field.size == 8 ? detail::load_le<double>(bytes) : detail::load_le<float>(bytes);
    case 'U':
      switch (field.size) {
        case 1: return static_cast<double>(static_cast<unsigned char>(bytes[0]));
        case 2: return detail::load_le<std::uint16_t>(bytes);
        case 4: return detail::load_le<std::uint32_t>(bytes);
        default: return static_cast<double>(detail::load_le<std::uint64_t>(bytes));
      }
    default:
      switch (field.size) {
        case 1: return static_cast<double>(static_cast<signed char>(bytes[0]));
        case 2: return detail::load_le<std::int16_t>(bytes);
        case 4: return detail::load_le<std::int32_t>(bytes);
        default: return static_cast<double>(detail::load_le<std::int64_t>(bytes));
      }
  }
}

/// A packed colour 0xRRGGBB: PCL's F4 rgb holds the bits in a float; a U4 holds them as they are.
std::uint32_t packed_rgb(std::uint32_t bits) { return bits & 0xFFFFFFu; }

/// The attribute values of one point, `value_of(field index)` reading a field's value as a double
/// and `bits_of(field index)` its 4 bytes.
template <class ValueOf, class BitsOf>
PointValues attribute_values(const PcdHeader& header, std::uint8_t columns, ValueOf&& value_of, BitsOf&& bits_of) {
  PointValues values;
  if (columns & kIntensity) values.intensity = static_cast<float>(value_of(header.intensity_field));
  if (columns & kColour) values.rgb = packed_rgb(bits_of(header.rgb_field));
  if (columns & kTime) values.time_s = value_of(header.time_field);
  if (columns & kRing) values.ring = static_cast<std::uint16_t>(value_of(header.ring_field));
  return values;
}

/// Adds one point read from the data; the builder drops (and counts) a NaN "no return" point.
/// `fail(axis, message, problem)` is called to throw at the right line or byte.
template <class Fail>
void add_point(detail::ScanBuilder& builder, const std::array<double, 3>& xyz, const PointValues& values, Fail&& fail) {
  if (!(std::isnan(xyz[0]) || std::isnan(xyz[1]) || std::isnan(xyz[2]))) {
    for (int axis = 0; axis < 3; ++axis) {
      if (!std::isfinite(xyz[static_cast<std::size_t>(axis)])) {
        fail(axis, std::string(1, static_cast<char>('x' + axis)) + " is infinite", InputProblem::kNonFinite);
      }
    }
  }
  const auto added = builder.add(xyz[0], xyz[1], xyz[2], values);
  if (added != detail::ScanBuilder::AddResult::kOk) fail(0, builder.describe(added), builder.problem_of(added));
}

void read_ascii_data(LineReader& reader, const PcdHeader& header, detail::ScanBuilder& builder, std::size_t file_size) {
  // Each value takes at least one character and one separator: a cheap bound before reserving.
  const std::uint64_t remaining = file_size - header.data_offset;
  if (header.points > (remaining + 1) / (2 * header.values_per_point)) {
    reader.fail("POINTS " + std::to_string(header.points) + " cannot fit in the " + std::to_string(remaining) +
                    " bytes after the header: the file is truncated, or POINTS is wrong",
                InputProblem::kTruncated);
  }
  builder.reserve(static_cast<std::size_t>(header.points));
  std::vector<std::string_view> tokens(header.values_per_point);
  std::uint64_t lines_read = 0;
  std::string_view line;
  while (reader.next(line)) {
    if (detail::is_blank(line)) continue;
    if (lines_read == header.points) reader.fail("more data lines than POINTS " + std::to_string(header.points));
    ++lines_read;
    const std::size_t count = detail::split_tokens(line, tokens);
    if (count != header.values_per_point) {
      const std::string problem = "expected " + std::to_string(header.values_per_point) +
                                  " values per point (FIELDS/COUNT), found " + std::to_string(count);
      if (count < header.values_per_point) reader.fail_short_line(problem);
      reader.fail(problem);
    }
    std::array<double, 3> xyz{};
    for (int axis = 0; axis < 3; ++axis) {
      const std::string_view token = tokens[header.fields[static_cast<std::size_t>(header.xyz_fields[axis])].first_value];
      const auto status = detail::parse_double(token, xyz[static_cast<std::size_t>(axis)]);
      if (status != detail::NumberStatus::kOk) {
        const std::string problem = std::string(1, static_cast<char>('x' + axis)) + " value " + detail::quoted(token) +
                                    " is not a number or out of range";
        if (status == detail::NumberStatus::kOutOfRange) reader.fail(problem, InputProblem::kNonFinite);
        if (token.data() + token.size() == line.data() + line.size()) reader.fail_short_line(problem);
        reader.fail(problem);
      }
    }
    // Attribute values that do not parse are a malformed line, as coordinates are.
    const auto token_of = [&](int field) { return tokens[header.fields[static_cast<std::size_t>(field)].first_value]; };
    const auto value_of = [&](int field) {
      double value = 0.0;
      if (detail::parse_double(token_of(field), value) != detail::NumberStatus::kOk) {
        reader.fail(header.fields[static_cast<std::size_t>(field)].name + " value " + detail::quoted(token_of(field)) +
                    " is not a number");
      }
      return value;
    };
    const auto bits_of = [&](int field) -> std::uint32_t {
      const double value = value_of(field);
      if (header.fields[static_cast<std::size_t>(field)].type != 'F') return static_cast<std::uint32_t>(value);
      const float packed = static_cast<float>(value);  // PCL writes the float that holds the bits
      std::uint32_t bits = 0;
      std::memcpy(&bits, &packed, 4);
      return bits;
    };
    const PointValues values = attribute_values(header, builder.columns(), value_of, bits_of);
    add_point(builder, xyz, values,
              [&](int, const std::string& message, InputProblem problem) { reader.fail(message, problem); });
  }
  if (lines_read < header.points) {
    reader.fail("only " + std::to_string(lines_read) + " of POINTS " + std::to_string(header.points) +
                    " data lines: the file ends early",
                InputProblem::kTruncated);
  }
}

/// Reads x, y, z of every point from decoded binary data. Field f of point i lies at
/// field_base(f) + i * field_stride(f); for AoS records the stride is the record size, for the
/// decompressed SoA blocks it is the field's own size. `byte_of` maps a data offset to the file
/// offset to report (the compressed block's start for compressed data).
template <class FieldBase, class FieldStride, class ByteOf>
void read_binary_points(const char* data, const PcdHeader& header, detail::ScanBuilder& builder, const std::string& path,
                        FieldBase&& field_base, FieldStride&& field_stride, ByteOf&& byte_of) {
  builder.reserve(static_cast<std::size_t>(header.points));
  const std::uint8_t columns = builder.columns();
  std::array<std::uint64_t, 3> base{}, stride{};
  std::array<bool, 3> is_double{};
  for (std::size_t axis = 0; axis < 3; ++axis) {
    const PcdField& field = header.fields[static_cast<std::size_t>(header.xyz_fields[axis])];
    base[axis] = field_base(field);
    stride[axis] = field_stride(field);
    is_double[axis] = field.size == 8;
  }
  for (std::uint64_t i = 0; i < header.points; ++i) {
    std::array<double, 3> xyz{};
    for (std::size_t axis = 0; axis < 3; ++axis) {
      const char* value = data + base[axis] + i * stride[axis];
      xyz[axis] = is_double[axis] ? detail::load_le<double>(value) : detail::load_le<float>(value);
    }
    const auto at = [&](int field) {
      const PcdField& f = header.fields[static_cast<std::size_t>(field)];
      return data + field_base(f) + i * field_stride(f);
    };
    const PointValues values = attribute_values(
        header, columns, [&](int field) { return load_value(at(field), header.fields[static_cast<std::size_t>(field)]); },
        [&](int field) { return detail::load_le<std::uint32_t>(at(field)); });
    add_point(builder, xyz, values, [&](int axis, const std::string& message, InputProblem problem) {
      const std::uint64_t offset = base[static_cast<std::size_t>(axis)] + i * stride[static_cast<std::size_t>(axis)];
      detail::fail_at_byte(path, byte_of(offset), "point " + std::to_string(i) + ": " + message, problem);
    });
  }
}

}  // namespace

Scan read_pcd(const fs::path& path, const ReadSettings& settings) {
  const detail::ScanFileBytes file(path);
  const std::string& bytes = file.bytes();
  const std::string name = path.string();
  LineReader reader(bytes, name);
  detail::ScanBuilder builder(path, settings, LengthUnit::kMetre);
  const PcdHeader header = read_header(reader, settings, centimetres_per(builder.unit()));
  builder.carries(header.attributes());

  const std::uint64_t remaining = bytes.size() - header.data_offset;
  const char* data = bytes.data() + header.data_offset;
  if (header.points > std::numeric_limits<std::uint64_t>::max() / header.point_bytes) {
    detail::fail_at_byte(name, header.data_offset, "POINTS x point size overflows", InputProblem::kCountBeyondLimits);
  }
  const std::uint64_t data_bytes = header.points * header.point_bytes;
  switch (header.encoding) {
    case PcdEncoding::kAscii:
      read_ascii_data(reader, header, builder, bytes.size());
      break;
    case PcdEncoding::kBinary: {
      if (data_bytes > remaining) {
        detail::fail_at_byte(name, header.data_offset + remaining,
                             "binary data truncated: " + std::to_string(header.points) + " points of " +
                                 std::to_string(header.point_bytes) + " bytes need " + std::to_string(data_bytes) +
                                 " bytes, the file has " + std::to_string(remaining) + " after the header",
                             InputProblem::kTruncated);
      }
      read_binary_points(
          data, header, builder, name, [](const PcdField& f) { return f.byte_offset; },
          [&](const PcdField&) { return header.point_bytes; },
          [&](std::uint64_t offset) { return header.data_offset + offset; });
      break;
    }
    case PcdEncoding::kBinaryCompressed: {
      if (remaining < 8) {
        detail::fail_at_byte(name, header.data_offset, "binary_compressed data truncated: no block sizes",
                             InputProblem::kTruncated);
      }
      const std::uint64_t compressed_bytes = detail::load_le<std::uint32_t>(data);
      const std::uint64_t uncompressed_bytes = detail::load_le<std::uint32_t>(data + 4);
      if (compressed_bytes > remaining - 8) {
        detail::fail_at_byte(name, header.data_offset,
                             "compressed block of " + std::to_string(compressed_bytes) + " bytes is truncated (" +
                                 std::to_string(remaining - 8) + " bytes left)",
                             InputProblem::kTruncated);
      }
      if (uncompressed_bytes != data_bytes) {
        detail::fail_at_byte(name, header.data_offset + 4,
                             "uncompressed size " + std::to_string(uncompressed_bytes) + " differs from POINTS x point size = " +
                                 std::to_string(data_bytes));
      }
      if (uncompressed_bytes > compressed_bytes * kLzfMaxExpansion) {
        detail::fail_at_byte(name, header.data_offset,
                             "uncompressed size " + std::to_string(uncompressed_bytes) + " cannot come from " +
                                 std::to_string(compressed_bytes) + " LZF bytes");
      }
      std::string decompressed(static_cast<std::size_t>(uncompressed_bytes), '\0');
      const unsigned int got = lzf_decompress(data + 8, static_cast<unsigned int>(compressed_bytes), decompressed.data(),
                                              static_cast<unsigned int>(uncompressed_bytes));
      if (got != uncompressed_bytes) {
        detail::fail_at_byte(name, header.data_offset + 8,
                             "LZF block is corrupt (decompressed to " + std::to_string(got) + " of " +
                                 std::to_string(uncompressed_bytes) + " bytes)");
      }
      // Structure of arrays: field f's block starts at POINTS x (bytes of the fields before it).
      read_binary_points(
          decompressed.data(), header, builder, name,
          [&](const PcdField& f) { return f.byte_offset * header.points; },
          [](const PcdField& f) { return f.size * f.count; },
          [&](std::uint64_t) { return header.data_offset + 8; });
      break;
    }
  }
  if (builder.size() == 0) {
    detail::fail_at_byte(name, header.data_offset, builder.no_points_message(), builder.no_points_problem());
  }
  Scan scan = builder.finish(/*split_unmarked=*/false);
  scan.pose_cm = header.viewpoint_cm;
  return scan;
}

void write_pcd(const fs::path& path, const Scan& scan, PcdEncoding encoding, LengthUnit unit) {
  const double divisor = centimetres_per(unit);
  const std::size_t n = scan.size();
  const auto value = [&](std::size_t i, int axis) { return static_cast<float>(scan.file_point(i)[axis] / divisor); };

  Eigen::Quaterniond q(Eigen::Matrix3d(scan.pose_cm.block<3, 3>(0, 0)));
  q.normalize();
  // The attributes the scan carries, after x y z: intensity F4, rgb F4 (PCL's packed colour), time
  // F8, ring U2 (return numbers have no PCL field and are not written).
  const PointAttributes& attributes = scan.attributes;
  const std::uint8_t columns = attributes.columns() & static_cast<std::uint8_t>(kIntensity | kColour | kTime | kRing);
  std::string fields = "x y z", sizes = "4 4 4", types = "F F F", counts = "1 1 1";
  const auto field = [&](const char* name, const char* size, const char* type) {
    fields += std::string(" ") + name;
    sizes += std::string(" ") + size;
    types += std::string(" ") + type;
    counts += " 1";
  };
  if (columns & kIntensity) field("intensity", "4", "F");
  if (columns & kColour) field("rgb", "4", "F");
  if (columns & kTime) field("time", "8", "F");
  if (columns & kRing) field("ring", "2", "U");
  std::string out = "# .PCD v0.7 - Point Cloud Data file format (minemap)\nVERSION 0.7\nFIELDS " + fields +
                    "\nSIZE " + sizes + "\nTYPE " + types + "\nCOUNT " + counts + "\nWIDTH " + std::to_string(n) +
                    "\nHEIGHT 1\nVIEWPOINT";
  const auto rgb_float = [&](std::size_t i) {
    float packed = 0.0f;
    std::memcpy(&packed, &attributes.rgb[i], 4);
    return packed;
  };
  for (const double v : {scan.pose_cm(0, 3) / divisor, scan.pose_cm(1, 3) / divisor, scan.pose_cm(2, 3) / divisor, q.w(),
                         q.x(), q.y(), q.z()}) {
    out += ' ';
    detail::append_number(out, v);
  }
  out += "\nPOINTS " + std::to_string(n) + "\nDATA ";
  switch (encoding) {
    case PcdEncoding::kAscii:
      out += "ascii\n";
      for (std::size_t i = 0; i < n; ++i) {
        for (int axis = 0; axis < 3; ++axis) {
          if (axis > 0) out += ' ';
          detail::append_number(out, value(i, axis));
        }
        const auto append = [&](auto v) {
          out += ' ';
          detail::append_number(out, v);
        };
        if (columns & kIntensity) append(attributes.intensity[i]);
        if (columns & kColour) append(rgb_float(i));
        if (columns & kTime) append(attributes.time_s[i]);
        if (columns & kRing) out += ' ' + std::to_string(attributes.ring[i]);
        out += '\n';
      }
      break;
    case PcdEncoding::kBinary:
      out += "binary\n";
      out.reserve(out.size() + n * 12);
      for (std::size_t i = 0; i < n; ++i) {
        for (int axis = 0; axis < 3; ++axis) detail::append_le(out, value(i, axis));
        if (columns & kIntensity) detail::append_le(out, attributes.intensity[i]);
        if (columns & kColour) detail::append_le(out, attributes.rgb[i]);
        if (columns & kTime) detail::append_le(out, attributes.time_s[i]);
        if (columns & kRing) detail::append_le(out, attributes.ring[i]);
      }
      break;
    case PcdEncoding::kBinaryCompressed: {
      out += "binary_compressed\n";
      std::string soa;
      soa.reserve(n * 12);
      for (int axis = 0; axis < 3; ++axis) {
        for (std::size_t i = 0; i < n; ++i) detail::append_le(soa, value(i, axis));
      }
      const auto column = [&](const auto& values) {
        for (const auto v : values) detail::append_le(soa, v);
      };
      if (columns & kIntensity) column(attributes.intensity);
      if (columns & kColour) column(attributes.rgb);
      if (columns & kTime) column(attributes.time_s);
      if (columns & kRing) column(attributes.ring);
      if (soa.size() > std::numeric_limits<std::uint32_t>::max() / 2) {
        throw OutputError("cannot write " + path.string() + ": too many points for one LZF block");
      }
      // LZF expands incompressible data by at most 1 byte in 32.
      std::string compressed(soa.size() + soa.size() / 16 + 64, '\0');
      unsigned int compressed_bytes = 0;
      if (!soa.empty()) {
        compressed_bytes = lzf_compress(soa.data(), static_cast<unsigned int>(soa.size()), compressed.data(),
                                        static_cast<unsigned int>(compressed.size()));
        if (compressed_bytes == 0) throw OutputError("cannot write " + path.string() + ": LZF compression failed");
      }
      detail::append_le<std::uint32_t>(out, compressed_bytes);
      detail::append_le<std::uint32_t>(out, static_cast<std::uint32_t>(soa.size()));
      out.append(compressed.data(), compressed_bytes);
      break;
    }
  }
  write_file_atomically(path, out);
}

}  // namespace minemap::io
