// The shared real scans (../shared/data) load with the point counts their READMEs give, in metres,
// and quickly. Counts are exact: these files hold no NaN points (the NaN rule would drop them).
#include <gtest/gtest.h>


#include "io_test_helpers.hpp"
#include "minemap/io/formats.hpp"

namespace minemap {
namespace {

std::filesystem::path data_dir(const std::string& name) {
  const auto dir = test::shared_data_dir() / name;
  if (!std::filesystem::is_directory(dir)) ADD_FAILURE() << "shared data missing: " << dir;
  return dir;
}


TEST(RealData, FastGicpPairIsBinaryPcdInMetres) {
  const auto dir = data_dir("fast_gicp_pair");
  const Scan target = io::read_pcd(dir / "251370668.pcd");
  const Scan source = io::read_pcd(dir / "251371071.pcd");
  EXPECT_EQ(target.size(), 69'088u);
  EXPECT_EQ(source.size(), 69'792u);
  EXPECT_EQ(target.name, "251370668");
  EXPECT_TRUE(target.pose_cm.isIdentity());  // VIEWPOINT 0 0 0 1 0 0 0
  // README: maximum range about 78 m, so within 80 m = 8000 cm.
  double max_range_cm = 0;
  for (const auto& p : target.points_cm) max_range_cm = std::max(max_range_cm, double(p.norm()));
  EXPECT_GT(max_range_cm, 5000.0);
  EXPECT_LT(max_range_cm, 8000.0);

  const auto relative = io::read_trajectory(dir / "relative.txt");
  ASSERT_EQ(relative.size(), 1u);
  EXPECT_NEAR(relative[0](0, 3), 48.5657, 1e-9);  // 0.485657 m

  const io::Survey survey = io::read_survey(dir);
  EXPECT_EQ(survey.format, "pcd");
  ASSERT_EQ(survey.scans.size(), 2u);
  EXPECT_EQ(survey.scans[0].name, "251370668");
}

// Reading speed is measured in bench/bench_search.cpp (BM_Read*), not here: tests do not time.
TEST(RealData, MineJinchuanIsCompressedPcd) {
  const auto dir = data_dir("mine_jinchuan_pcr");
  const Scan first = io::read_pcd(dir / "2025-04-21-11-04-46.pcd");
  const Scan second = io::read_pcd(dir / "2025-05-13-10-25-38.pcd");
  EXPECT_EQ(first.size(), 176'758u);
  EXPECT_EQ(second.size(), 239'171u);
  // README: z from -128 m (one isolated point) to 4 m for the first; x up to 255 m for the second.
  Bounds3d bounds;
  for (std::size_t i = 0; i < first.size(); ++i) bounds.extend(first.file_point(i));
  EXPECT_NEAR(bounds.min_cm.z(), -12800.0, 100.0);
  EXPECT_LT(bounds.max_cm.z(), 500.0);
  Bounds3d second_bounds;
  for (std::size_t i = 0; i < second.size(); ++i) second_bounds.extend(second.file_point(i));
  EXPECT_NEAR(second_bounds.max_cm.x(), 25500.0, 100.0);
}

TEST(RealData, Kitti07SequenceIsXyzBinWithGraphTruth) {
  const auto dir = data_dir("kitti07_sequence");
  const io::Survey survey = io::read_survey(dir);
  EXPECT_EQ(survey.format, "kitti");
  EXPECT_EQ(survey.unit, LengthUnit::kMetre);
  const std::vector<std::size_t> counts{21'562, 24'703, 24'573, 16'911, 19'872};
  ASSERT_EQ(survey.scans.size(), counts.size());
  for (std::size_t k = 0; k < counts.size(); ++k) {
    EXPECT_EQ(survey.scans[k].size(), counts[k]) << "scan " << k;
    EXPECT_EQ(survey.scans[k].name, "00000" + std::to_string(k));
    EXPECT_TRUE(survey.scans[k].pose_cm.isIdentity());
  }
  ASSERT_TRUE(survey.truth_cm.has_value());
  ASSERT_EQ(survey.truth_cm->size(), 5u);
  // v0 1.24762 0.168291 0.0144288 ...; v4 3.84648 27.7398 -0.110073 ...
  EXPECT_TRUE(Eigen::Vector3d((*survey.truth_cm)[0].col(3).head<3>()).isApprox(Eigen::Vector3d(124.762, 16.8291, 1.44288), 1e-12));
  EXPECT_TRUE(Eigen::Vector3d((*survey.truth_cm)[4].col(3).head<3>()).isApprox(Eigen::Vector3d(384.648, 2773.98, -11.0073), 1e-12));
  // And the same graph on its own.
  EXPECT_EQ(io::read_graph_poses(dir / "graph.txt").size(), 5u);
}

TEST(RealData, LargeTextScanRoundTrips) {
  // A .3d of 123k lines (the paper's scans have 341 x 361 points) from the real mine cloud.
  const auto dir = data_dir("mine_jinchuan_pcr");
  Scan cloud = io::read_pcd(dir / "2025-04-21-11-04-46.pcd");
  cloud.points_cm.resize(123'000);
  test::TempDir tmp;
  io::write_uos_points(tmp / "scan000.3d", cloud);
  const Scan back = io::read_uos_points(tmp / "scan000.3d");
  EXPECT_EQ(back.size(), 123'000u);
  for (std::size_t i = 0; i < back.size(); i += 997) ASSERT_LT((back.file_point(i) - cloud.file_point(i)).norm(), 1e-3);
}

}  // namespace
}  // namespace minemap
