// 3DTK uos files: .3d points (3DTK's parsing rules, slice markers, exact round trips), .pose
// (Euler conventions checked against an independent Rx*Ry*Rz) and .frames (column-major layout).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <clocale>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <algorithm>
#include <charconv>
#include <cstring>
#include <sstream>

#include "io_test_helpers.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/io/slice_detection.hpp"
#include "minemap/io/text_reader.hpp"
#include "minemap/sim/mine_simulator.hpp"

namespace minemap {
namespace {

using test::at_line;
using test::expect_input_error;
using test::TempDir;
using test::write_text;

constexpr double kDegToRad = std::numbers::pi / 180.0;

/// R = Rx(a) * Ry(b) * Rz(c) built from Eigen's axis rotations, independent of minemap's formulas.
Eigen::Matrix3d rx_ry_rz(const Eigen::Vector3d& angles_deg) {
  return (Eigen::AngleAxisd(angles_deg.x() * kDegToRad, Eigen::Vector3d::UnitX()) *
          Eigen::AngleAxisd(angles_deg.y() * kDegToRad, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(angles_deg.z() * kDegToRad, Eigen::Vector3d::UnitZ()))
      .toRotationMatrix();
}

std::vector<std::string> tokens_of(const std::string& text) {
  std::istringstream in(text);
  std::vector<std::string> tokens;
  for (std::string token; in >> token;) tokens.push_back(token);
  return tokens;
}

// ---- .3d points ---------------------------------------------------------------------------------

// parse_double's fast path (Clinger's) against the oracle, std::from_chars: the same value, bit
// for bit, and the same verdict, for every number a scan file may hold and the edges around it.
TEST(TextNumbers, TheFastPathReadsEveryDecimalAsFromCharsDoes) {
  const auto oracle = [](std::string_view token, double& value) {
    if (!token.empty() && token.front() == '+') token.remove_prefix(1);
    const auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), value);
    return error == std::errc() && end == token.data() + token.size();
  };
  const auto same = [&](const std::string& token) {
    double fast = 0.0, slow = 0.0;
    const bool ok = io::detail::parse_double(token, fast) == io::detail::NumberStatus::kOk;
    const bool ok_oracle = oracle(token, slow) && !(token.size() > 1 && token[0] == '+' && (token[1] == '-' || token[1] == '+'));
    ASSERT_EQ(ok, ok_oracle) << token;
    if (ok) {
      ASSERT_EQ(std::memcmp(&fast, &slow, sizeof fast), 0) << token << ": " << fast << " against " << slow;
    }
  };
  for (const char* token : {"0", "-0", "0.0", "-0.0", "1", "-1", "192.39798", "-5.890489e-15", "1.0202626e-14", "1e22",
                            "1e23", "9007199254740992", "9007199254740993", "9007199254740993e-5", "1234567890123456789",
                            "12345678901234567890", "0.1", "0.3", "2.5e-22", "2.5e-23", "1E5", "1e+5", "1e-0", "5.", ".5",
                            "-.5", "1e", "1e+", "e5", "-", "+1", "+-1", "inf", "nan", "1.5x", "1..5", "--1", "1e400",
                            "0.000000000000000000001", "1e99999999999"}) {
    same(token);
  }
  std::mt19937_64 rng(29);
  for (int n = 0; n < 200000; ++n) {
    std::string token = rng() % 2 ? "-" : "";
    const int whole = static_cast<int>(rng() % 12), fraction = static_cast<int>(rng() % 14);
    for (int k = 0; k < std::max(whole, 1); ++k) token += static_cast<char>('0' + rng() % 10);
    if (fraction > 0) token += '.';
    for (int k = 0; k < fraction; ++k) token += static_cast<char>('0' + rng() % 10);
    if (rng() % 3 == 0) {
      token += 'e';
      token += std::to_string(static_cast<int>(rng() % 61) - 30);
    }
    same(token);
  }
  for (int n = 0; n < 100000; ++n) {  // floats printed as the writers print them (shortest round trip)
    const double v = std::ldexp(static_cast<double>(rng() % (1u << 24)), static_cast<int>(rng() % 80) - 60);
    char text[64];
    std::snprintf(text, sizeof text, rng() % 2 ? "%.8g" : "%.17g", rng() % 2 ? v : -v);
    same(text);
  }
}

TEST(UosPoints, RoundTripIsBitExactAndKeepsSlices) {
  TempDir dir;
  Scan scan = test::random_scan(1000, -5000.0f, 5000.0f, 7);
  scan.slice_offsets = {0, 100, 100, 350, 999, 1000};  // includes an empty slice and a 1-point slice
  const auto path = dir / "scan007.3d";
  io::write_uos_points(path, scan);
  const Scan back = io::read_uos_points(path);
  EXPECT_EQ(back.name, "scan007");
  ASSERT_EQ(back.size(), scan.size());
  for (std::size_t i = 0; i < scan.size(); ++i) ASSERT_EQ(back.points_cm[i], scan.points_cm[i]) << "point " << i;
  EXPECT_EQ(back.slice_offsets, scan.slice_offsets);
  EXPECT_TRUE(back.local_origin_cm.isZero());
}

TEST(UosPoints, RoundTripInMetresIsExact) {
  TempDir dir;
  const Scan scan = test::random_scan(2000, -8000.0f, 8000.0f, 11);
  const auto path = dir / "scan000.3d";
  io::write_uos_points(path, scan, LengthUnit::kMetre);
  io::ReadSettings settings;
  settings.unit = LengthUnit::kMetre;
  const Scan back = io::read_uos_points(path, settings);
  ASSERT_EQ(back.size(), scan.size());
  for (std::size_t i = 0; i < scan.size(); ++i) ASSERT_EQ(back.points_cm[i], scan.points_cm[i]) << "point " << i;
  EXPECT_FALSE(back.has_slices());
}

TEST(UosPoints, FarCloudKeepsCentimetreResolution) {
  TempDir dir;
  Scan scan = test::random_scan(500, -300.0f, 300.0f, 3);
  scan.local_origin_cm = Eigen::Vector3d(1.0e7, -2.0e7, 3.0e6);  // 100 km out: float alone has 1-2 m steps
  const auto path = dir / "scan001.3d";
  io::write_uos_points(path, scan);
  const Scan back = io::read_uos_points(path);
  ASSERT_EQ(back.size(), scan.size());
  EXPECT_GT(back.local_origin_cm.norm(), 1.0e6);
  for (std::size_t i = 0; i < scan.size(); ++i) {
    ASSERT_LT((back.file_point(i) - scan.file_point(i)).norm(), 1e-3) << "point " << i;
  }
}

TEST(UosPoints, Reads3dtkStyleInputWithHeaderCommentsAndReflectance) {
  TempDir dir;
  const auto path = dir / "scan000.3d";
  write_text(path,
             "81360 points\r\n"          // header: 2 tokens, tolerated
             "w x b\r\n"                  // header: not numbers, tolerated
             "# a comment\r\n"
             "\r\n"
             "1.5\t-2 3e2 17\r\n"         // tabs, exponent, reflectance column
             "  +4 5 6 0.5 # trailing comment\r\n"
             "\n"
             "-7.25 8 9 1");             // no final newline
  const Scan scan = io::read_uos_points(path);
  ASSERT_EQ(scan.size(), 3u);
  EXPECT_EQ(scan.points_cm[0], Eigen::Vector3f(1.5f, -2.0f, 300.0f));
  EXPECT_EQ(scan.points_cm[1], Eigen::Vector3f(4.0f, 5.0f, 6.0f));
  EXPECT_EQ(scan.points_cm[2], Eigen::Vector3f(-7.25f, 8.0f, 9.0f));
  EXPECT_FALSE(scan.has_slices());
}

TEST(UosPoints, TenHeaderLinesAreToleratedButNotEleven) {
  TempDir dir;
  std::string ten_bad;
  for (int i = 0; i < 10; ++i) ten_bad += "header line " + std::to_string(i) + "\n";
  const auto ok_path = dir / "ok.3d";
  write_text(ok_path, ten_bad + "1 2 3\n");
  EXPECT_EQ(io::read_uos_points(ok_path).size(), 1u);

  const auto bad_path = dir / "bad.3d";
  write_text(bad_path, ten_bad + "# comments do not count\none too many\n1 2 3\n");
  expect_input_error([&] { io::read_uos_points(bad_path); }, {at_line(bad_path, 12), "more than 10"});
}

TEST(UosPoints, BadLineAfterTheFirstPointNamesItsLine) {
  TempDir dir;
  const auto path = dir / "scan000.3d";
  write_text(path, "# x y z\n1 2 3\n4 5 6\n7 8 x9\n");
  expect_input_error([&] { io::read_uos_points(path); }, {at_line(path, 4), "'x9' is not a number"});
  write_text(path, "1 2 3\n4 5\n");
  expect_input_error([&] { io::read_uos_points(path); }, {at_line(path, 2), "found 2"});
  write_text(path, "1 2 3\n4 5 6 7 8\n");
  expect_input_error([&] { io::read_uos_points(path); }, {at_line(path, 2), "found 5"});
}

TEST(UosPoints, ColumnCountMustStayTheSame) {
  TempDir dir;
  const auto path = dir / "scan000.3d";
  write_text(path, "1 2 3\n1 2 3\n1 2 3 4\n");
  expect_input_error([&] { io::read_uos_points(path); }, {at_line(path, 3), "expected 3 values as on line 1"});
}

TEST(UosPoints, InfiniteOrOutOfRangeCoordinatesAreRefused) {
  TempDir dir;
  const auto path = dir / "scan000.3d";
  for (const std::string bad : {"inf", "-inf", "1e999", "1e39"}) {
    write_text(path, "1 2 3\n4 " + bad + " 6\n");
    expect_input_error([&] { io::read_uos_points(path); }, {at_line(path, 2)});
  }
  // Even as the very first line, a non-finite point is an error, not a tolerated header.
  write_text(path, "inf 0 0\n1 2 3\n");
  expect_input_error([&] { io::read_uos_points(path); }, {at_line(path, 1), "not finite"});
}

TEST(UosPoints, NaNPointsAreDroppedAndCounted) {
  TempDir dir;
  const auto path = dir / "scan000.3d";
  // NaN in any of x y z drops the point, also as the very first line (not a tolerated header).
  write_text(path, "nan 0 0\n1 2 3\n4 NaN 6\n7 8 9\n");
  io::ReadReport report;
  io::ReadSettings settings;
  settings.report = &report;
  const Scan scan = io::read_uos_points(path, settings);
  ASSERT_EQ(scan.size(), 2u);
  EXPECT_EQ(scan.points_cm[1], Eigen::Vector3f(7, 8, 9));
  EXPECT_EQ(report.nan_points_dropped, 2u);
  write_text(path, "nan 0 0\n1 nan 3\n");
  expect_input_error([&] { io::read_uos_points(path); }, {at_line(path, 2), "all 2 are NaN"});
}

TEST(UosPoints, EmptyMissingAndCommentOnlyFilesAreRefused) {
  TempDir dir;
  const auto empty = dir / "empty.3d";
  write_text(empty, "");
  expect_input_error([&] { io::read_uos_points(empty); }, {empty.string(), "no points"});
  const auto comments = dir / "comments.3d";
  write_text(comments, "# nothing\n\n# slice 0\n");
  expect_input_error([&] { io::read_uos_points(comments); }, {at_line(comments, 3), "no points"});
  const auto missing = dir / "missing.3d";
  expect_input_error([&] { io::read_uos_points(missing); }, {missing.string(), "cannot open"});
  expect_input_error([&] { io::read_uos_points(dir.path()); }, {dir.path().string(), "folder"});
}

// Scan files are read into a buffer each thread reuses: a smaller file after a larger one, and a
// file after a failed read, must come back with their own bytes only.
TEST(UosPoints, ReadsInTurnKeepNothingOfTheScanBefore) {
  TempDir dir;
  const Scan large = test::random_scan(5000, -5000.0f, 5000.0f, 3);
  const Scan small = test::random_scan(40, -50.0f, 50.0f, 4);
  io::write_uos_points(dir / "scan000.3d", large);
  io::write_uos_points(dir / "scan001.3d", small);
  write_text(dir / "scan002.3d", "1 2 3\n4 5 x\n");
  EXPECT_EQ(io::read_uos_points(dir / "scan000.3d").size(), large.size());
  const Scan back = io::read_uos_points(dir / "scan001.3d");
  ASSERT_EQ(back.size(), small.size());
  for (std::size_t i = 0; i < small.size(); ++i) ASSERT_EQ(back.points_cm[i], small.points_cm[i]) << "point " << i;
  expect_input_error([&] { io::read_uos_points(dir / "scan002.3d"); }, {at_line(dir / "scan002.3d", 2), "not a number"});
  expect_input_error([&] { io::read_uos_points(dir / "missing.3d"); }, {"missing.3d", "cannot open"});
  EXPECT_EQ(io::read_uos_points(dir / "scan001.3d").size(), small.size());
  // Two alive at once in one thread: the second gets a buffer of its own.
  const io::detail::ScanFileBytes first(dir / "scan000.3d");
  const io::detail::ScanFileBytes second(dir / "scan001.3d");
  EXPECT_NE(&first.bytes(), &second.bytes());
  EXPECT_EQ(first.bytes(), io::detail::read_file_bytes(dir / "scan000.3d"));
  EXPECT_EQ(second.bytes(), io::detail::read_file_bytes(dir / "scan001.3d"));
}

TEST(UosPoints, UnmarkedFilesSplitIntoFixedSlicesOnRequest) {
  TempDir dir;
  const auto path = dir / "scan000.3d";
  std::string text;
  for (int i = 0; i < 10; ++i) text += std::to_string(i) + " 0 0\n";
  write_text(path, text);
  io::ReadSettings settings;
  settings.points_per_slice = 4;
  EXPECT_EQ(io::read_uos_points(path, settings).slice_offsets, (std::vector<std::uint32_t>{0, 4, 8, 10}));
  EXPECT_FALSE(io::read_uos_points(path).has_slices());
  // Markers win over points_per_slice; points before the first marker form slice 0.
  write_text(path, "1 1 1\n# slice 0\n2 2 2\n3 3 3\n#slice 1\n4 4 4\n# slice one\n5 5 5\n");
  EXPECT_EQ(io::read_uos_points(path, settings).slice_offsets, (std::vector<std::uint32_t>{0, 1, 3, 5}));
}

// A scan of the paper's scanner written without markers: its slices are found again from the order
// of its points, exactly; a cloud that is not in scanner order (shuffled, or moved far from its
// scanner) gets none.
TEST(UosPoints, UnmarkedScannerOrderedFilesGetTheirSlicesBack) {
  sim::SimulationSettings sim_settings;
  sim_settings.mine.scans = 2;
  const sim::SimulatedSurvey survey = sim::simulate_mine_survey(sim_settings);
  const Scan& scan = survey.scans[1];
  ASSERT_TRUE(scan.has_slices());
  std::vector<std::size_t> expected;  // the first point of every slice that has points
  for (std::size_t s = 0; s < scan.num_slices(); ++s) {
    if (scan.slice_offsets[s] < scan.slice_offsets[s + 1]) expected.push_back(scan.slice_offsets[s]);
  }
  EXPECT_EQ(io::detect_slice_starts(scan.points_cm), expected);

  TempDir dir;
  Scan unmarked = scan;
  unmarked.slice_offsets.clear();
  io::write_uos_points(dir / "scan001.3d", unmarked);
  io::ReadReport report;
  io::ReadSettings settings;
  settings.report = &report;
  const Scan read = io::read_uos_points(dir / "scan001.3d", settings);
  ASSERT_TRUE(read.has_slices());
  EXPECT_EQ(read.num_slices(), expected.size());
  EXPECT_EQ(report.slices_detected, expected.size());
  settings.detect_slices = false;
  EXPECT_FALSE(io::read_uos_points(dir / "scan001.3d", settings).has_slices());

  std::vector<Eigen::Vector3f> shuffled = scan.points_cm;
  std::mt19937 random(3);
  std::shuffle(shuffled.begin(), shuffled.end(), random);
  EXPECT_TRUE(io::detect_slice_starts(shuffled).empty());
  std::vector<Eigen::Vector3f> far = scan.points_cm;  // in a world frame, 500 m from the scanner
  for (auto& p : far) p += Eigen::Vector3f(50000.0f, 0.0f, 20000.0f);
  EXPECT_TRUE(io::detect_slice_starts(far).empty());
}

TEST(UosPoints, RightHandedMetresBecome3dtkCentimetres) {
  TempDir dir;
  const auto path = dir / "scan000.3d";
  write_text(path, "1 2 3\n");
  io::ReadSettings settings;
  settings.unit = LengthUnit::kMetre;
  settings.right_handed_to_3dtk = true;
  // x_3dtk = -100 y, y_3dtk = 100 z, z_3dtk = 100 x
  EXPECT_EQ(io::read_uos_points(path, settings).points_cm[0], Eigen::Vector3f(-200.0f, 300.0f, 100.0f));
}

TEST(UosPoints, ParsingIgnoresTheProcessLocale) {
  const char* locale = nullptr;
  for (const char* name : {"de_DE.UTF-8", "de_DE.utf8", "fr_FR.UTF-8", "fr_FR.utf8"}) {
    if (std::setlocale(LC_NUMERIC, name)) {
      locale = name;
      break;
    }
  }
  // scripts/install-deps.sh test generates de_DE.UTF-8, so this check always runs in CI.
  ASSERT_NE(locale, nullptr) << "no locale with a decimal comma: run scripts/install-deps.sh test";
  TempDir dir;
  const auto path = dir / "scan000.3d";
  write_text(path, "1.5 2.25 -3.125\n");
  const Scan scan = io::read_uos_points(path);
  std::setlocale(LC_NUMERIC, "C");
  EXPECT_EQ(scan.points_cm[0], Eigen::Vector3f(1.5f, 2.25f, -3.125f));
}

// ---- .pose and 3DTK's Euler convention ----------------------------------------------------------

TEST(UosPose, EulerToPoseIsRxRyRzOn3dtkExample) {
  // dat/scan001.pose from FORMATS-3DTK.md.
  EulerPose euler;
  euler.position_cm = Eigen::Vector3d(-3.10605, -7.50803, 156.917);
  euler.angles_deg = Eigen::Vector3d(1.35694, -0.852409, -0.56224);
  const Pose pose = euler_to_pose(euler);
  EXPECT_TRUE((pose.block<3, 3>(0, 0).isApprox(rx_ry_rz(euler.angles_deg), 1e-14)));
  EXPECT_EQ(Eigen::Vector3d(pose.col(3).head<3>()), euler.position_cm);
  // 3DTK's column-major M[8] = sin(theta_y) sits in row 0, column 2.
  EXPECT_NEAR(pose(0, 2), std::sin(euler.angles_deg.y() * kDegToRad), 1e-15);
  // p_global = R p_local + t.
  const Eigen::Vector3d p_local(100.0, -50.0, 1000.0);
  const Eigen::Vector3d expected = rx_ry_rz(euler.angles_deg) * p_local + euler.position_cm;
  EXPECT_TRUE((pose * p_local.homogeneous()).head<3>().isApprox(expected, 1e-14));
  // And back.
  const EulerPose again = pose_to_euler(pose);
  EXPECT_TRUE(again.angles_deg.isApprox(euler.angles_deg, 1e-12));
}

TEST(UosPose, GimbalLockBranchFollows3dtk) {
  // theta_y = 90 deg: only theta_x + theta_z is defined; 3DTK reports theta_x = 0.
  EulerPose euler;
  euler.angles_deg = Eigen::Vector3d(20.0, 90.0, 15.0);
  const Pose pose = euler_to_pose(euler);
  const EulerPose recovered = pose_to_euler(pose);
  EXPECT_DOUBLE_EQ(recovered.angles_deg.x(), 0.0);
  EXPECT_NEAR(recovered.angles_deg.y(), 90.0, 1e-9);
  EXPECT_NEAR(recovered.angles_deg.z(), 35.0, 1e-9);
  EXPECT_TRUE(euler_to_pose(recovered).isApprox(pose, 1e-12));
  // theta_y = 89.9 deg (|cos| = 0.0017 <= 0.005) also takes 3DTK's branch, losing a little rotation.
  euler.angles_deg = Eigen::Vector3d(20.0, 89.9, 15.0);
  EXPECT_DOUBLE_EQ(pose_to_euler(euler_to_pose(euler)).angles_deg.x(), 0.0);
}

TEST(UosPose, ReadsThe3dtkExampleFile) {
  TempDir dir;
  const auto path = dir / "scan001.pose";
  write_text(path, "-3.10605 -7.50803 156.917\n1.35694 -0.852409 -0.56224\n");
  const EulerPose pose = io::read_uos_pose(path);
  EXPECT_EQ(pose.position_cm, Eigen::Vector3d(-3.10605, -7.50803, 156.917));
  EXPECT_EQ(pose.angles_deg, Eigen::Vector3d(1.35694, -0.852409, -0.56224));
  EXPECT_TRUE(io::read_uos_pose(path, LengthUnit::kMetre).position_cm.isApprox(Eigen::Vector3d(-310.605, -750.803, 15691.7), 1e-15));
  write_text(path, "-3.10605 -7.50803 156.917 1.35694 -0.852409 -0.56224");  // one line is fine too
  EXPECT_EQ(io::read_uos_pose(path).angles_deg.z(), -0.56224);
}

TEST(UosPose, WritesTwoLinesAndRoundTripsExactlyEvenNearGimbalLock) {
  TempDir dir;
  const auto path = dir / "scan000.pose";
  for (const Eigen::Vector3d& angles : {Eigen::Vector3d(1.35694, -0.852409, -0.56224), Eigen::Vector3d(-170, 45, 120),
                                       Eigen::Vector3d(20, 89.9, 15), Eigen::Vector3d(-30, -90, 40),
                                       Eigen::Vector3d(10, 100, -20)}) {
    EulerPose euler;
    euler.position_cm = Eigen::Vector3d(12345.678, -0.001, 98.5);
    euler.angles_deg = angles;
    const Pose pose = euler_to_pose(euler);
    io::write_uos_pose(path, pose);
    const std::string text = test::read_text(path);
    EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 2) << text;
    EXPECT_EQ(tokens_of(text).size(), 6u);
    const Pose back = euler_to_pose(io::read_uos_pose(path));
    EXPECT_LT((back - pose).cwiseAbs().maxCoeff(), 1e-9) << "angles " << angles.transpose() << "\n" << text;
  }
}

