// The motion of a moving sensor (issue 26): SE(3)'s log and exp, the deskew of one sweep against a
// brute-force oracle (each point moved by its own exact motion), the overlap test that scales with
// a small scan, and the motion model's start on a sequence with no odometry.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "minemap/backend/cpu_backend.hpp"
#include "minemap/filter/deskew.hpp"
#include "minemap/slam/survey_matching.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

Pose random_pose(std::mt19937& rng, double max_cm, double max_deg) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const Eigen::Vector3d axis = Eigen::Vector3d(unit(rng), unit(rng), unit(rng)).normalized();
  Pose pose = Pose::Identity();
  pose.block<3, 3>(0, 0) = Eigen::AngleAxisd(max_deg * unit(rng) * M_PI / 180.0, axis).toRotationMatrix();
  pose.block<3, 1>(0, 3) = max_cm * Eigen::Vector3d(unit(rng), unit(rng), unit(rng));
  return pose;
}

TEST(Se3, ExpUndoesLogAndFractionsCompose) {
  std::mt19937 rng(7);
  for (int k = 0; k < 200; ++k) {
    const Pose pose = random_pose(rng, 500.0, k < 100 ? 170.0 : 1e-4);  // large turns, and next to none
    EXPECT_LT((se3_exp(se3_log(pose)) - pose).cwiseAbs().maxCoeff(), 1e-9) << k;
    const Pose half = motion_fraction(pose, 0.5);
    EXPECT_LT((half * half - pose).cwiseAbs().maxCoeff(), 1e-9) << k;
    EXPECT_LT((motion_fraction(pose, -1.0) - rigid_inverse(pose)).cwiseAbs().maxCoeff(), 1e-9) << k;
  }
  // A constant turn while driving: the motion is a circle's arc, and a quarter of it a quarter.
  Pose turn = Pose::Identity();
  turn.block<3, 3>(0, 0) = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  turn.block<3, 1>(0, 3) = Eigen::Vector3d(1000.0, 1000.0, 0.0);  // a quarter circle of radius 10 m
  const Pose eighth = motion_fraction(turn, 0.5);
  EXPECT_NEAR(eighth(0, 3), 1000.0 * std::sin(M_PI / 4), 1e-9);
  EXPECT_NEAR(eighth(1, 3), 1000.0 * (1.0 - std::cos(M_PI / 4)), 1e-9);
}

/// A room seen by a sensor that moves by `sweep` during the sweep (its middle at the identity):
/// each point carries its time, and its coordinates in the frame the sensor had then.
struct SkewedSweep {
  Scan scan;
  std::vector<Eigen::Vector3d> truth;  ///< the points in the middle's frame
};

SkewedSweep skewed_room(const Pose& sweep, double duration_s, const Eigen::Vector3d& local_origin_cm) {
  SkewedSweep out;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (int k = 0; k < 5000; ++k) {
    const double fraction = static_cast<double>(k) / 5000.0 - 0.5;
    const Eigen::Vector3d p(800.0 * unit(rng), 800.0 * unit(rng), 300.0 * unit(rng));  // middle's frame
    // The sensor at fraction f stands at motion_fraction(sweep, f) in the middle's frame.
    const Pose at = motion_fraction(sweep, fraction);
    const Eigen::Vector3d seen = rigid_inverse(at).block<3, 3>(0, 0) * p + rigid_inverse(at).block<3, 1>(0, 3);
    out.truth.push_back(p);
    out.scan.points_cm.push_back((seen - local_origin_cm).cast<float>());
    out.scan.attributes.time_s.push_back(1000.0 + duration_s * (fraction + 0.5));
  }
  out.scan.local_origin_cm = local_origin_cm;
  return out;
}

TEST(Deskew, EachPointMovesIntoTheMiddlesFrameAsTheOracleSays) {
  Pose sweep = Pose::Identity();  // 10 m/s for 0.1 s, turning 20 deg/s
  sweep.block<3, 3>(0, 0) = Eigen::AngleAxisd(2.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  sweep.block<3, 1>(0, 3) = Eigen::Vector3d(100.0, 3.0, -1.0);
  for (const Eigen::Vector3d& origin : {Eigen::Vector3d::Zero().eval(), Eigen::Vector3d(50000.0, -20000.0, 300.0)}) {
    const SkewedSweep skewed = skewed_room(sweep, 0.1, origin);
    const SweepTiming timing = sweep_timing(skewed.scan, 1.0);
    ASSERT_FALSE(timing.empty());
    EXPECT_NEAR(timing.stamp_s, 1000.05, 1e-3);
    EXPECT_NEAR(timing.duration_s, 0.1, 1e-3);
    const auto deskewed = deskewed_points(skewed.scan, timing, sweep);
    double worst_before = 0.0, worst_after = 0.0;
    for (std::size_t i = 0; i < deskewed.size(); ++i) {
      const Eigen::Vector3d truth = skewed.truth[i] - origin;
      worst_before = std::max(worst_before, (skewed.scan.points_cm[i].cast<double>() - truth).norm());
      worst_after = std::max(worst_after, (deskewed[i].cast<double>() - truth).norm());
    }
    EXPECT_GT(worst_before, 50.0);  // the sweep's ends lie 50 cm from where the middle sees them
    EXPECT_LT(worst_after, origin.norm() > 0 ? 0.1 : 0.05) << "the 4096 steps and float";
  }
}

TEST(Deskew, ScansWithoutOneSweepsTimesAreLeftAsTheyAre) {
  SkewedSweep skewed = skewed_room(Pose::Identity(), 0.1, Eigen::Vector3d::Zero());
  EXPECT_TRUE(sweep_timing(skewed.scan, 0.05).empty());  // longer than the longest sweep: a scan taken standing
  Scan no_times = skewed.scan;
  no_times.attributes.time_s.clear();
  EXPECT_TRUE(sweep_timing(no_times, 1.0).empty());
  Scan one_time = skewed.scan;
  std::fill(one_time.attributes.time_s.begin(), one_time.attributes.time_s.end(), 5.0);
  EXPECT_TRUE(sweep_timing(one_time, 1.0).empty());
  EXPECT_EQ(deskewed_points(no_times, {}, Pose::Identity()), no_times.points_cm);
}

TEST(Overlap, ASmallScanNeedsPairsInProportionToItsSize) {
  const MappingSettings settings;
  EXPECT_EQ(settings.min_pairs_for(80000), 250);  // the paper's scans: the paper's 250
  EXPECT_EQ(settings.min_pairs_for(2500), 250);
  EXPECT_EQ(settings.min_pairs_for(1500), 150);   // a 5 000-point keyframe's voxel means
  EXPECT_EQ(settings.min_pairs_for(10), 3);       // never below Horn's three
  MappingSettings fixed;
  fixed.min_overlap_fraction = 1.0;
  EXPECT_EQ(fixed.min_pairs_for(1500), 250);
}

}  // namespace
}  // namespace minemap
