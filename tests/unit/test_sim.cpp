// The simulated mine survey: determinism across thread counts, the scanner's geometry, the mine's
// ground truth, the drive and the odometry, noise and outliers, overlap of consecutive scans.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <unordered_map>
#include <vector>

#include "minemap/core/pose.hpp"
#include "minemap/sim/mine_geometry.hpp"
#include "minemap/sim/mine_simulator.hpp"
#include "minemap/sim/scanner.hpp"
#include "minemap/sim/trajectory.hpp"

namespace minemap::sim {
namespace {

constexpr double kDegPerRad = 180.0 / std::numbers::pi;
constexpr int kPaperPointsPerScan = 361 * 341;  // 123,101: every beam returns

SimulationSettings few_scans(int scans, std::uint32_t seed = 7) {
  SimulationSettings settings;
  settings.mine.scans = scans;
  settings.mine.seed = seed;
  return settings;
}

/// Same mine and drive, a coarser scanner: for checks that need many runs, not full density.
SimulationSettings coarse(SimulationSettings settings) {
  settings.scanner.points_per_slice = 91;  // 2 deg steps
  settings.scanner.slices = 61;            // 1 deg steps
  return settings;
}

SimulationSettings without_errors(SimulationSettings settings) {
  settings.scanner.range_noise_sigma_cm = 0.0;
  settings.scanner.mixed_pixel_probability = 0.0;
  settings.scanner.reflection_probability = 0.0;
  return settings;
}

SimulatedSurvey simulate_with_threads(const SimulationSettings& settings, int threads) {
  tbb::task_arena arena(threads);
  SimulatedSurvey survey;
  arena.execute([&] { survey = simulate_mine_survey(settings); });
  return survey;
}

Eigen::Vector3d to_world(const Pose& pose, const Eigen::Vector3f& p) {
  return pose.block<3, 3>(0, 0) * p.cast<double>() + pose.block<3, 1>(0, 3);
}

/// A hash grid for "is there a point within r of q" on one scan's points (brute force per cell).
class PointGrid {
 public:
  PointGrid(const std::vector<Eigen::Vector3d>& points, double cell_cm) : points_(points), cell_(cell_cm) {
    for (std::size_t i = 0; i < points.size(); ++i) cells_[key(cell_of(points[i]))].push_back(i);
  }
  double nearest_distance(const Eigen::Vector3d& q) const {
    const Eigen::Vector3i c = cell_of(q);
    double best = std::numeric_limits<double>::infinity();
    for (int dx = -1; dx <= 1; ++dx) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = cells_.find(key(c + Eigen::Vector3i(dx, dy, dz)));
          if (it == cells_.end()) continue;
          for (const std::size_t i : it->second) best = std::min(best, (points_[i] - q).norm());
        }
      }
    }
    return best;  // exact whenever it is below the cell size
  }

 private:
  Eigen::Vector3i cell_of(const Eigen::Vector3d& p) const {
    return (p / cell_).array().floor().cast<int>();
  }
  static std::int64_t key(const Eigen::Vector3i& c) {
    return (static_cast<std::int64_t>(c.x()) * 73856093) ^ (static_cast<std::int64_t>(c.y()) * 19349663) ^
           (static_cast<std::int64_t>(c.z()) * 83492791);
  }
  const std::vector<Eigen::Vector3d>& points_;
  double cell_;
  std::unordered_map<std::int64_t, std::vector<std::size_t>> cells_;
};

/// One full-resolution 4-scan survey, shared by the read-only checks.
class SimSurvey : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    settings_ = new SimulationSettings(few_scans(4));
    survey_ = new SimulatedSurvey(simulate_mine_survey(*settings_));
  }
  static void TearDownTestSuite() {
    delete survey_;
    delete settings_;
    survey_ = nullptr;
    settings_ = nullptr;
  }
  static SimulationSettings* settings_;
  static SimulatedSurvey* survey_;
};
SimulationSettings* SimSurvey::settings_ = nullptr;
SimulatedSurvey* SimSurvey::survey_ = nullptr;

// ---------------------------------------------------------------------------------------------
// Determinism

