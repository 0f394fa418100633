// Accuracy and agreement of the whole mapper: the simulated mine against ground truth, real scan
// pairs against their reference poses, CPU against OpenCL, and run-to-run determinism.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <numbers>
#include <random>

#include "minemap/backend/cpu_backend.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/sim/mine_simulator.hpp"
#include "minemap/sim/moving_lidar.hpp"
#include "minemap/slam/local_map.hpp"
#include "minemap/slam/loop_closing.hpp"
#include "minemap/slam/survey_matching.hpp"
#include "minemap/slam/survey_state.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

/// The first `scans` scans of a simulated survey (seed 1 = the default survey of `minemap simulate`).
sim::SimulatedSurvey small_survey(int scans, std::uint32_t seed = 1) {
  sim::SimulationSettings settings;
  settings.mine.scans = scans;
  settings.mine.seed = seed;
  return sim::simulate_mine_survey(settings);
}

/// The stop-and-go survey of `minemap simulate --loop 80` (seed 1): 17 scans, one 80 m loop.
sim::SimulatedSurvey loop_survey_80m() {
  sim::SimulationSettings settings;
  settings.mine.seed = 1;
  settings.mine.loop_length_cm = 8000.0;
  return sim::simulate_mine_survey(settings);
}

using test::odometry_of;
using test::poses_of;

TEST(MappingSimulatedMine, SimultaneousMatchingIsAccurateAndBeatsPairwise) {
  // The first 24 scans (92 m) of the default survey. (The whole 250 m survey takes minutes; its
  // figures are in docs/benchmarks.md.)
  const auto survey = small_survey(24);
  MappingSettings settings = MappingSettings::simultaneous();
  CpuBackend cpu;
  settings.mode = MatchingMode::kPairwise;
  const auto pairwise = map_survey(survey.scans, settings, cpu);
  settings.mode = MatchingMode::kSimultaneous;
  const auto simultaneous = map_survey(survey.scans, settings, cpu);
  ASSERT_TRUE(pairwise.all_registered());
  ASSERT_TRUE(simultaneous.all_registered());
  const auto odometry = pose_errors(odometry_of(survey.scans), survey.truth_cm);
  const auto paired = pose_errors(poses_of(pairwise), survey.truth_cm);
  const auto relaxed = pose_errors(poses_of(simultaneous), survey.truth_cm);
  std::printf("mean translation error: odometry %.2f cm, pairwise %.2f cm, simultaneous %.2f cm over %.1f m\n",
              odometry.mean_translation_cm, paired.mean_translation_cm, relaxed.mean_translation_cm,
              relaxed.path_length_cm / 100.0);
  EXPECT_LE(relaxed.mean_translation_cm, 0.002 * relaxed.path_length_cm);  // at most 0.2 % of the drive
  EXPECT_LT(relaxed.mean_translation_cm, 0.1 * odometry.mean_translation_cm);
  EXPECT_LT(relaxed.mean_translation_cm, paired.mean_translation_cm);
  EXPECT_GT(simultaneous.relaxation_matches, 0);
  EXPECT_GT(simultaneous.step3_icp_iterations, 0);
}

// The relaxation's bounds (a few matches after each new scan, the rest queued for later; a union of
// the nearest overlapping scans) keep the cost per scan flat (bench/time_per_scan.sh); they must not
// cost accuracy against the paper's queue, emptied after every scan over every overlapping scan.
TEST(MappingSimulatedMine, TheBoundedRelaxationIsAsAccurateAsThePapersQueue) {
  const auto survey = small_survey(12);
  CpuBackend cpu;
  MappingSettings settings = MappingSettings::simultaneous();
  // A match that moves a scan by more than 1 cm re-queues its neighbours: the queue grows.
  settings.moved_translation_cm = 1.0;
  settings.moved_rotation_deg = 0.05;
  const auto bounded = map_survey(survey.scans, settings, cpu);
  settings.max_relaxation_matches_per_scan = 1;
  settings.max_relaxation_neighbours = 2;
  const auto tight = map_survey(survey.scans, settings, cpu);
  settings.max_relaxation_matches_per_scan = 0;
  settings.max_relaxation_neighbours = 0;
  const auto unbounded = map_survey(survey.scans, settings, cpu);
  for (const auto* result : {&bounded, &tight, &unbounded}) {
    ASSERT_TRUE(result->all_registered());
    EXPECT_TRUE(result->doubtful().empty());
  }
  const std::size_t n = survey.scans.size();
  // At most one match after each of scans 1..n-1, then at most 2 per scan to empty the queue.
  EXPECT_LE(static_cast<std::size_t>(tight.relaxation_matches), (n - 1) + 2 * n);
  EXPECT_GT(static_cast<std::size_t>(tight.relaxation_matches), n - 1);  // what waited was matched later
  EXPECT_GT(unbounded.relaxation_matches, tight.relaxation_matches);
  for (std::size_t i = 1; i < n; ++i) EXPECT_GT(bounded.scans[i].match_s, 0.0) << i;
  const double e_bounded = pose_errors(poses_of(bounded), survey.truth_cm).mean_translation_cm;
  const double e_tight = pose_errors(poses_of(tight), survey.truth_cm).mean_translation_cm;
  const double e_unbounded = pose_errors(poses_of(unbounded), survey.truth_cm).mean_translation_cm;
  std::printf("mean error: default bounds %.2f cm (%d matches), 1 match / 2 neighbours %.2f cm (%d), unbounded %.2f cm "
              "(%d)\n",
              e_bounded, bounded.relaxation_matches, e_tight, tight.relaxation_matches, e_unbounded,
              unbounded.relaxation_matches);
  EXPECT_LE(e_bounded, 1.25 * e_unbounded + 1.0);
  EXPECT_LE(e_tight, 2.0 * e_unbounded + 2.0);
}

TEST(MappingSimulatedMine, IncrementalMatchingBeatsOdometry) {
  const auto survey = small_survey(8, 11);
  MappingSettings settings;
  CpuBackend cpu;
  settings.mode = MatchingMode::kIncremental;
  const auto result = map_survey(survey.scans, settings, cpu);
  ASSERT_TRUE(result.all_registered());
  const auto odometry = pose_errors(odometry_of(survey.scans), survey.truth_cm);
  const auto incremental = pose_errors(poses_of(result), survey.truth_cm);
  EXPECT_LT(incremental.mean_translation_cm, 0.1 * odometry.mean_translation_cm);
  EXPECT_LE(incremental.mean_translation_cm, 0.002 * incremental.path_length_cm);
}

// A survey that drives a loop back to its start: the loop is found, matched and closed, and the
// map is more accurate for it; without loop closing the first and last scans disagree more.
TEST(MappingLoops, ALoopSurveyIsClosedAndItsEndsAgree) {
  sim::SimulationSettings sim_settings;
  sim_settings.mine.seed = 1;
  sim_settings.mine.loop_length_cm = 12000.0;
  const auto survey = sim::simulate_mine_survey(sim_settings);
  ASSERT_GE(survey.scans.size(), 25u);
  CpuBackend cpu;
  MappingSettings settings;
  const auto closed = map_survey(survey.scans, settings, cpu);
  settings.loops.enabled = false;
  const auto open = map_survey(survey.scans, settings, cpu);
  ASSERT_TRUE(closed.all_registered());
  ASSERT_TRUE(open.all_registered());
  EXPECT_TRUE(closed.doubtful().empty());
  int loops_closed = 0;
  for (const LoopClosure& loop : closed.loops) loops_closed += loop.closed ? 1 : 0;
  EXPECT_GE(loops_closed, 1);
  EXPECT_TRUE(open.loops.empty());
  // How far the last scan is from where the truth puts it relative to the first.
  const auto end_error = [&](const MappingResult& result) {
    const std::vector<Pose> poses = poses_of(result);
    const Pose estimated = rigid_inverse(poses.front()) * poses.back();
    const Pose truth = rigid_inverse(survey.truth_cm.front()) * survey.truth_cm.back();
    return translation_norm(rigid_inverse(truth) * estimated);
  };
  const auto closed_errors = pose_errors(poses_of(closed), survey.truth_cm);
  const auto open_errors = pose_errors(poses_of(open), survey.truth_cm);
  std::printf("loop of %.1f m: end-to-start error %.2f cm closed, %.2f cm open; mean error %.2f cm closed, %.2f cm "
              "open\n",
              closed_errors.path_length_cm / 100.0, end_error(closed), end_error(open),
              closed_errors.mean_translation_cm, open_errors.mean_translation_cm);
  EXPECT_LT(end_error(closed), 5.0);
  EXPECT_LT(end_error(closed), end_error(open));
  EXPECT_LT(closed_errors.mean_translation_cm, open_errors.mean_translation_cm);
  EXPECT_LE(closed_errors.mean_translation_cm, 0.001 * closed_errors.path_length_cm);
}

