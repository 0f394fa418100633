// KITTI .bin: 4- and 3-float round trips, and the byte offsets of truncated or non-finite data.
#include <gtest/gtest.h>

#include <limits>

#include "io_test_helpers.hpp"
#include "minemap/io/formats.hpp"

namespace minemap {
namespace {

using test::at_byte;
using test::expect_input_error;
using test::TempDir;
using test::write_text;

std::string floats_to_bytes(std::initializer_list<float> values) {
  std::string out;
  for (const float v : values) out.append(reinterpret_cast<const char*>(&v), sizeof v);
  return out;
}

TEST(KittiBin, RoundTripWithAndWithoutIntensity) {
  TempDir dir;
  const Scan scan = test::random_scan(1200, -8000.0f, 8000.0f, 41, "000003");
  for (const int floats : {4, 3}) {
    const auto path = dir / "000003.bin";
    io::write_kitti_bin(path, scan, floats);
    EXPECT_EQ(std::filesystem::file_size(path), scan.size() * 4 * static_cast<std::size_t>(floats));
    const Scan back = io::read_kitti_bin(path, {}, floats);
    EXPECT_EQ(back.name, "000003");
    ASSERT_EQ(back.size(), scan.size());
    for (std::size_t i = 0; i < scan.size(); ++i) {
      for (int axis = 0; axis < 3; ++axis) {
        ASSERT_LE(std::abs(back.points_cm[i][axis] - scan.points_cm[i][axis]),
                  3e-7f * std::max(1.0f, std::abs(scan.points_cm[i][axis])))
            << floats << " floats, point " << i;
      }
    }
  }
}

TEST(KittiBin, ReadsKnownValuesInMetresAndIgnoresIntensity) {
  TempDir dir;
  const auto path = dir / "000000.bin";
  write_text(path, floats_to_bytes({1.0f, -2.5f, 0.25f, 0.7f, 10.0f, 20.0f, 30.0f, std::numeric_limits<float>::quiet_NaN()}));
  const Scan scan = io::read_kitti_bin(path);
  ASSERT_EQ(scan.size(), 2u);
  EXPECT_EQ(scan.points_cm[0], Eigen::Vector3f(100.0f, -250.0f, 25.0f));
  EXPECT_EQ(scan.points_cm[1], Eigen::Vector3f(1000.0f, 2000.0f, 3000.0f));
  io::ReadSettings cm;
  cm.unit = LengthUnit::kCentimetre;
  EXPECT_EQ(io::read_kitti_bin(path, cm).points_cm[1], Eigen::Vector3f(10.0f, 20.0f, 30.0f));
}

TEST(KittiBin, BadFilesNameTheByte) {
  TempDir dir;
  const auto path = dir / "000001.bin";
  write_text(path, floats_to_bytes({1, 2, 3, 4, 5, 6, 7, 8}) + "abc");
  expect_input_error([&] { io::read_kitti_bin(path); }, {at_byte(path, 32), "not a multiple of 16"});
  write_text(path, floats_to_bytes({1, 2, 3, 4, 5, 6, 7}));
  expect_input_error([&] { io::read_kitti_bin(path, {}, 3); }, {at_byte(path, 24), "not a multiple of 12"});
  write_text(path, floats_to_bytes({1, 2, 3, 4, 5, -std::numeric_limits<float>::infinity(), 7, 8}));
  expect_input_error([&] { io::read_kitti_bin(path); }, {at_byte(path, 20), "point 1", "y is not finite"});
  // A NaN point is dropped (a no-return marker); a file of NaN points only is an error.
  const float nan = std::numeric_limits<float>::quiet_NaN();
  write_text(path, floats_to_bytes({1, 2, 3, 4, 5, 6, nan, 8}));
  EXPECT_EQ(io::read_kitti_bin(path).size(), 1u);
  write_text(path, floats_to_bytes({nan, 2, 3, 4, 5, 6, nan, 8}));
  expect_input_error([&] { io::read_kitti_bin(path); }, {at_byte(path, 0), "all 2 are NaN"});
  write_text(path, "");
  expect_input_error([&] { io::read_kitti_bin(path); }, {at_byte(path, 0), "no points"});
  write_text(path, floats_to_bytes({1, 2, 3, 4, 5, 6, 7, 8}));
  io::ReadSettings one_point;
  one_point.max_points = 1;
  expect_input_error([&] { io::read_kitti_bin(path, one_point); }, {path.string(), "max_points"});
  EXPECT_THROW(io::read_kitti_bin(path, {}, 5), std::invalid_argument);  // a caller's bug, not bad input
}

}  // namespace
}  // namespace minemap