TEST(SimDeterminism, BitIdenticalForOneAndTwoThreads) {
  const SimulationSettings settings = few_scans(3, 11);
  const SimulatedSurvey a = simulate_with_threads(settings, 1);
  const SimulatedSurvey b = simulate_with_threads(settings, 2);
  ASSERT_EQ(a.scans.size(), 3u);
  ASSERT_EQ(a.scans.size(), b.scans.size());
  EXPECT_EQ(a.driven_distance_cm, b.driven_distance_cm);
  for (std::size_t k = 0; k < a.scans.size(); ++k) {
    EXPECT_EQ(a.scans[k].name, b.scans[k].name);
    EXPECT_EQ(a.scans[k].slice_offsets, b.scans[k].slice_offsets);
    ASSERT_EQ(a.scans[k].points_cm.size(), b.scans[k].points_cm.size());
    const auto mismatch = std::mismatch(a.scans[k].points_cm.begin(), a.scans[k].points_cm.end(),
                                        b.scans[k].points_cm.begin());
    EXPECT_TRUE(mismatch.first == a.scans[k].points_cm.end())
        << "scan " << k << " differs at point " << (mismatch.first - a.scans[k].points_cm.begin());
    EXPECT_EQ(a.scans[k].pose_cm, b.scans[k].pose_cm);
    EXPECT_EQ(a.truth_cm[k], b.truth_cm[k]);
  }
}

TEST(SimDeterminism, SeedChangesTheSurvey) {
  const SimulatedSurvey a = simulate_mine_survey(coarse(few_scans(2, 1)));
  const SimulatedSurvey b = simulate_mine_survey(coarse(few_scans(2, 2)));
  EXPECT_NE(a.truth_cm[1], b.truth_cm[1]);
  EXPECT_NE(a.scans[0].points_cm, b.scans[0].points_cm);
}

TEST(SimDeterminism, ShortSurveyIsTheStartOfTheLongOne) {
  // The mine does not depend on the number of scans, and stop k is the same in both.
  const SimulatedSurvey shorter = simulate_mine_survey(coarse(few_scans(2)));
  const SimulatedSurvey longer = simulate_mine_survey(coarse(few_scans(4)));
  for (std::size_t k = 0; k < 2; ++k) {
    EXPECT_EQ(shorter.truth_cm[k], longer.truth_cm[k]);
    EXPECT_EQ(shorter.scans[k].pose_cm, longer.scans[k].pose_cm);
    EXPECT_EQ(shorter.scans[k].points_cm, longer.scans[k].points_cm);
  }
}

// ---------------------------------------------------------------------------------------------
// The scanner's geometry (full resolution)

TEST_F(SimSurvey, ScansHaveThePapersShape) {
  const ScannerSettings& sc = settings_->scanner;
  ASSERT_EQ(survey_->scans.size(), 4u);
  ASSERT_EQ(survey_->truth_cm.size(), 4u);
  for (std::size_t k = 0; k < survey_->scans.size(); ++k) {
    const Scan& scan = survey_->scans[k];
    EXPECT_EQ(scan.name, "scan00" + std::to_string(k));
    EXPECT_NO_THROW(scan.validate());
    ASSERT_EQ(scan.num_slices(), 341u);
    for (std::size_t i = 0; i < scan.num_slices(); ++i) EXPECT_LE(scan.slice(i).size(), 361u);
    // Almost every beam returns in a tunnel, as in the paper's scan (123,101 points).
    EXPECT_GE(scan.size(), 100000u);
    EXPECT_LE(scan.size(), static_cast<std::size_t>(kPaperPointsPerScan));
    for (const Eigen::Vector3f& p : scan.points_cm) {
      const double range = p.cast<double>().norm();
      ASSERT_GE(range, sc.min_range_cm - 1e-3);
      ASSERT_LE(range, sc.max_range_cm + 1e-3);
    }
  }
}

TEST_F(SimSurvey, SliceHasOneTiltAndCounterClockwiseOrder) {
  const ScannerModel model(settings_->scanner);
  const Scan& scan = survey_->scans[1];
  for (std::size_t i = 0; i < scan.num_slices(); ++i) {
    const double tilt = model.tilt_deg(static_cast<int>(i));
    double previous_sweep = -1e9;
    for (const Eigen::Vector3f& pf : scan.slice(i)) {
      const Eigen::Vector3d p = pf.cast<double>();
      const double range = p.norm();
      // Sweep angle: -90 deg at the right (+x), +90 at the left; strictly increasing in a slice.
      const double sweep = std::asin(std::clamp(-p.x() / range, -1.0, 1.0)) * kDegPerRad;
      EXPECT_GT(sweep, previous_sweep) << "slice " << i;
      previous_sweep = sweep;
      // The tilt is the elevation of the beam in its tilted plane (defined away from +-90 deg).
      if (std::abs(p.x()) < 0.9 * range) {
        EXPECT_NEAR(std::atan2(p.y(), p.z()) * kDegPerRad, tilt, 1e-3) << "slice " << i;
      }
    }
  }
  EXPECT_DOUBLE_EQ(model.tilt_deg(0), -30.0);
  EXPECT_DOUBLE_EQ(model.tilt_deg(340), 30.0);
  EXPECT_DOUBLE_EQ(model.sweep_deg(0), -90.0);
  EXPECT_DOUBLE_EQ(model.sweep_deg(180), 0.0);
}