// Each closed loop of a patrol carries the guesses of every later scan (LoopClosing::carry), and
// the next loop's move is computed from guesses earlier moves placed. Sixty laps, a loop each, as a
// 6 000-scan patrol closes them: every guess stays a rigid motion, and each loop's pair stands as
// its match found it. (A move computed as it stood before 2026-12-05 compounded round-off loop after
// loop: a 2 000-scan patrol's rotations were scaled by 30 % after 60 loops.)
TEST(MappingLoops, LoopAfterLoopTheCarriedGuessesStayRigid) {
  constexpr std::size_t kLaps = 60, kScansPerLap = 100;
  std::mt19937 random(28);
  std::normal_distribution<double> noise(0.0, 1.0);
  // A 400 m circle, a little tilted and rolled, each lap a little off the one before (cm).
  std::vector<Pose> guess((kLaps + 1) * kScansPerLap);
  for (std::size_t k = 0; k < guess.size(); ++k) {
    const double heading = 2.0 * std::numbers::pi * double(k % kScansPerLap) / double(kScansPerLap);
    Pose pose = Pose::Identity();
    pose.block<3, 3>(0, 0) = (Eigen::AngleAxisd(heading + 0.01 * noise(random), Eigen::Vector3d::UnitY()) *
                              Eigen::AngleAxisd(0.02 * noise(random), Eigen::Vector3d::UnitX()) *
                              Eigen::AngleAxisd(0.02 * noise(random), Eigen::Vector3d::UnitZ()))
                                 .toRotationMatrix();
    pose.block<3, 1>(0, 3) = Eigen::Vector3d(6366.0 * std::cos(heading), 30.0 * double(k / kScansPerLap),
                                             6366.0 * std::sin(heading)) +
                             20.0 * Eigen::Vector3d(noise(random), noise(random), noise(random));
    guess[k] = pose;
  }
  for (std::size_t lap = 1; lap <= kLaps; ++lap) {
    const std::size_t from = (lap - 1) * kScansPerLap + 37, to = lap * kScansPerLap + 37 + lap % 3;
    Pose from_to = Pose::Identity();  // a match: near the place `from` stands, a little turned
    from_to.block<3, 3>(0, 0) = Eigen::AngleAxisd(0.01 * noise(random), Eigen::Vector3d::UnitY()).toRotationMatrix();
    from_to.block<3, 1>(0, 3) = Eigen::Vector3d(30.0 * noise(random), 5.0 * noise(random), 30.0 * noise(random));
    detail::LoopClosing::carry(guess, from, to, from_to);
    const Pose stands = rigid_inverse(guess[from]) * guess[to];
    EXPECT_LT(translation_norm(rigid_inverse(from_to) * stands), 1e-4) << "lap " << lap;
    EXPECT_LT(rotation_angle_deg(rigid_inverse(from_to) * stands), 1e-4) << "lap " << lap;  // acos near 0: 1e-6 deg of round-off
  }
  for (std::size_t k = 0; k < guess.size(); ++k) {
    ASSERT_TRUE(is_valid_rigid(guess[k], 1e-9)) << "scan " << k << ": det " << guess[k].block<3, 3>(0, 0).determinant();
  }
}

// A patrol: four laps of a 120 m loop. From its second lap on every scan is near an earlier one, one
// long return: with one loop edge for it the laps drift apart between edges. Cut every 100 m of
// drive (LoopClosureSettings::max_return_path_cm) each piece gets its own edge, and each closed edge
// carries the scans after it to where it found its scan before the next piece is looked for.
TEST(MappingLoops, APatrolsLapsAreTiedTogetherEveryHundredMetres) {
  sim::SimulationSettings sim_settings;
  sim_settings.mine.seed = 1;
  sim_settings.mine.loop_length_cm = 12000.0;
  sim_settings.mine.scans = 120;
  const auto survey = sim::simulate_mine_survey(sim_settings);
  ASSERT_EQ(survey.scans.size(), 120u);
  CpuBackend cpu;
  MappingSettings settings;
  const auto tied = map_survey(survey.scans, settings, cpu);
  settings.loops.max_return_path_cm = 0.0;  // one edge a return
  const auto once = map_survey(survey.scans, settings, cpu);
  ASSERT_TRUE(tied.all_registered());
  EXPECT_TRUE(tied.doubtful().empty());
  const auto closed = [](const MappingResult& result) {
    int count = 0;
    for (const LoopClosure& loop : result.loops) count += loop.closed ? 1 : 0;
    return count;
  };
  EXPECT_GE(closed(tied), 3);
  EXPECT_EQ(closed(once), 1);
  // Each scan of laps 2-4 against the scan of lap 1 nearest it in truth: where the map puts one
  // from the other, against the truth (cm).
  const auto lap_disagreement = [&](const MappingResult& result) {
    const std::vector<Pose> poses = poses_of(result);
    std::vector<double> apart;
    for (std::size_t j = 30; j < poses.size(); ++j) {
      std::size_t nearest = 0;
      for (std::size_t i = 1; i < 30; ++i) {
        if ((survey.truth_cm[i].block<3, 1>(0, 3) - survey.truth_cm[j].block<3, 1>(0, 3)).norm() <
            (survey.truth_cm[nearest].block<3, 1>(0, 3) - survey.truth_cm[j].block<3, 1>(0, 3)).norm()) {
          nearest = i;
        }
      }
      const Eigen::Vector3d mapped = poses[j].block<3, 1>(0, 3) - poses[nearest].block<3, 1>(0, 3);
      const Eigen::Vector3d truth = survey.truth_cm[j].block<3, 1>(0, 3) - survey.truth_cm[nearest].block<3, 1>(0, 3);
      apart.push_back((mapped - truth).norm());
    }
    std::nth_element(apart.begin(), apart.begin() + apart.size() / 2, apart.end());
    return apart[apart.size() / 2];
  };
  const auto tied_errors = pose_errors(poses_of(tied), survey.truth_cm);
  const auto once_errors = pose_errors(poses_of(once), survey.truth_cm);
  std::printf("patrol of %.0f m: laps from the first (median) %.1f cm tied every 100 m, %.1f cm one edge a return; "
              "mean error %.1f / %.1f cm\n",
              tied_errors.path_length_cm / 100.0, lap_disagreement(tied), lap_disagreement(once),
              tied_errors.mean_translation_cm, once_errors.mean_translation_cm);
  EXPECT_LT(lap_disagreement(tied), 20.0);
  EXPECT_LT(lap_disagreement(tied), 0.5 * lap_disagreement(once));
  EXPECT_LT(tied_errors.mean_translation_cm, 0.5 * once_errors.mean_translation_cm);
  EXPECT_LE(tied_errors.mean_translation_cm, 0.0005 * tied_errors.path_length_cm);
  // A loop match far from where the loops before put its scan is a look-alike place, not an edge:
  // with the limit at a millionth of the drive every match after the first is refused, and said.
  settings.loops.max_return_path_cm = MappingSettings{}.loops.max_return_path_cm;
  settings.loops.max_misclosure_fraction = 1e-6;
  const auto strict = map_survey(survey.scans, settings, cpu);
  EXPECT_EQ(closed(strict), 1);
  bool refused = false;
  for (const LoopClosure& loop : strict.loops) {
    refused = refused || loop.doubt.find("from where the loops closed before put it") != std::string::npos;
  }
  EXPECT_TRUE(refused);
  EXPECT_FALSE(strict.doubtful().empty());
}

