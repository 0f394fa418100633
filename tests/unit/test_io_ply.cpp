// PLY: ascii and binary_little_endian round trips, files with other properties, lists and other
// elements (before and after the vertices), and malformed or truncated input.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>

#include "io_test_helpers.hpp"
#include "minemap/io/formats.hpp"

namespace minemap {
namespace {

using test::at_byte;
using test::at_line;
using test::expect_input_error;
using test::TempDir;
using test::write_text;

template <class T>
void put(std::string& out, T value) {
  out.append(reinterpret_cast<const char*>(&value), sizeof value);
}

TEST(Ply, RoundTripBinaryAndAscii) {
  TempDir dir;
  const auto points = test::random_cloud(1500, -20000.0f, 20000.0f, 31);
  for (const bool binary : {true, false}) {
    for (const LengthUnit unit : {LengthUnit::kMetre, LengthUnit::kCentimetre}) {
      const auto path = dir / "map.ply";
      io::write_ply(path, points, binary, unit);
      const std::string text = test::read_text(path);
      EXPECT_NE(text.find(binary ? "format binary_little_endian 1.0" : "format ascii 1.0"), std::string::npos);
      io::ReadSettings settings;
      settings.unit = unit;
      const Scan scan = io::read_ply(path, settings);
      EXPECT_EQ(scan.name, "map");
      ASSERT_EQ(scan.size(), points.size());
      for (std::size_t i = 0; i < points.size(); ++i) {
        const Eigen::Vector3d back = scan.file_point(i);
        for (int axis = 0; axis < 3; ++axis) {
          ASSERT_LE(std::abs(back[axis] - points[i][axis]), 3e-7 * std::max(1.0f, std::abs(points[i][axis])))
              << (binary ? "binary" : "ascii") << " point " << i;
        }
      }
    }
  }
}

/// A PLY with a face element before the vertices, lists and odd types inside the vertex element and
/// an edge element after it. The vertices are (i, -2i, 2i) for i = 0..3.
std::string mixed_ply(bool binary) {
  std::string out = "ply\r\nformat ";
  out += binary ? "binary_little_endian" : "ascii";
  out += " 1.0\r\ncomment made by a test\nobj_info nothing\n"
      "element face 2\nproperty list uchar int vertex_indices\nproperty uchar flags\n"
      "element marker 5\n"  // no properties: takes no data
      "element vertex 4\nproperty double x\nproperty uchar red\nproperty list uint8 float32 extra\n"
      "property float y\nproperty int z\nproperty short s\n"
      "element edge 1\nproperty int v1\nproperty int v2\nend_header\n";
  if (binary) {
    put<std::uint8_t>(out, 3);
    for (const std::int32_t index : {0, 1, 2}) put(out, index);
    put<std::uint8_t>(out, 7);
    put<std::uint8_t>(out, 0);  // an empty list
    put<std::uint8_t>(out, 9);
    for (int i = 0; i < 4; ++i) {
      put<double>(out, i);
      put<std::uint8_t>(out, 200);
      put<std::uint8_t>(out, static_cast<std::uint8_t>(i));  // list of i floats
      for (int k = 0; k < i; ++k) put<float>(out, 1.5f * k);
      put<float>(out, -2.0f * i);
      put<std::int32_t>(out, i * 2);  // z, an int property
      put<std::int16_t>(out, -1);
    }
    for (const std::int32_t index : {0, 1}) put(out, index);  // the edge after the vertices
  } else {
    out += "3 0 1 2 7\n0 9\n";
    for (int i = 0; i < 4; ++i) {
      std::vector<std::string> values{std::to_string(i), "200", std::to_string(i)};
      for (int k = 0; k < i; ++k) values.push_back(std::to_string(1.5 * k));
      for (const std::string& v : {std::to_string(-2.0 * i), std::to_string(i * 2), std::string("-1")}) values.push_back(v);
      for (const std::string& v : values) out.append(v).append(" ");
      out += '\n';
    }
    out += "0 1\n";
  }
  return out;
}

TEST(Ply, SkipsOtherPropertiesListsAndElements) {
  TempDir dir;
  for (const bool binary : {true, false}) {
    const auto path = dir / "mixed.ply";
    write_text(path, mixed_ply(binary));
    io::ReadSettings settings;
    settings.unit = LengthUnit::kCentimetre;
    const Scan scan = io::read_ply(path, settings);
    ASSERT_EQ(scan.size(), 4u) << (binary ? "binary" : "ascii");
    for (int i = 0; i < 4; ++i) {
      EXPECT_EQ(scan.points_cm[static_cast<std::size_t>(i)], Eigen::Vector3f(float(i), -2.0f * i, 2.0f * i))
          << (binary ? "binary" : "ascii") << " vertex " << i;
    }
  }
}

TEST(Ply, MalformedHeadersAreRefused) {
  TempDir dir;
  const auto path = dir / "bad.ply";
  const std::string good = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                           "property float z\nend_header\n1 2 3\n";
  write_text(path, good);
  ASSERT_EQ(io::read_ply(path).size(), 1u);
  const auto replaced = [&](const std::string& from, const std::string& to) { return test::replace_once(good, from, to); };
  struct Case {
    std::string text;
    long line;
    std::string message;
  };
  const std::vector<Case> cases{
      {replaced("ply\n", "plx\n"), 1, "not a PLY file"},
      {replaced("ascii", "binary_big_endian"), 2, "binary_big_endian"},
      {replaced("ascii", "utf8"), 2, "unknown PLY format"},
      {replaced("end_header\n1 2 3\n", ""), 6, "no end_header"},
      {replaced("format ascii 1.0\n", ""), 6, "no format line"},
      {replaced("property float z", "property float w"), 3, "no property z"},
      {replaced("property float x", "property list uchar float x"), 3, "x is a list"},
      {replaced("property float y", "property quad y"), 5, "unknown PLY property type"},
      {replaced("element vertex 1", "element vertex -1"), 3, "not a non-negative integer"},
      {replaced("element vertex 1", "element vertex 0"), 3, "no points"},
      {replaced("element vertex 1", "element point 1"), 7, "no vertex element"},
      {replaced("element vertex 1", "element vertex 1000000000000"), 3, "max_points"},
      {replaced("end_header", "what\nend_header"), 7, "unknown PLY header keyword"},
      {replaced("1 2 3\n", "1  2\n"), 8, "ends before property z"},
      {replaced("1 2 3\n", "1 2 3 4\n"), 8, "has 4 values"},
      {replaced("1 2 3\n", "1 inf 3\n"), 8, "not a finite number"},
      {replaced("1 2 3\n", "1 nan 3\n"), 3, "all 1 are NaN"},  // NaN vertices are dropped; none left
      {replaced("1 2 3\n", "\n\n\n\n\n\n"), 13, "file ends after 0 of 1 vertex lines"},
      {replaced("1 2 3\n", ""), 3, "cannot fit"},
  };
  for (const Case& c : cases) {
    write_text(path, c.text);
    expect_input_error([&] { io::read_ply(path); }, {at_line(path, c.line), c.message});
  }
}

TEST(Ply, TruncatedOrNonFiniteBinaryDataNamesTheByte) {
  TempDir dir;
  const auto path = dir / "bin.ply";
  const std::string header = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                             "property float y\nproperty float z\nend_header\n";
  std::string data;
  for (float v : {1.f, 2.f, 3.f, 4.f, std::numeric_limits<float>::infinity(), 6.f, 7.f, 8.f, 9.f}) put(data, v);
  write_text(path, header + data);
  expect_input_error([&] { io::read_ply(path); }, {at_byte(path, header.size() + 16), "vertex 1", "y is not finite"});
  write_text(path, header + data.substr(0, 30));
  expect_input_error([&] { io::read_ply(path); }, {at_byte(path, header.size()), "file ends inside the vertices"});
  // An absurd vertex count with no max_points limit is refused from the file size, not allocated.
  const std::string huge_header = test::replace_once(header, "vertex 3", "vertex 1000000000000");
  write_text(path, huge_header + data);
  io::ReadSettings unlimited;
  unlimited.max_points = std::numeric_limits<std::uint64_t>::max();
  expect_input_error([&] { io::read_ply(path, unlimited); }, {at_byte(path, huge_header.size())});
  // A list that claims more items than the file holds, in an element before the vertices.
  const std::string list_header = "ply\nformat binary_little_endian 1.0\nelement face 1\n"
                                  "property list uint int idx\nelement vertex 1\nproperty float x\n"
                                  "property float y\nproperty float z\nend_header\n";
  std::string list_data;
  put<std::uint32_t>(list_data, 4000000000u);
  write_text(path, list_header + list_data);
  expect_input_error([&] { io::read_ply(path); }, {at_byte(path, list_header.size() + 4), "face list idx"});
}

}  // namespace
}  // namespace minemap