// ---------------------------------------------------------------------------------------------
// Truth and odometry

TEST_F(SimSurvey, OdometryStartsAtTruthAndThenDeviates) {
  EXPECT_EQ(survey_->scans[0].pose_cm, survey_->truth_cm[0]);
  for (std::size_t k = 1; k < survey_->scans.size(); ++k) {
    const Pose error = rigid_inverse(survey_->truth_cm[k]) * survey_->scans[k].pose_cm;
    EXPECT_GT(translation_norm(error) + rotation_angle_deg(error), 0.5) << "scan " << k;
    EXPECT_TRUE(is_valid_rigid(survey_->scans[k].pose_cm));
    EXPECT_TRUE(is_valid_rigid(survey_->truth_cm[k]));
  }
  // Stop-and-go along +z, mean_step_cm apart (jittered by +-10 % per stop).
  const double step = settings_->mine.mean_step_cm;
  const double steps = static_cast<double>(survey_->scans.size() - 1);
  EXPECT_GT(survey_->driven_distance_cm, 0.75 * steps * step);
  EXPECT_LT(survey_->driven_distance_cm, 1.25 * steps * step);
  EXPECT_NEAR(survey_->driven_distance_cm, path_length_cm(survey_->truth_cm), 1e-9);
}

/// The whole default drive, poses only (no scanning).
struct Drive {
  std::vector<ScanStop> stops;
  std::vector<Pose> truth;
  std::vector<Pose> odometry;
};
Drive default_drive(const SimulationSettings& settings) {
  Drive drive;
  drive.stops = plan_stops(settings.mine);
  const MineWorld world(settings.mine, drive.stops.back().z_cm);
  for (const ScanStop& stop : drive.stops) {
    drive.truth.push_back(robot_pose_on_floor(world, stop, settings.scanner.mount_height_cm));
    EXPECT_TRUE(world.in_open_space(drive.truth.back().block<3, 1>(0, 3))) << "stop at z " << stop.z_cm;
  }
  drive.odometry = simulate_odometry(drive.truth, settings.odometry, settings.mine.seed);
  return drive;
}

TEST(SimDrive, FullDriveCoversTheDriveLengthAndRisesByTheGain) {
  const SimulationSettings settings;
  const Drive drive = default_drive(settings);
  ASSERT_EQ(drive.stops.size(), static_cast<std::size_t>(planned_scan_count(settings.mine)));
  EXPECT_EQ(drive.stops.front().z_cm, 0.0);
  EXPECT_NEAR(drive.stops.back().z_cm, settings.mine.drive_length_cm, 0.11 * settings.mine.mean_step_cm);
  const double length = path_length_cm(drive.truth);
  EXPECT_GT(length, settings.mine.drive_length_cm * 0.98);
  EXPECT_LT(length, settings.mine.drive_length_cm * 1.05);
  // The paper: 4 m of elevation over the 250 m drive.
  const double rise = drive.truth.back()(1, 3) - drive.truth.front()(1, 3);
  EXPECT_NEAR(rise, settings.mine.elevation_gain_cm, 40.0);
  // The robot stands on the floor: pitch and roll follow it (never flat, never wild).
  double max_tilt_deg = 0.0;
  for (const Pose& pose : drive.truth) {
    const double tilt = std::acos(std::clamp(pose(1, 1), -1.0, 1.0)) * kDegPerRad;  // body up vs world up
    max_tilt_deg = std::max(max_tilt_deg, tilt);
  }
  EXPECT_GT(max_tilt_deg, 0.5);
  EXPECT_LT(max_tilt_deg, 8.0);
}

