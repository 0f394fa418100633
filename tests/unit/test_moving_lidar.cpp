// The moving LiDAR simulator (sim/moving_lidar.hpp): determinism across thread counts, sweep times
// around the mid-sweep stamp, a standing sensor, the motion distortion (every point on the mine's
// surface under the pose AT ITS OWN TIME, off by about v T / 2 at the sweep's ends under the
// mid-sweep pose), the handheld's pattern, the path, odometry, and `minemap simulate`'s PCD output.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include "minemap/core/pose.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/sim/mine_geometry.hpp"
#include "minemap/sim/moving_lidar.hpp"
#include "test_support.hpp"

namespace minemap::sim {
namespace {

constexpr double kDegPerRad = 180.0 / std::numbers::pi;

MovingSimulationSettings sweeps_of(MovingSensor sensor, int sweeps, std::uint32_t seed = 5) {
  MovingSimulationSettings settings;
  settings.sensor = sensor;
  settings.sweeps = sweeps;
  settings.mine.seed = seed;
  return settings;
}

MovingSimulationSettings without_noise(MovingSimulationSettings settings) {
  settings.range_noise_sigma_cm = 0.0;
  return settings;
}

MovingSurvey simulate_with_threads(const MovingSimulationSettings& settings, int threads) {
  tbb::task_arena arena(threads);
  MovingSurvey survey;
  arena.execute([&] { survey = simulate_moving_survey(settings); });
  return survey;
}

Eigen::Vector3d apply(const Pose& pose, const Eigen::Vector3d& p) {
  return pose.block<3, 3>(0, 0) * p + pose.block<3, 1>(0, 3);
}

/// The true range along point p's beam, cast in the mine from the sensor's pose `pose_rh`
/// (right-handed world, cm); infinity when nothing is hit.
double true_range(const SensorTrajectory& trajectory, const Pose& pose_rh, const Eigen::Vector3d& p) {
  const Pose pose_3dtk = right_handed_pose_to_3dtk(pose_rh, 1.0);
  const Eigen::Vector3d direction = pose_3dtk.block<3, 3>(0, 0) * right_handed_to_3dtk(p.normalized(), 1.0);
  const RayHit hit = trajectory.world().cast_ray(Eigen::Vector3d(pose_3dtk.block<3, 1>(0, 3)), direction, 1e5);
  return hit.hit() ? hit.range_cm : std::numeric_limits<double>::infinity();
}

void expect_bit_identical(const MovingSurvey& a, const MovingSurvey& b) {
  ASSERT_EQ(a.scans.size(), b.scans.size());
  EXPECT_EQ(a.stamps_s, b.stamps_s);
  EXPECT_EQ(a.driven_distance_cm, b.driven_distance_cm);
  for (std::size_t k = 0; k < a.scans.size(); ++k) {
    EXPECT_EQ(a.scans[k].name, b.scans[k].name);
    EXPECT_TRUE(a.scans[k].points_cm == b.scans[k].points_cm) << "sweep " << k;
    EXPECT_EQ(a.scans[k].attributes.time_s, b.scans[k].attributes.time_s);
    EXPECT_EQ(a.scans[k].attributes.intensity, b.scans[k].attributes.intensity);
    EXPECT_EQ(a.scans[k].attributes.ring, b.scans[k].attributes.ring);
    EXPECT_EQ(a.scans[k].pose_cm, b.scans[k].pose_cm);
    EXPECT_EQ(a.truth_cm[k], b.truth_cm[k]);
  }
}

// ---------------------------------------------------------------------------------------------
// Determinism

TEST(MovingDeterminism, BitIdenticalForOneAndTwoThreads) {
  for (const MovingSensor sensor : {MovingSensor::kSpinning, MovingSensor::kHandheld}) {
    MovingSimulationSettings settings = sweeps_of(sensor, 2, 11);
    settings.odometry = true;
    settings.turn_deg_s = 20.0;
    expect_bit_identical(simulate_with_threads(settings, 1), simulate_with_threads(settings, 2));
  }
}

TEST(MovingDeterminism, SeedChangesTheSurveyAndFewerSweepsAreTheStart) {
  MovingSimulationSettings settings = sweeps_of(MovingSensor::kSpinning, 2, 1);
  settings.spinning.beams = 8;
  const MovingSurvey a = simulate_moving_survey(settings);
  settings.mine.seed = 2;
  const MovingSurvey b = simulate_moving_survey(settings);
  EXPECT_NE(a.scans[0].points_cm, b.scans[0].points_cm);
  settings.mine.seed = 1;
  settings.sweeps = 3;
  const MovingSurvey longer = simulate_moving_survey(settings);
  for (std::size_t k = 0; k < 2; ++k) {
    EXPECT_EQ(a.truth_cm[k], longer.truth_cm[k]);
    EXPECT_EQ(a.scans[k].points_cm, longer.scans[k].points_cm);
  }
}

// ---------------------------------------------------------------------------------------------
// Sweeps: times, layout, frames

TEST(MovingSweeps, TimesSpanHalfAPeriodAroundTheMidSweepStamp) {
  for (const MovingSensor sensor : {MovingSensor::kSpinning, MovingSensor::kHandheld}) {
    const MovingSimulationSettings settings = sweeps_of(sensor, 3);
    const MovingSurvey survey = simulate_moving_survey(settings);
    const double period = settings.sweep_period_s();
    ASSERT_EQ(survey.scans.size(), 3u);
    for (std::size_t k = 0; k < survey.scans.size(); ++k) {
      const Scan& scan = survey.scans[k];
      EXPECT_DOUBLE_EQ(survey.stamps_s[k], (static_cast<double>(k) + 0.5) * period);
      EXPECT_EQ(survey.truth_cm[k], survey.trajectory.T_world_sensor(survey.stamps_s[k]));
      EXPECT_EQ(scan.pose_cm, Pose::Identity()) << "no odometry unless asked for";
      EXPECT_TRUE(scan.slice_offsets.empty());
      ASSERT_EQ(scan.attributes.time_s.size(), scan.size());
      ASSERT_EQ(scan.attributes.intensity.size(), scan.size());
      EXPECT_EQ(scan.attributes.ring.size(), sensor == MovingSensor::kSpinning ? scan.size() : 0u);
      double lo = 1e9, hi = -1e9;
      for (std::size_t i = 0; i < scan.size(); ++i) {
        const double offset = scan.attributes.time_s[i] - survey.stamps_s[k];
        lo = std::min(lo, offset);
        hi = std::max(hi, offset);
        if (i > 0) {
          EXPECT_LE(scan.attributes.time_s[i - 1], scan.attributes.time_s[i]) << "in measuring order";
        }
      }
      EXPECT_GE(lo, -0.5 * period - 1e-12);
      EXPECT_LT(hi, 0.5 * period);
      EXPECT_LT(lo, -0.49 * period);
      EXPECT_GT(hi, 0.49 * period);
    }
  }
}

TEST(MovingSweeps, SpinningColumnsShareATimeAndSweepClockwiseFromBehind) {
  const MovingSimulationSettings settings = sweeps_of(MovingSensor::kSpinning, 1);
  const MovingSurvey survey = simulate_moving_survey(settings);
  const Scan& scan = survey.scans[0];
  const SpinningLidarSettings& lidar = settings.spinning;
  // Nearly every beam returns inside a mine.
  EXPECT_GT(scan.size(), static_cast<std::size_t>(0.95 * lidar.beams * lidar.columns));
  EXPECT_LE(scan.size(), static_cast<std::size_t>(lidar.beams * lidar.columns));
  const double step = settings.sweep_period_s() / lidar.columns;
  for (std::size_t i = 0; i < scan.size(); ++i) {
    const Eigen::Vector3d p = scan.points_cm[i].cast<double>();
    const double offset = scan.attributes.time_s[i] - survey.stamps_s[0];
    const double column = offset / step + 0.5 * lidar.columns;
    ASSERT_NEAR(column, std::round(column), 1e-6) << "a column's points share its time";
    const double azimuth = std::numbers::pi - 2.0 * std::numbers::pi * std::round(column) / lidar.columns;
    const double elevation = lidar.min_elevation_deg + (lidar.max_elevation_deg - lidar.min_elevation_deg) *
                                                           scan.attributes.ring[i] / (lidar.beams - 1);
    const Eigen::Vector3d expected(std::cos(elevation / kDegPerRad) * std::cos(azimuth),
                                   std::cos(elevation / kDegPerRad) * std::sin(azimuth),
                                   std::sin(elevation / kDegPerRad));
    ASSERT_LT((p.normalized() - expected).norm(), 1e-5) << "point " << i;
  }
}

TEST(MovingSweeps, HandheldRosetteHasThousandsOfPointsPerSweepInItsCone) {
  const MovingSimulationSettings settings = sweeps_of(MovingSensor::kHandheld, 3);
  const MovingSurvey survey = simulate_moving_survey(settings);
  for (const Scan& scan : survey.scans) {
    EXPECT_GE(scan.size(), 5000u);
    EXPECT_LE(scan.size(), 20000u);
    double widest_deg = 0.0;
    for (const Eigen::Vector3f& p : scan.points_cm) {
      const double off_axis = std::acos(std::clamp(static_cast<double>(p.normalized().x()), -1.0, 1.0)) * kDegPerRad;
      widest_deg = std::max(widest_deg, off_axis);
    }
    EXPECT_LE(widest_deg, 0.5 * settings.handheld.fov_deg + 1e-3);
    EXPECT_GT(widest_deg, 0.45 * settings.handheld.fov_deg);
  }
  // The pattern does not repeat from one sweep to the next.
  EXPECT_NE(survey.scans[0].points_cm.front(), survey.scans[1].points_cm.front());
}

TEST(MovingSweeps, TruthIsRightHandedZUpAlongTheDrive) {
  const MovingSurvey survey = simulate_moving_survey(sweeps_of(MovingSensor::kSpinning, 1));
  const Pose& pose = survey.truth_cm[0];
  EXPECT_TRUE(is_valid_rigid(pose));
  const Eigen::Matrix3d rotation = pose.block<3, 3>(0, 0);
  EXPECT_NEAR(rotation.determinant(), 1.0, 1e-9);
  EXPECT_GT(pose(0, 0), 0.99) << "sensor x (forward) along world x (the drive)";
  EXPECT_GT(pose(2, 2), 0.99) << "sensor z up";
  const SpinningLidarSettings lidar;
  EXPECT_NEAR(pose(2, 3), lidar.mount_height_cm, 60.0) << "mounted above the floor near z = 0";
  EXPECT_NEAR(pose(0, 3), 0.5 * lidar.speed_mps * 100.0 * 0.1, 5.0) << "half a sweep driven";
}

// ---------------------------------------------------------------------------------------------
// Standing and moving: the distortion

TEST(MovingDistortion, StandingSensorMeasuresFromOnePose) {
  MovingSimulationSettings settings = without_noise(sweeps_of(MovingSensor::kSpinning, 2));
  settings.speed_mps = 0.0;
  const MovingSurvey survey = simulate_moving_survey(settings);
  ASSERT_EQ(survey.scans.size(), 2u);
  EXPECT_EQ(survey.driven_distance_cm, 0.0);
  EXPECT_EQ(survey.truth_cm[0], survey.truth_cm[1]);
  // A standing spinning sensor sees the same sweep every turn...
  EXPECT_EQ(survey.scans[0].points_cm, survey.scans[1].points_cm);
  // ... and every point where a sensor standing at the truth would see it.
  const Scan& scan = survey.scans[0];
  for (std::size_t i = 0; i < scan.size(); i += 7) {
    const Eigen::Vector3d p = scan.points_cm[i].cast<double>();
    ASSERT_NEAR(true_range(survey.trajectory, survey.truth_cm[0], p), p.norm(), 0.01 + 1e-5 * p.norm()) << "point " << i;
  }
  // The handheld stands still too (its sway follows the distance walked).
  settings.sensor = MovingSensor::kHandheld;
  const MovingSurvey handheld = simulate_moving_survey(settings);
  EXPECT_EQ(handheld.trajectory.T_world_sensor(0.0), handheld.trajectory.T_world_sensor(0.2));
}

/// Every point lies on the mine's surface under the pose at its own time. Under the mid-sweep pose
/// a point taken dt from the middle is off by at least about v dt; by about v dt itself where the
/// sensor mostly translates (`translating`: the vehicle on a straight drive; the path's gentle
/// curve and the pitch and roll the rough floor gives it turn far points by a little more or less).
/// A walker's sway turns the handheld by about a degree in half a sweep: far points move more.
void check_distortion(const MovingSimulationSettings& settings, bool translating) {
  const MovingSurvey survey = simulate_moving_survey(settings);
  const double v_cm_s = 100.0 * survey.speed_mps;
  const double period = settings.sweep_period_s();
  std::vector<double> end_ratios;
  int checked = 0, off_surface = 0;
  for (std::size_t k = 0; k < survey.scans.size(); ++k) {
    const Scan& scan = survey.scans[k];
    const Pose& mid = survey.truth_cm[k];
    for (std::size_t i = 0; i < scan.size(); i += 5) {
      const Eigen::Vector3d p = scan.points_cm[i].cast<double>();
      const double t = scan.attributes.time_s[i];
      const Pose own = survey.trajectory.T_world_sensor(t);
      // float points: their direction is good to about 1e-7, which a ray grazing a rough surface
      // turns into a few millimetres of range now and then.
      const double error = std::abs(true_range(survey.trajectory, own, p) - p.norm());
      ASSERT_LT(error, 2.0) << "sweep " << k << " point " << i;
      checked += 1;
      off_surface += error > 0.02 + 1e-5 * p.norm() ? 1 : 0;
      const double dt = t - survey.stamps_s[k];
      if (std::abs(dt) > 0.45 * period) {
        // The sensor itself moved v |dt| along the path (the vehicle's pitching swings a roof mount
        // by a little more, the walker's bob by up to 2 cm).
        EXPECT_NEAR(translation_norm(rigid_inverse(mid) * own), v_cm_s * std::abs(dt), 0.05 * v_cm_s * std::abs(dt) + 2.0);
        end_ratios.push_back((apply(own, p) - apply(mid, p)).norm() / (v_cm_s * std::abs(dt)));
      }
    }
  }
  EXPECT_LT(off_surface, checked / 200) << "of " << checked << " points, more than 0.5 % off the surface";
  ASSERT_GT(end_ratios.size(), 50u);
  std::nth_element(end_ratios.begin(), end_ratios.begin() + end_ratios.size() / 2, end_ratios.end());
  const double median = end_ratios[end_ratios.size() / 2];
  if (translating) {
    EXPECT_NEAR(median, 1.0, 0.2) << "median offset at the sweep's ends over v |dt|";
  } else {
    EXPECT_GT(median, 0.8) << "median offset at the sweep's ends over v |dt|";
  }
}

TEST(MovingDistortion, SpinningAtTenMetresPerSecond) {
  check_distortion(without_noise(sweeps_of(MovingSensor::kSpinning, 2)), /*translating=*/true);
}

TEST(MovingDistortion, SpinningWhileTurning) {
  MovingSimulationSettings settings = without_noise(sweeps_of(MovingSensor::kSpinning, 2));
  settings.turn_deg_s = 90.0;
  const MovingSurvey survey = simulate_moving_survey(settings);
  // The weave is at its peak rate at t = 0: the first sweep turns by about 9 degrees.
  const Pose start = survey.trajectory.T_world_sensor(0.0);
  const Pose end = survey.trajectory.T_world_sensor(settings.sweep_period_s());
  EXPECT_NEAR(rotation_angle_deg(rigid_inverse(start) * end), 9.0, 1.0);
  check_distortion(settings, /*translating=*/false);
}

TEST(MovingDistortion, HandheldWithItsSway) {
  const MovingSimulationSettings settings = without_noise(sweeps_of(MovingSensor::kHandheld, 2));
  check_distortion(settings, /*translating=*/false);
  // The walker sways by a few degrees over a stride.
  const MovingSurvey survey = simulate_moving_survey(settings);
  double widest = 0.0;
  const Pose first = survey.trajectory.T_world_sensor(0.0);
  for (double t = 0.0; t < 2.0; t += 0.05) {
    widest = std::max(widest, rotation_angle_deg(rigid_inverse(first) * survey.trajectory.T_world_sensor(t)));
  }
  EXPECT_GT(widest, 2.0);
  EXPECT_LT(widest, 12.0);
}

TEST(MovingDistortion, RangeNoiseHasTheConfiguredSigma) {
  const MovingSimulationSettings settings = sweeps_of(MovingSensor::kSpinning, 1);
  const MovingSurvey survey = simulate_moving_survey(settings);
  const Scan& scan = survey.scans[0];
  double sum = 0.0, sum_sq = 0.0;
  int n = 0;
  for (std::size_t i = 0; i < scan.size(); i += 11) {
    const Eigen::Vector3d p = scan.points_cm[i].cast<double>();
    const double error = p.norm() - true_range(survey.trajectory, survey.trajectory.T_world_sensor(scan.attributes.time_s[i]), p);
    sum += error;
    sum_sq += error * error;
    ++n;
  }
  const double mean = sum / n;
  EXPECT_NEAR(mean, 0.0, 0.15);
  EXPECT_NEAR(std::sqrt(sum_sq / n - mean * mean), settings.range_noise_sigma_cm, 0.15);
}

// ---------------------------------------------------------------------------------------------
// The path and the odometry

TEST(MovingPath, SensorStaysInOpenSpaceAndALoopCloses) {
  for (const double loop_cm : {0.0, 15000.0}) {
    MovingSimulationSettings settings = sweeps_of(MovingSensor::kSpinning, 1);
    settings.spinning.beams = 1;
    settings.spinning.columns = 4;
    settings.mine.loop_length_cm = loop_cm;
    const SensorTrajectory trajectory = simulate_moving_survey(settings).trajectory;
    const double duration = trajectory.duration_s();
    ASSERT_TRUE(std::isfinite(duration));
    EXPECT_GT(trajectory.path_length_cm(), loop_cm > 0.0 ? 0.7 * loop_cm : settings.mine.drive_length_cm);
    for (double t = 0.0; t <= duration; t += 0.05) {
      const Pose pose = trajectory.T_world_sensor_3dtk(t);
      ASSERT_TRUE(trajectory.world().in_open_space(pose.block<3, 1>(0, 3))) << "loop " << loop_cm << " t " << t;
    }
    if (loop_cm > 0.0) {
      const Pose gap = rigid_inverse(trajectory.T_world_sensor(0.0)) * trajectory.T_world_sensor(duration);
      EXPECT_LT(translation_norm(gap), 1.0);
      EXPECT_LT(rotation_angle_deg(gap), 0.5);
    }
  }
}

TEST(MovingPath, OdometryStartsAtTruthAndDrifts) {
  MovingSimulationSettings settings = sweeps_of(MovingSensor::kSpinning, 30);
  settings.spinning.beams = 1;  // the poses are what is checked here
  settings.spinning.columns = 8;
  settings.odometry = true;
  const MovingSurvey survey = simulate_moving_survey(settings);
  ASSERT_EQ(survey.odometry_cm.size(), 30u);
  EXPECT_EQ(survey.odometry_cm[0], survey.truth_cm[0]);
  for (std::size_t k = 0; k < survey.scans.size(); ++k) EXPECT_EQ(survey.scans[k].pose_cm, survey.odometry_cm[k]);
  const Pose end_error = rigid_inverse(survey.truth_cm.back()) * survey.odometry_cm.back();
  EXPECT_GT(translation_norm(end_error), 5.0);    // 29 m driven: a 2 % slip alone is 58 cm
  EXPECT_LT(translation_norm(end_error), 300.0);
}

TEST(MovingSettings, InvalidSettingsAreRejected) {
  MovingSimulationSettings settings = sweeps_of(MovingSensor::kSpinning, 1);
  settings.rate_hz = 0.0;
  EXPECT_THROW(simulate_moving_survey(settings), std::invalid_argument);
  settings = sweeps_of(MovingSensor::kSpinning, 0);
  settings.speed_mps = 0.0;
  EXPECT_THROW(simulate_moving_survey(settings), std::invalid_argument) << "standing still needs a sweep count";
  settings = sweeps_of(MovingSensor::kSpinning, 1);
  settings.speed_mps = -1.0;
  EXPECT_THROW(simulate_moving_survey(settings), std::invalid_argument);
  settings = sweeps_of(MovingSensor::kSpinning, 1);
  settings.spinning.beams = 0;
  EXPECT_THROW(simulate_moving_survey(settings), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// `minemap simulate`: PCD sweeps with times, truth.tum; read back by read_survey and by `map`

TEST(MovingCli, PcdSweepsReadBackWithTheirTimesAndTruth) {
  test::TempDir dir;
  const std::string survey_dir = (dir / "survey").string();
  std::string output;
  ASSERT_EQ(test::run_cli("simulate --sensor spinning --scans 3 --speed-mps 2 --odometry --out " + survey_dir, &output), 0)
      << output;
  EXPECT_NE(output.find("simulated 3 sweeps"), std::string::npos) << output;
  for (const char* name : {"scan000.pcd", "scan001.pcd", "scan002.pcd", "truth.tum", "odometry.tum"}) {
    EXPECT_TRUE(std::filesystem::exists(dir / "survey" / name)) << name;
  }
  const io::Survey read = io::read_survey(survey_dir);
  EXPECT_EQ(read.format, "pcd");
  ASSERT_EQ(read.scans.size(), 3u);
  const std::vector<io::TimedPose> truth = io::read_tum(dir / "survey" / "truth.tum");
  const std::vector<io::TimedPose> odometry = io::read_tum(dir / "survey" / "odometry.tum");
  ASSERT_EQ(truth.size(), 3u);
  ASSERT_EQ(odometry.size(), 3u);

  MovingSimulationSettings settings = sweeps_of(MovingSensor::kSpinning, 3, MineSettings{}.seed);
  settings.speed_mps = 2.0;
  settings.odometry = true;
  const MovingSurvey expected = simulate_moving_survey(settings);
  for (std::size_t k = 0; k < 3; ++k) {
    const Scan& scan = read.scans[k];
    ASSERT_EQ(scan.size(), expected.scans[k].size());
    EXPECT_EQ(scan.attributes.time_s, expected.scans[k].attributes.time_s) << "times are written as doubles";
    EXPECT_EQ(scan.attributes.ring, expected.scans[k].attributes.ring);
    EXPECT_EQ(scan.attributes.intensity.size(), scan.size());
    EXPECT_NEAR(truth[k].timestamp_s, expected.stamps_s[k], 1e-9);
    EXPECT_LT(translation_norm(rigid_inverse(truth[k].pose_cm) * expected.truth_cm[k]), 0.01);
    EXPECT_LT(translation_norm(rigid_inverse(odometry[k].pose_cm) * expected.odometry_cm[k]), 0.01);
    // The PCD's VIEWPOINT carries the odometry pose (float metres, so to within a millimetre).
    EXPECT_LT(translation_norm(rigid_inverse(scan.pose_cm) * expected.odometry_cm[k]), 0.1);
    for (std::size_t i = 0; i < scan.size(); i += 97) {
      EXPECT_LT((scan.file_point(i) - expected.scans[k].points_cm[i].cast<double>()).norm(), 0.01);
    }
  }
}

TEST(MovingCli, MapReadsTheSweepsAndAgreesWithTheTruthFrame) {
  // Started at the truth, `map` keeps a slow sensor's sweeps within centimetres of it: the sweeps'
  // frame, truth.tum's and the PCD reader's agree (a mismatch would put the starts metres or tens
  // of degrees apart). Not zero: point-to-point ICP on a spinning sensor's rings, which move with
  // it, pulls each sweep back by part of its motion (about 5 cm at 0.5 m/s, 10 Hz).
  test::TempDir dir;
  const std::string survey_dir = (dir / "survey").string();
  std::string output;
  ASSERT_EQ(test::run_cli("simulate --sensor spinning --scans 4 --speed-mps 0.5 --out " + survey_dir, &output), 0)
      << output;
  const std::string truth = survey_dir + "/truth.tum";
  ASSERT_EQ(test::run_cli("map " + survey_dir + " --out " + (dir / "out").string() + " --backend cpu --initial-poses " +
                              truth + " --reference-poses " + truth,
                          &output),
            0)
      << output;
  const std::vector<std::string> lines = test::lines_containing(output, "registered mean");
  ASSERT_EQ(lines.size(), 1u) << output;
  double mean_m = 1e9, max_m = 1e9, rotation_deg = 1e9;
  const std::string& line = lines[0];
  ASSERT_EQ(std::sscanf(line.c_str() + line.find("registered mean"), "registered mean %lf m", &mean_m), 1) << line;
  ASSERT_EQ(std::sscanf(line.c_str() + line.find("max"), "max %lf m", &max_m), 1) << line;
  ASSERT_EQ(std::sscanf(line.c_str() + line.find("mean rotation"), "mean rotation %lf deg", &rotation_deg), 1) << line;
  EXPECT_LT(mean_m, 0.15) << line;
  EXPECT_LT(max_m, 0.25) << line;
  EXPECT_LT(rotation_deg, 1.0) << line;
}

TEST(MovingCli, TiltingStaysTheDefaultAndRefusesMovingOptions) {
  test::TempDir dir;
  std::string output;
  ASSERT_EQ(test::run_cli("simulate --scans 2 --out " + (dir / "tilting").string(), &output), 0) << output;
  EXPECT_TRUE(std::filesystem::exists(dir / "tilting" / "scan001.3d"));
  EXPECT_EQ(test::run_cli("simulate --scans 2 --speed-mps 3 --out " + (dir / "bad").string(), &output), 2) << output;
  EXPECT_EQ(test::run_cli("simulate --sensor handheld --beams 16 --scans 1 --out " + (dir / "bad").string(), &output), 2)
      << output;
  EXPECT_EQ(test::run_cli("simulate --sensor spinning --step-m 1 --scans 1 --out " + (dir / "bad").string(), &output), 2)
      << output;
  // Sweeps are not written over a folder that holds another survey's scans.
  EXPECT_EQ(test::run_cli("simulate --sensor spinning --scans 1 --out " + (dir / "tilting").string(), &output), 5)
      << output;
}

}  // namespace
}  // namespace minemap::sim
