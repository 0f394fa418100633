// PCD v0.7: round trips in every encoding, files with other fields and F8 coordinates written by an
// independent test-side encoder (with its own literal-only LZF), PCL's NaN convention, and every
// malformed-header and truncated-data case.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <chrono>
#include <cmath>
#include <cstdio>
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

/// The process's peak resident memory so far (kB).
long peak_rss_kb() {
  rusage usage{};
  ::getrusage(RUSAGE_SELF, &usage);
  return usage.ru_maxrss;
}

// ---- an independent PCD encoder for test inputs ------------------------------------------------

struct TestField {
  std::string name;
  char type;  // I U F
  int size;
  int count;
};

/// LZF in its simplest legal form: literal runs of at most 32 bytes (control byte = length - 1).
std::string lzf_literal_runs(const std::string& raw) {
  std::string out;
  for (std::size_t i = 0; i < raw.size(); i += 32) {
    const std::size_t n = std::min<std::size_t>(32, raw.size() - i);
    out += static_cast<char>(n - 1);
    out.append(raw, i, n);
  }
  return out;
}

void append_value(std::string& out, const TestField& field, double value) {
  const auto put = [&](auto typed) { out.append(reinterpret_cast<const char*>(&typed), sizeof typed); };
  if (field.type == 'F') {
    field.size == 4 ? put(static_cast<float>(value)) : put(value);
  } else if (field.type == 'U') {
    if (field.size == 1) put(static_cast<std::uint8_t>(value));
    if (field.size == 2) put(static_cast<std::uint16_t>(value));
    if (field.size == 4) put(static_cast<std::uint32_t>(value));
    if (field.size == 8) put(static_cast<std::uint64_t>(value));
  } else {
    if (field.size == 1) put(static_cast<std::int8_t>(value));
    if (field.size == 2) put(static_cast<std::int16_t>(value));
    if (field.size == 4) put(static_cast<std::int32_t>(value));
    if (field.size == 8) put(static_cast<std::int64_t>(value));
  }
}

/// values[point][field][k]
using PointValues = std::vector<std::vector<std::vector<double>>>;

std::string pcd_header(const std::vector<TestField>& fields, std::size_t width, std::size_t height,
                       const std::string& data, const std::string& viewpoint = "0 0 0 1 0 0 0") {
  std::string fields_line = "FIELDS", size_line = "SIZE", type_line = "TYPE", count_line = "COUNT";
  for (const auto& f : fields) {
    fields_line.append(" ").append(f.name);
    size_line.append(" ").append(std::to_string(f.size));
    type_line.append(" ").append(1, f.type);
    count_line.append(" ").append(std::to_string(f.count));
  }
  std::string header = "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n";
  for (const std::string& line : {fields_line, size_line, type_line, count_line, "WIDTH " + std::to_string(width),
                                  "HEIGHT " + std::to_string(height), "VIEWPOINT " + viewpoint,
                                  "POINTS " + std::to_string(width * height), "DATA " + data}) {
    header.append(line).append("\n");
  }
  return header;
}

std::string encode_pcd(const std::vector<TestField>& fields, const PointValues& points, const std::string& data,
                       std::size_t height = 1) {
  std::string out = pcd_header(fields, points.size() / height, height, data);
  if (data == "ascii") {
    for (const auto& point : points) {
      std::string line;
      for (const auto& values : point) {
        for (const double v : values) {
          char buffer[40];
          std::snprintf(buffer, sizeof buffer, "%.17g ", v);
          line += buffer;
        }
      }
      out += line + "\n";
    }
  } else if (data == "binary") {
    for (const auto& point : points) {
      for (std::size_t f = 0; f < fields.size(); ++f) {
        for (const double v : point[f]) append_value(out, fields[f], v);
      }
    }
  } else {  // binary_compressed: structure of arrays
    std::string raw;
    for (std::size_t f = 0; f < fields.size(); ++f) {
      for (const auto& point : points) {
        for (const double v : point[f]) append_value(raw, fields[f], v);
      }
    }
    const std::string block = lzf_literal_runs(raw);
    const auto compressed = static_cast<std::uint32_t>(block.size());
    const auto uncompressed = static_cast<std::uint32_t>(raw.size());
    out.append(reinterpret_cast<const char*>(&compressed), 4);
    out.append(reinterpret_cast<const char*>(&uncompressed), 4);
    out += block;
  }
  return out;
}