TEST(MappingInterruption, AStopBetweenScansKeepsTheScansMatchedSoFar) {
  const auto survey = small_survey(6, 3);
  CpuBackend cpu;
  const auto full = map_survey(survey.scans, MappingSettings{}, cpu);
  EXPECT_FALSE(full.interrupted);
  EXPECT_EQ(full.scans_matched, 6u);
  std::size_t asked = 0;
  const auto stopped = map_survey(survey.scans, MappingSettings{}, cpu, {}, [&] { return ++asked > 3; });
  ASSERT_TRUE(stopped.interrupted);
  EXPECT_EQ(stopped.scans_matched, 4u);  // scans 1, 2, 3 were matched after scan 0
  // Incremental matching never moves a scan again: the kept ones are the full run's, bit for bit.
  for (std::size_t i = 0; i < 4; ++i) EXPECT_EQ(stopped.scans[i].pose_cm, full.scans[i].pose_cm) << i;
  // The paper's relaxation stops between its matches too.
  asked = 0;
  const auto relaxed = map_survey(survey.scans, MappingSettings::simultaneous(), cpu, {}, [&] { return ++asked > 5; });
  EXPECT_TRUE(relaxed.interrupted);
  EXPECT_LT(relaxed.scans_matched, 6u);
}

TEST(MappingDeterminism, BitIdenticalPosesRunToRunAndForOneOrTwoThreads) {
  const auto survey = small_survey(5, 3);
  MappingSettings settings;
  CpuBackend cpu;
  std::vector<Pose> one, two, again;
  tbb::task_arena(1).execute([&] { one = poses_of(map_survey(survey.scans, settings, cpu)); });
  tbb::task_arena(2).execute([&] { two = poses_of(map_survey(survey.scans, settings, cpu)); });
  tbb::task_arena(2).execute([&] { again = poses_of(map_survey(survey.scans, settings, cpu)); });
  for (std::size_t i = 0; i < one.size(); ++i) {
    EXPECT_EQ(one[i], two[i]) << "scan " << i;
    EXPECT_EQ(two[i], again[i]) << "scan " << i;
  }
}

// The last loop the run closed, or nullptr.
const LoopClosure* last_closed(const MappingResult& mapped) {
  const LoopClosure* closed = nullptr;
  for (const LoopClosure& loop : mapped.loops) closed = loop.closed ? &loop : closed;
  return closed;
}

// A closed loop states its misclosure (the gap before the relaxation, against the drive between),
// and one beyond loops.max_misclosure_fraction makes its later scan doubtful: the chain was that
// far off. The stop-and-go loop closes 0.06 % apart: trusted at the default 1 %, doubtful at 0.03 %.
TEST(MappingLoops, AMisclosureBeyondTheLimitMakesTheLoopsScanDoubtful) {
  const auto survey = loop_survey_80m();
  CpuBackend cpu;
  MappingSettings settings;
  const auto mapped = map_survey(survey.scans, settings, cpu);
  const LoopClosure* closed = last_closed(mapped);
  ASSERT_NE(closed, nullptr);
  EXPECT_GT(closed->path_cm, 5000.0);
  EXPECT_LT(closed->gap_before_cm, 0.01 * closed->path_cm);
  EXPECT_TRUE(mapped.doubtful().empty());
  settings.loops.max_misclosure_fraction = 0.5 * closed->gap_before_cm / closed->path_cm;
  const auto strict = map_survey(survey.scans, settings, cpu);
  ASSERT_EQ(strict.doubtful().size(), 1u);
  const ScanOutcome& doubtful = strict.scans[strict.doubtful().front()];
  EXPECT_EQ(strict.doubtful().front(), closed->to);
  EXPECT_NE(doubtful.health.doubt.find("the loop from " + strict.scans[closed->from].name + " closed"),
            std::string::npos)
      << doubtful.health.doubt;
  // The poses are the same: the verdict changes what the run says, not the map.
  for (std::size_t k = 0; k < mapped.scans.size(); ++k) EXPECT_EQ(mapped.scans[k].pose_cm, strict.scans[k].pose_cm);
}

// A loop match is an edge only when its turn of the later scan is one drift could make
// (loops.max_turn_deg_per_100m): a corridor seen the other way fits as well as the right place. The
// stop-and-go loop's right match turns its scan a fraction of a degree and is kept at the default;
// with the limit at half its turn it is refused, says so, and no loop edge turns the scan that far.
TEST(MappingLoops, ALoopMatchThatTurnsItsScanFasterThanDriftCanIsNotAnEdge) {
  const auto survey = loop_survey_80m();
  CpuBackend cpu;
  MappingSettings settings;
  const auto mapped = map_survey(survey.scans, settings, cpu);
  const LoopClosure* closed = last_closed(mapped);
  ASSERT_NE(closed, nullptr);
  const double per_100m = closed->gap_before_deg / (closed->path_cm / 10000.0);
  std::printf("the loop from %s to %s turned its scan %.3f deg over %.1f m (%.3f deg per 100 m)\n",
              mapped.scans[closed->from].name.c_str(), mapped.scans[closed->to].name.c_str(), closed->gap_before_deg,
              closed->path_cm / 100.0, per_100m);
  EXPECT_GT(closed->gap_before_deg, 0.0);
  EXPECT_LT(per_100m, 0.1 * settings.loops.max_turn_deg_per_100m);
  EXPECT_TRUE(mapped.doubtful().empty());

  settings.loops.max_turn_deg_per_100m = 0.5 * per_100m;
  const auto strict = map_survey(survey.scans, settings, cpu);
  bool refused = false;
  for (const LoopClosure& loop : strict.loops) {
    if (loop.closed) {
      EXPECT_LE(loop.gap_before_deg, settings.loops.max_turn_deg_per_100m * loop.path_cm / 10000.0);
      continue;
    }
    if (loop.from == closed->from && loop.to == closed->to) {
      refused = true;
      EXPECT_NE(loop.doubt.find("the match turned it"), std::string::npos) << loop.doubt;
      EXPECT_NE(loop.doubt.find("deg per 100 m"), std::string::npos) << loop.doubt;
    }
  }
  EXPECT_TRUE(refused);
  // Refused and nothing else closed: the return is named, its drift unmeasured.
  const bool any_closed = std::any_of(strict.loops.begin(), strict.loops.end(), [](const LoopClosure& l) { return l.closed; });
  if (!any_closed) {
    ASSERT_FALSE(strict.doubtful().empty());
    EXPECT_NE(strict.scans[strict.doubtful().back()].health.doubt.find("the match turned it"), std::string::npos);
  }
  MappingSettings bad;
  bad.loops.max_turn_deg_per_100m = -1.0;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
}