// The loop survey: around the pillars right of the drive and back. Every stop stands in open space
// (in the entries and cross-cuts, never in a pillar), the loop is about as long as asked, its last
// stop is its first again, and it goes round (through the parallel entry, x beyond the pillars).
TEST(SimDrive, LoopSurveyGoesAroundThePillarsAndBackToItsStart) {
  for (const std::uint32_t seed : {1u, 7u}) {
    SimulationSettings settings;
    settings.mine.seed = seed;
    settings.mine.loop_length_cm = 12000.0;
    const MineWorld world(settings.mine, settings.mine.drive_length_cm);
    const std::vector<ScanStop> stops = plan_loop_stops(settings.mine, world);
    std::vector<Pose> truth;
    double max_x = 0.0;
    for (const ScanStop& stop : stops) {
      truth.push_back(robot_pose_on_floor(world, stop, settings.scanner.mount_height_cm));
      EXPECT_TRUE(world.in_open_space(truth.back().block<3, 1>(0, 3))) << "seed " << seed << " stop at x " << stop.x_cm
                                                                       << " z " << stop.z_cm;
      max_x = std::max(max_x, stop.x_cm);
    }
    const double length = path_length_cm(truth);
    EXPECT_GT(length, 0.7 * settings.mine.loop_length_cm) << "seed " << seed;
    EXPECT_LT(length, 1.4 * settings.mine.loop_length_cm) << "seed " << seed;
    EXPECT_GT(max_x, world.entries()[1].x_min_cm) << "seed " << seed;  // reached the parallel entry
    const Pose closure = rigid_inverse(truth.front()) * truth.back();
    EXPECT_LT(translation_norm(closure), 30.0) << "seed " << seed;
    EXPECT_LT(rotation_angle_deg(closure), 5.0) << "seed " << seed;
    EXPECT_NEAR(stops.size(), std::lround(length / settings.mine.mean_step_cm) + 1, 2.0) << "seed " << seed;
    // A shorter survey is the start of the loop.
    settings.mine.scans = 5;
    const std::vector<ScanStop> start = plan_loop_stops(settings.mine, world);
    ASSERT_EQ(start.size(), 5u);
    EXPECT_EQ(start[4].z_cm, stops[4].z_cm);
    // A longer one drives round again: each lap starts at the first scan's place, and its stops are
    // the first lap's again (their jitter aside, within a step).
    const std::size_t lap = stops.size() - 1;
    settings.mine.scans = static_cast<int>(2 * lap + 3);
    const std::vector<ScanStop> laps = plan_loop_stops(settings.mine, world);
    ASSERT_EQ(laps.size(), 2 * lap + 3);
    for (const std::size_t k : {lap, 2 * lap}) {
      EXPECT_EQ(laps[k].x_cm, stops.front().x_cm) << "seed " << seed << " stop " << k;
      EXPECT_EQ(laps[k].z_cm, stops.front().z_cm) << "seed " << seed << " stop " << k;
    }
    for (std::size_t k = 1; k < lap; ++k) {
      EXPECT_LT(std::hypot(laps[lap + k].x_cm - stops[k].x_cm, laps[lap + k].z_cm - stops[k].z_cm),
                settings.mine.mean_step_cm) << "seed " << seed << " stop " << lap + k;
    }
  }
}

// `minemap simulate` writes a long survey a part at a time: the same scans, bit for bit, as the
// survey simulated at once, whatever the part's size; the truth and the distance alike.
TEST(SimDrive, ASurveySimulatedInPartsIsTheSurveySimulatedAtOnce) {
  SimulationSettings settings;
  settings.mine.scans = 7;
  const SimulatedSurvey whole = simulate_mine_survey(settings);
  std::vector<Scan> scans;
  std::vector<std::size_t> firsts;
  const SimulatedSurvey parts =
      simulate_mine_survey_in_parts(settings, 3, [&](std::vector<Scan>& part, std::size_t first, std::size_t total) {
        EXPECT_EQ(total, 7u);
        EXPECT_LE(part.size(), 3u);
        firsts.push_back(first);
        for (Scan& scan : part) scans.push_back(std::move(scan));
      });
  EXPECT_EQ(firsts, (std::vector<std::size_t>{0, 3, 6}));
  EXPECT_TRUE(parts.scans.empty());
  ASSERT_EQ(scans.size(), whole.scans.size());
  for (std::size_t i = 0; i < scans.size(); ++i) {
    EXPECT_EQ(scans[i].name, whole.scans[i].name);
    EXPECT_TRUE(scans[i].pose_cm == whole.scans[i].pose_cm) << "scan " << i;
    EXPECT_EQ(scans[i].points_cm, whole.scans[i].points_cm) << "scan " << i;
    EXPECT_EQ(scans[i].slice_offsets, whole.scans[i].slice_offsets) << "scan " << i;
  }
  EXPECT_EQ(parts.truth_cm, whole.truth_cm);
  EXPECT_EQ(parts.driven_distance_cm, whole.driven_distance_cm);
}

TEST(SimDrive, ElevationGainFollowsTheSetting) {
  SimulationSettings settings;
  settings.mine.elevation_gain_cm = 1000.0;
  settings.mine.seed = 3;
  const Drive drive = default_drive(settings);
  EXPECT_NEAR(drive.truth.back()(1, 3) - drive.truth.front()(1, 3), 1000.0, 40.0);
}

