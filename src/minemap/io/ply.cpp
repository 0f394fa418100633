// PLY (http://paulbourke.net/dataformats/ply/): a text header of elements and their properties, then
// the elements' instances in header order, as ascii lines or binary little-endian records.
//
// Choices:
//  - Only the "vertex" element is read; x, y and z may be any scalar type (float and double in
//    practice, int in some exports). The attributes minemap keeps (Scan::attributes), any scalar
//    type: intensity (or scalar_intensity, scalar_Intensity, reflectance), colour (red, green and
//    blue together; integers up to 255, or 16-bit ones scaled down), time (or timestamp, gps_time,
//    scalar_GpsTime; seconds) and ring. Other vertex properties are skipped, lists included.
//  - Elements declared before "vertex" (rare, e.g. faces first) are walked and skipped, lists
//    properly; elements after it are not read at all.
//  - ascii: one element instance per line (what every writer produces), so a wrong value count is
//    reported at its line instead of shifting every later value.
//  - binary_big_endian is refused with a clear message (no real survey data uses it).
//  - A vertex with a NaN coordinate is dropped and counted, as in every point reader (formats.hpp;
//    PLY has no "no return" convention, but exporters write NaN for missing points); an infinite
//    one is an InputError.
#include <algorithm>
#include <array>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <string>
#include <vector>

#include "minemap/core/atomic_file.hpp"
#include "minemap/io/binary_data.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/io/scan_builder.hpp"
#include "minemap/io/text_reader.hpp"
#include "minemap/io/text_writer.hpp"

namespace minemap::io {
namespace {

using detail::LineReader;

enum class PlyScalar { kInt8, kUInt8, kInt16, kUInt16, kInt32, kUInt32, kFloat32, kFloat64 };

struct PlyTypeName {
  std::string_view name;
  std::string_view alias;
  PlyScalar type;
};
constexpr std::array<PlyTypeName, 8> kPlyTypes{{{"char", "int8", PlyScalar::kInt8},
                                                {"uchar", "uint8", PlyScalar::kUInt8},
                                                {"short", "int16", PlyScalar::kInt16},
                                                {"ushort", "uint16", PlyScalar::kUInt16},
                                                {"int", "int32", PlyScalar::kInt32},
                                                {"uint", "uint32", PlyScalar::kUInt32},
                                                {"float", "float32", PlyScalar::kFloat32},
                                                {"double", "float64", PlyScalar::kFloat64}}};

std::uint64_t size_of(PlyScalar type) {
  switch (type) {
    case PlyScalar::kInt8:
    case PlyScalar::kUInt8:
      return 1;
    case PlyScalar::kInt16:
    case PlyScalar::kUInt16:
      return 2;
    case PlyScalar::kInt32:
    case PlyScalar::kUInt32:
    case PlyScalar::kFloat32:
      return 4;
    case PlyScalar::kFloat64:
      return 8;
  }
  return 0;
}

bool is_integer(PlyScalar type) { return type != PlyScalar::kFloat32 && type != PlyScalar::kFloat64; }

double load_scalar(const char* bytes, PlyScalar type) {
  switch (type) {
    case PlyScalar::kInt8:
      return detail::load_le<std::int8_t>(bytes);
    case PlyScalar::kUInt8:
      return detail::load_le<std::uint8_t>(bytes);
    case PlyScalar::kInt16:
      return detail::load_le<std::int16_t>(bytes);
    case PlyScalar::kUInt16:
      return detail::load_le<std::uint16_t>(bytes);
    case PlyScalar::kInt32:
      return detail::load_le<std::int32_t>(bytes);
    case PlyScalar::kUInt32:
      return detail::load_le<std::uint32_t>(bytes);
    case PlyScalar::kFloat32:
      return detail::load_le<float>(bytes);
    case PlyScalar::kFloat64:
      return detail::load_le<double>(bytes);
  }
  return 0.0;
}

PlyScalar parse_type(const LineReader& reader, std::string_view token) {
  for (const auto& entry : kPlyTypes) {
    if (token == entry.name || token == entry.alias) return entry.type;
  }
  reader.fail("unknown PLY property type " + detail::quoted(token));
}

struct PlyProperty {
  std::string name;
  PlyScalar type = PlyScalar::kFloat32;  ///< the value type (list items for lists)
  bool is_list = false;
  PlyScalar count_type = PlyScalar::kUInt8;  ///< lists only
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::int64_t line = 0;
  std::vector<PlyProperty> properties;