// A spinning LiDAR's loop at 10 m/s around the pillars (turns of up to 50 deg within one sweep):
// once mapped with exit 0 and 2 % of its drive off. Now the loop that closed 95 cm apart says so,
// and with loop matches kept to 30 cm (none trusted) the unclosed return says so.
TEST(MappingLoops, AMovingSensorsLoopThatIsOffIsDoubtfulClosedOrNot) {
  sim::MovingSimulationSettings simulation;
  simulation.sensor = sim::MovingSensor::kSpinning;
  simulation.mine.loop_length_cm = 8000.0;
  const sim::MovingSurvey survey = sim::simulate_moving_survey(simulation);
  CpuBackend cpu;
  MappingSettings settings;
  const auto closed = map_survey(survey.scans, settings, cpu);
  const auto errors = pose_errors(poses_of(closed), survey.truth_cm);
  ASSERT_GT(errors.mean_translation_cm, 0.01 * errors.path_length_cm);  // the case: more than 1 % off
  bool misclosure = false;
  for (const std::size_t k : closed.doubtful()) {
    misclosure |= closed.scans[k].health.doubt.find("the relaxation only spread it") != std::string::npos;
  }
  EXPECT_TRUE(misclosure);
  // No loop match trusted: loop matches at the pair bound only (the chain as above; a cap on every
  // retry, 30 cm, once made it here, but then most sweeps start out of their matches' reach and
  // are doubtful for that, the return among them).
  settings.loops.bound_factors = {1.0f};
  const auto unclosed = map_survey(survey.scans, settings, cpu);
  for (const LoopClosure& loop : unclosed.loops) EXPECT_FALSE(loop.closed);
  bool unclosed_return = false;
  for (const std::size_t k : unclosed.doubtful()) {
    unclosed_return |= unclosed.scans[k].health.doubt.find("the drive came back near") != std::string::npos;
  }
  EXPECT_TRUE(unclosed_return);
}

// A hand-held rosette scanner's loop (seed 5, 63 m): one sweep's pattern sees too little of a
// place, and its return's sweeps found no pairs in the start's sweeps one at a time ("too few
// pairs": the drift over the loop stayed in the map, named). Matched against the start's visit
// (the sweeps around it, one local map: LoopClosureSettings::visit_sweeps) the loop closes, and the
// relaxation takes the map within 1 % (GCC's Release build: closed 51 cm apart, 0.44 % of the path;
// the same loop through the CLI's PCD files 0.50 %, and 0.77 % unclosed).
TEST(MappingLoops, ANarrowFieldSweepsLoopIsClosedAgainstTheVisitItReturnsTo) {
  sim::MovingSimulationSettings simulation;
  simulation.sensor = sim::MovingSensor::kHandheld;
  simulation.mine.loop_length_cm = 8000.0;
  simulation.mine.seed = 5;
  const sim::MovingSurvey survey = sim::simulate_moving_survey(simulation);
  CpuBackend cpu;
  const MappingSettings defaults;
  ASSERT_EQ(defaults.loops.visit_sweeps, 6);
  const auto closed = map_survey(survey.scans, defaults, cpu);
  const auto errors = pose_errors(poses_of(closed), survey.truth_cm);
  const LoopClosure* loop = last_closed(closed);
  ASSERT_NE(loop, nullptr);
  std::printf("loop from %s to %s closed %.0f cm apart; the map %.1f cm off (%.2f %% of %.1f m)\n",
              closed.scans[loop->from].name.c_str(), closed.scans[loop->to].name.c_str(), loop->gap_before_cm,
              errors.mean_translation_cm, 100.0 * errors.mean_translation_cm / errors.path_length_cm,
              errors.path_length_cm / 100.0);
  EXPECT_LT(loop->from, 12u);
  EXPECT_GT(loop->to + 12, closed.scans.size());
  EXPECT_LT(errors.mean_translation_cm, 0.01 * errors.path_length_cm);
  // The one sweep alone: no loop match finds pairs, and the return is named.
  MappingSettings alone = defaults;
  alone.loops.visit_sweeps = 0;
  const auto unclosed = map_survey(survey.scans, alone, cpu);
  for (const LoopClosure& candidate : unclosed.loops) EXPECT_FALSE(candidate.closed);
  ASSERT_FALSE(unclosed.doubtful().empty());
  EXPECT_NE(unclosed.scans[unclosed.doubtful().back()].health.doubt.find("the drive came back near"),
            std::string::npos);
  EXPECT_GT(pose_errors(poses_of(unclosed), survey.truth_cm).mean_translation_cm, errors.mean_translation_cm);
  MappingSettings bad;
  bad.loops.visit_sweeps = -1;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
}

/// Poses and every verdict alike, bit for bit.
void expect_same_result(const MappingResult& a, const MappingResult& b) {
  ASSERT_EQ(a.scans.size(), b.scans.size());
  for (std::size_t i = 0; i < a.scans.size(); ++i) {
    EXPECT_TRUE(a.scans[i].pose_cm == b.scans[i].pose_cm) << "scan " << i;
    EXPECT_EQ(a.scans[i].health.doubt, b.scans[i].health.doubt) << "scan " << i;
    EXPECT_EQ(a.scans[i].points_used, b.scans[i].points_used) << "scan " << i;
    EXPECT_EQ(a.scans[i].points_in, b.scans[i].points_in) << "scan " << i;
  }
  EXPECT_EQ(a.step1_icp_iterations, b.step1_icp_iterations);
}

// The CLI lets each scan's points go once prepared (a sweep's once matched): the same map, and the
// raw points are gone; the OpenCL backend keeps them (its failure matches again on the CPU). One
// thread, so that the stop-and-go scans are prepared in several chunks (4 scans each).
TEST(MappingSimulatedMine, LettingThePointsGoGivesTheSameMapAndFreesThem) {
  tbb::task_arena one(1);
  one.execute([] {
    CpuBackend cpu;
    const MappingSettings settings;
    const auto survey = small_survey(10);
    const MappingResult kept = map_survey(survey.scans, settings, cpu);
    std::vector<Scan> scans = survey.scans;
    const MappingResult released = map_survey_releasing_points(scans, settings, cpu);
    expect_same_result(kept, released);
    for (std::size_t i = 0; i < scans.size(); ++i) {
      EXPECT_TRUE(scans[i].points_cm.empty() && scans[i].attributes.intensity.empty()) << "scan " << i;
      EXPECT_EQ(scans[i].name, survey.scans[i].name);
      EXPECT_FALSE(released.scans[i].used_points_cm->empty());
    }
    sim::MovingSimulationSettings moving;
    moving.sensor = sim::MovingSensor::kHandheld;
    moving.sweeps = 8;
    const sim::MovingSurvey sweeps = sim::simulate_moving_survey(moving);
    std::vector<Scan> sweep_scans = sweeps.scans;
    expect_same_result(map_survey(sweeps.scans, settings, cpu),
                       map_survey_releasing_points(sweep_scans, settings, cpu));
    for (const Scan& sweep : sweep_scans) EXPECT_TRUE(sweep.points_cm.empty() && sweep.attributes.time_s.empty());
  });
  auto opencl = test::opencl_backend();  // throws without OpenCL: the test fails, never skips
  const auto survey = small_survey(3);
  std::vector<Scan> scans = survey.scans;
  expect_same_result(map_survey(survey.scans, MappingSettings{}, *opencl),
                     map_survey_releasing_points(scans, MappingSettings{}, *opencl));
  for (std::size_t i = 0; i < scans.size(); ++i) EXPECT_EQ(scans[i].points_cm, survey.scans[i].points_cm);
}

/// PartwiseMapper fed `scans` in parts of `part_scans`, as the CLI feeds it what it reads.
MappingResult map_in_parts(const std::vector<Scan>& scans, std::size_t part_scans, const MappingSettings& settings,
                           ComputeBackend& backend, const StopRequested& stop = {}, const MemoryBound& bound = {}) {
  PartwiseMapper mapper(settings, backend, {}, stop, bound);
  for (std::size_t first = 0; first < scans.size(); first += part_scans) {
    std::vector<Scan> part(scans.begin() + static_cast<std::ptrdiff_t>(first),
                           scans.begin() + static_cast<std::ptrdiff_t>(std::min(scans.size(), first + part_scans)));
    if (!mapper.add(part, scans.size())) break;
    for (const Scan& scan : part) EXPECT_TRUE(scan.points_cm.empty());
  }
  return mapper.finish();
}

