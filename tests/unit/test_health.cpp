// Registration health (registration/health.hpp): a wrong registration is reported by name, never
// passed off as a map. Each test of a verdict has a case where the answer is known: a cloud judged
// against itself, the simulated mine against its truth, and the real LiDAR in ../shared/data from
// starts that are out of the pair bound's reach.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "minemap/backend/cpu_backend.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/registration/health.hpp"
#include "minemap/sim/mine_simulator.hpp"
#include "minemap/slam/survey_matching.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

/// Three walls of a 4 m room corner, points every 5 cm (cm): a surface with structure in x, y and z.
std::vector<Eigen::Vector3f> room_corner() {
  std::vector<Eigen::Vector3f> points;
  for (int a = 0; a < 80; ++a) {
    for (int b = 0; b < 80; ++b) {
      const float u = 5.0f * static_cast<float>(a), v = 5.0f * static_cast<float>(b);
      points.emplace_back(u, v, 0.0f);
      points.emplace_back(u, 0.0f, v);
      points.emplace_back(0.0f, u, v);
    }
  }
  return points;
}

Pose shifted(double x_cm, double y_cm, double z_cm) {
  Pose pose = Pose::Identity();
  pose.block<3, 1>(0, 3) = Eigen::Vector3d(x_cm, y_cm, z_cm);
  return pose;
}

class Health : public ::testing::Test {
 protected:
  CpuBackend cpu;
  std::shared_ptr<const PreparedCloud> cloud = cpu.prepare(room_corner(), KdTreeSettings{});
  IcpSettings icp;  // 25 cm bound
  HealthSettings settings;
  RegistrationHealth judge(const Pose& end, const Pose& start, const Pose& model_pose = Pose::Identity()) {
    const WorldModel model{cloud.get(), model_pose};
    return judge_registration(cpu, *cloud, end, start, {&model, 1}, icp, settings);
  }
};

TEST_F(Health, ACloudOnItselfIsTrusted) {
  const RegistrationHealth health = judge(Pose::Identity(), shifted(10, -5, 3));
  EXPECT_TRUE(health.judged);
  EXPECT_FALSE(health.doubtful()) << health.doubt;
  EXPECT_DOUBLE_EQ(health.paired_fraction, 1.0);
  EXPECT_DOUBLE_EQ(health.beyond_bound_fraction, 0.0);
  EXPECT_DOUBLE_EQ(health.edge_fraction, 0.0);
  EXPECT_NEAR(health.moved_cm, std::sqrt(10.0 * 10 + 5 * 5 + 3 * 3), 1e-9);  // a translation moves every point alike
}