const std::vector<TestField> kXyz{{"x", 'F', 4, 1}, {"y", 'F', 4, 1}, {"z", 'F', 4, 1}};

PointValues xyz_points(const std::vector<Eigen::Vector3d>& xyz) {
  PointValues points;
  for (const auto& p : xyz) points.push_back({{p.x()}, {p.y()}, {p.z()}});
  return points;
}

const char* const kEncodings[] = {"ascii", "binary", "binary_compressed"};

void expect_near_float(const Eigen::Vector3f& a, const Eigen::Vector3f& b, const std::string& what) {
  for (int i = 0; i < 3; ++i) {
    EXPECT_LE(std::abs(a[i] - b[i]), 3e-7f * std::max(1.0f, std::abs(b[i]))) << what << " axis " << i;
  }
}

// ---- round trips ---------------------------------------------------------------------------------

class PcdRoundTrip : public ::testing::TestWithParam<std::tuple<io::PcdEncoding, LengthUnit>> {};

TEST_P(PcdRoundTrip, PointsAndViewpointSurvive) {
  const auto [encoding, unit] = GetParam();
  TempDir dir;
  Scan scan = test::random_scan(2000, -5000.0f, 5000.0f, 21, "cloud");
  EulerPose euler;
  euler.position_cm = Eigen::Vector3d(123.4, -56.7, 8.9);
  euler.angles_deg = Eigen::Vector3d(3, -40, 170);
  scan.pose_cm = euler_to_pose(euler);
  const auto path = dir / "cloud.pcd";
  io::write_pcd(path, scan, encoding, unit);
  io::ReadSettings settings;
  settings.unit = unit;
  const Scan back = io::read_pcd(path, settings);
  EXPECT_EQ(back.name, "cloud");
  ASSERT_EQ(back.size(), scan.size());
  for (std::size_t i = 0; i < scan.size(); ++i) {
    if (unit == LengthUnit::kCentimetre) {
      ASSERT_EQ(back.points_cm[i], scan.points_cm[i]) << "point " << i;
    } else {
      expect_near_float(back.points_cm[i], scan.points_cm[i], "point " + std::to_string(i));
    }
  }
  EXPECT_LT((back.pose_cm - scan.pose_cm).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_FALSE(back.has_slices());
}

INSTANTIATE_TEST_SUITE_P(AllEncodings, PcdRoundTrip,
                         ::testing::Combine(::testing::Values(io::PcdEncoding::kAscii, io::PcdEncoding::kBinary,
                                                              io::PcdEncoding::kBinaryCompressed),
                                            ::testing::Values(LengthUnit::kMetre, LengthUnit::kCentimetre)));

TEST(Pcd, WriterProducesTheDeclaredEncoding) {
  TempDir dir;
  // A repetitive cloud compresses; if the writer skipped LZF the file would not shrink.
  Scan scan;
  for (int i = 0; i < 3000; ++i) scan.points_cm.emplace_back(static_cast<float>(i % 10), 5.0f, -1.0f);
  io::write_pcd(dir / "b.pcd", scan, io::PcdEncoding::kBinary);
  io::write_pcd(dir / "c.pcd", scan, io::PcdEncoding::kBinaryCompressed);
  const std::string binary = test::read_text(dir / "b.pcd");
  const std::string compressed = test::read_text(dir / "c.pcd");
  EXPECT_NE(binary.find("\nDATA binary\n"), std::string::npos);
  EXPECT_NE(compressed.find("\nDATA binary_compressed\n"), std::string::npos);
  EXPECT_NE(binary.find("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n"), std::string::npos);
  EXPECT_LT(compressed.size() * 4, binary.size());
  EXPECT_EQ(io::read_pcd(dir / "c.pcd").size(), 3000u);
}

TEST(Pcd, ReadsOtherFieldsAndDoubleCoordinatesInEveryEncoding) {
  TempDir dir;
  const std::vector<TestField> fields{{"intensity", 'F', 4, 1}, {"x", 'F', 8, 1}, {"rgb", 'U', 4, 1},
                                      {"y", 'F', 8, 1},         {"normal", 'F', 4, 3}, {"z", 'F', 4, 1},
                                      {"label", 'U', 2, 1},     {"t", 'I', 1, 2}};
  PointValues points;
  std::vector<Eigen::Vector3d> xyz;
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d p(0.125 * i - 3.0, 100.0 - 0.5 * i, 0.25 * (i % 7));
    xyz.push_back(p);
    points.push_back({{1000.0 + i}, {p.x()}, {double(0xFF00FF)}, {p.y()}, {0.0, 0.6, 0.8}, {p.z()}, {double(i)}, {-1.0, 1.0}});
  }
  for (const char* data : kEncodings) {
    const auto path = dir / (std::string(data) + ".pcd");
    write_text(path, encode_pcd(fields, points, data));
    const Scan scan = io::read_pcd(path);
    ASSERT_EQ(scan.size(), xyz.size()) << data;
    for (std::size_t i = 0; i < xyz.size(); ++i) {
      EXPECT_EQ(scan.file_point(i).cast<float>(), (xyz[i] * 100.0).cast<float>()) << data << " point " << i;
    }
  }
}

