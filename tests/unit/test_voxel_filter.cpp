// The voxel reduction against a brute-force oracle, and the whole-survey mode that uses it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <tuple>

#include "minemap/backend/cpu_backend.hpp"
#include "minemap/filter/voxel_filter.hpp"
#include "minemap/sim/mine_simulator.hpp"
#include "minemap/slam/survey_matching.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

TEST(VoxelFilter, EachOccupiedCellGivesTheMeanOfItsPointsInOrderOfFirstAppearance) {
  auto points = test::random_cloud(20000, -100.f, 100.f, 21);  // about 2600 cells of 15 cm
  // Duplicates and points on cell borders, where floor() decides.
  for (int i = 0; i < 200; ++i) points.push_back(points[static_cast<std::size_t>(i)]);
  for (float v : {-30.f, 0.f, 15.f, 30.f}) points.emplace_back(v, v, v);
  const float voxel = 15.f;
  const auto reduced = voxel_mean_filter(points, voxel);
  // The oracle: a std::map from cell to (first index, sum, count).
  std::map<std::tuple<long, long, long>, std::tuple<std::size_t, Eigen::Vector3d, int>> cells;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const auto& p = points[i];
    const auto key = std::make_tuple(static_cast<long>(std::floor(double(p.x()) / voxel)),
                                     static_cast<long>(std::floor(double(p.y()) / voxel)),
                                     static_cast<long>(std::floor(double(p.z()) / voxel)));
    auto [it, fresh] = cells.emplace(key, std::make_tuple(i, Eigen::Vector3d::Zero(), 0));
    std::get<1>(it->second) += p.cast<double>();
    std::get<2>(it->second) += 1;
  }
  ASSERT_EQ(reduced.size(), cells.size());
  std::vector<std::pair<std::size_t, Eigen::Vector3f>> expected;
  for (const auto& [key, cell] : cells) {
    expected.emplace_back(std::get<0>(cell), (std::get<1>(cell) / std::get<2>(cell)).cast<float>());
  }
  std::sort(expected.begin(), expected.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  for (std::size_t k = 0; k < reduced.size(); ++k) EXPECT_EQ(reduced[k], expected[k].second) << k;
  EXPECT_LT(reduced.size(), points.size() / 2);
}

TEST(VoxelFilter, RefusesANonPositiveVoxelAndKeepsAnEmptyCloudEmpty) {
  const std::vector<Eigen::Vector3f> none;
  EXPECT_TRUE(voxel_mean_filter(none, 10.f).empty());
  const std::vector<Eigen::Vector3f> one{{1, 2, 3}};
  EXPECT_THROW(voxel_mean_filter(one, 0.f), std::invalid_argument);
  EXPECT_THROW(voxel_mean_filter(one, -1.f), std::invalid_argument);
  EXPECT_THROW(voxel_mean_filter(one, std::nanf("")), std::invalid_argument);
  MappingSettings settings;
  settings.reduction = Reduction::kVoxel;
  settings.voxel_cm = 0.f;
  EXPECT_THROW(settings.validate(), std::invalid_argument);
}

// Incremental matching against the metascan (one tree of the registered neighbours) on voxel means:
// the whole-survey mode of issue 14, on the first 16 scans of the default survey.
// The OpenCL kernels (kernels/voxel_means.cl) give the host's voxel means bit for bit: the cells'
// order, their means and the intensities' means; dense cells (hundreds of points, sorted on the
// device), duplicates, cell borders, negative cells, a cloud with a point beyond the kernels' reach
// (computed on the host), an empty cloud. What PoCL cannot show: the sort of each cell's points
// before summing (a GPU's atomics hand out places in any order, PoCL's in the points' order; and a
// cell's points, all within one voxel, mostly sum exactly in double in any order).
TEST(VoxelFilter, TheOpenClKernelsGiveTheHostsMeansBitForBit) {
  const std::unique_ptr<ComputeBackend> opencl = test::opencl_backend();
  auto points = test::random_cloud(30000, -3000.f, 3000.f, 5);
  const auto dense = test::random_cloud(2000, 0.f, 14.f, 6);  // about 3 cells of 10 cm: ~700 points each
  points.insert(points.end(), dense.begin(), dense.end());
  for (int i = 0; i < 500; ++i) points.push_back(points[static_cast<std::size_t>(7 * i)]);
  for (float v : {-30.f, -15.f, 0.f, 15.f, 30.f}) points.emplace_back(v, -v, v);
  std::vector<float> values(points.size());
  for (std::size_t k = 0; k < values.size(); ++k) values[k] = 0.001f * float((k * 7919) % 100003);
  CpuBackend cpu;
  for (const float voxel : {10.f, 15.f, 200.f}) {
    const auto host = voxel_mean_filter(points, voxel);
    ASSERT_GT(host.size(), 1000u);
    EXPECT_EQ(opencl->voxel_means(points, voxel), host) << voxel << " cm";
    EXPECT_EQ(cpu.voxel_means(points, voxel), host) << voxel << " cm";
    std::vector<float> host_values, device_values;
    const auto host_with = voxel_mean_filter(points, voxel, values, host_values);
    EXPECT_EQ(opencl->voxel_means(points, voxel, values, &device_values), host_with) << voxel << " cm";
    EXPECT_EQ(device_values, host_values) << voxel << " cm";
  }
  auto far = points;
  far.emplace_back(2.0e7f, 0.f, 0.f);  // 200 km: beyond 2^20 cells of 10 cm
  EXPECT_EQ(opencl->voxel_means(far, 10.f), voxel_mean_filter(far, 10.f));
  EXPECT_TRUE(opencl->voxel_means({}, 10.f).empty());
  EXPECT_THROW(opencl->voxel_means(points, 0.f), std::invalid_argument);
  std::vector<float> out;
  EXPECT_THROW(opencl->voxel_means(points, 10.f, std::span(values).first(3), &out), std::invalid_argument);
}

TEST(VoxelFilter, IncrementalMatchingOnVoxelMeansIsAccurate) {
  sim::SimulationSettings simulation;
  simulation.mine.scans = 16;
  const auto survey = sim::simulate_mine_survey(simulation);
  MappingSettings settings;
  settings.mode = MatchingMode::kIncremental;
  settings.reduction = Reduction::kVoxel;
  settings.icp.refine_pair_dist_fraction = 0.0f;
  CpuBackend cpu;
  const auto result = map_survey(survey.scans, settings, cpu);
  ASSERT_TRUE(result.all_registered());
  const auto registered = pose_errors(test::poses_of(result), survey.truth_cm);
  const auto drifted = pose_errors(test::odometry_of(survey.scans), survey.truth_cm);
  std::printf("16 scans, incremental on 15 cm voxel means: %.2f cm (odometry %.2f cm) over %.1f m\n",
              registered.mean_translation_cm, drifted.mean_translation_cm, registered.path_length_cm / 100.0);
  EXPECT_LE(registered.mean_translation_cm, 0.002 * registered.path_length_cm);
  EXPECT_LT(registered.mean_translation_cm, 0.1 * drifted.mean_translation_cm);
  EXPECT_LT(result.scans[1].points_used, survey.scans[1].size() / 5);  // reduced
}

}  // namespace
}  // namespace minemap