TEST(SimDrive, OdometryDriftGrowsToMetresAndDegrees) {
  const SimulationSettings settings;
  const Drive drive = default_drive(settings);
  const auto error_at = [&](std::size_t k) -> Pose { return rigid_inverse(drive.truth[k]) * drive.odometry[k]; };
  EXPECT_EQ(drive.odometry[0], drive.truth[0]);
  const std::size_t last = drive.truth.size() - 1;
  const Pose end_error = error_at(last);
  EXPECT_GT(translation_norm(end_error), 300.0);  // metres
  EXPECT_GT(rotation_angle_deg(end_error), 2.0);  // degrees
  const auto position_error = [&](std::size_t k) {
    return (drive.truth[k].block<3, 1>(0, 3) - drive.odometry[k].block<3, 1>(0, 3)).norm();
  };
  const double quarter = position_error(last / 4);
  const double half = position_error(last / 2);
  const double end = position_error(last);
  EXPECT_LT(quarter, half);
  EXPECT_LT(half, end);
  // One step's error stays small: what ICP has to fix per scan pair.
  for (std::size_t k = 1; k <= last; ++k) {
    const Pose true_step = rigid_inverse(drive.truth[k - 1]) * drive.truth[k];
    const Pose odo_step = rigid_inverse(drive.odometry[k - 1]) * drive.odometry[k];
    const Pose step_error = rigid_inverse(true_step) * odo_step;
    EXPECT_LT(translation_norm(step_error), 35.0) << "step " << k;
    EXPECT_LT(rotation_angle_deg(step_error), 2.0) << "step " << k;
  }
}

// ---------------------------------------------------------------------------------------------
// Noise and outliers

TEST(SimErrors, RangeNoiseHasTheConfiguredSigma) {
  SimulationSettings clean = without_errors(few_scans(1, 5));
  SimulationSettings noisy = clean;
  noisy.scanner.range_noise_sigma_cm = 1.5;
  const Scan a = simulate_mine_survey(clean).scans[0];
  const Scan b = simulate_mine_survey(noisy).scans[0];
  double sum = 0.0, sum_sq = 0.0;
  std::size_t count = 0;
  for (std::size_t i = 0; i < a.num_slices(); ++i) {
    // Beams drop out only near the range limits; compare slices where none did.
    if (a.slice(i).size() != b.slice(i).size()) continue;
    for (std::size_t j = 0; j < a.slice(i).size(); ++j) {
      const double d = b.slice(i)[j].cast<double>().norm() - a.slice(i)[j].cast<double>().norm();
      sum += d;
      sum_sq += d * d;
      ++count;
    }
  }
  ASSERT_GT(count, 100000u);
  const double mean = sum / count;
  const double sigma = std::sqrt(sum_sq / count - mean * mean);
  EXPECT_NEAR(mean, 0.0, 0.05);
  EXPECT_NEAR(sigma, 1.5, 0.05);
}

/// Points whose range differs from both slice neighbours' by more than `jump_cm` the same way.
std::size_t isolated_points(const Scan& scan, double jump_cm) {
  std::size_t count = 0;
  for (std::size_t i = 0; i < scan.num_slices(); ++i) {
    const auto slice = scan.slice(i);
    for (std::size_t j = 1; j + 1 < slice.size(); ++j) {
      const double r = slice[j].norm();
      const double before = r - slice[j - 1].norm();
      const double after = r - slice[j + 1].norm();
      if (std::abs(before) > jump_cm && std::abs(after) > jump_cm && (before > 0) == (after > 0)) ++count;
    }
  }
  return count;
}

TEST(SimErrors, OutliersStandOutInTheirSlices) {
  const SimulationSettings noisy = few_scans(1, 5);
  SimulationSettings clean = noisy;
  clean.scanner.mixed_pixel_probability = 0.0;
  clean.scanner.reflection_probability = 0.0;
  // Salt and pepper: points far from both slice neighbours, the way the paper's median filter sees
  // them. Reflections alone give ~0.2 % of 123k beams.
  const std::size_t isolated = isolated_points(simulate_mine_survey(noisy).scans[0], 50.0);
  const std::size_t isolated_clean = isolated_points(simulate_mine_survey(clean).scans[0], 50.0);
  EXPECT_GT(isolated, isolated_clean + 150) << isolated << " vs " << isolated_clean;
  EXPECT_LT(isolated, isolated_clean + 1000) << isolated << " vs " << isolated_clean;
}