TEST(UosPose, BadPoseFilesNameTheirLine) {
  TempDir dir;
  const auto path = dir / "scan000.pose";
  write_text(path, "1 2 3\n4 5\n");
  expect_input_error([&] { io::read_uos_pose(path); }, {at_line(path, 2), "found 5 numbers"});
  write_text(path, "1 2 3\n4 5 6\n7\n");
  expect_input_error([&] { io::read_uos_pose(path); }, {at_line(path, 3), "more than 6"});
  write_text(path, "1 2 3\n4 nan 6\n");
  expect_input_error([&] { io::read_uos_pose(path); }, {at_line(path, 2), "not finite"});
  write_text(path, "1 2 three\n4 5 6\n");
  expect_input_error([&] { io::read_uos_pose(path); }, {at_line(path, 1), "'three' is not a number"});
  write_text(path, "");
  expect_input_error([&] { io::read_uos_pose(path); }, {path.string(), "found 0 numbers"});
}

// ---- .frames -------------------------------------------------------------------------------------

TEST(UosFrames, LinesAreColumnMajorWithTranslationLast) {
  TempDir dir;
  const auto path = dir / "scan000.frames";
  Pose pose = Pose::Identity();
  pose.block<3, 3>(0, 0) = rx_ry_rz(Eigen::Vector3d(10, -20, 30));
  pose.col(3).head<3>() = Eigen::Vector3d(11, 22, 33);
  const std::vector<io::FrameLine> frames{{pose, 3}};
  io::write_uos_frames(path, frames);
  const std::vector<std::string> tokens = tokens_of(test::read_text(path));
  ASSERT_EQ(tokens.size(), 17u);
  const double expected[16] = {pose(0, 0), pose(1, 0), pose(2, 0), 0,  // R11 R21 R31 0
                               pose(0, 1), pose(1, 1), pose(2, 1), 0,  // R12 R22 R32 0
                               pose(0, 2), pose(1, 2), pose(2, 2), 0,  // R13 R23 R33 0
                               11,         22,         33,         1};
  for (int i = 0; i < 16; ++i) EXPECT_EQ(std::stod(tokens[static_cast<std::size_t>(i)]), expected[i]) << "token " << i;
  EXPECT_EQ(tokens[16], "3");
  EXPECT_NE(pose(1, 0), pose(0, 1));  // the check above would not see a transposition otherwise
}