// A survey read a part at a time (the CLI on the CPU) maps as the whole survey at once, stop-and-go
// and sweeps alike, with parts smaller and larger than the matcher's own chunks; a stop requested
// mid-run keeps the scans matched before it, as map_survey does.
TEST(MappingSimulatedMine, ASurveyMappedPartByPartIsTheSurveyMappedAtOnce) {
  CpuBackend cpu;
  const MappingSettings settings;
  const auto survey = small_survey(10);
  const MappingResult whole = map_survey(survey.scans, settings, cpu);
  for (const std::size_t part_scans : {std::size_t{1}, std::size_t{3}, std::size_t{16}}) {
    SCOPED_TRACE(part_scans);
    expect_same_result(whole, map_in_parts(survey.scans, part_scans, settings, cpu));
  }
  sim::MovingSimulationSettings moving;
  moving.sensor = sim::MovingSensor::kSpinning;
  moving.sweeps = 8;
  const sim::MovingSurvey sweeps = sim::simulate_moving_survey(moving);
  expect_same_result(map_survey(sweeps.scans, settings, cpu), map_in_parts(sweeps.scans, 3, settings, cpu));
  int asked = 0;
  const StopRequested stop_at_the_sixth = [&] { return ++asked > 5; };
  const MappingResult stopped = map_in_parts(survey.scans, 3, settings, cpu, stop_at_the_sixth);
  EXPECT_TRUE(stopped.interrupted);
  EXPECT_GE(stopped.scans_matched, 2u);
  EXPECT_LT(stopped.scans_matched, 10u);
  for (std::size_t i = 0; i < stopped.scans_matched; ++i) {
    EXPECT_TRUE(stopped.scans[i].pose_cm == whole.scans[i].pose_cm) << "scan " << i;
  }
}

// A memory bound (the CLI's --held-clouds-mb) lets the clouds of the scans used least recently go
// to a spill file and reads them back when a metascan, a loop or the map needs them: on a loop
// survey, stop-and-go and sweeps, with a bound that holds almost nothing, the same poses, loops,
// health and map points as with all held; the scans let go of keep no points in memory, and the
// spill leaves no file behind. A bound on another backend than the CPU is refused, as one without
// a folder.
TEST(MappingSimulatedMine, AMemoryBoundGivesTheSameMapAndLetsTheCloudsGo) {
  CpuBackend cpu;
  const MappingSettings settings;
  const test::TempDir folder;
  const MemoryBound tight{.held_clouds_mb = 1, .spill_folder = folder.path()};
  sim::SimulationSettings loop_settings;
  loop_settings.mine.seed = 1;
  loop_settings.mine.loop_length_cm = 12000.0;
  const auto loop = sim::simulate_mine_survey(loop_settings);
  const MappingResult held = map_survey(loop.scans, settings, cpu);
  const MappingResult bounded = map_in_parts(loop.scans, 4, settings, cpu, {}, tight);
  expect_same_result(held, bounded);
  ASSERT_EQ(held.loops.size(), bounded.loops.size());
  ASSERT_FALSE(held.loops.empty());
  for (std::size_t k = 0; k < held.loops.size(); ++k) {
    EXPECT_EQ(held.loops[k].closed, bounded.loops[k].closed);
    EXPECT_EQ(held.loops[k].gap_before_cm, bounded.loops[k].gap_before_cm);
    EXPECT_EQ(held.loops[k].gap_after_cm, bounded.loops[k].gap_after_cm);
  }
  ASSERT_TRUE(bounded.spilled);
  std::size_t let_go = 0;
  for (std::size_t i = 0; i < held.scans.size(); ++i) {
    EXPECT_EQ(held.scans[i].health.after_loop_closure, bounded.scans[i].health.after_loop_closure) << "scan " << i;
    let_go += bounded.scans[i].used_points_cm ? 0 : 1;
    const MapPoints points = bounded.map_points(i);
    ASSERT_TRUE(points.points_cm) << "scan " << i;
    EXPECT_EQ(*points.points_cm, *held.scans[i].used_points_cm) << "scan " << i;
  }
  EXPECT_GE(let_go, held.scans.size() / 2);
  EXPECT_TRUE(std::filesystem::is_empty(folder.path()));  // the spill file was unlinked at once

  sim::MovingSimulationSettings moving;
  moving.sensor = sim::MovingSensor::kSpinning;
  moving.sweeps = 8;
  const sim::MovingSurvey sweeps = sim::simulate_moving_survey(moving);
  expect_same_result(map_survey(sweeps.scans, settings, cpu), map_in_parts(sweeps.scans, 3, settings, cpu, {}, tight));

  auto opencl = test::opencl_backend();
  EXPECT_THROW(PartwiseMapper(settings, *opencl, {}, {}, tight), std::invalid_argument);
  EXPECT_THROW(PartwiseMapper(settings, cpu, {}, {}, MemoryBound{.held_clouds_mb = 1, .spill_folder = {}}), std::invalid_argument);
}

// A metascan's union reads the model points of a scan let go of straight from the spill (the
// judging after a loop takes hundreds a scan): the points the scan held, for a scan whose model is
// its data cloud and for one with a model of its own, held or not.
TEST(MappingSimulatedMine, AScanLetGoOfGivesTheModelPointsItHeld) {
  CpuBackend cpu;
  const MappingSettings settings;
  const test::TempDir folder;
  detail::SurveyState state;
  state.bound_memory(std::make_shared<detail::ScanSpill>(folder.path(), settings, cpu), 0);
  const auto points = [](int n, float at) {
    std::vector<Eigen::Vector3f> cloud;
    for (int k = 0; k < n; ++k) cloud.emplace_back(at + float(k), 2.0f * float(k), -0.5f * float(k));
    return cloud;
  };
  std::vector<std::vector<Eigen::Vector3f>> models;
  for (int i = 0; i < 3; ++i) {
    Scan scan;
    scan.name = "scan" + std::to_string(i);
    detail::PreparedScan prepared;
    prepared.cloud = cpu.prepare(points(50 + i, 100.0f * float(i)), settings.tree);
    prepared.model_cloud = i == 1 ? prepared.cloud : cpu.prepare(points(70 + i, -7.0f * float(i)), settings.tree);
    prepared.probe = prepared.cloud;
    models.push_back(prepared.model_cloud->point_vector());
    state.add(scan, std::move(prepared));
  }
  const auto model_of = [&](std::size_t i) {
    const detail::ModelPoints model = state.model_points(i);
    return std::vector<Eigen::Vector3f>(model.points().begin(), model.points().end());
  };
  for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(model_of(i), models[i]) << "held, scan " << i;
  state.release_over_budget();  // a bound of 0: all but the newest let go of
  ASSERT_GT(state.spilled_bytes(), 0u);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(model_of(i), models[i]) << "let go of, scan " << i;
  EXPECT_EQ(state.prepared(0).model_cloud->point_vector(), models[0]);  // and taken back, the same
}