/// Scans `settings` (1 scan) and pairs every point with its beam's true range and its neighbours'.
struct BeamRecord {
  double measured;
  double truth;
  double before;  ///< true range of the previous beam (infinity: none)
  double after;
};
std::vector<BeamRecord> beam_records(const SimulationSettings& settings) {
  const SimulatedSurvey survey = simulate_mine_survey(settings);
  const MineWorld world(settings.mine, plan_stops(settings.mine).back().z_cm);
  const ScannerModel model(settings.scanner);
  const Scan& scan = survey.scans[0];
  std::vector<BeamRecord> records;
  for (int i = 0; i < model.slices(); ++i) {
    const std::vector<double> truth = model.true_ranges(world, survey.truth_cm[0], i);
    const auto slice = scan.slice(static_cast<std::size_t>(i));
    std::size_t next = 0;
    for (std::size_t j = 0; j < truth.size(); ++j) {
      if (!std::isfinite(truth[j])) continue;
      EXPECT_LT(next, slice.size());
      if (next >= slice.size()) break;
      // Without noise, a beam whose measured direction matches is this beam.
      const Eigen::Vector3d dir = slice[next].cast<double>().normalized();
      if ((dir - model.direction(i, static_cast<int>(j))).norm() > 1e-5) continue;  // dropped beam
      const double inf = std::numeric_limits<double>::infinity();
      records.push_back({slice[next].cast<double>().norm(), truth[j], j > 0 ? truth[j - 1] : inf,
                         j + 1 < truth.size() ? truth[j + 1] : inf});
      ++next;
    }
    EXPECT_EQ(next, slice.size()) << "slice " << i;
  }
  return records;
}

TEST(SimErrors, MixedPixelsLieBetweenTheTwoSurfaces) {
  SimulationSettings settings = coarse(without_errors(few_scans(1, 6)));
  settings.scanner.mixed_pixel_probability = 0.3;
  std::size_t mixed = 0;
  for (const BeamRecord& b : beam_records(settings)) {
    if (std::abs(b.measured - b.truth) < 1e-2) continue;
    ++mixed;
    // Between its own surface and one neighbour's, never beyond either.
    const bool between_before = std::isfinite(b.before) && b.measured > std::min(b.truth, b.before) &&
                                b.measured < std::max(b.truth, b.before);
    const bool between_after = std::isfinite(b.after) && b.measured > std::min(b.truth, b.after) &&
                               b.measured < std::max(b.truth, b.after);
    EXPECT_TRUE(between_before || between_after) << b.measured << " truth " << b.truth;
  }
  EXPECT_GT(mixed, 20u);
}

TEST(SimErrors, ReflectionsAreRareSpuriousRanges) {
  SimulationSettings settings = without_errors(few_scans(1, 6));
  settings.scanner.reflection_probability = 0.002;
  std::size_t spurious = 0, beams = 0;
  for (const BeamRecord& b : beam_records(settings)) {
    ++beams;
    if (std::abs(b.measured - b.truth) < 1e-2) continue;
    ++spurious;
    const double ratio = b.measured / b.truth;
    EXPECT_TRUE((ratio > 0.1 && ratio < 0.85) || (ratio > 1.15 && ratio < 2.6)) << ratio;
  }
  // Binomial(123k, 0.002): 246 +- 16; beams pushed past max range drop out.
  EXPECT_GT(spurious, 150u);
  EXPECT_LT(spurious, 350u);
  EXPECT_GT(beams, 100000u);
}

// ---------------------------------------------------------------------------------------------
// Overlap and ground truth

TEST_F(SimSurvey, ConsecutiveScansOverlapUnderTruePoses) {
  for (std::size_t k = 0; k + 1 < survey_->scans.size(); ++k) {
    const Scan& a = survey_->scans[k];
    const Scan& b = survey_->scans[k + 1];
    std::vector<Eigen::Vector3d> a_world;
    a_world.reserve(a.size());
    for (const Eigen::Vector3f& p : a.points_cm) a_world.push_back(to_world(survey_->truth_cm[k], p));
    const PointGrid grid(a_world, 10.0);
    std::size_t near = 0, total = 0;
    for (std::size_t i = 0; i < b.size(); i += 53) {
      ++total;
      if (grid.nearest_distance(to_world(survey_->truth_cm[k + 1], b.points_cm[i])) <= 10.0) ++near;
    }
    const double fraction = static_cast<double>(near) / total;
    EXPECT_GT(fraction, 0.6) << "scans " << k << "," << k + 1;
  }
}