  bool has_lists() const {
    for (const auto& p : properties) {
      if (p.is_list) return true;
    }
    return false;
  }
  /// Bytes of one binary instance when every list is empty (the exact size without lists).
  std::uint64_t min_binary_size() const {
    std::uint64_t bytes = 0;
    for (const auto& p : properties) bytes += p.is_list ? size_of(p.count_type) : size_of(p.type);
    return bytes;
  }
};

enum class PlyEncoding { kAscii, kBinaryLittleEndian };

/// The vertex properties that hold the attributes minemap keeps (indices, kNone: absent).
struct PlyAttributeProperties {
  static constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();
  std::size_t intensity = kNone, time = kNone, ring = kNone;
  std::array<std::size_t, 3> rgb{kNone, kNone, kNone};
  bool colour_is_16_bit = false;
  std::uint8_t columns() const {
    const bool colour = rgb[0] != kNone && rgb[1] != kNone && rgb[2] != kNone;
    return static_cast<std::uint8_t>((intensity != kNone ? kIntensity : 0) | (colour ? kColour : 0) |
                                     (time != kNone ? kTime : 0) | (ring != kNone ? kRing : 0));
  }
};

struct PlyHeader {
  PlyEncoding encoding = PlyEncoding::kAscii;
  std::vector<PlyElement> elements;
  std::size_t vertex_element = 0;
  std::array<std::size_t, 3> xyz_properties{};  ///< indices into the vertex element's properties
  PlyAttributeProperties attributes;
  std::size_t data_offset = 0;
};

/// Finds the attribute properties among the vertex element's scalar properties.
PlyAttributeProperties attribute_properties(const PlyElement& vertex) {
  PlyAttributeProperties found;
  using Names = std::initializer_list<std::string_view>;
  const auto claim = [&](std::size_t& slot, std::size_t p, Names names) {
    for (const std::string_view name : names) {
      if (vertex.properties[p].name == name && slot == PlyAttributeProperties::kNone) slot = p;
    }
  };
  for (std::size_t p = 0; p < vertex.properties.size(); ++p) {
    if (vertex.properties[p].is_list) continue;
    claim(found.intensity, p, Names{"intensity", "scalar_intensity", "scalar_Intensity", "reflectance"});
    claim(found.time, p, Names{"time", "timestamp", "gps_time", "scalar_GpsTime"});
    claim(found.ring, p, Names{"ring"});
    claim(found.rgb[0], p, Names{"red"});
    claim(found.rgb[1], p, Names{"green"});
    claim(found.rgb[2], p, Names{"blue"});
  }
  for (const std::size_t channel : found.rgb) {
    if (channel != PlyAttributeProperties::kNone && size_of(vertex.properties[channel].type) == 2) {
      found.colour_is_16_bit = true;
    }
  }
  return found;
}

/// Collects one vertex's attribute values, property by property.
struct AttributeCollector {
  const PlyAttributeProperties& where;
  PointValues values;
  std::array<double, 3> channel{};