TEST_F(Health, ASmoothTunnelIsDegenerateARoomCornerIsNot) {
  // The corner pins every direction: measured, and trusted.
  const SurfaceNormals corner_planes(room_corner(), 50.0f);
  const WorldModel corner{cloud.get(), Pose::Identity()};
  const RegistrationHealth boxed =
      judge_registration(cpu, *cloud, Pose::Identity(), Pose::Identity(), {&corner, 1}, icp, settings, 0.0f,
                         &corner_planes);
  EXPECT_FALSE(boxed.doubtful()) << boxed.doubt;
  EXPECT_GT(boxed.translation_constraint, 0.3);
  // A smooth tunnel along z, 400 x 250 cm, 40 m long, matched against itself slid by 20 cm along
  // it: every pair fits, but nothing pinned the slide. Only the constraint test can tell.
  std::vector<Eigen::Vector3f> tunnel;
  for (float along = -2000.0f; along < 2000.0f; along += 5.0f) {
    for (float u = 0.0f; u < 250.0f; u += 5.0f) {
      tunnel.emplace_back(-200.0f, u - 125.0f, along);
      tunnel.emplace_back(200.0f, u - 125.0f, along);
    }
    for (float u = 0.0f; u < 400.0f; u += 5.0f) {
      tunnel.emplace_back(u - 200.0f, -125.0f, along);
      tunnel.emplace_back(u - 200.0f, 125.0f, along);
    }
  }
  const auto prepared = cpu.prepare(tunnel, KdTreeSettings{});
  const SurfaceNormals tunnel_planes(tunnel, 50.0f);
  const WorldModel model{prepared.get(), Pose::Identity()};
  const RegistrationHealth slid = judge_registration(cpu, *prepared, shifted(0, 0, 20), Pose::Identity(),
                                                     {&model, 1}, icp, settings, 0.0f, &tunnel_planes);
  ASSERT_TRUE(slid.doubtful());
  EXPECT_NE(slid.doubt.find("degenerate"), std::string::npos) << slid.doubt;
  EXPECT_GT(slid.paired_fraction, 0.95);  // what the other tests see: a perfect fit
  EXPECT_LT(slid.translation_constraint, settings.min_translation_constraint);
  EXPECT_NEAR(std::abs(slid.weakest_direction.z()), 1.0, 1e-3);
  // Without the planes the constraint is not measured, and the slide passes.
  const RegistrationHealth unmeasured =
      judge_registration(cpu, *prepared, shifted(0, 0, 20), Pose::Identity(), {&model, 1}, icp, settings);
  EXPECT_FALSE(unmeasured.doubtful()) << unmeasured.doubt;
  EXPECT_LT(unmeasured.translation_constraint, 0.0);
}

TEST_F(Health, SurfacesThatSitApartAreDoubtful) {
  // Stuck 30 cm short in x and y: the two walls' counterparts lie beyond the bound but within 4x it;
  // the floor (z = 0) slides onto itself, and near the corner some wall points find the floor.
  const RegistrationHealth health = judge(shifted(30, 30, 0), shifted(30, 30, 0));
  ASSERT_TRUE(health.doubtful());
  EXPECT_NE(health.doubt.find("beyond the 25 cm pair bound"), std::string::npos) << health.doubt;
  EXPECT_GT(health.beyond_bound_fraction, 0.55);
  EXPECT_LE(health.beyond_bound_fraction, 2.0 / 3.0);
}

TEST_F(Health, PairsSpreadAcrossTheBoundAreDoubtful) {
  // 15 cm apart along the diagonal: every pair is within the bound, and all in its outer half.
  const RegistrationHealth health = judge(shifted(15, 15, 15), shifted(15, 15, 15));
  ASSERT_TRUE(health.doubtful());
  EXPECT_NE(health.doubt.find("outer half"), std::string::npos) << health.doubt;
}

TEST_F(Health, AMatchThatMovedFartherThanItsReachIsDoubtful) {
  const RegistrationHealth health = judge(Pose::Identity(), shifted(40, 0, 0));  // 1.6 bounds
  ASSERT_TRUE(health.doubtful());
  EXPECT_NE(health.doubt.find("out of reach"), std::string::npos) << health.doubt;
  settings.max_reach = 2.0;
  EXPECT_FALSE(judge(Pose::Identity(), shifted(40, 0, 0)).doubtful());
}

TEST_F(Health, LittleOverlapIsDoubtfulAndJudgingCanBeSwitchedOff) {
  const RegistrationHealth far = judge(Pose::Identity(), Pose::Identity(), shifted(0, 0, 390));  // model 3.9 m up
  ASSERT_TRUE(far.doubtful());
  EXPECT_NE(far.doubt.find("paired"), std::string::npos) << far.doubt;
  settings.enabled = false;
  EXPECT_FALSE(judge(Pose::Identity(), Pose::Identity(), shifted(0, 0, 390)).judged);
  HealthSettings bad;
  bad.max_edge_fraction = 1.5;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
}