TEST(SimGroundTruth, RibPointsSeenFromTwoScansCoincide) {
  // Noise-free: a rib point of scan 1, looked at again from scan 0's true pose, lies on the surface
  // that ray hits (or behind something closer), never in free space.
  const SimulationSettings settings = without_errors(few_scans(2, 9));
  const SimulatedSurvey survey = simulate_mine_survey(settings);
  const std::vector<ScanStop> stops = plan_stops(settings.mine);
  const MineWorld world(settings.mine, stops.back().z_cm);
  const Eigen::Vector3d o0 = survey.truth_cm[0].block<3, 1>(0, 3);
  const Eigen::Vector3d o1 = survey.truth_cm[1].block<3, 1>(0, 3);
  std::size_t ribs = 0, same = 0, occluded = 0, through = 0;
  const Scan& scan = survey.scans[1];
  for (std::size_t i = 0; i < scan.size(); i += 7) {
    const Eigen::Vector3d p = to_world(survey.truth_cm[1], scan.points_cm[i]);
    const Eigen::Vector3d from1 = p - o1;
    const RayHit own = world.cast_ray(o1, from1.normalized(), settings.scanner.max_range_cm);
    if (own.kind != SurfaceKind::kRib) continue;
    ++ribs;
    const Eigen::Vector3d from0 = p - o0;
    const RayHit other = world.cast_ray(o0, from0.normalized(), settings.scanner.max_range_cm);
    const double distance = from0.norm();
    if (std::abs(other.range_cm - distance) < 0.5) {
      ++same;
    } else if (other.range_cm < distance) {
      ++occluded;
    } else {
      ++through;
    }
  }
  ASSERT_GT(ribs, 2000u);
  EXPECT_GT(static_cast<double>(same) / ribs, 0.5) << same << " of " << ribs << ", occluded " << occluded;
  EXPECT_LT(static_cast<double>(through) / ribs, 0.01) << through << " of " << ribs;
}

TEST(SimGroundTruth, PointsLieOnTheMinesSurfaces) {
  // Noise-free points are their beams' true ranges, and floor and roof hits lie on the height fields.
  const SimulationSettings settings = coarse(without_errors(few_scans(1, 4)));
  const SimulatedSurvey survey = simulate_mine_survey(settings);
  const MineWorld world(settings.mine, plan_stops(settings.mine).back().z_cm);
  const ScannerModel model(settings.scanner);
  const Pose& pose = survey.truth_cm[0];
  const Eigen::Vector3d origin = pose.block<3, 1>(0, 3);
  std::size_t kinds[5] = {0, 0, 0, 0, 0};
  for (int i = 0; i < model.slices(); ++i) {
    const auto slice = survey.scans[0].slice(static_cast<std::size_t>(i));
    std::size_t next = 0;
    for (int j = 0; j < model.points_per_slice(); ++j) {
      const Eigen::Vector3d dir = pose.block<3, 3>(0, 0) * model.direction(i, j);
      const RayHit hit = world.cast_ray(origin, dir, settings.scanner.max_range_cm);
      if (!hit.hit() || hit.range_cm < settings.scanner.min_range_cm) continue;
      ASSERT_LT(next, slice.size());
      EXPECT_NEAR(slice[next++].cast<double>().norm(), hit.range_cm, 1e-3 * std::max(1.0, hit.range_cm / 1000.0));
      ++kinds[static_cast<int>(hit.kind)];
      const Eigen::Vector3d p = origin + hit.range_cm * dir;
      if (hit.kind == SurfaceKind::kFloor) {
        EXPECT_NEAR(p.y(), world.floor_height(p.x(), p.z()).value, 0.02);
      } else if (hit.kind == SurfaceKind::kRoof) {
        EXPECT_NEAR(p.y(), world.roof_height(p.x(), p.z()).value, 0.02);
      }
    }
    EXPECT_EQ(next, slice.size());
  }
  // A tunnel: floor, roof, ribs and objects are all seen.
  EXPECT_GT(kinds[static_cast<int>(SurfaceKind::kFloor)], 500u);
  EXPECT_GT(kinds[static_cast<int>(SurfaceKind::kRoof)], 300u);
  EXPECT_GT(kinds[static_cast<int>(SurfaceKind::kRib)], 300u);
  EXPECT_GT(kinds[static_cast<int>(SurfaceKind::kObject)], 20u);
}