  void take(std::size_t p, double value) {
    if (p == where.intensity) values.intensity = static_cast<float>(value);
    if (p == where.time) values.time_s = value;
    if (p == where.ring) values.ring = static_cast<std::uint16_t>(value);
    for (std::size_t c = 0; c < 3; ++c) {
      if (p == where.rgb[c]) channel[c] = value;
    }
  }
  const PointValues& finish() {
    std::uint32_t packed = 0;
    for (std::size_t c = 0; c < 3; ++c) {
      const double v = where.colour_is_16_bit ? channel[c] / 257.0 : channel[c];
      packed = (packed << 8) | static_cast<std::uint32_t>(std::clamp(std::lround(v), 0L, 255L));
    }
    values.rgb = packed;
    return values;
  }
};

PlyHeader read_header(LineReader& reader, const ReadSettings& settings) {
  PlyHeader header;
  std::string_view line;
  if (!reader.next(line)) reader.fail("empty file, not a PLY file", InputProblem::kEmpty);
  if (detail::trim(line) != "ply") reader.fail("not a PLY file (the first line is not 'ply')");
  bool have_format = false;
  bool have_end = false;
  std::vector<std::string_view> tokens;
  while (!have_end && reader.next(line)) {
    detail::split_all_tokens(line, tokens);
    if (tokens.empty()) continue;
    const std::string_view keyword = tokens[0];
    if (keyword == "comment" || keyword == "obj_info") continue;
    if (keyword == "end_header") {
      have_end = true;
    } else if (keyword == "format") {
      if (have_format) reader.fail("second format line");
      if (tokens.size() != 3) reader.fail("expected 'format <ascii|binary_little_endian> 1.0'");
      if (tokens[1] == "ascii") {
        header.encoding = PlyEncoding::kAscii;
      } else if (tokens[1] == "binary_little_endian") {
        header.encoding = PlyEncoding::kBinaryLittleEndian;
      } else if (tokens[1] == "binary_big_endian") {
        reader.fail("binary_big_endian PLY is not supported (convert it to binary_little_endian or ascii)");
      } else {
        reader.fail("unknown PLY format " + detail::quoted(tokens[1]));
      }
      have_format = true;
    } else if (keyword == "element") {
      if (tokens.size() != 3) reader.fail("expected 'element <name> <count>'");
      PlyElement element;
      element.name = std::string(tokens[1]);
      element.line = reader.line_number();
      if (!detail::parse_uint64(tokens[2], element.count)) {
        reader.fail("element count " + detail::quoted(tokens[2]) + " is not a non-negative integer");
      }
      header.elements.push_back(std::move(element));
    } else if (keyword == "property") {
      if (header.elements.empty()) reader.fail("property before any element");
      PlyProperty property;
      if (tokens.size() == 5 && tokens[1] == "list") {
        property.is_list = true;
        property.count_type = parse_type(reader, tokens[2]);
        if (!is_integer(property.count_type)) reader.fail("list count type must be an integer type");
        property.type = parse_type(reader, tokens[3]);
        property.name = std::string(tokens[4]);
      } else if (tokens.size() == 3) {
        property.type = parse_type(reader, tokens[1]);
        property.name = std::string(tokens[2]);
      } else {
        reader.fail("expected 'property <type> <name>' or 'property list <count type> <type> <name>'");
      }
      header.elements.back().properties.push_back(std::move(property));
    } else {
      reader.fail("unknown PLY header keyword " + detail::quoted(keyword));
    }
  }
  if (!have_end) reader.fail("header has no end_header line: the file ends in the header", InputProblem::kTruncated);
  if (!have_format) reader.fail("header has no format line");
  header.data_offset = reader.offset();

  bool have_vertex = false;
  for (std::size_t e = 0; e < header.elements.size() && !have_vertex; ++e) {
    if (header.elements[e].name == "vertex") {
      header.vertex_element = e;
      have_vertex = true;
    }
  }
  if (!have_vertex) reader.fail("no vertex element");
  const PlyElement& vertex = header.elements[header.vertex_element];
  for (std::size_t axis = 0; axis < 3; ++axis) {
    const std::string axis_name(1, static_cast<char>('x' + axis));
    bool found = false;
    for (std::size_t p = 0; p < vertex.properties.size() && !found; ++p) {
      if (vertex.properties[p].name != axis_name) continue;
      if (vertex.properties[p].is_list) detail::fail_at_line(reader.path(), vertex.line, "vertex property " + axis_name + " is a list");
      header.xyz_properties[axis] = p;
      found = true;
    }
    if (!found) detail::fail_at_line(reader.path(), vertex.line, "vertex element has no property " + axis_name);
  }
  header.attributes = attribute_properties(vertex);
  if (vertex.count == 0) {
    detail::fail_at_line(reader.path(), vertex.line, "no points (element vertex 0)", InputProblem::kEmpty);
  }
  if (vertex.count > settings.max_points) {
    detail::fail_at_line(reader.path(), vertex.line,
                         "claims " + std::to_string(vertex.count) + " vertices, more than max_points = " +
                             std::to_string(settings.max_points),
                         InputProblem::kCountBeyondLimits);
  }
  return header;
}

/// Binary data with bounds checks that report the file offset.
class BinaryCursor {
 public:
  BinaryCursor(std::string_view bytes, std::size_t start, std::string path)
      : bytes_(bytes), position_(start), path_(std::move(path)) {}