TEST(UosFrames, RoundTripKeepsEveryLineAndTheLastIsTheFinalPose) {
  TempDir dir;
  const auto path = dir / "scan001.frames";
  std::vector<io::FrameLine> frames;
  for (int k = 0; k < 4; ++k) {
    EulerPose euler;
    euler.position_cm = Eigen::Vector3d(10.0 * k, -3.5 * k, 1000.25);
    euler.angles_deg = Eigen::Vector3d(5.0 * k, -7.0 * k, 1.5 * k);
    frames.push_back({euler_to_pose(euler), k % 5});
  }
  io::write_uos_frames(path, frames, LengthUnit::kMetre);
  const auto back = io::read_uos_frames(path, LengthUnit::kMetre);
  ASSERT_EQ(back.size(), frames.size());
  for (std::size_t k = 0; k < frames.size(); ++k) {
    EXPECT_LT((back[k].pose_cm - frames[k].pose_cm).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_EQ(back[k].type, frames[k].type);
  }
  EXPECT_EQ(back.back().pose_cm.col(3), frames.back().pose_cm.col(3));
}

TEST(UosFrames, Reads3dtkSixDigitLinesSkippingBlanksAndComments) {
  TempDir dir;
  const auto path = dir / "scan001.frames";
  EulerPose euler;
  euler.position_cm = Eigen::Vector3d(-3.10605, -7.50803, 156.917);
  euler.angles_deg = Eigen::Vector3d(1.35694, -0.852409, -0.56224);
  const Pose pose = euler_to_pose(euler);
  // As 3DTK's operator<< writes it: 6 significant digits, column-major, then the type.
  std::string line;
  for (int col = 0; col < 4; ++col) {
    for (int row = 0; row < 4; ++row) {
      char buffer[32];
      std::snprintf(buffer, sizeof buffer, "%g ", pose(row, col));
      line += buffer;
    }
  }
  write_text(path, "# written by 3DTK\n" + line + "1\n\n" + line + "2\n");
  const auto frames = io::read_uos_frames(path);
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(frames[1].type, 2);
  EXPECT_LT((frames[1].pose_cm - pose).cwiseAbs().maxCoeff(), 1e-4);
  const Eigen::Matrix3d r = frames[1].pose_cm.block<3, 3>(0, 0);
  EXPECT_LT((r * r.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-12);  // re-orthonormalised
}

TEST(UosFrames, BadLinesNameTheirLine) {
  TempDir dir;
  const auto path = dir / "scan000.frames";
  const std::string identity = "1 0 0 0 0 1 0 0 0 0 1 0 5 6 7 1";
  write_text(path, identity + " 1\n" + identity + "\n");
  expect_input_error([&] { io::read_uos_frames(path); }, {at_line(path, 2), "found 16"});
  write_text(path, identity + " 1\n\n1.01 0 0 0 0 1 0 0 0 0 1 0 5 6 7 1 1\n");
  expect_input_error([&] { io::read_uos_frames(path); }, {at_line(path, 3), "not orthonormal"});
  write_text(path, "-1 0 0 0 0 1 0 0 0 0 1 0 5 6 7 1 1\n");
  expect_input_error([&] { io::read_uos_frames(path); }, {at_line(path, 1), "reflection"});
  write_text(path, identity + " 9\n");
  expect_input_error([&] { io::read_uos_frames(path); }, {at_line(path, 1), "frame type"});
  write_text(path, "1 0 0 0 0 1 0 0 0 0 1 0 5 inf 7 1 1\n");
  expect_input_error([&] { io::read_uos_frames(path); }, {at_line(path, 1), "not finite"});
  write_text(path, "1 0 0 0.5 0 1 0 0 0 0 1 0 5 6 7 1 1\n");
  expect_input_error([&] { io::read_uos_frames(path); }, {at_line(path, 1), "0 0 0 1"});
  write_text(path, "# only a comment\n");
  expect_input_error([&] { io::read_uos_frames(path); }, {path.string(), "no frames"});
}

}  // namespace
}  // namespace minemap