TEST(Pcd, NaNPointsAreDroppedAsPclNoReturnMarkers) {
  TempDir dir;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<Eigen::Vector3d> xyz{{1, 2, 3}, {nan, nan, nan}, {4, 5, 6}, {7, 8, 9}, {nan, 1, 1}, {0.5, 0.25, 0}};
  for (const char* data : kEncodings) {
    const auto path = dir / (std::string(data) + ".pcd");
    write_text(path, encode_pcd(kXyz, xyz_points(xyz), data, /*height=*/2));  // organized 3 x 2
    const Scan scan = io::read_pcd(path);
    ASSERT_EQ(scan.size(), 4u) << data;
    EXPECT_EQ(scan.points_cm[1], Eigen::Vector3f(400, 500, 600)) << data;
    EXPECT_EQ(scan.points_cm[3], Eigen::Vector3f(50, 25, 0)) << data;
  }
  const auto all_nan = dir / "all_nan.pcd";
  write_text(all_nan, encode_pcd(kXyz, xyz_points({{nan, nan, nan}}), "binary"));
  expect_input_error([&] { io::read_pcd(all_nan); }, {all_nan.string(), "no points"});
}

TEST(Pcd, InfiniteCoordinatesAreErrorsAtTheirByteOrLine) {
  TempDir dir;
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<Eigen::Vector3d> xyz{{1, 2, 3}, {4, inf, 6}, {7, 8, 9}};
  const std::string header = pcd_header(kXyz, 3, 1, "binary");
  const auto binary = dir / "binary.pcd";
  write_text(binary, encode_pcd(kXyz, xyz_points(xyz), "binary"));
  expect_input_error([&] { io::read_pcd(binary); }, {at_byte(binary, header.size() + 12 + 4), "point 1", "y is infinite"});
  const auto ascii = dir / "ascii.pcd";
  write_text(ascii, encode_pcd(kXyz, xyz_points(xyz), "ascii"));
  expect_input_error([&] { io::read_pcd(ascii); }, {at_line(ascii, 13), "infinite"});
  const auto compressed = dir / "compressed.pcd";
  write_text(compressed, encode_pcd(kXyz, xyz_points(xyz), "binary_compressed"));
  expect_input_error([&] { io::read_pcd(compressed); }, {compressed.string() + "@byte", "point 1", "infinite"});
}

