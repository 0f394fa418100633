// Trajectory files: 4x4, TUM, KITTI and graph round trips, format detection, rotation validation
// and re-orthonormalisation, and line numbers of malformed input.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "io_test_helpers.hpp"
#include "minemap/io/formats.hpp"

namespace minemap {
namespace {

using test::at_line;
using test::expect_input_error;
using test::TempDir;
using test::write_text;

std::vector<Pose> sample_poses() {
  std::vector<Pose> poses;
  for (int k = 0; k < 5; ++k) {
    EulerPose euler;
    euler.position_cm = Eigen::Vector3d(123.25 * k, -7.5 * k * k, 0.001 * k + 3.0);
    euler.angles_deg = Eigen::Vector3d(11.0 * k - 20.0, 30.0 - 13.0 * k, 170.0 - 70.0 * k);
    poses.push_back(euler_to_pose(euler));
  }
  return poses;
}

void expect_same_poses(const std::vector<Pose>& actual, const std::vector<Pose>& expected, double tolerance) {
  ASSERT_EQ(actual.size(), expected.size());
  for (std::size_t k = 0; k < expected.size(); ++k) {
    EXPECT_LT((actual[k] - expected[k]).cwiseAbs().maxCoeff(), tolerance) << "pose " << k;
  }
}

TEST(Trajectories, EveryFormatRoundTripsAndIsDetected) {
  TempDir dir;
  const auto poses = sample_poses();
  for (const LengthUnit unit : {LengthUnit::kMetre, LengthUnit::kCentimetre}) {
    io::write_matrix_poses(dir / "matrix.txt", poses, unit);
    expect_same_poses(io::read_matrix_poses(dir / "matrix.txt", unit), poses, 1e-9);
    io::write_kitti_poses(dir / "kitti.txt", poses, unit);
    expect_same_poses(io::read_kitti_poses(dir / "kitti.txt", unit), poses, 1e-9);
    io::write_graph_poses(dir / "graph.txt", poses, unit);
    expect_same_poses(io::read_graph_poses(dir / "graph.txt", unit), poses, 1e-9);
    std::vector<io::TimedPose> timed;
    for (std::size_t k = 0; k < poses.size(); ++k) timed.push_back({1.6e9 + 0.1 * static_cast<double>(k), poses[k]});
    io::write_tum(dir / "tum.txt", timed, unit);
    const auto tum = io::read_tum(dir / "tum.txt", unit);
    ASSERT_EQ(tum.size(), timed.size());
    for (std::size_t k = 0; k < timed.size(); ++k) {
      EXPECT_EQ(tum[k].timestamp_s, timed[k].timestamp_s);
      EXPECT_LT((tum[k].pose_cm - poses[k]).cwiseAbs().maxCoeff(), 1e-9);
    }
  }
  EXPECT_EQ(io::detect_trajectory_format(dir / "matrix.txt"), io::TrajectoryFormat::kMatrix4x4);
  EXPECT_EQ(io::detect_trajectory_format(dir / "kitti.txt"), io::TrajectoryFormat::kKitti);
  EXPECT_EQ(io::detect_trajectory_format(dir / "graph.txt"), io::TrajectoryFormat::kGraph);
  EXPECT_EQ(io::detect_trajectory_format(dir / "tum.txt"), io::TrajectoryFormat::kTum);
  for (const char* name : {"matrix.txt", "kitti.txt", "graph.txt", "tum.txt"}) {
    expect_same_poses(io::read_trajectory(dir / name, LengthUnit::kCentimetre), poses, 1e-9);
  }
}

TEST(Trajectories, KnownValuesInEachLayout) {
  TempDir dir;
  // 90 deg about z, translation (1, 2, 3) m.
  Pose expected = Pose::Identity();
  expected.block<3, 3>(0, 0) << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  expected.block<3, 1>(0, 3) = Eigen::Vector3d(100, 200, 300);
  write_text(dir / "m.txt", "# a comment\n0 -1 0 1\n1 0 0 2\n\n0 0 1 3\n0 0 0 1\n\n0 -1 0 1 1 0 0 2 0 0 1 3 0 0 0 1\n");
  expect_same_poses(io::read_matrix_poses(dir / "m.txt"), {expected, expected}, 1e-12);
  write_text(dir / "k.txt", "0 -1 0 1 1 0 0 2 0 0 1 3\r\n");
  expect_same_poses(io::read_kitti_poses(dir / "k.txt"), {expected}, 1e-12);
  const std::string q = "0 0 0.70710678118654752 0.70710678118654752";  // qx qy qz qw
  write_text(dir / "t.txt", "# timestamp tx ty tz qx qy qz qw\n17.5 1 2 3 " + q + "\n");
  expect_same_poses({io::read_tum(dir / "t.txt").at(0).pose_cm}, {expected}, 1e-12);
  EXPECT_EQ(io::read_tum(dir / "t.txt").at(0).timestamp_s, 17.5);
  // Graph vertices come back ordered by K, whatever the file order.
  write_text(dir / "g.txt", "v1 1 2 3 " + q + "\nv0 0 0 0 0 0 0 1\n");
  const auto graph = io::read_graph_poses(dir / "g.txt");
  expect_same_poses(graph, {Pose::Identity(), expected}, 1e-12);
}

TEST(Trajectories, SixDigitRotationsAreAcceptedAndReOrthonormalised) {
  TempDir dir;
  // fast_gicp's relative.txt: 6 significant digits, so R R^T is off by ~1e-6.
  write_text(dir / "relative.txt",
             "    0.999941    0.0108432 -0.000635437     0.485657\n"
             "  -0.0108468     0.999924  -0.00587782      0.10642\n"
             " 0.000571654   0.00588436     0.999983   -0.0131581\n"
             "           0            0            0            1\n");
  const auto poses = io::read_matrix_poses(dir / "relative.txt");
  ASSERT_EQ(poses.size(), 1u);
  const Eigen::Matrix3d r = poses[0].block<3, 3>(0, 0);
  EXPECT_LT((r * r.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
  EXPECT_NEAR(poses[0](0, 3), 48.5657, 1e-9);
  EXPECT_NEAR(r(0, 1), 0.0108432, 1e-5);
}

TEST(Trajectories, MalformedFilesNameTheirLine) {
  TempDir dir;
  const auto path = dir / "poses.txt";
  struct Case {
    std::string text;
    std::vector<Pose> (*read)(const std::filesystem::path&, LengthUnit);
    long line;
    std::string message;
  };
  const auto tum = [](const std::filesystem::path& p, LengthUnit u) {
    std::vector<Pose> out;
    for (const auto& t : io::read_tum(p, u)) out.push_back(t.pose_cm);
    return out;
  };
  const std::vector<Case> cases{
      {"1 0 0 0\n0 1 0 0\n0 0 1 0\n", io::read_matrix_poses, 3, "ends inside a matrix"},
      {"1 0 0 0\n0 1 0 0 5\n", io::read_matrix_poses, 2, "expected 4 values"},
      {"1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 2\n", io::read_matrix_poses, 4, "0 0 0 1"},
      {"2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", io::read_matrix_poses, 4, "not orthonormal"},
      {"1 0 0 0\n0 1 0 0\n0 0 -1 0\n0 0 0 1\n", io::read_matrix_poses, 4, "reflection"},
      {"# nothing here\n", io::read_matrix_poses, 1, "no poses"},
      {"1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n", io::read_kitti_poses, 2, "expected 12 values"},
      {"1 0 0 0 0 1 0 0 0 0 1 nan\n", io::read_kitti_poses, 1, "not finite"},
      {"1 0 0 0 0 1.1 0 0 0 0 1 0\n", io::read_kitti_poses, 1, "not orthonormal"},
      {"0 1 2 3 0 0 0 1\n1 1 2 3 0 0 0 1.01\n", tum, 2, "quaternion is not unit length"},
      {"0 1 2 3 0 0 0\n", tum, 1, "expected 8 values"},
      {"v0 0 0 0 0 0 0 1\nv0 1 1 1 0 0 0 1\n", io::read_graph_poses, 2, "v0 appears twice"},
      {"v0 0 0 0 0 0 0 1\nv2 1 1 1 0 0 0 1\n", io::read_graph_poses, 2, "no vertex v1"},
      {"x0 0 0 0 0 0 0 1\n", io::read_graph_poses, 1, "not a vertex name"},
      {"1 2 3 4 5\n", io::read_trajectory, 1, "cannot tell the trajectory format"},
  };
  for (const Case& c : cases) {
    write_text(path, c.text);
    expect_input_error([&] { c.read(path, LengthUnit::kMetre); }, {at_line(path, c.line), c.message});
  }
}

}  // namespace
}  // namespace minemap