// The judging after the loops searches a block of scans in a row standing at one place as one tree
// (JudgingClouds), with the block's scans that are not among a judged scan's neighbours (the scan
// itself, a run at either end) left out of the search: each point's nearest model point is the one
// the neighbours' own trees give (the distance to a float's last bits: taken in the block's frame),
// and the brute force's over the neighbours alone; where those left out are not one run, the
// block is searched scan by scan. On the OpenCL device the same trees give the host's distances
// bit for bit.
TEST(MappingJudging, BlocksOfScansInARowFindWhatEachScansOwnTreeFinds) {
  static_assert(detail::JudgingClouds::kBlockScans > 40, "the survey below is one block");
  CpuBackend cpu;
  const MappingSettings settings;
  const auto fill = [&](ComputeBackend& backend, detail::SurveyState& state, double step_cm) {
    for (std::size_t i = 0; i < 40; ++i) {
      Scan scan;
      scan.name = "scan" + std::to_string(i);
      scan.pose_cm.block<3, 3>(0, 0) = Eigen::AngleAxisd(0.01 * double(i), Eigen::Vector3d::UnitZ()).toRotationMatrix();
      scan.pose_cm.block<3, 1>(0, 3) = Eigen::Vector3d(step_cm * double(i), 3.0 * double(i), -1.0 * double(i));
      detail::PreparedScan prepared;
      prepared.cloud = backend.prepare(test::random_cloud(300, -500.f, 500.f, 700 + std::uint32_t(i)), settings.tree);
      prepared.model_cloud = prepared.cloud;
      prepared.probe = prepared.cloud;
      state.add(scan, std::move(prepared));
    }
  };
  detail::SurveyState state;
  fill(cpu, state, 50.0);  // 50 cm steps: at one place (loops.max_distance_cm per 16 scans)
  const auto search = [&](ComputeBackend& backend, const PreparedCloud& data, const std::vector<WorldModel>& models,
                          const Pose& at) {
    std::vector<ModelPlacement> placed;
    for (const WorldModel& m : models) placed.push_back({m.cloud, rigid_inverse(m.world_from_model) * at, m.skip});
    return backend.nearest(data, placed, SearchMethod::kExact, PairingSettings{200.0f});
  };
  const detail::LocalMap local_map(settings, cpu);
  detail::JudgingClouds clouds(local_map);
  // Each case: the judged scan, its neighbours (nearest first), and how many trees they take.
  struct Case {
    std::size_t judged;
    std::size_t below;  // the neighbours: scans [0, below) but the judged one
    std::size_t trees;
  };
  for (const Case& c : {Case{20, 40, 1}, Case{35, 30, 1}, Case{20, 30, 29}}) {
    // 20 of 0-39: the block, 20 left out; 35 of 0-29: 30-39 left out (35 among them); 20 of 0-29:
    // 20 and 30-39 are two runs, scan by scan.
    std::vector<std::size_t> near;
    for (std::size_t j = 0; j < c.below; ++j) {
      if (j != c.judged) near.push_back(j);
    }
    std::stable_sort(near.begin(), near.end(), [&](std::size_t a, std::size_t b) {
      return (a > c.judged ? a - c.judged : c.judged - a) < (b > c.judged ? b - c.judged : c.judged - b);
    });
    const std::vector<WorldModel> blocks = clouds.models(state, near, c.judged);
    ASSERT_EQ(blocks.size(), c.trees) << "judged " << c.judged;
    std::vector<std::shared_ptr<const PreparedCloud>> own;
    std::vector<WorldModel> each;
    for (const std::size_t j : near) {
      own.push_back(cpu.prepare(state.prepared(j).model_cloud->point_vector(), settings.tree));
      each.push_back({own.back().get(), state.pose(j)});
    }
    const Pose& at = state.pose(c.judged);
    const PreparedCloud& data = *state.prepared(c.judged).probe;
    const std::vector<NearestPair> by_block = search(cpu, data, blocks, at);
    const std::vector<NearestPair> by_scan = search(cpu, data, each, at);
    ASSERT_EQ(by_block.size(), data.points().size());
    std::size_t paired = 0;
    for (std::size_t k = 0; k < by_block.size(); ++k) {
      // The brute force, in double in the world frame.
      const Eigen::Vector3d p = at.block<3, 3>(0, 0) * data.points()[k].cast<double>() + at.block<3, 1>(0, 3);
      double best = 200.0 * 200.0;
      bool found = false;
      for (const std::size_t j : near) {
        const Pose& pose = state.pose(j);
        for (const Eigen::Vector3f& m : state.prepared(j).model_cloud->points()) {
          const double d = (pose.block<3, 3>(0, 0) * m.cast<double>() + pose.block<3, 1>(0, 3) - p).squaredNorm();
          if (d < best) {
            best = d;
            found = true;
          }
        }
      }
      ASSERT_EQ(by_block[k].squared_distance_cm2 >= 0.0f, found) << "judged " << c.judged << ", point " << k;
      ASSERT_EQ(by_scan[k].squared_distance_cm2 >= 0.0f, found) << "judged " << c.judged << ", point " << k;
      if (!found) continue;
      ++paired;
      EXPECT_NEAR(by_block[k].squared_distance_cm2, best, 1e-5 * best + 1e-3) << "point " << k;
      EXPECT_NEAR(by_block[k].squared_distance_cm2, by_scan[k].squared_distance_cm2, 1e-5 * best + 1e-3) << "point " << k;
    }
    EXPECT_GT(paired, by_block.size() / 2);
  }
  EXPECT_EQ(clouds.held(), 1u + 29u);  // the block, and the scans of the last case
  // The block was last used judging 35, the scans judging 20.
  clouds.forget_unused(35 + detail::JudgingClouds::kKeptFor + 1);
  EXPECT_EQ(clouds.held(), 1u);  // the block outlives the judged scans of its own
  clouds.forget_unused(35 + detail::JudgingClouds::kKeptFor + detail::JudgingClouds::kBlockScans + 1);
  EXPECT_EQ(clouds.held(), 0u);
  // Scans 4 m apart (stop-and-go) are no place's: each searched in its own tree.
  std::vector<std::size_t> near;
  for (std::size_t j = 0; j < 40; ++j) {
    if (j != 20) near.push_back(j);
  }
  detail::SurveyState apart;
  fill(cpu, apart, 400.0);
  detail::JudgingClouds scan_by_scan(local_map);
  EXPECT_EQ(scan_by_scan.models(apart, near, 20).size(), near.size());
  // The device's trees, searched on the device: the host's distances bit for bit.
  const std::unique_ptr<ComputeBackend> opencl = test::opencl_backend();  // throws without OpenCL: fails
  detail::SurveyState on_device;
  fill(*opencl, on_device, 50.0);
  const detail::LocalMap device_map(settings, *opencl);
  detail::JudgingClouds device_clouds(device_map);
  const std::vector<WorldModel> device_models = device_clouds.models(on_device, near, 20);
  ASSERT_EQ(device_models.size(), 1u);
  EXPECT_GT(device_models[0].skip.count, 0);
  const std::vector<NearestPair> device = search(*opencl, *on_device.prepared(20).probe, device_models, on_device.pose(20));
  const std::vector<NearestPair> host = search(cpu, *state.prepared(20).probe, clouds.models(state, near, 20), state.pose(20));
  ASSERT_EQ(device.size(), host.size());
  for (std::size_t k = 0; k < device.size(); ++k) {
    EXPECT_EQ(device[k].squared_distance_cm2, host[k].squared_distance_cm2) << "point " << k;
  }
}