TEST(HealthSurveys, TheSimulatedMineIsTrustedEverywhere) {
  sim::SimulationSettings settings;
  settings.mine.scans = 16;
  const auto survey = sim::simulate_mine_survey(settings);
  CpuBackend cpu;
  const auto result = map_survey(survey.scans, MappingSettings{}, cpu);
  ASSERT_TRUE(result.all_registered());
  EXPECT_TRUE(result.doubtful().empty());
  for (std::size_t i = 1; i < result.scans.size(); ++i) EXPECT_TRUE(result.scans[i].health.judged) << i;
}

/// "Never a wrong map without saying so": from starts thrown 0.5-1 m and 2-4 degrees off (the
/// issue's real-data case, here with known truth), every scan whose pose ends more than 10 cm from
/// the truth, relative to its predecessor, is in a map that says it is doubtful.
TEST(HealthSurveys, StartsOutOfReachEndInADoubtfulMapOrARightOne) {
  sim::SimulationSettings settings;
  settings.mine.scans = 12;
  settings.mine.seed = 5;
  auto survey = sim::simulate_mine_survey(settings);
  for (std::size_t i = 1; i < survey.scans.size(); ++i) {
    const double sign = (i % 2 == 0) ? 1.0 : -1.0;
    const Pose noise = euler_to_pose({Eigen::Vector3d(60.0 * sign, -40.0, 20.0 * sign), Eigen::Vector3d(1.0, -1.5, 3.0 * sign)});
    survey.scans[i].pose_cm = survey.truth_cm[i] * noise;
  }
  CpuBackend cpu;
  for (const MatchingMode mode : {MatchingMode::kIncremental, MatchingMode::kPairwise}) {
    MappingSettings mapping;
    mapping.mode = mode;
    const auto result = map_survey(survey.scans, mapping, cpu);
    const auto poses = test::poses_of(result);
    std::size_t wrong = 0;
    for (std::size_t i = 1; i < poses.size(); ++i) {
      const Pose relative_error = rigid_inverse(rigid_inverse(survey.truth_cm[i - 1]) * survey.truth_cm[i]) *
                                  (rigid_inverse(poses[i - 1]) * poses[i]);
      if (translation_norm(relative_error) > 10.0) ++wrong;
    }
    std::printf("%s: %zu of %zu steps wrong, %zu scans doubtful\n", to_string(mode), wrong, poses.size() - 1,
                result.doubtful().size());
    if (wrong > 0) {
      EXPECT_FALSE(result.doubtful().empty() && result.all_registered()) << to_string(mode);
    }
  }
}

TEST(HealthRealData, ALidarPairOutOfTheBoundsReachIsDoubtfulThenRightFromAWiderBound) {
  io::SurveyReadSettings read;
  const auto survey = io::read_survey(test::shared_data_dir() / "fast_gicp_pair", read);
  ASSERT_EQ(survey.scans.size(), 2u);
  CpuBackend cpu;
  // From the identity, 0.50 m and 0.7 degrees from relative.txt: twice the 25 cm bound's reach. (The
  // start as the odometry gives it: the constant-velocity model's first match would start at 2 m.)
  MappingSettings mapping;
  mapping.motion.model = MotionModel::kOdometry;
  mapping.retry_bound_factors.clear();
  mapping.recovery.enabled = false;
  const auto narrow = map_survey(survey.scans, mapping, cpu);
  ASSERT_EQ(narrow.doubtful(), std::vector<std::size_t>{1});
  EXPECT_NE(narrow.scans[1].health.doubt.find("out of reach"), std::string::npos) << narrow.scans[1].health.doubt;
  // That match converged right from out of reach: a second one from the scan's own features
  // (recovery) ends at the same pose, so with recovery on it is trusted, at the same pose.
  mapping.recovery.enabled = true;
  const auto confirmed = map_survey(survey.scans, mapping, cpu);
  ASSERT_TRUE(confirmed.doubtful().empty()) << confirmed.scans[1].health.doubt;
  EXPECT_TRUE(confirmed.scans[1].pose_cm == narrow.scans[1].pose_cm);
  EXPECT_NE(confirmed.scans[1].health.note.find("FPFH"), std::string::npos);
  // The default tries a doubtful match again from 1 m (then 4 m), coarse to fine: trusted, and right.
  MappingSettings from_odometry;
  from_odometry.motion.model = MotionModel::kOdometry;
  const auto retried = map_survey(survey.scans, from_odometry, cpu);
  ASSERT_TRUE(retried.doubtful().empty()) << retried.scans[1].health.doubt;
  EXPECT_EQ(retried.scans[1].health.retry_bound_cm, 100.0f);
  std::ifstream in(test::shared_data_dir() / "fast_gicp_pair" / "relative.txt");
  Pose relative = Pose::Identity();
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) in >> relative(r, c);
  }
  relative.block<3, 1>(0, 3) *= 100.0;  // m -> cm
  // The default, with no odometry, starts by constant velocity at 2 m (MotionSettings::initial_bound_cm):
  // trusted too, and at the same pose.
  const auto wide = map_survey(survey.scans, MappingSettings{}, cpu);
  ASSERT_TRUE(wide.doubtful().empty()) << wide.scans[1].health.doubt;
  for (const auto* result : {&retried, &wide}) {
    const Pose found = rigid_inverse(result->scans[0].pose_cm) * result->scans[1].pose_cm;
    const Pose difference = rigid_inverse(relative) * found;
    // The point-to-point minimum lies about 1 cm and 0.35 degrees from this GICP result (docs/benchmarks.md).
    EXPECT_LT(translation_norm(difference), 3.0);
    EXPECT_LT(rotation_angle_deg(difference), 0.6);
  }
}