  std::uint64_t position() const { return position_; }
  std::uint64_t remaining() const { return bytes_.size() - position_; }
  [[noreturn]] void fail(std::uint64_t offset, const std::string& message,
                         InputProblem problem = InputProblem::kMalformed) const {
    detail::fail_at_byte(path_, offset, message, problem);
  }

  /// `count` bytes at the current position, then advances; fails when the file ends first.
  const char* take(std::uint64_t count, std::string_view what) {
    if (count > remaining()) {
      fail(position_,
           "file ends inside " + std::string(what) + " (" + std::to_string(count) + " bytes needed, " +
               std::to_string(remaining()) + " left)",
           InputProblem::kTruncated);
    }
    const char* at = bytes_.data() + position_;
    position_ += count;
    return at;
  }

 private:
  std::string_view bytes_;
  std::uint64_t position_;
  std::string path_;
};

/// Walks one binary instance of `element`; calls on_scalar(property index, bytes) for scalars.
template <class OnScalar>
void walk_binary_instance(BinaryCursor& cursor, const PlyElement& element, OnScalar&& on_scalar) {
  for (std::size_t p = 0; p < element.properties.size(); ++p) {
    const PlyProperty& property = element.properties[p];
    if (!property.is_list) {
      on_scalar(p, cursor.take(size_of(property.type), element.name + " property " + property.name));
      continue;
    }
    const std::uint64_t at = cursor.position();
    const double count = load_scalar(cursor.take(size_of(property.count_type), element.name + " list count"), property.count_type);
    if (count < 0) cursor.fail(at, "negative list length in " + element.name + " property " + property.name);
    cursor.take(static_cast<std::uint64_t>(count) * size_of(property.type), element.name + " list " + property.name);
  }
}

void skip_binary_element(BinaryCursor& cursor, const PlyElement& element) {
  if (element.properties.empty()) return;
  if (!element.has_lists()) {
    const std::uint64_t size = element.min_binary_size();
    if (element.count > cursor.remaining() / size) {
      cursor.fail(cursor.position(),
                  "file ends inside element " + element.name + " (" + std::to_string(element.count) + " instances of " +
                      std::to_string(size) + " bytes declared)",
                  InputProblem::kTruncated);
    }
    cursor.take(element.count * size, element.name);
    return;
  }
  // Every instance takes at least one byte, so this loop ends with the file at the latest.
  for (std::uint64_t i = 0; i < element.count; ++i) walk_binary_instance(cursor, element, [](std::size_t, const char*) {});
}

void read_binary_vertices(BinaryCursor& cursor, const PlyHeader& header, detail::ScanBuilder& builder) {
  const PlyElement& vertex = header.elements[header.vertex_element];
  // Checked before reserving: the declared count must fit in what is left of the file.
  if (vertex.count > cursor.remaining() / vertex.min_binary_size()) {
    cursor.fail(cursor.position(),
                "file ends inside the vertices: " + std::to_string(vertex.count) + " declared, " +
                    std::to_string(cursor.remaining()) + " bytes left",
                InputProblem::kTruncated);
  }
  builder.reserve(static_cast<std::size_t>(vertex.count));
  for (std::uint64_t i = 0; i < vertex.count; ++i) {
    std::array<double, 3> xyz{};
    std::array<std::uint64_t, 3> offsets{};
    AttributeCollector attributes{header.attributes, {}, {}};
    const bool collect = builder.columns() != 0;
    walk_binary_instance(cursor, vertex, [&](std::size_t p, const char* bytes) {
      for (std::size_t axis = 0; axis < 3; ++axis) {
        if (header.xyz_properties[axis] == p) {
          xyz[axis] = load_scalar(bytes, vertex.properties[p].type);
          offsets[axis] = cursor.position() - size_of(vertex.properties[p].type);
        }
      }
      if (collect) attributes.take(p, load_scalar(bytes, vertex.properties[p].type));
    });
    for (std::size_t axis = 0; axis < 3; ++axis) {
      if (std::isinf(xyz[axis])) {  // NaN drops the vertex (ScanBuilder)
        cursor.fail(offsets[axis], "vertex " + std::to_string(i) + ": " + static_cast<char>('x' + axis) + " is not finite",
                    InputProblem::kNonFinite);
      }
    }
    const auto added = builder.add(xyz[0], xyz[1], xyz[2], collect ? attributes.finish() : PointValues{});
    if (added != detail::ScanBuilder::AddResult::kOk) {
      cursor.fail(offsets[0], "vertex " + std::to_string(i) + ": " + builder.describe(added), builder.problem_of(added));
    }
  }
  if (builder.size() == 0) cursor.fail(header.data_offset, builder.no_points_message(), builder.no_points_problem());
}

/// Checks one ascii instance line against `element`'s properties (lists: a count, then that many
/// values) and returns the token index of each scalar property (unused for lists).
void index_ascii_instance(const LineReader& reader, const PlyElement& element, std::span<const std::string_view> tokens,
                          std::vector<std::size_t>& token_of_property) {
  token_of_property.resize(element.properties.size());
  std::size_t next = 0;
  for (std::size_t p = 0; p < element.properties.size(); ++p) {
    const PlyProperty& property = element.properties[p];
    if (next >= tokens.size()) {
      reader.fail_short_line(element.name + " line ends before property " + property.name + " (" +
                             std::to_string(tokens.size()) + " values)");
    }
    token_of_property[p] = next;
    if (!property.is_list) {
      ++next;
      continue;
    }
    std::uint64_t count = 0;
    if (!detail::parse_uint64(tokens[next], count)) {
      reader.fail("list length " + detail::quoted(tokens[next]) + " of " + property.name + " is not a non-negative integer");
    }
    if (count > tokens.size() - next - 1) reader.fail_short_line("list " + property.name + " is longer than its line");
    next += 1 + count;
  }
  if (next != tokens.size()) {
    reader.fail(element.name + " line has " + std::to_string(tokens.size()) + " values, the header declares " +
                std::to_string(next));
  }
}

/// The next non-blank line's tokens; fails when the file ends before `element`'s instances do.
void next_ascii_instance(LineReader& reader, const PlyElement& element, std::uint64_t index,
                         std::vector<std::string_view>& tokens) {
  std::string_view line;
  while (reader.next(line)) {
    if (detail::is_blank(line)) continue;
    detail::split_all_tokens(line, tokens);
    return;
  }
  reader.fail("file ends after " + std::to_string(index) + " of " + std::to_string(element.count) + " " + element.name +
                  " lines",
              InputProblem::kTruncated);
}

void read_ascii_data(LineReader& reader, const PlyHeader& header, detail::ScanBuilder& builder, std::size_t file_size) {
  std::vector<std::string_view> tokens;
  std::vector<std::size_t> token_of_property;
  for (std::size_t e = 0; e < header.vertex_element; ++e) {
    const PlyElement& element = header.elements[e];
    if (element.properties.empty()) continue;
    for (std::uint64_t i = 0; i < element.count; ++i) {
      next_ascii_instance(reader, element, i, tokens);
      index_ascii_instance(reader, element, tokens, token_of_property);
    }
  }
  const PlyElement& vertex = header.elements[header.vertex_element];
  // Each value takes a character and a separator: a cheap bound before reserving.
  const std::uint64_t remaining = file_size - reader.offset();
  if (vertex.count > (remaining + 1) / (2 * vertex.properties.size())) {
    detail::fail_at_line(reader.path(), vertex.line,
                         std::to_string(vertex.count) + " vertices cannot fit in the " + std::to_string(remaining) +
                             " bytes of data left: the file is truncated, or the count is wrong",
                         InputProblem::kTruncated);
  }
  builder.reserve(static_cast<std::size_t>(vertex.count));
  for (std::uint64_t i = 0; i < vertex.count; ++i) {
    next_ascii_instance(reader, vertex, i, tokens);
    index_ascii_instance(reader, vertex, tokens, token_of_property);
    std::array<double, 3> xyz{};
    for (std::size_t axis = 0; axis < 3; ++axis) {
      const std::size_t token_index = token_of_property[header.xyz_properties[axis]];
      const std::string_view token = tokens[token_index];
      const auto status = detail::parse_double(token, xyz[axis]);
      if (status == detail::NumberStatus::kOk && !std::isinf(xyz[axis])) continue;  // NaN: dropped by the builder
      const std::string problem = std::string(1, static_cast<char>('x' + axis)) + " value " + detail::quoted(token) +
                                  " is not a finite number";
      if (status != detail::NumberStatus::kNotANumber) reader.fail(problem, InputProblem::kNonFinite);
      if (token_index + 1 == tokens.size()) reader.fail_short_line(problem);
      reader.fail(problem);
    }
    PointValues values;
    if (builder.columns() != 0) {
      AttributeCollector attributes{header.attributes, {}, {}};
      for (std::size_t p = 0; p < vertex.properties.size(); ++p) {
        if (vertex.properties[p].is_list) continue;
        const std::string_view token = tokens[token_of_property[p]];
        double value = 0.0;
        if (p != header.xyz_properties[0] && p != header.xyz_properties[1] && p != header.xyz_properties[2] &&
            (p == header.attributes.intensity || p == header.attributes.time || p == header.attributes.ring ||
             p == header.attributes.rgb[0] || p == header.attributes.rgb[1] || p == header.attributes.rgb[2])) {
          if (detail::parse_double(token, value) != detail::NumberStatus::kOk) {
            reader.fail(vertex.properties[p].name + " value " + detail::quoted(token) + " is not a number");
          }
          attributes.take(p, value);
        }
      }
      values = attributes.finish();
    }
    const auto added = builder.add(xyz[0], xyz[1], xyz[2], values);
    if (added != detail::ScanBuilder::AddResult::kOk) reader.fail(builder.describe(added), builder.problem_of(added));
  }
  if (builder.size() == 0) {
    detail::fail_at_line(reader.path(), vertex.line, builder.no_points_message(), builder.no_points_problem());
  }
}

}  // namespace

Scan read_ply(const fs::path& path, const ReadSettings& settings) {
  const detail::ScanFileBytes file(path);
  const std::string& bytes = file.bytes();
  LineReader reader(bytes, path.string());
  detail::ScanBuilder builder(path, settings, LengthUnit::kMetre);
  const PlyHeader header = read_header(reader, settings);
  builder.carries(header.attributes.columns());
  if (header.encoding == PlyEncoding::kAscii) {
    read_ascii_data(reader, header, builder, bytes.size());
  } else {
    BinaryCursor cursor(bytes, header.data_offset, path.string());
    for (std::size_t e = 0; e < header.vertex_element; ++e) skip_binary_element(cursor, header.elements[e]);
    read_binary_vertices(cursor, header, builder);
  }
  return builder.finish(/*split_unmarked=*/false);
}

namespace {
/// The width of the vertex count in a streamed header: written blank-padded, patched at the end.
constexpr std::size_t kCountWidth = 20;
}  // namespace

struct PlyStreamWriter::File {
  explicit File(const fs::path& path) : file(path) {}
  AtomicOutputFile file;
};

PlyStreamWriter::PlyStreamWriter(const fs::path& path, Layout layout)
    : file_(std::make_unique<File>(path)), layout_(std::move(layout)) {
  std::string header = "ply\nformat binary_little_endian 1.0\n";
  for (const std::string& comment : layout_.comments) header += "comment " + comment + "\n";
  header += "element vertex ";
  count_offset_ = header.size();
  header += std::string(kCountWidth, ' ') + "\n";
  const char* coordinate = layout_.double_coordinates ? "double" : "float";
  for (const char* axis : {"x", "y", "z"}) header += std::string("property ") + coordinate + " " + axis + "\n";
  const std::uint8_t a = layout_.attributes;
  if (a & kIntensity) header += "property float intensity\n";
  if (a & kColour) header += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  if (a & kTime) header += "property double time\n";
  if (a & kRing) header += "property ushort ring\n";
  if (a & kReturnNumber) header += "property uchar return_number\n";
  if (layout_.scan_index) header += "property uint scan\n";
  header += "end_header\n";
  file_->file.stream().write(header.data(), static_cast<std::streamsize>(header.size()));
}

PlyStreamWriter::~PlyStreamWriter() = default;

void PlyStreamWriter::write(std::span<const Eigen::Vector3d> points, const PointAttributes& attributes,
                            std::uint32_t scan) {
  const std::uint8_t a = layout_.attributes;
  buffer_.clear();
  for (std::size_t i = 0; i < points.size(); ++i) {
    for (int axis = 0; axis < 3; ++axis) {
      if (layout_.double_coordinates) detail::append_le(buffer_, points[i][axis]);
      else detail::append_le(buffer_, static_cast<float>(points[i][axis]));
    }
    if (a != 0) {
      const PointValues v = attributes.at(i);
      if (a & kIntensity) detail::append_le(buffer_, v.intensity);
      if (a & kColour) {
        for (const int shift : {16, 8, 0}) detail::append_le(buffer_, static_cast<std::uint8_t>((v.rgb >> shift) & 0xFF));
      }
      if (a & kTime) detail::append_le(buffer_, v.time_s);
      if (a & kRing) detail::append_le(buffer_, v.ring);
      if (a & kReturnNumber) detail::append_le(buffer_, v.return_number);
    }
    if (layout_.scan_index) detail::append_le(buffer_, scan);
  }
  std::ostream& out = file_->file.stream();
  out.write(buffer_.data(), static_cast<std::streamsize>(buffer_.size()));
  if (!out) throw OutputError("cannot write " + file_->file.path().string() + ": write failed (disk full?)");
  count_ += points.size();
}

void PlyStreamWriter::finish() {
  std::ostream& out = file_->file.stream();
  const std::string count = std::to_string(count_);
  out.seekp(static_cast<std::streamoff>(count_offset_));
  out.write(count.data(), static_cast<std::streamsize>(count.size()));
  file_->file.commit();
}

void write_ply(const fs::path& path, std::span<const Eigen::Vector3f> points_cm, bool binary, LengthUnit unit) {
  const double divisor = centimetres_per(unit);
  std::string out = "ply\nformat ";
  out += binary ? "binary_little_endian" : "ascii";
  out += " 1.0\ncomment minemap, unit ";
  out += to_string(unit);
  out += "\nelement vertex " + std::to_string(points_cm.size()) +
         "\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
  out.reserve(out.size() + points_cm.size() * (binary ? 12 : 36));
  for (const Eigen::Vector3f& p : points_cm) {
    for (int axis = 0; axis < 3; ++axis) {
      const auto value = static_cast<float>(p[axis] / divisor);
      if (binary) {
        detail::append_le(out, value);
      } else {
        if (axis > 0) out += ' ';
        detail::append_number(out, value);
      }
    }
    if (!binary) out += '\n';
  }
  write_file_atomically(path, out);
}

}  // namespace minemap::io