TEST(SimGroundTruth, RaysNeverPassThroughFloorOrRoof) {
  // March every beam in 5 cm steps up to its hit: it must stay between floor and roof.
  constexpr double kMarchStepCm = 5.0;
  constexpr double kToleranceCm = 0.05;
  for (const std::uint32_t seed : {1u, 2u}) {
    const SimulationSettings settings = coarse(few_scans(2, seed));
    const std::vector<ScanStop> stops = plan_stops(settings.mine);
    const MineWorld world(settings.mine, stops.back().z_cm);
    const ScannerModel model(settings.scanner);
    std::size_t rays = 0, crossings = 0;
    for (const ScanStop& stop : stops) {
      const Pose pose = robot_pose_on_floor(world, stop, settings.scanner.mount_height_cm);
      const Eigen::Vector3d origin = pose.block<3, 1>(0, 3);
      for (int i = 0; i < model.slices(); ++i) {
        for (int j = 0; j < model.points_per_slice(); ++j) {
          const Eigen::Vector3d dir = pose.block<3, 3>(0, 0) * model.direction(i, j);
          const RayHit hit = world.cast_ray(origin, dir, settings.scanner.max_range_cm);
          const double end = hit.hit() ? hit.range_cm : settings.scanner.max_range_cm;
          ++rays;
          for (double t = kMarchStepCm; t < end - kMarchStepCm; t += kMarchStepCm) {
            const Eigen::Vector3d p = origin + t * dir;
            if (p.y() < world.floor_height(p.x(), p.z()).value - kToleranceCm ||
                p.y() > world.roof_height(p.x(), p.z()).value + kToleranceCm) {
              ++crossings;
              break;
            }
          }
        }
      }
    }
    // Grazing beams over a bump may take a later crossing of the same surface; nothing more.
    EXPECT_LT(static_cast<double>(crossings) / rays, 1e-3) << crossings << " of " << rays << ", seed " << seed;
  }
}

TEST(SimGroundTruth, MineIsARoomAndPillarLayout) {
  const MineSettings mine;
  const MineWorld world(mine, mine.drive_length_cm);
  // Drive plus two parallel entries per side; pillars plus the four rock blocks around.
  EXPECT_EQ(world.entries().size(), 1u + 2u * static_cast<std::size_t>(mine.parallel_entries_per_side));
  EXPECT_GT(world.prisms().size(), 4u * (mine.drive_length_cm / mine.crosscut_spacing_max_cm));
  // Cross-cut spacing along the drive's right rib is irregular (no repeating period).
  std::vector<RockPrism> rib;
  for (const RockPrism& p : world.prisms()) {
    if (std::abs(p.x_min_cm - 0.5 * mine.main_entry_width_cm) < 30.0) rib.push_back(p);
  }
  std::sort(rib.begin(), rib.end(), [](const RockPrism& a, const RockPrism& b) { return a.z_min_cm < b.z_min_cm; });
  ASSERT_GT(rib.size(), 10u);
  std::vector<double> crosscut_centres;
  for (std::size_t i = 0; i + 1 < rib.size(); ++i) {
    crosscut_centres.push_back(0.5 * (rib[i].z_max_cm + rib[i + 1].z_min_cm));
  }
  double min_gap = 1e9, max_gap = 0.0;
  for (std::size_t i = 1; i < crosscut_centres.size(); ++i) {
    min_gap = std::min(min_gap, crosscut_centres[i] - crosscut_centres[i - 1]);
    max_gap = std::max(max_gap, crosscut_centres[i] - crosscut_centres[i - 1]);
  }
  EXPECT_GT(max_gap - min_gap, 300.0);
  EXPECT_GE(min_gap, mine.crosscut_spacing_min_cm - 1e-6);
  EXPECT_LE(max_gap, mine.crosscut_spacing_max_cm + 1e-6);
  // The drive is 2-3 m high and 4-5 m wide where the robot stands.
  for (double z = 0.0; z < mine.drive_length_cm; z += 1000.0) {
    const double height = world.roof_height(0.0, z).value - world.floor_height(0.0, z).value;
    EXPECT_GT(height, 200.0) << z;
    EXPECT_LT(height, 300.0) << z;
  }
  EXPECT_FALSE(std::isnan(world.broken_bar_z_cm()));
}

TEST(SimSettings, InvalidSettingsAreRejected) {
  SimulationSettings bad_scanner = few_scans(1);
  bad_scanner.scanner.slices = 0;
  EXPECT_THROW(simulate_mine_survey(bad_scanner), std::invalid_argument);
  SimulationSettings bad_step = few_scans(1);
  bad_step.mine.mean_step_cm = 0.0;
  EXPECT_THROW(simulate_mine_survey(bad_step), std::invalid_argument);
  SimulationSettings bad_mine = few_scans(1);
  bad_mine.mine.crosscut_spacing_min_cm = 100.0;  // narrower than a cross-cut
  EXPECT_THROW(simulate_mine_survey(bad_mine), std::invalid_argument);
}

}  // namespace
}  // namespace minemap::sim