// A metascan's union on the OpenCL device (kernels/union.cl) is the host's bit for bit: the points
// moved in double and cast to float, those outside the box left out, in order; a part that is not
// the device's (read back from a spill) is placed on the host beside those that are.
TEST(MappingBackendsAgreeOnUnions, PlacedWithinABoxOnTheDeviceAsOnTheHost) {
  const std::unique_ptr<ComputeBackend> opencl = test::opencl_backend();
  CpuBackend cpu;
  std::vector<std::shared_ptr<const PreparedCloud>> clouds;
  std::vector<std::vector<Eigen::Vector3f>> read_back;
  std::vector<UnionPart> parts;
  for (int k = 0; k < 6; ++k) {
    clouds.push_back(opencl->prepare(test::random_cloud(3000 + 500 * k, -2000.f, 2000.f, 40 + k), {}));
    Pose pose = Pose::Identity();
    pose.block<3, 3>(0, 0) = Eigen::AngleAxisd(0.3 * k + 0.1, Eigen::Vector3d(0.2, -0.5, 1.0).normalized()).toRotationMatrix();
    pose.block<3, 1>(0, 3) = Eigen::Vector3d(123.456 * k, -98.7 * k, 3.21 * k);
    parts.push_back({clouds.back()->points(), clouds.back().get(), pose});
  }
  read_back.push_back(test::random_cloud(2000, -500.f, 500.f, 49));
  parts.push_back({read_back.back(), nullptr, parts[2].frame_from_cloud});
  std::swap(parts[3], parts.back());  // the host's part among the device's
  const Eigen::Vector3d lo(-1500.0, -1200.0, -900.0), hi(1400.0, 1300.0, 1000.0);
  const auto host = cpu.placed_within(parts, lo, hi);
  const auto device = opencl->placed_within(parts, lo, hi);
  ASSERT_EQ(host.size(), parts.size());
  std::size_t kept = 0, all = 0;
  for (std::size_t k = 0; k < parts.size(); ++k) {
    EXPECT_EQ(device[k], host[k]) << "part " << k;
    kept += host[k].size();
    all += parts[k].points_cm.size();
  }
  EXPECT_GT(kept, all / 10);  // the box cuts: some in, some out
  EXPECT_LT(kept, all * 9 / 10);
  // Moved as the union always moved them (Eigen's product in double, then cast), clipped, in order.
  const Pose& pose = parts[0].frame_from_cloud;
  std::size_t next = 0;
  for (const Eigen::Vector3f& p : parts[0].points_cm) {
    const Eigen::Vector3d q = pose.block<3, 3>(0, 0) * p.cast<double>() + pose.block<3, 1>(0, 3);
    if ((q.array() < lo.array()).any() || (q.array() > hi.array()).any()) continue;
    ASSERT_LT(next, host[0].size());
    EXPECT_EQ(host[0][next++], q.cast<float>());
  }
  EXPECT_EQ(next, host[0].size());
}

class MappingBackendsAgree : public ::testing::TestWithParam<const char*> {};

// The default (voxel means, metascan) and the paper's relaxation on slice-filtered scans.
INSTANTIATE_TEST_SUITE_P(Presets, MappingBackendsAgree, ::testing::Values("default", "simultaneous"));

TEST_P(MappingBackendsAgree, OpenClAndCpuGiveTheSamePoses) {
  const auto survey = small_survey(5, 5);
  const MappingSettings settings =
      std::string(GetParam()) == "default" ? MappingSettings{} : MappingSettings::simultaneous();
  CpuBackend cpu_backend;
  const auto cpu = map_survey(survey.scans, settings, cpu_backend);
  auto opencl = test::opencl_backend();  // throws without OpenCL: the test fails, never skips
  const auto device = map_survey(survey.scans, settings, *opencl);
  ASSERT_EQ(cpu.scans.size(), device.scans.size());
  // Everything the run said about its backend, printed with any failure below.
  std::string said = device.backend + " | note: " + device.backend_note;
  for (const auto& note : device.notes) said += " | " + note;
  SCOPED_TRACE(said);
  EXPECT_NE(device.backend.find("opencl"), std::string::npos);
  for (std::size_t i = 0; i < cpu.scans.size(); ++i) {
    const Pose difference = rigid_inverse(cpu.scans[i].pose_cm) * device.scans[i].pose_cm;
    EXPECT_LT(translation_norm(difference), 0.01) << "scan " << i << " (cm)";
    EXPECT_LT(rotation_angle_deg(difference), 0.001) << "scan " << i << " (deg)";
    // PoCL does double precision, so the device sums are the CPU's bits (kPairSumBlock): same poses.
    EXPECT_TRUE(cpu.scans[i].pose_cm == device.scans[i].pose_cm) << "scan " << i;
  }
}

// Real scans, where the simulated ones never showed it: the two Jinchuan mine scans (a 4 m retry
// through a 200 cm bound) once differed in one pair of 200 000 (the CPU search's hint bound,
// detail::kHintBoundMargin), and the poses then differed by a centimetre.
TEST(MappingBackends, RealMineScansGiveTheSamePosesOnBothBackends) {
  const io::Survey survey = io::read_survey(test::shared_data_dir() / "mine_jinchuan_pcr");
  CpuBackend cpu_backend;
  const auto cpu = map_survey(survey.scans, MappingSettings{}, cpu_backend);
  auto opencl = test::opencl_backend();  // throws without OpenCL: the test fails, never skips
  const auto device = map_survey(survey.scans, MappingSettings{}, *opencl);
  ASSERT_EQ(cpu.scans.size(), 2u);
  ASSERT_EQ(device.scans.size(), 2u);
  EXPECT_TRUE(cpu.scans[1].registered);
  EXPECT_EQ(cpu.scans[1].last_match.iterations(), device.scans[1].last_match.iterations());
  EXPECT_TRUE(cpu.scans[1].pose_cm == device.scans[1].pose_cm) << "cpu\n"
                                                               << cpu.scans[1].pose_cm << "\nopencl\n"
                                                               << device.scans[1].pose_cm;
}

// The judging after a loop searches each neighbour's own tree (one launch per neighbour on the
// device): the same health figures, bit for bit, on both backends, as the same poses.
TEST(MappingBackends, ALoopIsJudgedAgainAlikeOnBothBackends) {
  const auto survey = loop_survey_80m();
  CpuBackend cpu_backend;
  const auto cpu = map_survey(survey.scans, MappingSettings{}, cpu_backend);
  auto opencl = test::opencl_backend();  // throws without OpenCL: the test fails, never skips
  const auto device = map_survey(survey.scans, MappingSettings{}, *opencl);
  ASSERT_EQ(cpu.scans.size(), device.scans.size());
  ASSERT_TRUE(std::any_of(cpu.loops.begin(), cpu.loops.end(), [](const LoopClosure& loop) { return loop.closed; }));
  std::size_t judged_again = 0;
  for (std::size_t i = 0; i < cpu.scans.size(); ++i) {
    const RegistrationHealth& a = cpu.scans[i].health;
    const RegistrationHealth& b = device.scans[i].health;
    EXPECT_TRUE(cpu.scans[i].pose_cm == device.scans[i].pose_cm) << "scan " << i;
    EXPECT_EQ(a.after_loop_closure, b.after_loop_closure) << "scan " << i;
    EXPECT_EQ(a.rms_cm, b.rms_cm) << "scan " << i;
    EXPECT_EQ(a.paired_fraction, b.paired_fraction) << "scan " << i;
    EXPECT_EQ(a.beyond_bound_fraction, b.beyond_bound_fraction) << "scan " << i;
    EXPECT_EQ(a.edge_fraction, b.edge_fraction) << "scan " << i;
    EXPECT_EQ(a.doubt, b.doubt) << "scan " << i;
    judged_again += a.after_loop_closure ? 1 : 0;
  }
  EXPECT_GE(judged_again, cpu.scans.size() / 2);
}

