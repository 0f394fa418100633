// Determinism of the `minemap map` outputs: repeated runs and 1 or 2 threads write identical bytes
// in every file (report.json: all but what the clock and the OS say, "timings_s" and "memory_mb",
// and how each run was asked for: "command_line", "run_options"), on the CPU and on PoCL;
// PoCL and the CPU give poses that agree within a few ICP convergence steps (see the last test).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <set>
#include <string>

#include "test_support.hpp"

namespace minemap {
namespace {

namespace fs = std::filesystem;
using test::run_cli;
using test::TempDir;

std::set<std::string> file_names(const fs::path& dir) {
  std::set<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) names.insert(entry.path().filename().string());
  return names;
}

/// report.json without what may differ between runs of one mapping: its wall-clock timings, and how
/// the run was asked for (the command line, with its --out; threads and backend: run_options).
std::string report_without_timings(const fs::path& dir) {
  auto report = nlohmann::json::parse(test::read_text(dir / "report.json"));
  for (const char* key : {"timings_s", "memory_mb", "command_line", "run_options"}) {
    EXPECT_TRUE(report.contains(key)) << key;
    report.erase(key);
  }
  return report.dump(2);
}

/// Every file of `b` has the bytes of the same file in `a`, and neither has a file the other lacks.
void expect_identical_outputs(const fs::path& a, const fs::path& b) {
  const auto names = file_names(a);
  EXPECT_EQ(names, file_names(b));
  for (const char* expected : {"scan000.frames", "scan003.pose", "trajectory.tum", "map.ply", "top.png", "side.png",
                               "map.html", "report.json"}) {
    EXPECT_TRUE(names.count(expected)) << expected;
  }
  for (const auto& name : names) {
    if (name == "minemap.log") continue;  // the run's console output: times and paths differ
    if (name == "report.json") {
      EXPECT_EQ(report_without_timings(a), report_without_timings(b)) << name;
    } else {
      // Whole-file comparison; no diff dump for the binary ones.
      EXPECT_TRUE(test::read_text(a / name) == test::read_text(b / name))
          << name << " differs between " << a << " and " << b;
    }
  }
}

TEST(Determinism, RepeatedRunsAndOneOrTwoThreadsWriteIdenticalBytes) {
  TempDir dir("minemap-determinism");
  std::string output;
  const std::string survey = (dir / "survey").string();
  ASSERT_EQ(run_cli("simulate --out " + survey + " --scans 4", &output), 0) << output;
  for (const char* run : {"two-a", "two-b", "one"}) {
    const std::string threads = std::string(run) == "one" ? "1" : "2";
    ASSERT_EQ(run_cli("--threads " + threads + " map " + survey + " --out " + (dir / run).string() + " --backend cpu",
                      &output),
              0)
        << output;
  }
  expect_identical_outputs(dir / "two-a", dir / "two-b");
  expect_identical_outputs(dir / "two-a", dir / "one");
}

/// Rotation angle (degrees) and translation length (cm, uos files are in cm) between two 4x4 poses.
std::pair<double, double> pose_difference(const nlohmann::json& a, const nlohmann::json& b) {
  Eigen::Matrix4d ma, mb;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      ma(r, c) = a[r][c].get<double>();
      mb(r, c) = b[r][c].get<double>();
    }
  }
  const Eigen::Matrix3d relative = ma.block<3, 3>(0, 0).transpose() * mb.block<3, 3>(0, 0);
  const double angle_deg = Eigen::AngleAxisd(relative).angle() * 180.0 / 3.14159265358979323846;
  return {(ma.block<3, 1>(0, 3) - mb.block<3, 1>(0, 3)).norm(), angle_deg};
}

TEST(Determinism, PoclRunsRepeatByteForByteAndGiveTheCpuPosesBitForBit) {
  // Fails (exit 6), never skips, when no OpenCL platform is present.
  //
  // PoCL has cl_khr_fp64, so the device makes the ICP sums exactly as the CPU does
  // (pair_sums_blocks, kPairSumBlock): with bit-identical pairs (same traversal, no contraction,
  // correctly rounded sqrt) the poses must be the same bits. The stated contract for devices
  // without double precision (float sums; an ICP may then stop an iteration earlier or later) is
  // 0.01 cm and 0.001 degrees; those bounds are checked too, so a failure says how far apart.
  constexpr double kToleranceCm = 0.01, kToleranceDeg = 0.001;
  TempDir dir("minemap-determinism-pocl");
  std::string output;
  const std::string survey = (dir / "survey").string();
  ASSERT_EQ(run_cli("simulate --out " + survey + " --scans 4", &output), 0) << output;
  ASSERT_EQ(run_cli("map " + survey + " --out " + (dir / "cpu").string() + " --backend cpu", &output), 0) << output;
  for (const char* run : {"opencl", "opencl-again"}) {
    ASSERT_EQ(run_cli("map " + survey + " --out " + (dir / run).string() + " --backend opencl", &output), 0) << output;
  }
  expect_identical_outputs(dir / "opencl", dir / "opencl-again");
  const auto cpu = nlohmann::json::parse(test::read_text(dir / "cpu" / "report.json"));
  const auto pocl = nlohmann::json::parse(test::read_text(dir / "opencl" / "report.json"));
  ASSERT_EQ(pocl["backend"].get<std::string>().rfind("opencl", 0), 0u) << pocl["backend"] << "\n" << output;
  ASSERT_TRUE(pocl["notes"].empty()) << pocl["notes"];
  ASSERT_EQ(cpu["scans"].size(), 4u);
  ASSERT_EQ(pocl["scans"].size(), 4u);
  double max_cm = 0.0, max_deg = 0.0;
  bool bit_identical = true;
  for (std::size_t i = 0; i < 4; ++i) {
    const auto [cm, deg] = pose_difference(cpu["scans"][i]["pose"], pocl["scans"][i]["pose"]);
    EXPECT_LE(cm, kToleranceCm) << "scan " << i;
    EXPECT_LE(deg, kToleranceDeg) << "scan " << i;
    max_cm = std::max(max_cm, cm);
    max_deg = std::max(max_deg, deg);
    bit_identical = bit_identical && cpu["scans"][i]["pose"] == pocl["scans"][i]["pose"];
  }
  std::cout << "PoCL vs CPU: max " << max_cm << " cm, " << max_deg << " deg; poses "
            << (bit_identical ? "bit-identical" : "not bit-identical") << "\n";
  RecordProperty("pocl_vs_cpu_max_cm", std::to_string(max_cm));
  RecordProperty("pocl_vs_cpu_max_deg", std::to_string(max_deg));
  RecordProperty("pocl_vs_cpu_bit_identical", bit_identical ? "yes" : "no");
  EXPECT_TRUE(bit_identical);
  // Every pose-bearing output is then the same bytes as the CPU run's.
  for (const char* name : {"scan000.pose", "scan003.pose", "scan003.frames", "trajectory.tum", "map.ply"}) {
    EXPECT_EQ(test::read_text(dir / "cpu" / name), test::read_text(dir / "opencl" / name)) << name;
  }
}

}  // namespace
}  // namespace minemap