TEST(HealthRealData, CarScansSevenMetresApartFromTheIdentityAreDoubtfulAtAnyBoundOrRight) {
  // KITTI 07 without its graph poses as a start: the car moves 3-12 m and turns up to 40 degrees
  // between these scans. A run that ends wrong must say so. (Before the constant-velocity motion
  // model, whose first match starts at 2 m, every run ended metres off; now each ends within 5 cm
  // of graph.txt, with false alarms: the reach test measures from the identity.)
  io::SurveyReadSettings read;
  auto survey = io::read_survey(test::shared_data_dir() / "kitti07_sequence", read);
  ASSERT_TRUE(survey.truth_cm.has_value());
  for (Scan& scan : survey.scans) scan.pose_cm = Pose::Identity();
  CpuBackend cpu;
  for (const float bound_cm : {25.0f, 100.0f, 300.0f}) {
    MappingSettings mapping;
    mapping.icp.max_pair_dist_cm = bound_cm;
    const auto result = map_survey(survey.scans, mapping, cpu);
    const auto errors = pose_errors(test::poses_of(result), *survey.truth_cm);
    std::printf("%g cm: mean error %.1f cm, %zu doubtful\n", double(bound_cm), errors.mean_translation_cm,
                result.doubtful().size());
    if (errors.mean_translation_cm > 30.0) {  // 1 % of the 29.5 m driven
      EXPECT_FALSE(result.doubtful().empty() && result.all_registered()) << bound_cm << " cm: a wrong map, trusted";
    }
  }
  // Started where an identity odometry says, every bound ends metres off, as it must: and says so.
  for (const float bound_cm : {25.0f, 100.0f, 300.0f}) {
    MappingSettings mapping;
    mapping.motion.model = MotionModel::kOdometry;
    mapping.icp.max_pair_dist_cm = bound_cm;
    const auto result = map_survey(survey.scans, mapping, cpu);
    const auto errors = pose_errors(test::poses_of(result), *survey.truth_cm);
    if (bound_cm == 25.0f) {
      ASSERT_GT(errors.mean_translation_cm, 100.0);  // wrong, as it must be from these starts
    }
    if (errors.mean_translation_cm > 30.0) {
      EXPECT_FALSE(result.doubtful().empty() && result.all_registered()) << bound_cm << " cm: a wrong map, trusted";
    }
  }
}

}  // namespace
}  // namespace minemap