// A moving sensor's sweeps: timed, deskewed by their steps, matched against a thinned local map
// (a spinning sensor's next sweep takes the same one: MotionSettings::local_map_sweeps), refined
// after the deskew, and a hand-held's held by the spring to its prediction: the same poses, bit for
// bit, on both backends. The spinning drive's poses differ with one metascan a sweep: the kept map
// is what was compared.
TEST(MappingBackends, AMovingSensorsSweepsGiveTheSamePosesOnBothBackends) {
  auto opencl = test::opencl_backend();  // throws without OpenCL: the test fails, never skips
  for (const sim::MovingSensor sensor : {sim::MovingSensor::kSpinning, sim::MovingSensor::kHandheld}) {
    sim::MovingSimulationSettings simulation;
    simulation.sensor = sensor;
    simulation.sweeps = 8;
    const sim::MovingSurvey survey = sim::simulate_moving_survey(simulation);
    CpuBackend cpu_backend;
    const MappingResult cpu = map_survey(survey.scans, MappingSettings{}, cpu_backend);
    const MappingResult device = map_survey(survey.scans, MappingSettings{}, *opencl);
    ASSERT_EQ(cpu.scans.size(), device.scans.size());
    ASSERT_TRUE(cpu.all_registered());
    for (std::size_t i = 0; i < cpu.scans.size(); ++i) {
      EXPECT_TRUE(cpu.scans[i].pose_cm == device.scans[i].pose_cm) << "scan " << i;
      EXPECT_EQ(cpu.scans[i].health.doubt, device.scans[i].health.doubt) << "scan " << i;
    }
    if (sensor == sim::MovingSensor::kSpinning) {
      MappingSettings each_sweep;
      each_sweep.motion.local_map_sweeps = 1;
      const MappingResult rebuilt = map_survey(survey.scans, each_sweep, cpu_backend);
      bool differ = false;
      for (std::size_t i = 0; i < cpu.scans.size(); ++i) differ = differ || rebuilt.scans[i].pose_cm != cpu.scans[i].pose_cm;
      EXPECT_TRUE(differ) << "the spinning sweeps took a kept local map";
    }
  }
}

TEST(MappingBackends, AnOpenClFailureMidRunFallsBackToTheCpuPoses) {
  const auto survey = small_survey(4, 5);
  MappingSettings settings;
  CpuBackend cpu_backend;
  const auto cpu = map_survey(survey.scans, settings, cpu_backend);
  opencl::OpenClOptions faulty;
  faulty.allow_cpu_device = true;
  faulty.fault = opencl::InjectedFault::parse("20");  // the 20th kernel launch fails (a pairing launch)
  auto opencl = test::opencl_backend(&faulty);
  const auto recovered = map_survey(survey.scans, settings, *opencl);
  ASSERT_EQ(recovered.notes.size(), 1u);
  EXPECT_NE(recovered.notes.front().find("CL_OUT_OF_RESOURCES"), std::string::npos) << recovered.notes.front();
  EXPECT_NE(recovered.backend.find("cpu"), std::string::npos);
  for (std::size_t i = 0; i < cpu.scans.size(); ++i) EXPECT_EQ(cpu.scans[i].pose_cm, recovered.scans[i].pose_cm) << i;
}

/// Reads a 4x4 text matrix (relative.txt).
Pose read_matrix(const std::filesystem::path& path) {
  std::ifstream in(path);
  Pose m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) in >> m(r, c);
  if (!in) throw std::runtime_error("cannot read " + path.string());
  return m;
}

TEST(MappingRealData, FastGicpPairMatchesAnIndependentPointToPointIcp) {
  // relative.txt is a GICP result. Point-to-point ICP (the paper's) has its own minimum about 1 cm
  // and 0.36 degrees away; tests/oracles/point_to_point_icp.py (SciPy, double precision) finds it
  // from the same start with the same bound. minemap must land there, on both backends, with all
  // points, exact search and a 25 cm bound.
  const auto dir = test::shared_data_dir() / "fast_gicp_pair";
  const Scan target = io::read_pcd(dir / "251370668.pcd");
  const Scan source = io::read_pcd(dir / "251371071.pcd");
  Pose reference = read_matrix(dir / "relative.txt");  // T_target_source, metres
  reference.block<3, 1>(0, 3) *= 100.0;
  Pose oracle;  // printed by tests/oracles/point_to_point_icp.py, cm
  oracle << 0.9999140258, 0.0131033606, -0.0004744002, 48.5047471671,  //
      -0.0131034484, 0.9999142471, -0.000076488, 11.0496269715,         //
      0.0004733573, 0.0000826942, 1.000000361, -2.2332278965,           //
      0, 0, 0, 1;
  oracle = orthonormalised(oracle);
  for (const std::string backend : {"cpu", "opencl"}) {
    auto pairing = test::backend_named(backend);
    auto target_cloud = pairing->prepare(target.points_cm, {});
    auto source_cloud = pairing->prepare(source.points_cm, {});
    IcpSettings settings;
    settings.method = SearchMethod::kExact;
    settings.max_pair_dist_cm = 25.0f;
    settings.termination.min_translation_step_cm = 1e-5;
    settings.termination.min_rotation_step_deg = 1e-6;
    settings.termination.max_iterations = 500;
    const WorldModel model{target_cloud.get(), target.world_from_points()};
    Scan placed = source;
    placed.pose_cm = target.pose_cm * reference;
    const IcpResult result = register_icp(*pairing, *source_cloud, placed.world_from_points(), {&model, 1}, settings);
    ASSERT_TRUE(result.ok()) << to_string(result.stop);
    Scan registered = source;
    registered.set_world_from_points(result.world_from_data);
    const Pose estimated = rigid_inverse(target.pose_cm) * registered.pose_cm;  // T_target_source
    const Pose to_oracle = rigid_inverse(oracle) * estimated;
    const Pose to_reference = rigid_inverse(reference) * estimated;
    std::printf("%s: %d iterations, %zu pairs, rms %.3f cm; to oracle %.4f cm %.5f deg; to relative.txt %.3f cm %.3f deg\n",
                backend.c_str(), result.iterations(), result.pairs, result.rms_cm, translation_norm(to_oracle),
                rotation_angle_deg(to_oracle), translation_norm(to_reference), rotation_angle_deg(to_reference));
    EXPECT_EQ(result.pairs, 59693u);
    EXPECT_LT(translation_norm(to_oracle), 0.05);
    EXPECT_LT(rotation_angle_deg(to_oracle), 0.002);
    EXPECT_LT(translation_norm(to_reference), 2.0);
    EXPECT_LT(rotation_angle_deg(to_reference), 0.4);
  }
}

TEST(MappingRealData, Kitti07RelativePosesMatchTheGraph) {
  io::SurveyReadSettings read;
  const auto survey = io::read_survey(test::shared_data_dir() / "kitti07_sequence", read);
  ASSERT_EQ(survey.scans.size(), 5u);
  ASSERT_TRUE(survey.truth_cm.has_value());
  // Start from the reference poses perturbed by about 30 cm and 1 degree per scan.
  std::vector<Scan> scans = survey.scans;
  for (std::size_t i = 0; i < scans.size(); ++i) {
    const double sign = (i % 2 == 0) ? 1.0 : -1.0;
    const Pose noise = euler_to_pose({Eigen::Vector3d(20.0 * sign, -15.0, 10.0 * sign), Eigen::Vector3d(0.3, -0.4, 0.8 * sign)});
    scans[i].pose_cm = i == 0 ? (*survey.truth_cm)[0] : (*survey.truth_cm)[i] * noise;
  }
  MappingSettings settings;
  CpuBackend cpu;
  settings.mode = MatchingMode::kPairwise;
  settings.icp.max_pair_dist_cm = 100.0f;  // the scans are voxel-downsampled to about 20 cm,
  settings.icp.refine_pair_dist_fraction = 0.0f;  // so a refinement would find few, biased pairs
  settings.icp.method = SearchMethod::kExact;
  const auto result = map_survey(scans, settings, cpu);
  ASSERT_TRUE(result.all_registered());
  const auto errors = pose_errors(poses_of(result), *survey.truth_cm);
  std::printf("kitti07: max relative error %.2f cm %.3f deg\n", errors.max_relative_translation_cm,
              errors.max_relative_rotation_deg);
  EXPECT_LT(errors.max_relative_translation_cm, 10.0);
  EXPECT_LT(errors.max_relative_rotation_deg, 0.2);
}

}  // namespace
}  // namespace minemap
