// The scan graph's global relaxation (slam/pose_graph.hpp): exact measurements give back the true
// poses from a wrong start; a chain with a biased heading and one loop edge ends where the loop
// says, its drift spread over the steps; bad graphs are refused.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>
#include <random>

#include "minemap/slam/pose_graph.hpp"

namespace minemap {
namespace {

constexpr double kRad = std::numbers::pi / 180.0;

Pose make_pose(double yaw_deg, double pitch_deg, const Eigen::Vector3d& t_cm) {
  Pose p = Pose::Identity();
  p.block<3, 3>(0, 0) = (Eigen::AngleAxisd(yaw_deg * kRad, Eigen::Vector3d::UnitY()) *
                         Eigen::AngleAxisd(pitch_deg * kRad, Eigen::Vector3d::UnitX()))
                            .toRotationMatrix();
  p.block<3, 1>(0, 3) = t_cm;
  return p;
}

/// A square loop of 4 x 6 steps of 400 cm in the x-z plane, turning 90 deg at each corner, with a
/// little pitch and height on the way; the last pose is the first again.
std::vector<Pose> square_loop() {
  std::vector<Pose> poses;
  Pose current = Pose::Identity();
  poses.push_back(current);
  for (int leg = 0; leg < 4; ++leg) {
    for (int step = 0; step < 6; ++step) {
      const bool corner = step == 5;
      current = current * make_pose(corner ? 90.0 : 0.0, 0.0, Eigen::Vector3d(0.0, 0.0, 400.0));
      poses.push_back(current);
    }
  }
  return poses;
}

double worst_error_cm(const std::vector<Pose>& a, const std::vector<Pose>& b) {
  double worst = 0.0;
  for (std::size_t k = 0; k < a.size(); ++k) worst = std::max(worst, translation_norm(rigid_inverse(a[k]) * b[k]));
  return worst;
}

TEST(PoseGraph, ExactMeasurementsGiveBackThePosesFromAWrongStart) {
  const std::vector<Pose> truth = square_loop();
  std::vector<PoseGraphEdge> edges;
  for (std::size_t k = 1; k < truth.size(); ++k) edges.push_back({k - 1, k, rigid_inverse(truth[k - 1]) * truth[k]});
  edges.push_back({0, truth.size() - 1, rigid_inverse(truth.front()) * truth.back()});
  edges.push_back({3, 20, rigid_inverse(truth[3]) * truth[20]});
  std::vector<Pose> start = truth;
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 1.0);
  for (std::size_t k = 1; k < start.size(); ++k) {
    start[k] = start[k] * make_pose(3.0 * noise(rng), 2.0 * noise(rng), 50.0 * Eigen::Vector3d(noise(rng), noise(rng), noise(rng)));
  }
  const PoseGraphResult result = optimise_pose_graph(start, edges, 0);
  EXPECT_TRUE(result.converged);
  EXPECT_LT(result.final_cost, 1e-8 * result.initial_cost);
  EXPECT_LT(worst_error_cm(result.poses, truth), 1e-3);
  EXPECT_EQ(result.poses[0], truth[0]);  // the fixed pose does not move
}

TEST(PoseGraph, ALoopEdgeSpreadsAHeadingDriftOverTheLoop) {
  const std::vector<Pose> truth = square_loop();
  const std::size_t n = truth.size();
  // Every step measured 0.2 deg too far left: the chain alone ends metres from the start.
  std::vector<PoseGraphEdge> edges;
  std::vector<Pose> chained{truth[0]};
  for (std::size_t k = 1; k < n; ++k) {
    const Pose measured = rigid_inverse(truth[k - 1]) * truth[k] * make_pose(0.2, 0.0, Eigen::Vector3d::Zero());
    edges.push_back({k - 1, k, measured});
    chained.push_back(chained.back() * measured);
  }
  const double drift_before = translation_norm(rigid_inverse(truth.back()) * chained.back());
  ASSERT_GT(drift_before, 100.0);
  edges.push_back({0, n - 1, rigid_inverse(truth.front()) * truth.back(), 1.0});
  const PoseGraphResult result = optimise_pose_graph(chained, edges, 0);
  ASSERT_TRUE(result.converged);
  // The loop closes: the last pose is back at the first (the loop edge holds against 24 biased
  // steps, each of which gives a little), and no pose is as far off as the chain's end was.
  const double end_after = translation_norm(rigid_inverse(truth.back()) * result.poses.back());
  EXPECT_LT(end_after, 0.1 * drift_before);
  EXPECT_LT(worst_error_cm(result.poses, truth), 0.5 * drift_before);
  EXPECT_LT(result.final_cost, 0.1 * result.initial_cost);
  // Each step keeps close to what it measured: the correction is spread, not put in one step.
  for (std::size_t k = 1; k < n; ++k) {
    const auto r = pose_graph_residual(result.poses[k - 1], result.poses[k], edges[k - 1].from_to);
    EXPECT_LT(r.tail<3>().norm(), 0.5 * kRad) << "step " << k;
  }
}

TEST(PoseGraph, AConsistentEdgeHasNoResidualAndAChainAloneStaysPut) {
  const std::vector<Pose> truth = square_loop();
  EXPECT_LT(pose_graph_residual(truth[2], truth[7], rigid_inverse(truth[2]) * truth[7]).norm(), 1e-9);
  std::vector<PoseGraphEdge> edges;
  for (std::size_t k = 1; k < truth.size(); ++k) edges.push_back({k - 1, k, rigid_inverse(truth[k - 1]) * truth[k]});
  const PoseGraphResult result = optimise_pose_graph(truth, edges, 0);
  EXPECT_LT(worst_error_cm(result.poses, truth), 1e-6);
}

TEST(PoseGraph, EdgesMustJoinTwoPosesOfTheGraph) {
  const std::vector<Pose> poses(3, Pose::Identity());
  const std::vector<PoseGraphEdge> outside{{0, 3, Pose::Identity()}};
  EXPECT_THROW(optimise_pose_graph(poses, outside, 0), std::invalid_argument);
  const std::vector<PoseGraphEdge> self{{1, 1, Pose::Identity()}};
  EXPECT_THROW(optimise_pose_graph(poses, self, 0), std::invalid_argument);
  EXPECT_THROW(optimise_pose_graph(poses, {}, 5), std::invalid_argument);
}

}  // namespace
}  // namespace minemap