TEST(Pcd, AbsurdPointCountsAreRefusedBeforeAllocating) {
  TempDir dir;
  const auto path = dir / "huge.pcd";
  for (const char* data : kEncodings) {
    std::string text = pcd_header(kXyz, 1'000'000'000'000, 1, data);
    text += std::string(64, '\1');
    write_text(path, text);
    const long rss_before_kb = peak_rss_kb();
    // Default max_points (50 million) refuses from the header alone, at the POINTS line.
    expect_input_error([&] { io::read_pcd(path); }, {at_line(path, 10), "max_points"});
    // With no max_points limit the real file size still refuses it, without a 12 TB allocation.
    io::ReadSettings unlimited;
    unlimited.max_points = std::numeric_limits<std::uint64_t>::max();
    expect_input_error([&] { io::read_pcd(path, unlimited); }, {path.string()});
    // Nothing the size of the claim was allocated (the peak would have jumped by gigabytes).
    EXPECT_LT(peak_rss_kb() - rss_before_kb, 100'000) << data;
  }
}

TEST(Pcd, MalformedHeadersNameTheirLine) {
  TempDir dir;
  const auto path = dir / "bad.pcd";
  const std::string good =
      "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n"
      "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n1 2 3\n";
  write_text(path, good);
  ASSERT_EQ(io::read_pcd(path).points_cm[0], Eigen::Vector3f(100, 200, 300));
  const auto replaced = [&](const std::string& from, const std::string& to) { return test::replace_once(good, from, to); };
  struct Case {
    std::string text;
    long line;
    std::string message;
  };
  const std::vector<Case> cases{
      {good.substr(0, good.find("DATA")), 9, "no DATA"},  // header only
      {replaced("DATA ascii", "DATA binary_gzip"), 10, "unknown DATA type"},
      {replaced("SIZE 4 4 4", "SIZE 4 4"), 10, "SIZE has 2"},
      {replaced("COUNT 1 1 1", "COUNT 1 1 1 1"), 10, "COUNT has 4"},
      {replaced("WIDTH 1", "WIDTH -5"), 6, "not a non-negative integer"},
      {test::replace_once(replaced("WIDTH 1", "WIDTH 0"), "POINTS 1", "POINTS 0"), 9, "no points"},
      {replaced("POINTS 1", "POINTS 2"), 9, "differs from WIDTH x HEIGHT"},
      {replaced("TYPE F F F", "TYPE U F F"), 10, "field x must be TYPE F"},
      {replaced("SIZE 4 4 4", "SIZE 3 4 4"), 10, "invalid for TYPE F"},
      {replaced("TYPE F F F", "TYPE F F Q"), 10, "is not I, U or F"},
      {replaced("COUNT 1 1 1", "COUNT 1 1 0"), 10, "COUNT 0"},
      {replaced("FIELDS x y z", "FIELDS x y w"), 10, "no field z"},
      {replaced("HEIGHT 1", "HEIGHT 1\nWIDTH 1"), 8, "appears twice"},
      {replaced("HEIGHT 1", "HEIGHT 1\nFOO 1"), 8, "unknown header keyword"},
      {replaced("VIEWPOINT 0 0 0 1 0 0 0", "VIEWPOINT 0 0 0 2 0 0 0"), 8, "quaternion"},
      {replaced("VIEWPOINT 0 0 0 1 0 0 0", "VIEWPOINT 0 0 0 1 0 0"), 8, "expects 7"},
      {replaced("1 2 3\n", "1  2\n"), 11, "expected 3 values"},
      {replaced("1 2 3\n", "1 2 3\n4 5 6\n"), 12, "more data lines"},
      {replaced("1 2 3\n", "\n\n\n\n\n\n"), 16, "only 0 of POINTS 1"},
      {replaced("1 2 3\n", "\n"), 10, "cannot fit"},  // fewer bytes than 3 values need
      {replaced("1 2 3\n", "1 zwei 3\n"), 11, "'zwei'"},
  };
  for (const Case& c : cases) {
    write_text(path, c.text);
    expect_input_error([&] { io::read_pcd(path); }, {at_line(path, c.line), c.message});
  }
  write_text(path, "");
  expect_input_error([&] { io::read_pcd(path); }, {path.string(), "empty file"});
}

TEST(Pcd, TruncatedAndCorruptBinaryDataNameTheByte) {
  TempDir dir;
  const Scan scan = test::random_scan(300, -1000.0f, 1000.0f, 5);
  const std::string header_end = "DATA binary\n";

  const auto binary = dir / "binary.pcd";
  io::write_pcd(binary, scan, io::PcdEncoding::kBinary);
  std::string bytes = test::read_text(binary);
  const std::size_t data_offset = bytes.find(header_end) + header_end.size();
  write_text(binary, bytes.substr(0, bytes.size() - 5));
  expect_input_error([&] { io::read_pcd(binary); }, {at_byte(binary, bytes.size() - 5), "truncated"});
  write_text(binary, bytes.substr(0, data_offset));  // header only, DATA line present
  expect_input_error([&] { io::read_pcd(binary); }, {at_byte(binary, data_offset), "truncated"});

  const auto compressed = dir / "compressed.pcd";
  io::write_pcd(compressed, scan, io::PcdEncoding::kBinaryCompressed);
  bytes = test::read_text(compressed);
  const std::string compressed_end = "DATA binary_compressed\n";
  const std::size_t block = bytes.find(compressed_end) + compressed_end.size();
  std::uint32_t compressed_size = 0;
  std::memcpy(&compressed_size, bytes.data() + block, 4);

  std::string wrong_size = bytes;
  const std::uint32_t other = 999;
  std::memcpy(wrong_size.data() + block + 4, &other, 4);
  write_text(compressed, wrong_size);
  expect_input_error([&] { io::read_pcd(compressed); }, {at_byte(compressed, block + 4), "uncompressed size 999"});

  write_text(compressed, bytes.substr(0, bytes.size() - 10));
  expect_input_error([&] { io::read_pcd(compressed); }, {at_byte(compressed, block), "truncated"});

  write_text(compressed, bytes.substr(0, block + 6));
  expect_input_error([&] { io::read_pcd(compressed); }, {at_byte(compressed, block), "no block sizes"});

  std::string garbage = bytes;
  for (std::size_t i = block + 8; i < garbage.size(); ++i) garbage[i] = static_cast<char>(0xE0);
  write_text(compressed, garbage);
  expect_input_error([&] { io::read_pcd(compressed); }, {at_byte(compressed, block + 8), "LZF block is corrupt"});
}

TEST(Pcd, ViewpointBecomesThePose) {
  TempDir dir;
  const auto path = dir / "vp.pcd";
  const double h = std::sqrt(0.5);  // 90 deg about z: qw = qz = sqrt(1/2)
  std::string text = pcd_header(kXyz, 1, 1, "ascii", "1 2 3 " + std::to_string(h) + " 0 0 " + std::to_string(h));
  write_text(path, text + "1 0 0\n");
  const Scan scan = io::read_pcd(path);
  EXPECT_TRUE(scan.pose_cm.col(3).head<3>().isApprox(Eigen::Vector3d(100, 200, 300)));
  Eigen::Matrix3d rz90;
  rz90 << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  EXPECT_LT((scan.pose_cm.topLeftCorner(3, 3) - rz90).cwiseAbs().maxCoeff(), 1e-6);
}

TEST(Pcd, FarCloudIsStoredAroundALocalOrigin) {
  TempDir dir;
  Scan scan = test::random_scan(1000, -500.0f, 500.0f, 9);
  scan.local_origin_cm = Eigen::Vector3d(500000.0, -300000.0, 10000.0);  // 5 km out
  const auto path = dir / "far.pcd";
  io::write_pcd(path, scan, io::PcdEncoding::kBinary);
  const Scan back = io::read_pcd(path);
  EXPECT_GT(back.local_origin_cm.norm(), 100000.0);
  for (std::size_t i = 0; i < scan.size(); ++i) {
    // The file holds float metres: at 5 km that is a 0.05 cm step, kept through the reading.
    ASSERT_LT((back.file_point(i) - scan.file_point(i)).norm(), 0.1) << "point " << i;
  }
}

}  // namespace
}  // namespace minemap
