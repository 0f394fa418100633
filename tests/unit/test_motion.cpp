// The motion of a moving sensor (issue 26): SE(3)'s log and exp, the deskew of one sweep against a
// brute-force oracle (each point moved by its own exact motion), the overlap test that scales with
// a small scan, the local map's cells against a set oracle, and a spinning sensor mapped with no
// odometry against the simulator's truth (deskew on and off, local map thinned or not).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <initializer_list>
#include <limits>
#include <random>
#include <set>

#include "minemap/backend/cpu_backend.hpp"
#include "minemap/filter/deskew.hpp"
#include "minemap/sim/mine_simulator.hpp"
#include "minemap/sim/moving_lidar.hpp"
#include "minemap/slam/local_map.hpp"
#include "minemap/slam/motion_model.hpp"
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

namespace minemap {
namespace {

// The moving sensor's local map keeps the first point of each cell: the oracle, a std::set of the
// cells' integer coordinates, floors taken in double.
TEST(LocalMapCells, FirstPointPerCellKeepsWhatASetOracleKeeps) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> coordinate(-500.0f, 500.0f);
  std::vector<std::vector<Eigen::Vector3f>> parts(3);
  for (auto& part : parts) {
    for (int k = 0; k < 4000; ++k) part.emplace_back(coordinate(rng), coordinate(rng), coordinate(rng) * 0.05f);
    // Points on cell faces and copies of earlier points.
    part.emplace_back(10.0f, -20.0f, 0.0f);
    part.emplace_back(-10.0f, 20.0f, 30.0f);
    part.push_back(parts[0].front());
  }
  for (const double cell_cm : {10.0, 3.0, 40.0}) {
    std::set<std::array<long long, 3>> taken;
    std::vector<Eigen::Vector3f> expected;
    for (const auto& part : parts) {
      for (const Eigen::Vector3f& p : part) {
        const std::array<long long, 3> key{static_cast<long long>(std::floor(double(p.x()) / cell_cm)),
                                           static_cast<long long>(std::floor(double(p.y()) / cell_cm)),
                                           static_cast<long long>(std::floor(double(p.z()) / cell_cm))};
        if (taken.insert(key).second) expected.push_back(p);
      }
    }
    const auto kept = detail::first_point_per_cell(parts, cell_cm);
    ASSERT_EQ(kept.size(), expected.size()) << cell_cm;
    for (std::size_t k = 0; k < kept.size(); ++k) EXPECT_EQ(kept[k], expected[k]) << cell_cm << " cm, point " << k;
    EXPECT_LT(kept.size(), 3u * 4003u);
  }
  EXPECT_EQ(detail::concatenated(parts).size(), 3u * 4003u);
  EXPECT_TRUE(detail::first_point_per_cell({}, 10.0).empty());
}

TEST(LocalMapCells, TheCellMustBeAFiniteLengthOrZero) {
  MappingSettings settings;
  for (const double bad : {-1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    settings.motion.local_map_cell_cm = bad;
    EXPECT_THROW(settings.validate(), std::invalid_argument) << bad;
  }
  settings.motion.local_map_cell_cm = 0.0;  // every point
  EXPECT_NO_THROW(settings.validate());
}

// The judging after a loop takes whole visits to a place: i's own, the first, then the nearest in
// the drive; the scans keep the order they came in (nearest first), and a place passed at most
// `most` times keeps every scan.
std::vector<std::size_t> visits(const std::vector<std::size_t>& near, std::size_t i, std::size_t most) {
  return detail::nearest_visits(near, i, near, 10, most);  // every scan near stands at the place
}

TEST(LocalMapVisits, AThirdLapIsJudgedAgainstItsOwnTheFirstAndTheNearestLap) {
  // Scan 207 on its third lap of 100 scans; near it (nearest first) scans of four laps.
  const std::vector<std::size_t> near = {206, 208, 6, 106, 306, 205, 209, 5, 105, 305, 7, 107, 307};
  // Lap 4's scans (from 305) are 98 scans after 207, lap 2's (to 107) 100 before: lap 4 is kept.
  EXPECT_EQ(visits(near, 207, 3), (std::vector<std::size_t>{206, 208, 6, 306, 205, 209, 5, 305, 7, 307}));
  EXPECT_EQ(visits(near, 207, 2), (std::vector<std::size_t>{206, 208, 6, 205, 209, 5, 7}));
  EXPECT_EQ(visits(near, 207, 1), (std::vector<std::size_t>{206, 208, 205, 209}));
  EXPECT_EQ(visits(near, 207, 0), near);  // 0: all
  EXPECT_EQ(visits(near, 207, 4), near);  // four visits: all of them
  // Two laps as far in the drive: the earlier.
  EXPECT_EQ(visits({103, 3, 303}, 203, 3), (std::vector<std::size_t>{103, 3}));
  EXPECT_EQ(visits({103, 3, 303, 202}, 203, 3), (std::vector<std::size_t>{103, 3, 202}));
  // Scan 300, just before lap 4's scans near it: they are its own visit (within the gap).
  EXPECT_EQ(visits({305, 5, 205, 105}, 300, 2), (std::vector<std::size_t>{305, 5}));
  // Within the gap, scans are one visit however many: a slow drive is not cut into laps.
  EXPECT_EQ(detail::nearest_visits({1, 12, 23, 34, 45}, 50, {1, 12, 23, 34, 45}, 11, 1),
            (std::vector<std::size_t>{1, 12, 23, 34, 45}));
  EXPECT_TRUE(visits({}, 3, 3).empty());
}

// Scans near but not at the place (seen from afar: the other side of a small loop) go with the
// visit nearest them in the drive.
TEST(LocalMapVisits, AScanSeenFromAfarGoesWithTheVisitNearestItInTheDrive) {
  const std::vector<std::size_t> near = {6, 106, 150, 206, 306, 250, 50};
  const std::vector<std::size_t> at_place = {6, 106, 206, 306};
  // 150 is nearer lap 2's visit (106) than 207's own (206): left out with lap 2; 250 is 207's own,
  // 50 the first lap's.
  EXPECT_EQ(detail::nearest_visits(near, 207, at_place, 10, 2), (std::vector<std::size_t>{6, 206, 250, 50}));
  // Before the first visit and after the last: theirs.
  EXPECT_EQ(detail::nearest_visits({0, 400, 106}, 207, at_place, 10, 2), (std::vector<std::size_t>{0}));
  EXPECT_EQ(detail::nearest_visits({0, 400, 106}, 207, at_place, 10, 3), (std::vector<std::size_t>{0, 400}));
}

/// Sweep i of a hand-built state: 40 random points as its clouds; `sweep_s` 0 makes it a keyframe
/// without times (no stamp).
void add_sweep(detail::SurveyState& state, CpuBackend& cpu, const MappingSettings& settings, std::size_t i,
               double sweep_s, double stamp_s, std::uint32_t seed) {
  Scan scan;
  scan.name = "sweep" + std::to_string(i);
  detail::PreparedScan prepared;
  prepared.cloud = cpu.prepare(test::random_cloud(40, -500.f, 500.f, seed), settings.tree);
  prepared.model_cloud = prepared.probe = prepared.cloud;
  prepared.sweep_s = sweep_s;
  prepared.stamp_s = sweep_s > 0.0 ? stamp_s : std::nan("");
  state.add(scan, std::move(prepared));
}

/// Each of `values`, set into default settings by `set`, fails validation.
template <class Set>
void expect_rejected(Set set, std::initializer_list<double> values) {
  for (const double value : values) {
    MappingSettings bad;
    set(bad, value);
    EXPECT_THROW(bad.validate(), std::invalid_argument) << value;
  }
}

/// How far sweep k's turn from sweep 0 in `result` is from the truth's, deg.
double turn_from_first_off_deg(const MappingResult& result, const sim::MovingSurvey& survey, std::size_t k) {
  const Pose mapped = rigid_inverse(result.scans[0].pose_cm) * result.scans[k].pose_cm;
  const Pose truth = rigid_inverse(survey.truth_cm[0]) * survey.truth_cm[k];
  return rotation_angle_deg(rigid_inverse(truth) * mapped);
}

/// Sweeps 1..last stand the same relative to sweep 1 in both results (moved together, rigidly).
void expect_moved_together(const MappingResult& a, const MappingResult& b, std::size_t last) {
  for (std::size_t j = 2; j <= last; ++j) {
    const Pose before = rigid_inverse(a.scans[1].pose_cm) * a.scans[j].pose_cm;
    const Pose after = rigid_inverse(b.scans[1].pose_cm) * b.scans[j].pose_cm;
    EXPECT_LT((before - after).cwiseAbs().maxCoeff(), 1e-6) << j;
  }
}

/// Whether one of `result`'s notes contains `text`.
bool has_note(const MappingResult& result, const std::string& text) {
  for (const std::string& note : result.notes) {
    if (note.find(text) != std::string::npos) return true;
  }
  return false;
}

struct MovingRun {
  PoseErrors errors;
  std::size_t doubtful = 0;
  int iterations = 0;  ///< step 1's ICP iterations
};

/// The same scans with their points stored about another origin, `offset_cm` from the file's (read
/// relative to a local origin, as a file whose points lie far from its frame's origin): the same
/// points in the file's frame.
std::vector<Scan> stored_about(std::vector<Scan> scans, const Eigen::Vector3f& offset_cm) {
  for (Scan& scan : scans) {
    for (Eigen::Vector3f& p : scan.points_cm) p -= offset_cm;
    scan.local_origin_cm += offset_cm.cast<double>();
  }
  return scans;
}

MovingRun map_moving(const sim::MovingSurvey& survey, const MappingSettings& settings) {
  CpuBackend cpu;
  const MappingResult result = map_survey(survey.scans, settings, cpu);
  MovingRun run{pose_errors(test::poses_of(result), survey.truth_cm), 0, result.step1_icp_iterations};
  for (const auto& scan : result.scans) run.doubtful += scan.health.doubtful() ? 1 : 0;
  return run;
}

// A spinning 32-beam sensor at 10 m/s, no odometry: the constant-velocity motion model starts each
// sweep, the deskew by the registered step straightens it, the local map is thinned to 10 cm cells.
TEST(MovingMapping, SpinningAtTenMetresPerSecondWithoutOdometry) {
  sim::MovingSimulationSettings simulation;
  simulation.sensor = sim::MovingSensor::kSpinning;
  simulation.sweeps = 40;
  simulation.mine.seed = 3;
  const sim::MovingSurvey survey = sim::simulate_moving_survey(simulation);
  const MappingSettings defaults;
  const MovingRun run = map_moving(survey, defaults);
  MappingSettings off = defaults;
  off.motion.deskew = DeskewMode::kOff;
  const MovingRun skewed = map_moving(survey, off);
  MappingSettings all_points = defaults;
  all_points.motion.local_map_cell_cm = 0.0;
  const MovingRun unthinned = map_moving(survey, all_points);
  // Measured 2026-12-04 (39 m driven): 4.1 cm mean, 9.2 cm max; --deskew off 9.6 cm; all points 5.8 cm.
  // Since 2026-12-06 (the first match on the probe's points) 4.8 cm mean, 0.84 cm a step.
  EXPECT_LT(run.errors.mean_translation_cm, 8.0);
  EXPECT_LT(run.errors.max_translation_cm, 20.0);
  EXPECT_LT(run.errors.mean_relative_translation_cm, 1.5);
  EXPECT_LT(run.errors.mean_relative_rotation_deg, 0.4);
  EXPECT_EQ(run.doubtful, 0u);
  // The deskew halves the error (the step's error does not change: both ends of a step are equally
  // distorted, so scan-to-map matching cancels most of it; docs/benchmarks.md, "Moving LiDAR").
  EXPECT_LT(1.5 * run.errors.mean_translation_cm, skewed.errors.mean_translation_cm);
  // Thinning the local map costs no accuracy.
  EXPECT_LT(run.errors.mean_translation_cm, 1.25 * unthinned.errors.mean_translation_cm);
  // A provisional first match (MotionSettings::provisional_step_factor) spends fewer iterations,
  // and the refinement's full match keeps the accuracy.
  MappingSettings provisional = defaults;
  provisional.motion.provisional_step_factor = 3.0;
  const MovingRun quick = map_moving(survey, provisional);
  EXPECT_LT(quick.iterations, run.iterations * 9 / 10);
  EXPECT_LT(quick.errors.mean_translation_cm, 8.0);
  EXPECT_LT(quick.errors.mean_relative_translation_cm, 1.5);
  EXPECT_EQ(quick.doubtful, 0u);
  // The first match on the health probe's points alone (MotionSettings::provisional_probe, the
  // default), a quarter of them, against all points first: the refinement, on all of them, keeps
  // the accuracy.
  MappingSettings all_first = defaults;
  all_first.motion.provisional_probe = false;
  const MovingRun full = map_moving(survey, all_first);
  std::printf("probe first: %.2f cm mean, %.2f cm step; all points first: %.2f cm, %.2f cm\n",
              run.errors.mean_translation_cm, run.errors.mean_relative_translation_cm,
              full.errors.mean_translation_cm, full.errors.mean_relative_translation_cm);
  EXPECT_NE(run.errors.mean_translation_cm, full.errors.mean_translation_cm);  // the setting is used
  EXPECT_LT(run.errors.mean_translation_cm, 1.25 * full.errors.mean_translation_cm);
  EXPECT_LT(run.errors.mean_relative_translation_cm, 1.25 * full.errors.mean_relative_translation_cm);
  EXPECT_EQ(full.doubtful, 0u);
  // The refinement's match searching exactly from its first iteration (MotionSettings::
  // refine_search, not the default): it starts where the first match converged, where the paper's
  // approximate phase only leads it away; fewer iterations, the same accuracy. A spinning sensor's
  // sweeps are a wide field's: wide-exact is exact for them. With the exact search everywhere
  // (--search kd) the setting changes nothing.
  ASSERT_EQ(defaults.motion.refine_search, RefineSearch::kPapers);
  MappingSettings exact_refinement = defaults;
  exact_refinement.motion.refine_search = RefineSearch::kWideExact;
  const MovingRun refined = map_moving(survey, exact_refinement);
  std::printf("refinement exact: %d iterations, %.2f cm mean, %.2f cm step; approximate first: %d, %.2f cm, %.2f cm\n",
              refined.iterations, refined.errors.mean_translation_cm, refined.errors.mean_relative_translation_cm,
              run.iterations, run.errors.mean_translation_cm, run.errors.mean_relative_translation_cm);
  EXPECT_LT(refined.iterations, run.iterations);
  EXPECT_LT(refined.errors.mean_translation_cm, 1.25 * run.errors.mean_translation_cm);
  EXPECT_LT(refined.errors.mean_relative_translation_cm, 1.25 * run.errors.mean_relative_translation_cm);
  EXPECT_EQ(refined.doubtful, 0u);
  MappingSettings everywhere = defaults;
  everywhere.motion.refine_search = RefineSearch::kExact;
  const MovingRun exact_everywhere = map_moving(survey, everywhere);
  EXPECT_EQ(exact_everywhere.errors.mean_translation_cm, refined.errors.mean_translation_cm);  // a wide field
  sim::MovingSurvey first_twelve = survey;
  first_twelve.scans.resize(12);
  first_twelve.truth_cm.resize(12);
  MappingSettings exact = defaults;
  exact.icp.method = SearchMethod::kExact;
  MappingSettings exact_scheduled = exact;
  exact_scheduled.motion.refine_search = RefineSearch::kExact;
  CpuBackend cpu;
  const MappingResult exact_run = map_survey(first_twelve.scans, exact, cpu);
  const MappingResult exact_run_too = map_survey(first_twelve.scans, exact_scheduled, cpu);
  ASSERT_EQ(exact_run.scans.size(), exact_run_too.scans.size());
  for (std::size_t k = 0; k < exact_run.scans.size(); ++k) {
    EXPECT_EQ(exact_run.scans[k].pose_cm, exact_run_too.scans[k].pose_cm) << k;
  }
  MappingSettings bad = defaults;
  for (const double factor : {0.5, std::nan(""), std::numeric_limits<double>::infinity()}) {
    bad.motion.provisional_step_factor = factor;
    EXPECT_THROW(bad.validate(), std::invalid_argument) << factor;
  }
}

// The same sensor weaving (a yaw weave of 45 deg/s at its peak, a 2 s period): each sweep is
// distorted differently, so the distortion no longer cancels between neighbours, and the deskew is
// what keeps the map straight. Measured 2026-12-04 (60 sweeps, seed 2, bench/trajectory_errors.py):
// mean error 7.6 cm against 67.2 cm with --deskew off (8.9x), step error 0.96 against 2.19 cm.
TEST(MovingMapping, TheDeskewKeepsAWeavingSensorsMapFiveTimesCloser) {
  sim::MovingSimulationSettings simulation;
  simulation.sensor = sim::MovingSensor::kSpinning;
  simulation.sweeps = 60;
  simulation.turn_deg_s = 45.0;
  simulation.mine.seed = 2;
  const sim::MovingSurvey survey = sim::simulate_moving_survey(simulation);
  const MovingRun run = map_moving(survey, MappingSettings{});
  MappingSettings off;
  off.motion.deskew = DeskewMode::kOff;
  const MovingRun skewed = map_moving(survey, off);
  std::printf("weave: %.1f cm (step %.2f cm), deskew off %.1f cm (step %.2f cm)\n", run.errors.mean_translation_cm,
              run.errors.mean_relative_translation_cm, skewed.errors.mean_translation_cm,
              skewed.errors.mean_relative_translation_cm);
  EXPECT_EQ(run.doubtful, 0u);
  EXPECT_LT(5.0 * run.errors.mean_translation_cm, skewed.errors.mean_translation_cm);
  EXPECT_LT(1.5 * run.errors.mean_relative_translation_cm, skewed.errors.mean_relative_translation_cm);
}

// A hand-held sequence with sweeps missing, read as keyframes (no deskew, as a LIO front end saves
// them): the sweep after the gap ends far from the constant-velocity prediction, many times the
// recent predictions' error. Such a jump is not trusted on its point statistics alone (on a real
// building walk a wide first match slid 3 m along a corridor there, passed every health test, and
// the next prediction repeated the slide: docs/benchmarks.md, "Real moving sequences"): a second
// match from an independent start must end at the same pose, or the scan is doubtful.
TEST(MovingMapping, AJumpFromThePredictionIsTrustedOnlyWhenASecondStartAgrees) {
  sim::MovingSimulationSettings simulation;
  simulation.sensor = sim::MovingSensor::kHandheld;
  simulation.sweeps = 60;
  simulation.mine.seed = 2;
  const sim::MovingSurvey whole = sim::simulate_moving_survey(simulation);
  const auto without = [&](std::size_t first, std::size_t count) {
    sim::MovingSurvey survey = whole;
    survey.scans.erase(survey.scans.begin() + first, survey.scans.begin() + first + count);
    survey.truth_cm.erase(survey.truth_cm.begin() + first, survey.truth_cm.begin() + first + count);
    return survey;
  };
  MappingSettings settings;
  settings.motion.deskew = DeskewMode::kOff;
  CpuBackend cpu;
  // Three sweeps missing: the features put the scan where its match did. Trusted, and said. (At 25:
  // whether the features find a start in this self-similar mine is a matter of the place; at 30
  // they did while the keyframes' metascans kept every point, and since they are thinned to 10 cm
  // cells they are ambiguous there: 49 feature pairs held against 26 elsewhere, less than twice.)
  const sim::MovingSurvey gap = without(25, 3);
  const MappingResult result = map_survey(gap.scans, settings, cpu);
  const RegistrationHealth& jump = result.scans[25].health;
  std::printf("three missing: %.1f cm from the prediction; note: %s; doubt: %s\n", jump.correction_cm,
              jump.note.c_str(), jump.doubt.c_str());
  EXPECT_GT(jump.correction_cm, 30.0);
  EXPECT_NE(jump.note.find("from the prediction"), std::string::npos) << jump.note;
  EXPECT_NE(jump.note.find("confirmed"), std::string::npos) << jump.note;
  EXPECT_TRUE(result.doubtful().empty());
  EXPECT_LT(pose_errors(test::poses_of(result), gap.truth_cm).max_translation_cm, 30.0);
  // The rule off (no jump is ever far enough): the same pose, nothing said.
  MappingSettings unchecked = settings;
  unchecked.motion.confirm_sigmas = 1e9;
  const MappingResult plain = map_survey(gap.scans, unchecked, cpu);
  EXPECT_TRUE(plain.scans[25].health.note.empty());
  EXPECT_EQ(plain.scans[25].pose_cm, result.scans[25].pose_cm);
  // Four missing: the features find no start, and standing still lies within the match's reach of
  // the prediction (not independent). Right, but not confirmed: doubtful, and named.
  const sim::MovingSurvey wider = without(30, 4);
  const MappingResult unconfirmed = map_survey(wider.scans, settings, cpu);
  const RegistrationHealth& alone = unconfirmed.scans[30].health;
  std::printf("four missing: %.1f cm from the prediction; doubt: %s\n", alone.correction_cm, alone.doubt.c_str());
  EXPECT_EQ(unconfirmed.doubtful(), (std::vector<std::size_t>{30}));
  EXPECT_NE(alone.doubt.find("no independent start confirmed it"), std::string::npos) << alone.doubt;
  // The same sweeps deskewed by their times, the later ones' times moved earlier by the missing
  // sweeps' (the sensor sped up over one step: with the times kept, the motion model predicts the
  // gap and nothing jumps). The deskew's refinement matches each sweep again from where its first
  // match ended, and cannot see the jump: the doubt and the note stay with the scan.
  const auto sped_up = [&](sim::MovingSurvey survey, std::size_t first, std::size_t count) {
    const double missing_s = whole.scans[first + count].attributes.time_s.front() -
                             whole.scans[first].attributes.time_s.front();
    for (std::size_t k = first; k < survey.scans.size(); ++k) {
      for (auto& t : survey.scans[k].attributes.time_s) t -= missing_s;
    }
    return survey;
  };
  MappingSettings timed = settings;
  timed.motion.deskew = DeskewMode::kAuto;
  // (Whether the features confirm three missing once deskewed is a matter of the place: at 18, 38
  // and 40 they did, with the timed sweeps' weak-direction prediction on or off; at 25 they did only
  // with it off, 33 feature pairs holding against the 40 asked with it on, and at 30 neither. Since
  // the first sweep is matched again after sweep 20 the sweeps after it stand otherwise: 18, 35 and
  // 40 confirm, 22, 25, 30, 38, 42 and 45 not. Since the spring holds the hand-held sweeps: 18 and
  // 40 are recovered from their features, 45 confirmed, 22, 25, 30, 35 and 42 doubtful naming the
  // spring, 38 doubtful out of reach.)
  // Deskewed, a hand-held sweep is held by the spring to its prediction (MotionSettings::
  // sweep_start_spring_pairs), which holds a jump short: at 40 the held match was doubtful, its
  // retry not confirmed, and the scan's features placed it (recovered, 42 of the 44 cm).
  const sim::MovingSurvey timed_three = sped_up(without(40, 3), 40, 3);
  const MappingResult timed_gap = map_survey(timed_three.scans, timed, cpu);
  const RegistrationHealth& timed_jump = timed_gap.scans[40].health;
  std::printf("three missing, deskewed: %.1f cm; note: %s; doubt: %s; recovered from %zu feature pairs\n",
              timed_jump.correction_cm, timed_jump.note.c_str(), timed_jump.doubt.c_str(),
              timed_jump.recovered_inliers);
  EXPECT_TRUE(timed_jump.note.find("confirmed") != std::string::npos || timed_jump.recovered_inliers > 0)
      << timed_jump.note;
  // (Another sweep of the 57 may be named, by build: clang's ASan build names one.)
  EXPECT_FALSE(timed_jump.doubtful()) << timed_jump.doubt;
  EXPECT_LT(pose_errors(test::poses_of(timed_gap), timed_three.truth_cm).max_translation_cm, 30.0);
  // At 22 (GCC's Release build) the held match stopped 22 cm from the prediction, the free one
  // 44 cm (the truth's), and the features found no start in this self-similar place: neither is
  // confirmed, and the scan is named, its doubt saying both (SurveyMatcher::release_held_match).
  // Clang's TSan build ended it 41.6 cm from the prediction and trusted it (the map within 5 cm of
  // the truth; another sweep doubtful there): named, or right.
  const sim::MovingSurvey at_22 = sped_up(without(22, 3), 22, 3);
  const MappingResult held_gap = map_survey(at_22.scans, timed, cpu);
  const RegistrationHealth& held = held_gap.scans[22].health;
  std::printf("three missing at 22, deskewed: %.1f cm; doubt: %s; %zu doubtful, the map %.1f cm off at most\n",
              held.correction_cm, held.doubt.c_str(), held_gap.doubtful().size(),
              pose_errors(test::poses_of(held_gap), at_22.truth_cm).max_translation_cm);
  for (const std::size_t k : held_gap.doubtful()) std::printf("  doubtful %zu: %s\n", k, held_gap.scans[k].health.doubt.c_str());
  // (The sweep after it may be named too, predicted from the held step: with the refinement's exact
  // search on every sweep, RefineSearch::kExact, GCC's Release build names 23 as well, held 15 cm
  // from its prediction where the free match ended 37.)
  const bool named = held.doubtful() && held.doubt.find("the spring to the prediction held it") != std::string::npos;
  const bool right = !held.doubtful() &&
                     pose_errors(test::poses_of(held_gap), at_22.truth_cm).max_translation_cm < 30.0;
  EXPECT_TRUE(named || right) << held.doubt;
  const MappingResult timed_wider = map_survey(sped_up(wider, 30, 4).scans, timed, cpu);
  const RegistrationHealth& timed_alone = timed_wider.scans[30].health;
  std::printf("four missing, deskewed: %.1f cm; doubt: %s\n", timed_alone.correction_cm, timed_alone.doubt.c_str());
  EXPECT_EQ(timed_wider.doubtful(), (std::vector<std::size_t>{30}));
  EXPECT_NE(timed_alone.doubt.find("no independent start confirmed"), std::string::npos) << timed_alone.doubt;
  // Held 24 cm from the prediction where the free match ended 56 cm from it: both are named.
  EXPECT_NE(timed_alone.doubt.find("the spring to the prediction held it"), std::string::npos) << timed_alone.doubt;
}

// Keyframes without times (a hand-held unit's, deskewed by its own odometry): every match is final,
// and the first match at the wide adaptive bound runs its coarse stage on the health probe's points
// only (MotionSettings::wide_coarse_probe); the fine stage, on all of them, keeps the accuracy.
// Measured 2026-12-06 (40 keyframes, seeds 1, 2, 3, 5 at 0.5 and 1.4 m/s): mean error on the probe
// over all points 0.41-1.48, step error 0.37-1.04; seed 3 at 0.5 m/s: 2.00 against 2.39 cm (2.42
// against 3.39 cm since the keyframes' metascans are thinned to 10 cm cells, 2026-12-06).
TEST(MovingMapping, KeyframesRunTheirWideCoarseStageOnTheProbeAtTheSameAccuracy) {
  sim::MovingSimulationSettings simulation;
  simulation.sensor = sim::MovingSensor::kHandheld;
  simulation.sweeps = 40;
  simulation.speed_mps = 0.5;
  simulation.mine.seed = 3;
  sim::MovingSurvey survey = sim::simulate_moving_survey(simulation);
  for (Scan& scan : survey.scans) scan.attributes.time_s.clear();
  const MovingRun probe = map_moving(survey, MappingSettings{});
  MappingSettings all_points;
  all_points.motion.wide_coarse_probe = false;
  const MovingRun full = map_moving(survey, all_points);
  std::printf("wide coarse stage on the probe: %.2f cm mean, %.2f cm a step, %d iterations; on all points: %.2f cm, "
              "%.2f cm, %d\n",
              probe.errors.mean_translation_cm, probe.errors.mean_relative_translation_cm, probe.iterations,
              full.errors.mean_translation_cm, full.errors.mean_relative_translation_cm, full.iterations);
  EXPECT_NE(probe.errors.mean_translation_cm, full.errors.mean_translation_cm);  // the setting is used
  EXPECT_LT(probe.errors.mean_translation_cm, 1.5 * full.errors.mean_translation_cm);
  EXPECT_LT(probe.errors.mean_relative_translation_cm, 1.25 * full.errors.mean_relative_translation_cm);
  EXPECT_EQ(probe.doubtful, 0u);
  EXPECT_EQ(full.doubtful, 0u);
}

/// Simulated hand-held sweeps with their points' times, no odometry (seed 3, 30 sweeps).
sim::MovingSurvey handheld_sweeps() {
  sim::MovingSimulationSettings simulation;
  simulation.sensor = sim::MovingSensor::kHandheld;
  simulation.sweeps = 30;
  simulation.mine.seed = 3;
  return sim::simulate_moving_survey(simulation);
}

/// The same sweeps as keyframes: no times, no odometry.
sim::MovingSurvey handheld_keyframes() {
  sim::MovingSurvey keyframes = handheld_sweeps();
  for (Scan& scan : keyframes.scans) scan.attributes.time_s.clear();
  return keyframes;
}

/// A stop-and-go survey with odometry (4 scans, seed 7) maps to the same poses under both settings.
void expect_stop_and_go_alike(const MappingSettings& a, const MappingSettings& b) {
  sim::SimulationSettings stop_and_go;
  stop_and_go.mine.scans = 4;
  stop_and_go.mine.seed = 7;
  const sim::SimulatedSurvey survey = sim::simulate_mine_survey(stop_and_go);
  CpuBackend cpu;
  const MappingResult first = map_survey(survey.scans, a, cpu);
  const MappingResult second = map_survey(survey.scans, b, cpu);
  ASSERT_EQ(first.scans.size(), 4u);
  for (std::size_t k = 0; k < first.scans.size(); ++k) EXPECT_EQ(first.scans[k].pose_cm, second.scans[k].pose_cm) << k;
}

// Whose metascans are thinned (MotionPrediction::local_map_cell_cm): keyframes without times or
// odometry are a moving sensor's too, and their local map keeps one point per 10 cm cell as a timed
// sweep's does (on the four real sequences 0.9-0.99x the time, every mean error lower:
// docs/benchmarks.md, "Moving LiDAR"); a stop-and-go survey with odometry keeps every point, as the
// paper matches, and its poses do not depend on the cell at all.
TEST(MovingMapping, KeyframesWithoutOdometryMatchAThinnedLocalMapAndStopAndGoKeepsEveryPoint) {
  const sim::MovingSurvey keyframes = handheld_keyframes();
  MappingSettings every_point;
  every_point.motion.local_map_cell_cm = 0.0;
  const MovingRun thinned = map_moving(keyframes, MappingSettings{});
  const MovingRun all = map_moving(keyframes, every_point);
  std::printf("keyframes: thinned local map %.2f cm mean (%.2f a step), every point %.2f cm (%.2f)\n",
              thinned.errors.mean_translation_cm, thinned.errors.mean_relative_translation_cm,
              all.errors.mean_translation_cm, all.errors.mean_relative_translation_cm);
  EXPECT_NE(thinned.errors.mean_translation_cm, all.errors.mean_translation_cm);  // the cell is used
  EXPECT_LT(thinned.errors.mean_translation_cm, 1.5 * all.errors.mean_translation_cm);
  EXPECT_EQ(thinned.doubtful, 0u);
  MappingSettings coarse;
  coarse.motion.local_map_cell_cm = 50.0;
  expect_stop_and_go_alike(MappingSettings{}, coarse);
}

/// The CPU backend, counting the local maps assembled (placed_within: one for each metascan).
class UnionCountingBackend : public ComputeBackend {
 public:
  std::size_t unions = 0;
  std::string name() const override { return cpu_.name(); }
  std::string device_description() const override { return cpu_.device_description(); }
  std::shared_ptr<const PreparedCloud> prepare(std::vector<Eigen::Vector3f> points, const KdTreeSettings& settings,
                                               TreeBuild when = TreeBuild::kNow) override {
    return cpu_.prepare(std::move(points), settings, when);
  }
  std::vector<std::shared_ptr<const PreparedCloud>> prepare_many(std::vector<std::vector<Eigen::Vector3f>> clouds,
                                                                 const KdTreeSettings& settings,
                                                                 TreeBuild when = TreeBuild::kNow) override {
    return cpu_.prepare_many(std::move(clouds), settings, when);
  }
  PairSums pair_and_sum(const PreparedCloud& data, std::span<const ModelPlacement> models, SearchMethod method,
                        const PairingSettings& settings) override {
    return cpu_.pair_and_sum(data, models, method, settings);
  }
  PlaneSums pair_and_plane_sum(const PreparedCloud& data, std::span<const ModelPlacement> models, SearchMethod method,
                               const PairingSettings& settings, std::span<const Eigen::Vector3f> normals) override {
    return cpu_.pair_and_plane_sum(data, models, method, settings, normals);
  }
  std::vector<NearestPair> nearest(const PreparedCloud& data, std::span<const ModelPlacement> models,
                                   SearchMethod method, const PairingSettings& settings) override {
    return cpu_.nearest(data, models, method, settings);
  }
  std::vector<std::vector<Eigen::Vector3f>> placed_within(std::span<const UnionPart> parts,
                                                          const Eigen::Vector3d& min_cm,
                                                          const Eigen::Vector3d& max_cm) override {
    ++unions;
    return cpu_.placed_within(parts, min_cm, max_cm);
  }
  bool concurrent_voxel_means() const override { return cpu_.concurrent_voxel_means(); }

 protected:
  SliceFilterResult filter_slices_checked(const Scan& scan, const SliceFilterSettings& settings) override {
    return cpu_.filter_slices(scan, settings);
  }

 private:
  CpuBackend cpu_;
};

// A spinning sensor's metascan serves the sweep after it too (MotionSettings::local_map_sweeps, 2):
// built grown by the move the last step predicts, it is kept while the next sweep's box stays
// within its margin and no scan in it has moved since. On a spinning drive at 10 m/s fewer local
// maps are assembled than with one for every sweep, and the sweeps land as well (the figures on the
// simulated sequences: docs/benchmarks.md, "A spinning sensor's local map kept for the sweep after
// it"). A narrow field's sweeps (hand-held) and keyframes without times take one each, and so does
// a stop-and-go survey: the same poses as with the setting at 1.
TEST(MovingMapping, ASpinningSensorsLocalMapServesTheSweepAfterIt) {
  const MappingSettings kept;
  ASSERT_EQ(kept.motion.local_map_sweeps, 2);
  MappingSettings each_sweep;
  each_sweep.motion.local_map_sweeps = 1;
  sim::MovingSimulationSettings spinning;
  spinning.sensor = sim::MovingSensor::kSpinning;
  spinning.sweeps = 30;
  const sim::MovingSurvey drive = sim::simulate_moving_survey(spinning);
  UnionCountingBackend each, shared;
  const MappingResult one = map_survey(drive.scans, each_sweep, each);
  const MappingResult two = map_survey(drive.scans, kept, shared);
  ASSERT_TRUE(one.all_registered());
  ASSERT_TRUE(two.all_registered());
  const PoseErrors one_off = pose_errors(test::poses_of(one), drive.truth_cm);
  const PoseErrors two_off = pose_errors(test::poses_of(two), drive.truth_cm);
  std::printf("spinning, 30 sweeps: %zu local maps, %.2f cm mean (%.2f a step); serving two sweeps: %zu, %.2f cm "
              "(%.2f)\n",
              each.unions, one_off.mean_translation_cm, one_off.mean_relative_translation_cm, shared.unions,
              two_off.mean_translation_cm, two_off.mean_relative_translation_cm);
  EXPECT_LT(double(shared.unions), 0.75 * double(each.unions));
  EXPECT_LT(two_off.mean_translation_cm, 1.5 * one_off.mean_translation_cm + 1.0);
  EXPECT_LT(two_off.mean_relative_translation_cm, 1.25 * one_off.mean_relative_translation_cm);
  EXPECT_TRUE(two.doubtful().empty());
  // The narrow field and the keyframes: one metascan a match, the same poses.
  CpuBackend cpu;
  for (const sim::MovingSurvey& survey : {handheld_sweeps(), handheld_keyframes()}) {
    const MappingResult once = map_survey(survey.scans, each_sweep, cpu);
    const MappingResult again = map_survey(survey.scans, kept, cpu);
    ASSERT_EQ(once.scans.size(), again.scans.size());
    for (std::size_t k = 0; k < once.scans.size(); ++k) EXPECT_EQ(once.scans[k].pose_cm, again.scans[k].pose_cm) << k;
  }
  expect_stop_and_go_alike(each_sweep, kept);
  expect_rejected([](MappingSettings& s, double v) { s.motion.local_map_sweeps = int(v); }, {0.0, -1.0});
}

// What a kept metascan checks: a move of any scan but the newest (a scan matched again, turned
// back, or failed once a later one came in) counts; the newest's own matches do not.
TEST(MovingMapping, OnlyAMoveOfAScanBeforeTheNewestCountsAsAnOlderMove) {
  CpuBackend cpu;
  const MappingSettings settings;
  detail::SurveyState state;
  for (std::size_t i = 0; i < 3; ++i) add_sweep(state, cpu, settings, i, 0.1, 0.1 * double(i), 90 + std::uint32_t(i));
  const std::uint64_t before = state.older_moves();
  state.place(2, Pose::Identity());
  state.place(2, Pose::Identity(), IcpResult{});
  EXPECT_EQ(state.older_moves(), before);
  state.place(1, Pose::Identity());
  EXPECT_EQ(state.older_moves(), before + 1);
  state.fail(0, Pose::Identity(), IcpResult{});
  EXPECT_EQ(state.older_moves(), before + 2);
}

// The robust kernel of a keyframe's first wide match (MotionSettings::wide_coarse_kernel_fraction,
// once its bound is learned): keyframes without odometry are matched with it (and land as well as
// without it); a stop-and-go survey with odometry keeps the paper's sums, its poses not depending
// on the setting at all. The figures on real keyframes are in docs/benchmarks.md ("A robust kernel
// in the keyframes' coarse stage").
TEST(MovingMapping, KeyframesWeighTheirWideCoarseStageAndStopAndGoKeepsThePapersSums) {
  const sim::MovingSurvey keyframes = handheld_keyframes();
  MappingSettings unweighted;
  unweighted.motion.wide_coarse_kernel_fraction = 0.0;
  const MovingRun weighted = map_moving(keyframes, MappingSettings{});
  const MovingRun plain = map_moving(keyframes, unweighted);
  std::printf("keyframes: coarse kernel %.2f cm mean (%.2f a step), unweighted %.2f cm (%.2f)\n",
              weighted.errors.mean_translation_cm, weighted.errors.mean_relative_translation_cm,
              plain.errors.mean_translation_cm, plain.errors.mean_relative_translation_cm);
  EXPECT_NE(weighted.errors.mean_translation_cm, plain.errors.mean_translation_cm);  // the kernel is used
  EXPECT_LT(weighted.errors.mean_translation_cm, 1.5 * plain.errors.mean_translation_cm);
  EXPECT_LT(weighted.errors.mean_relative_translation_cm, 1.25 * plain.errors.mean_relative_translation_cm);
  EXPECT_EQ(weighted.doubtful, 0u);
  MappingSettings strong;
  strong.motion.wide_coarse_kernel_fraction = 0.1;
  expect_stop_and_go_alike(unweighted, strong);
}

// Where asked (MotionSettings::plane_objective), a moving sensor's matches minimise, after their
// coarse stage, the distances to each scan's own planes: timed sweeps and keyframes land at least
// as well as with the paper's point-to-point steps (a step's error is what a match decides; the
// mean error of 30 sweeps also carries the drift's chance: measured 2026-12-07, sweeps 1.90
// against 1.92 cm a step, keyframes 2.93 against 4.06 cm). A stop-and-go survey with odometry
// keeps the paper's ICP, its poses not depending on the setting at all. The figures on longer
// simulated and real sequences are in docs/benchmarks.md ("Point-to-plane for a moving sensor").
TEST(MovingMapping, AMovingSensorsMatchesMayMinimiseTheDistancesToItsPlanesAndStopAndGoKeepsThePapers) {
  MappingSettings planar;
  planar.motion.plane_objective = true;
  for (const bool timed : {true, false}) {
    const sim::MovingSurvey survey = timed ? handheld_sweeps() : handheld_keyframes();
    const MovingRun planes = map_moving(survey, planar);
    const MovingRun paper = map_moving(survey, MappingSettings{});
    std::printf("%s: planes %.2f cm mean (%.2f a step), point-to-point %.2f cm (%.2f)\n", timed ? "sweeps" : "keyframes",
                planes.errors.mean_translation_cm, planes.errors.mean_relative_translation_cm,
                paper.errors.mean_translation_cm, paper.errors.mean_relative_translation_cm);
    EXPECT_NE(planes.errors.mean_translation_cm, paper.errors.mean_translation_cm);  // the setting is used
    EXPECT_LT(planes.errors.mean_relative_translation_cm, 1.05 * paper.errors.mean_relative_translation_cm);
    EXPECT_LT(planes.errors.mean_translation_cm, 1.5 * paper.errors.mean_translation_cm);
    EXPECT_EQ(planes.doubtful, 0u);
  }
  expect_stop_and_go_alike(MappingSettings{}, planar);
}

TEST(MovingMapping, TheCoarseKernelMustBeAFiniteFractionOrZero) {
  MappingSettings settings;
  for (const double bad : {-0.5, std::nan(""), std::numeric_limits<double>::infinity()}) {
    settings.motion.wide_coarse_kernel_fraction = bad;
    EXPECT_THROW(settings.validate(), std::invalid_argument) << bad;
  }
  settings.motion.wide_coarse_kernel_fraction = 0.0;  // off
  EXPECT_NO_THROW(settings.validate());
  IcpSettings icp;
  icp.robust_scale_fraction = -1.0f;
  EXPECT_THROW(icp.validate(), std::invalid_argument);
}

// The slide test's second start: the match's move from the prediction along the weak direction is
// taken out, and nothing else of it (against the correction worked out by hand in the predicted
// frame, for random poses and directions).
TEST(MovingMapping, ASlidMatchStartsAgainWithOnlyItsMoveAlongTheWeakDirectionTakenOut) {
  std::mt19937 random(11);
  std::normal_distribution<double> normal(0.0, 1.0);
  const auto random_pose = [&](double metres, double degrees) {
    Pose pose = Pose::Identity();
    const Eigen::Vector3d axis = Eigen::Vector3d(normal(random), normal(random), normal(random)).normalized();
    pose.block<3, 3>(0, 0) = Eigen::AngleAxisd(degrees * M_PI / 180.0 * normal(random), axis).toRotationMatrix();
    pose.block<3, 1>(0, 3) = 100.0 * metres * Eigen::Vector3d(normal(random), normal(random), normal(random));
    return pose;
  };
  for (int k = 0; k < 50; ++k) {
    const Pose predicted = random_pose(500.0, 90.0);
    const Pose matched = predicted * random_pose(1.0, 5.0);
    const Eigen::Vector3d direction = Eigen::Vector3d(normal(random), normal(random), normal(random)).normalized();
    double along_cm = 0.0;
    const Pose start = detail::without_move_along(predicted, matched, direction, &along_cm);
    const Pose wanted = rigid_inverse(predicted) * matched;
    const Pose got = rigid_inverse(predicted) * start;
    EXPECT_NEAR(along_cm, direction.dot(wanted.block<3, 1>(0, 3)), 1e-6);
    EXPECT_NEAR(direction.dot(got.block<3, 1>(0, 3)), 0.0, 1e-6);  // nothing left along it
    const Eigen::Vector3d rest = wanted.block<3, 1>(0, 3) - along_cm * direction;
    EXPECT_LT((got.block<3, 1>(0, 3) - rest).norm(), 1e-6);
    EXPECT_LT((got.block<3, 3>(0, 0) - wanted.block<3, 3>(0, 0)).norm(), 1e-9);  // the turn kept whole
  }
}

// Where a timed sweep's match pinned a direction weakly, repeating its step repeats whatever error
// it made along it (the match cannot see it, so it stays where it starts): the simulated hand-held
// loops drifted 26-53 cm a sweep sideways for 7-14 sweeps in a row. The prediction then takes the recent
// well-pinned steps' mean move along that direction, scaled to the last step's time, and keeps the
// rest of the last step and its turn; everywhere else it is the last step, as KISS-ICP's.
TEST(MovingMapping, ATimedSweepsPredictionTakesTheWellPinnedStepsMoveAlongItsLastMatchsWeakDirection) {
  CpuBackend cpu;
  const MappingSettings defaults;
  ASSERT_GT(defaults.motion.weak_step_constraint, 0.0);
  struct Case {
    double last_constraint = 0.01;  // scan 10's match: pinned weakly sideways (its y)...
    double others_constraint = 0.3;  // ...the steps before it well
    double sweep_s = 0.1;            // timed sweeps; 0: keyframes without times
    double weak_step_constraint = MotionSettings{}.weak_step_constraint;
  };
  // Scans 0-10 stand on a walk turning 2 deg a step, 14 cm forward and 4 cm sideways every 0.1 s;
  // the last step (scan 9 to 10) took 0.2 s and slid 30 cm sideways besides its 28 cm forward.
  const auto pose_of = [](std::size_t i) {
    Pose pose = Pose::Identity();
    for (std::size_t k = 1; k <= i; ++k) {
      Pose step = Pose::Identity();
      step.block<3, 3>(0, 0) = Eigen::AngleAxisd(2.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      step.block<3, 1>(0, 3) = k < 10 ? Eigen::Vector3d(14.0, 4.0, 0.5) : Eigen::Vector3d(28.0, 38.0, 1.0);
      pose = pose * step;
    }
    return pose;
  };
  const auto stamp_of = [](std::size_t i) { return i <= 9 ? 0.1 * double(i) : 0.9 + 0.2 * double(i - 9); };
  const auto predict = [&](const Case& c) {
    MappingSettings settings = defaults;
    settings.motion.weak_step_constraint = c.weak_step_constraint;
    detail::SurveyState state;
    for (std::size_t i = 0; i < 12; ++i) {
      add_sweep(state, cpu, settings, i, c.sweep_s, stamp_of(i), 50 + std::uint32_t(i));
      if (i == 11) break;  // the sweep predicted
      state.place(i, pose_of(i));
      RegistrationHealth health;
      health.judged = i > 0;
      health.translation_constraint = i == 10 ? c.last_constraint : c.others_constraint;
      health.weakest_direction = Eigen::Vector3d::UnitY();
      state.judged(i, health);
    }
    const detail::MotionPrediction motion(settings);
    // The predicted step from scan 10, in its frame.
    return Pose(rigid_inverse(pose_of(10)) * motion.predict(state, 11).start);
  };
  const Pose last_step = rigid_inverse(pose_of(9)) * pose_of(10);
  const auto expect_step = [](const Pose& got, const Pose& wanted, const char* what) {
    EXPECT_LT((got.block<3, 1>(0, 3) - wanted.block<3, 1>(0, 3)).norm(), 1e-6) << what;
    EXPECT_LT((got.block<3, 3>(0, 0) - wanted.block<3, 3>(0, 0)).norm(), 1e-9) << what;
  };
  // Sweep 11 comes 0.2 s after sweep 10, as sweep 10 after 9: the last step, its sideways move the
  // others' 4 cm per 0.1 s over 0.2 s.
  Pose wanted = last_step;
  wanted(1, 3) = 8.0;
  expect_step(predict(Case{}), wanted, "weakly pinned");
  // Everywhere else, the last step as it was.
  expect_step(predict(Case{.last_constraint = 0.3}), last_step, "pinned well");
  expect_step(predict(Case{.sweep_s = 0.0}), last_step, "keyframes without times");
  expect_step(predict(Case{.weak_step_constraint = 0.0}), last_step, "off");
  expect_step(predict(Case{.others_constraint = 0.05}), last_step, "no well-pinned step before it");
  MappingSettings bad = defaults;
  for (const double fraction : {-0.1, 1.5, std::nan("")}) {
    bad.motion.weak_step_constraint = fraction;
    EXPECT_THROW(bad.validate(), std::invalid_argument) << fraction;
  }
  bad = defaults;
  bad.motion.weak_step_window = 0;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
}

// A hand-held sensor with a narrow cone (40 deg) weaving fast (60 deg/s at 5 Hz) up a smooth drive
// with no roof bars, rails or rubble: its surfaces pin the motion along the drive weakly (0.02-0.05
// of the best direction), and first matches from the wide adaptive bound move the sensor 25-45 cm
// along it. The slide test matches them again from the prediction, and those fit no closer (RMS
// within 1 %: the weave really went there): none is kept, and the run is the one with the test off,
// bit for bit (the metascan made for the second match is not kept either). Where the second match
// fits clearly closer (the real hand-held walks in docs/benchmarks.md, "Moving LiDAR") it is kept.
// MotionPrediction::unpinned_turn against sums by hand. Sweeps 0-12, 0.1 s apart, each step
// turning 4 deg about x one way and then the other (a sensor turned back and forth) and 5 cm
// forward; each match pinned its turn about x at 0.05 of its best axis (the axis given either way
// round: an eigenvector's sign means nothing).
TEST(MovingMapping, AnUnpinnedTurnSumsTheRecentWeaklyPinnedSweepsTurnsAboutTheirWeakAxes) {
  CpuBackend cpu;
  struct Case {
    double sweep_s = 0.1;                              // timed sweeps; 0: keyframes without times
    std::size_t pinned = 0;                            // > 0: this scan's match pinned every turn well
    double limit_deg = MotionSettings{}.max_unpinned_turn_deg;
    double window_s = MotionSettings{}.unpinned_turn_window_s;
  };
  const auto step_deg = [](std::size_t k) { return k % 2 == 0 ? 4.0 : -4.0; };
  const auto turn = [&](const Case& c) {
    MappingSettings settings;
    settings.motion.max_unpinned_turn_deg = c.limit_deg;
    settings.motion.unpinned_turn_window_s = c.window_s;
    detail::SurveyState state;
    Pose pose = Pose::Identity();
    for (std::size_t i = 0; i <= 12; ++i) {
      add_sweep(state, cpu, settings, i, c.sweep_s, 0.1 * double(i), 70 + std::uint32_t(i));
      if (i > 0) {
        Pose step = Pose::Identity();
        step.block<3, 3>(0, 0) =
            Eigen::AngleAxisd(step_deg(i) * M_PI / 180.0, Eigen::Vector3d::UnitX()).toRotationMatrix();
        step(0, 3) = 5.0;
        pose = pose * step;
      }
      state.place(i, pose);
      RegistrationHealth health;
      health.judged = i > 0;
      health.rotation_constraint = i == c.pinned ? 0.3 : 0.05;
      health.weakest_axis = i % 3 == 0 ? Eigen::Vector3d(-1.0, 0.0, 0.0) : Eigen::Vector3d(1.0, 0.0, 0.0);
      state.judged(i, health);
    }
    return detail::MotionPrediction(settings).unpinned_turn(state, 12);
  };
  // The last second: the steps into sweeps 3-12, 4 deg each whatever its sense.
  const std::optional<detail::UnpinnedTurn> all = turn(Case{});
  ASSERT_TRUE(all.has_value());
  EXPECT_NEAR(all->deg, 40.0, 1e-9);
  EXPECT_EQ(all->sweeps, 10);
  EXPECT_NEAR(all->seconds, 1.0, 1e-12);
  EXPECT_NEAR(all->constraint, 0.05, 1e-12);
  EXPECT_NEAR(turn(Case{.window_s = 0.5})->deg, 20.0, 1e-9);
  // A match that pinned its turns ends the run: the steps into sweeps 9-12.
  EXPECT_NEAR(turn(Case{.pinned = 8})->deg, 16.0, 1e-9);
  EXPECT_EQ(turn(Case{.pinned = 8})->sweeps, 4);
  // None where sweep 12 pinned its own turns, where the scans carry no times, or with the test off.
  EXPECT_FALSE(turn(Case{.pinned = 12}).has_value());
  EXPECT_FALSE(turn(Case{.sweep_s = 0.0}).has_value());
  EXPECT_FALSE(turn(Case{.limit_deg = 0.0}).has_value());
  expect_rejected([](MappingSettings& s, double v) { s.motion.max_unpinned_turn_deg = v; },
                  {-1.0, std::nan(""), std::numeric_limits<double>::infinity()});
  expect_rejected([](MappingSettings& s, double v) { s.motion.unpinned_turn_window_s = v; },
                  {0.0, -1.0, std::nan("")});
  expect_rejected([](MappingSettings& s, double v) { s.motion.unpinned_turn_constraint = v; },
                  {-0.1, 1.5, std::nan("")});
}

// The simulated hand-held rosette scanner in a drive: its surfaces hardly pin a turn about its view
// axis (0.03-0.05 of the best axis), and its pattern turns 6 deg from one sweep to the next. Walking
// slowly (0.5 m/s) the matches follow the pattern, 7 deg a sweep, and the map turns 80-88 deg off
// the truth, none of its sweeps named for it; with the test the sweeps that turned so are named and their turn about that axis
// taken out, and the sweeps after them stand right (within 3 deg at the 40th). Standing still the
// matches turn the sensor back and forth, 7-11 deg a sweep: named, though the map is not right
// there. Walking at 1.4 m/s (the sway turns the sensor about that axis too, 8-9 deg a second) no
// sweep is doubtful for it.
TEST(MovingMapping, ARosetteTurnedByItsPatternIsNamedAndItsTurnTakenOut) {
  sim::MovingSimulationSettings slow;
  slow.sensor = sim::MovingSensor::kHandheld;
  slow.speed_mps = 0.5;
  slow.sweeps = 40;
  slow.mine.seed = 4;
  CpuBackend cpu;
  const auto unpinned = [](const MappingResult& result) {
    std::size_t n = 0;
    for (const std::size_t k : result.doubtful()) {
      if (result.scans[k].health.failed != HealthTest::kUnpinnedTurn) continue;
      EXPECT_NE(result.scans[k].health.doubt.find("hardly pin"), std::string::npos);
      ++n;
    }
    return n;
  };
  MappingSettings off;
  off.motion.max_unpinned_turn_deg = 0.0;
  const sim::MovingSurvey walk = sim::simulate_moving_survey(slow);
  const MappingResult trusted = map_survey(walk.scans, off, cpu);
  const MappingResult named = map_survey(walk.scans, MappingSettings{}, cpu);
  ASSERT_TRUE(trusted.all_registered());
  ASSERT_TRUE(named.all_registered());
  double worst_deg = 0.0;  // the case: the map turned, and every sweep was trusted
  for (std::size_t k = 0; k < walk.scans.size(); ++k) worst_deg = std::max(worst_deg, turn_from_first_off_deg(trusted, walk, k));
  std::printf("walking at 0.5 m/s: turned up to %.1f deg off the truth with the test off; the 40th %.1f deg off "
              "with it, %zu sweeps named\n",
              worst_deg, turn_from_first_off_deg(named, walk, 39), unpinned(named));
  ASSERT_GT(worst_deg, 30.0);
  // (No sweep named for its turn; whether another test happens to doubt one of them differs with
  // the compiler's last bits: none with GCC, one under clang's TSan build.)
  EXPECT_EQ(unpinned(trusted), 0u);
  EXPECT_GT(unpinned(named), 0u);
  EXPECT_LT(turn_from_first_off_deg(named, walk, 39), 3.0);

  sim::MovingSimulationSettings standing = slow;
  standing.speed_mps = 0.0;
  standing.sweeps = 30;
  const sim::MovingSurvey still = sim::simulate_moving_survey(standing);
  const MappingResult still_trusted = map_survey(still.scans, off, cpu);
  worst_deg = 0.0;
  for (std::size_t k = 0; k < still.scans.size(); ++k) {
    worst_deg = std::max(worst_deg, turn_from_first_off_deg(still_trusted, still, k));
  }
  std::printf("standing still: turned up to %.1f deg with the test off\n", worst_deg);
  ASSERT_GT(worst_deg, 10.0);
  EXPECT_EQ(unpinned(still_trusted), 0u);
  EXPECT_GT(unpinned(map_survey(still.scans, MappingSettings{}, cpu)), 0u);

  sim::MovingSimulationSettings walking = slow;
  walking.speed_mps.reset();
  walking.sweeps = 60;
  const MappingResult walked = map_survey(sim::simulate_moving_survey(walking).scans, MappingSettings{}, cpu);
  EXPECT_EQ(unpinned(walked), 0u);
}

/// The first 25 sweeps of the simulated hand-held walk of seed 4.
sim::MovingSurvey handheld_walk_of_seed_4() {
  sim::MovingSimulationSettings simulation;
  simulation.sensor = sim::MovingSensor::kHandheld;
  simulation.sweeps = 25;
  simulation.mine.seed = 4;
  return sim::simulate_moving_survey(simulation);
}

// The simulated hand-held walk of seed 4: sweep 1's match against sweep 0 alone (one rosette
// pattern, a turn about the view axis the surfaces hardly pin) is 6.4 deg off, and every later
// pose keeps that turn. Matched again once 20 sweeps are in, sweep 0 says where they stand: the map
// turns right, within half a degree; the sweeps after it keep their places relative to each other
// (moved together), and sweep 0 stays where it was, the survey's frame.
TEST(MovingMapping, TheFirstSweepMatchedAgainstTheSweepsAfterItTurnsTheMapRight) {
  const sim::MovingSurvey survey = handheld_walk_of_seed_4();
  CpuBackend cpu;
  const MappingSettings defaults;
  ASSERT_EQ(defaults.motion.first_sweep_rematch_scans, 20);
  MappingSettings off = defaults;
  off.motion.first_sweep_rematch_scans = 0;
  const MappingResult once = map_survey(survey.scans, off, cpu);
  const MappingResult again = map_survey(survey.scans, defaults, cpu);
  ASSERT_TRUE(once.all_registered());
  ASSERT_TRUE(again.all_registered());
  std::printf("sweep 20 turned off the truth: matched once %.2f deg, again %.2f deg\n", turn_from_first_off_deg(once, survey, 20),
              turn_from_first_off_deg(again, survey, 20));
  EXPECT_GT(turn_from_first_off_deg(once, survey, 20), 3.0);  // the case
  for (const std::size_t k : {5u, 10u, 20u}) EXPECT_LT(turn_from_first_off_deg(again, survey, k), 1.0) << k;
  EXPECT_EQ(again.scans[0].pose_cm, once.scans[0].pose_cm);
  expect_moved_together(once, again, 20);
  EXPECT_TRUE(has_note(again, "matched again against the 20 sweeps"));
  expect_rejected([](MappingSettings& s, double v) { s.motion.first_sweep_rematch_scans = int(v); }, {-1.0});
}

// The spring to the prediction (MotionSettings::sweep_start_spring_pairs): a narrow-field timed
// sweep's matches from its prediction take it; keyframes without times and a spinning sensor's
// sweeps (they span 360 deg of azimuth about the sensor, wherever their points are stored) do not,
// their outputs the same bits with it off. Its effect
// on drift is docs/benchmarks.md's, "A spring for a narrow field"; the mechanism's test is
// test_horn_icp.cpp's IcpStartSpring.
TEST(MovingMapping, TheStartSpringHoldsNarrowFieldTimedSweepsOnly) {
  const sim::MovingSurvey survey = handheld_walk_of_seed_4();
  CpuBackend cpu;
  const MappingSettings spring;
  ASSERT_EQ(spring.motion.sweep_start_spring_pairs, 160.0);
  MappingSettings off = spring;
  off.motion.sweep_start_spring_pairs = 0.0;
  const auto mean_off_cm = [&](const MappingResult& result) {
    return pose_errors(test::poses_of(result), survey.truth_cm).mean_translation_cm;
  };
  const MappingResult held = map_survey(survey.scans, spring, cpu);
  const MappingResult free = map_survey(survey.scans, off, cpu);
  ASSERT_TRUE(held.all_registered());
  ASSERT_TRUE(free.all_registered());
  std::printf("hand-held, 25 sweeps: %.2f cm from the truth with the spring, %.2f cm without\n", mean_off_cm(held),
              mean_off_cm(free));
  bool differ = false;
  for (std::size_t k = 1; k < held.scans.size(); ++k) differ = differ || held.scans[k].pose_cm != free.scans[k].pose_cm;
  EXPECT_TRUE(differ) << "the timed sweeps' matches take the spring";
  EXPECT_LT(mean_off_cm(held), 5.0);
  // The same scans without their points' times: keyframes, matched without the spring.
  std::vector<Scan> keyframes = survey.scans;
  for (Scan& scan : keyframes) scan.attributes.time_s.clear();
  const MappingResult keyed = map_survey(keyframes, spring, cpu);
  const MappingResult keyed_off = map_survey(keyframes, off, cpu);
  ASSERT_EQ(keyed.scans.size(), keyed_off.scans.size());
  for (std::size_t k = 0; k < keyed.scans.size(); ++k) EXPECT_EQ(keyed.scans[k].pose_cm, keyed_off.scans[k].pose_cm) << k;
  // A spinning sensor's sweeps: no spring, the same bits; with every field held (360), they take it.
  sim::MovingSimulationSettings spinning;
  spinning.sensor = sim::MovingSensor::kSpinning;
  spinning.sweeps = 12;
  const sim::MovingSurvey drive = sim::simulate_moving_survey(spinning);
  const MappingResult spun = map_survey(drive.scans, spring, cpu);
  const MappingResult spun_off = map_survey(drive.scans, off, cpu);
  for (std::size_t k = 0; k < spun.scans.size(); ++k) EXPECT_EQ(spun.scans[k].pose_cm, spun_off.scans[k].pose_cm) << k;
  MappingSettings every_field = spring;
  every_field.motion.sweep_spring_max_field_deg = 360.0;
  const MappingResult spun_held = map_survey(drive.scans, every_field, cpu);
  bool spun_differ = false;
  for (std::size_t k = 1; k < spun.scans.size(); ++k) spun_differ = spun_differ || spun_held.scans[k].pose_cm != spun.scans[k].pose_cm;
  EXPECT_TRUE(spun_differ) << "every field held: the spinning sweeps take the spring";
  // The same sweeps stored about an origin 80 m to the side (read relative to a local origin, as a
  // file whose points lie far from its frame's): about that origin they span a few tens of degrees,
  // about the sensor still 360, and the field is the sensor's. No spring: the same bits as without.
  const std::vector<Scan> aside = stored_about(drive.scans, Eigen::Vector3f(0.0f, 8000.0f, 0.0f));
  const MappingResult aside_held = map_survey(aside, spring, cpu);
  const MappingResult aside_off = map_survey(aside, off, cpu);
  ASSERT_EQ(aside_held.scans.size(), aside_off.scans.size());
  for (std::size_t k = 0; k < aside_held.scans.size(); ++k) {
    EXPECT_EQ(aside_held.scans[k].pose_cm, aside_off.scans[k].pose_cm) << "stored aside " << k;
  }
  expect_rejected([](MappingSettings& s, double v) { s.motion.sweep_start_spring_pairs = v; },
                  {-1.0, std::numeric_limits<double>::infinity(), std::numeric_limits<double>::quiet_NaN()});
  expect_rejected([](MappingSettings& s, double v) { s.motion.sweep_spring_full_error_cm = v; },
                  {0.0, -1.0, std::numeric_limits<double>::quiet_NaN()});
  expect_rejected([](MappingSettings& s, double v) { s.motion.sweep_spring_max_field_deg = v; }, {0.0, 361.0});
  expect_rejected([](MappingSettings& s, double v) { s.motion.sprung_release_cm = v; },
                  {0.0, std::numeric_limits<double>::infinity()});
}

// The simulated spinning loop of seed 2 (80 m, 10 m/s), its first 22 sweeps: it starts in a corner,
// its first sweep turning 43 deg while it is taken, where the step into sweep 1 says 12.
sim::MovingSimulationSettings corner_loop_start() {
  sim::MovingSimulationSettings simulation;
  simulation.sensor = sim::MovingSensor::kSpinning;
  simulation.mine.loop_length_cm = 8000.0;
  simulation.mine.seed = 2;
  simulation.sweeps = 22;
  return simulation;
}

// The simulated spinning loop (seed 2) starts in a corner at 10 m/s: its first sweep turned 43 deg
// while it was taken, slowing from 600 to 250 deg/s, where the step into sweep 1 says 12. Deskewed
// by that step, the first sweep is bent, and matched again it leaves the map turned 2.4-6.2 deg about
// it (by build and origin). Its own motion fitted against the 20 sweeps after it, the map turns right within 2.5 deg (2.0 in
// GCC's Release build: the fit's velocity is constant over the sweep, the truth's fell to a third);
// sweeps 1-20 keep their places relative to each other, and scan 0 stays. Where the fit is not kept
// (it did not converge, or the match from it was not trusted), the run is the step's, bit for bit,
// and a note says so. Which of the two a build gets depends on last bits in this chaotic corner:
// clang's builds (the sanitizer runs) do not converge here (docs/benchmarks.md), the same sweeps
// stored about another origin converge there. The sweeps after it take one metascan each
// (local_map_sweeps 1), as when these figures were measured: the chain 1-20 through the corner is
// chaotic too, and with the spinning sensor's kept local map (the default since 2026-12-08) the
// fit is kept in both builds and sweep 20 ends 2.1 deg off in GCC's Release build, 3.0 in clang's
// ASan build (the step's 3.3 and 4.8), which is the local map's chaos, not the fit's.
TEST(MovingMapping, TheFirstSweepsOwnMotionFittedTurnsTheMapOfALoopStartingInACornerRight) {
  sim::MovingSimulationSettings simulation = corner_loop_start();
  const sim::MovingSurvey survey = sim::simulate_moving_survey(simulation);
  CpuBackend cpu;
  MappingSettings defaults;
  defaults.motion.local_map_sweeps = 1;
  ASSERT_TRUE(defaults.motion.first_sweep_fit);
  MappingSettings off = defaults;
  off.motion.first_sweep_fit = false;
  const double half_s = 0.5 * simulation.sweep_period_s();
  const Pose true_motion = rigid_inverse(survey.trajectory.T_world_sensor(survey.stamps_s[0] - half_s)) *
                           survey.trajectory.T_world_sensor(survey.stamps_s[0] + half_s);
  const auto motion_off_deg = [&](const MappingResult& result) {
    return rotation_angle_deg(rigid_inverse(true_motion) * result.scans[0].sweep_motion_cm.value());
  };
  // One set of sweeps mapped with the step's motion and with the fit: true where the fit was kept.
  const auto compare = [&](const std::vector<Scan>& scans, const char* what) {
    const MappingResult stepped = map_survey(scans, off, cpu);
    const MappingResult fitted = map_survey(scans, defaults, cpu);
    EXPECT_TRUE(stepped.all_registered()) << what;
    EXPECT_TRUE(fitted.all_registered()) << what;
    if (!stepped.all_registered() || !fitted.all_registered()) return false;
    const bool kept = has_note(fitted, "its own motion over the sweep, fitted");
    std::printf("%s: sweep 20 turned off the truth %.2f deg with the step's motion, %.2f with the fit (%s); the "
                "first sweep turned %.1f deg, deskewed by %.1f (the step), %.1f\n",
                what, turn_from_first_off_deg(stepped, survey, 20), turn_from_first_off_deg(fitted, survey, 20),
                kept ? "kept" : "not kept", rotation_angle_deg(true_motion),
                rotation_angle_deg(stepped.scans[0].sweep_motion_cm.value()),
                rotation_angle_deg(fitted.scans[0].sweep_motion_cm.value()));
    EXPECT_GT(motion_off_deg(stepped), 20.0) << what;  // the case: the step's motion is 31 deg short
    if (!kept) {
      EXPECT_TRUE(has_note(fitted, "could not be fitted") || has_note(fitted, "was not trusted")) << what;
      for (std::size_t k = 0; k < fitted.scans.size(); ++k) EXPECT_EQ(fitted.scans[k].pose_cm, stepped.scans[k].pose_cm);
      // Not silently: the first sweep, deskewed by a step that turned 12 deg, is named.
      EXPECT_TRUE(fitted.scans[0].health.doubtful()) << what;
      return false;
    }
    EXPECT_FALSE(fitted.scans[0].health.doubtful()) << what;
    for (const std::size_t k : {1u, 10u, 20u}) EXPECT_LT(turn_from_first_off_deg(fitted, survey, k), 2.5) << what << k;
    EXPECT_LT(turn_from_first_off_deg(fitted, survey, 20), turn_from_first_off_deg(stepped, survey, 20)) << what;
    // Deskewed by the fitted motion, nearer the truth's than the step's: within half its error where
    // the fit converged. A fit that settled (wandering with its pairs' churn at its last stage's cap:
    // the sanitizer build, as simulated) is only nearer: one constant velocity for a turn that slowed
    // to a third fits a range of them alike (61.9 deg there against the truth's 43.6 and the step's
    // 12.7), and the map is as right (sweep 20 1.58 deg off, the step's 5.00).
    const bool settled = has_note(fitted, "settled within");
    EXPECT_LT(motion_off_deg(fitted), (settled ? 1.0 : 0.5) * motion_off_deg(stepped)) << what;
    EXPECT_EQ(fitted.scans[0].pose_cm, stepped.scans[0].pose_cm) << what;
    expect_moved_together(stepped, fitted, 20);  // as matched before the rematch
    return true;
  };
  const bool kept_here = compare(survey.scans, "as simulated");
  // The same sweeps stored about another origin (a file's points far from its frame's origin, read
  // relative to a local one): the fit works in the file's frame, the match in the points' frame.
  const bool kept_elsewhere =
      compare(stored_about(survey.scans, Eigen::Vector3f(360.0f, -240.0f, 55.0f)), "stored about another origin");
  EXPECT_TRUE(kept_here || kept_elsewhere);  // the fit is kept in one of them, on every build measured
}

// Where the first sweep's fit is not kept, its deskew is the step's: on a sweep that turned fast
// that is not silently the map's frame. The seed-2 loop's fit held to one iteration a stage does
// not converge: the poses are the step's bit for bit, and scan 0 is doubtful, naming the step's
// 12 deg turn; with the limit above that turn it is not. A straight drive's first step turns
// 0.1 deg: its failed fit names nothing.
TEST(MovingMapping, AFirstSweepWhoseOwnMotionIsNotFittedAndThatTurnedFastIsDoubtful) {
  sim::MovingSimulationSettings simulation = corner_loop_start();
  const sim::MovingSurvey corner = sim::simulate_moving_survey(simulation);
  CpuBackend cpu;
  MappingSettings off;
  off.motion.first_sweep_fit = false;
  MappingSettings unfitted;
  unfitted.motion.first_sweep_fit_settings.max_iterations = 1;
  const MappingResult stepped = map_survey(corner.scans, off, cpu);
  const MappingResult failed = map_survey(corner.scans, unfitted, cpu);
  ASSERT_TRUE(failed.all_registered());
  EXPECT_TRUE(has_note(failed, "could not be fitted"));
  for (std::size_t k = 0; k < failed.scans.size(); ++k) EXPECT_EQ(failed.scans[k].pose_cm, stepped.scans[k].pose_cm);
  const RegistrationHealth& first = failed.scans[0].health;
  ASSERT_TRUE(first.doubtful());
  EXPECT_NE(first.doubt.find("could not be fitted against the 20 sweeps after it"), std::string::npos) << first.doubt;
  const std::size_t turn_at = first.doubt.find("turned the sensor ");
  ASSERT_NE(turn_at, std::string::npos) << first.doubt;
  const double turned_deg = std::stod(first.doubt.substr(turn_at + 18));
  EXPECT_GT(turned_deg, 10.0);
  EXPECT_LT(turned_deg, 15.0);
  EXPECT_GT(first.paired_fraction, 0.5);  // the figures of its match against them
  EXPECT_FALSE(stepped.scans[0].health.doubtful());  // the fit off: the user's choice, not judged
  unfitted.motion.unfitted_first_sweep_max_turn_deg = 20.0;
  const MappingResult allowed = map_survey(corner.scans, unfitted, cpu);
  EXPECT_FALSE(allowed.scans[0].health.doubtful());
  for (std::size_t k = 0; k < allowed.scans.size(); ++k) EXPECT_EQ(allowed.scans[k].pose_cm, stepped.scans[k].pose_cm);

  simulation.mine.loop_length_cm = 0.0;
  const sim::MovingSurvey straight = sim::simulate_moving_survey(simulation);
  unfitted.motion.unfitted_first_sweep_max_turn_deg = MotionSettings{}.unfitted_first_sweep_max_turn_deg;
  const MappingResult drive = map_survey(straight.scans, unfitted, cpu);
  ASSERT_TRUE(drive.all_registered());
  EXPECT_TRUE(has_note(drive, "could not be fitted"));
  EXPECT_FALSE(drive.scans[0].health.doubtful()) << drive.scans[0].health.doubt;
  expect_rejected([](MappingSettings& s, double v) { s.motion.unfitted_first_sweep_max_turn_deg = v; },
                  {-1.0, std::numeric_limits<double>::infinity()});
  expect_rejected([](MappingSettings& s, double v) { s.motion.first_sweep_fit_settings.max_iterations = int(v); },
                  {0.0});
}

TEST(MovingMapping, ASecondMatchFromThePredictionThatFitsNoCloserChangesNothing) {
  sim::MovingSimulationSettings simulation;
  simulation.sensor = sim::MovingSensor::kHandheld;
  simulation.sweeps = 45;
  simulation.rate_hz = 5.0;
  simulation.turn_deg_s = 60.0;
  simulation.handheld.fov_deg = 40.0;
  simulation.mine.wall_roughness_cm = simulation.mine.floor_roughness_cm = simulation.mine.ceiling_roughness_cm = 0.0;
  simulation.mine.rails = false;
  simulation.mine.timber_set_spacing_min_cm = simulation.mine.timber_set_spacing_max_cm = 1e6;
  simulation.mine.rubble_pile_spacing_min_cm = simulation.mine.rubble_pile_spacing_max_cm = 1e6;
  const sim::MovingSurvey survey = sim::simulate_moving_survey(simulation);
  const auto run = [&](double slide_constraint) {
    MappingSettings settings;
    settings.motion.slide_constraint = slide_constraint;
    // The first sweep matched again after sweep 20 moves the rest so that no first match slides
    // past the pair bound any more, and the spring to the prediction holds them from sliding in
    // the first place (in clang's TSan build a slide it left was then matched closer from the
    // prediction, and kept): the case is the sequence as matched once, free.
    settings.motion.first_sweep_rematch_scans = 0;
    settings.motion.sweep_start_spring_pairs = 0.0;
    CpuBackend cpu;
    return map_survey(survey.scans, settings, cpu);
  };
  const MappingResult with = run(MotionSettings{}.slide_constraint);
  const MappingResult without = run(0.0);
  std::printf("ICP iterations with the slide test %d, without %d\n", with.step1_icp_iterations,
              without.step1_icp_iterations);
  EXPECT_GT(with.step1_icp_iterations, without.step1_icp_iterations);  // second matches were tried...
  ASSERT_EQ(with.scans.size(), without.scans.size());
  for (std::size_t k = 0; k < with.scans.size(); ++k) {  // ...and none kept, nothing else changed
    EXPECT_EQ(with.scans[k].pose_cm, without.scans[k].pose_cm) << with.scans[k].name;
    EXPECT_EQ(with.scans[k].health.note.find("slid"), std::string::npos) << with.scans[k].name;
  }
  MappingSettings bad;
  for (const double fraction : {-0.1, 1.5, std::nan("")}) {
    bad.motion.slide_constraint = fraction;
    EXPECT_THROW(bad.validate(), std::invalid_argument) << fraction;
  }
  bad = MappingSettings{};
  for (const double factor : {0.0, 1.5, std::nan("")}) {
    bad.motion.slide_rms_factor = factor;
    EXPECT_THROW(bad.validate(), std::invalid_argument) << factor;
  }
}

}  // namespace
}  // namespace minemap
