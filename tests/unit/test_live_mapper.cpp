// LiveMapper (`minemap watch`): scans added one by one, then finished, give map_survey's result bit
// for bit in every mode; a run resumed from what an earlier run left gives it too.
#include <gtest/gtest.h>

#include "minemap/backend/cpu_backend.hpp"
#include "minemap/sim/mine_simulator.hpp"
#include "minemap/slam/survey_matching.hpp"

namespace minemap {
namespace {

sim::SimulatedSurvey survey_of(int scans) {
  sim::SimulationSettings settings;
  settings.mine.scans = scans;
  settings.mine.seed = 2;
  return sim::simulate_mine_survey(settings);
}

/// Everything a run decides, compared exactly (times aside: they are wall-clock).
void expect_same_run(const MappingResult& offline, const MappingResult& live) {
  ASSERT_EQ(offline.scans.size(), live.scans.size());
  for (std::size_t i = 0; i < offline.scans.size(); ++i) {
    const ScanOutcome& a = offline.scans[i];
    const ScanOutcome& b = live.scans[i];
    EXPECT_EQ(a.pose_cm, b.pose_cm) << "scan " << i;
    EXPECT_EQ(a.world_from_points, b.world_from_points) << "scan " << i;
    ASSERT_EQ(a.frames.size(), b.frames.size()) << "scan " << i;
    for (std::size_t k = 0; k < a.frames.size(); ++k) EXPECT_EQ(a.frames[k].pose_cm, b.frames[k].pose_cm);
    EXPECT_EQ(a.last_match.iterations(), b.last_match.iterations()) << "scan " << i;
    EXPECT_EQ(a.last_match.rms_cm, b.last_match.rms_cm) << "scan " << i;
    EXPECT_EQ(a.health.doubt, b.health.doubt) << "scan " << i;
    EXPECT_EQ(a.health.rms_cm, b.health.rms_cm) << "scan " << i;
    EXPECT_EQ(a.registered, b.registered);
    EXPECT_EQ(a.relaxation_matches, b.relaxation_matches);
    ASSERT_TRUE(a.used_points_cm && b.used_points_cm) << "scan " << i;
    EXPECT_EQ(*a.used_points_cm, *b.used_points_cm) << "scan " << i;
  }
  EXPECT_EQ(offline.step1_icp_iterations, live.step1_icp_iterations);
  EXPECT_EQ(offline.step3_icp_iterations, live.step3_icp_iterations);
  EXPECT_EQ(offline.relaxation_matches, live.relaxation_matches);
  EXPECT_EQ(offline.loops.size(), live.loops.size());
  EXPECT_EQ(offline.notes, live.notes);
  EXPECT_EQ(offline.scans_matched, live.scans_matched);
  EXPECT_FALSE(live.interrupted);
}

struct Mode {
  const char* name;
  MappingSettings settings;
};

std::vector<Mode> modes() {
  MappingSettings pairwise;
  pairwise.mode = MatchingMode::kPairwise;
  // Loop candidates on a straight drive (scans 3 apart, 12 m), so finish() closes loops here too.
  MappingSettings incremental;
  incremental.loops.min_scan_gap = 3;
  incremental.loops.max_distance_cm = 1500.0;
  incremental.loops.min_path_cm = 1000.0;
  // A queue that outlives each scan's budget, so the drain after the last scan matters.
  MappingSettings simultaneous = MappingSettings::simultaneous();
  simultaneous.max_relaxation_matches_per_scan = 1;
  simultaneous.moved_translation_cm = 0.1;  // every match re-queues its neighbours
  simultaneous.moved_rotation_deg = 0.01;
  return {{"pairwise", pairwise}, {"incremental", incremental}, {"simultaneous", simultaneous}};
}

TEST(LiveMapper, ScansAddedOneByOneGiveTheOfflineRun) {
  const auto survey = survey_of(6);
  for (const Mode& mode : modes()) {
    SCOPED_TRACE(mode.name);
    CpuBackend cpu;
    const MappingResult offline = map_survey(survey.scans, mode.settings, cpu);
    LiveMapper live(mode.settings, cpu);
    for (const Scan& scan : survey.scans) {
      live.add(scan);
      // Between scans, the map so far: every scan arrived holds a pose.
      EXPECT_EQ(live.result().scans.size(), live.size());
    }
    live.finish();
    expect_same_run(offline, live.result());
  }
}

TEST(LiveMapper, AResumedRunGivesTheOfflineRun) {
  const auto survey = survey_of(6);
  for (const Mode& mode : modes()) {
    SCOPED_TRACE(mode.name);
    CpuBackend cpu;
    const MappingResult offline = map_survey(survey.scans, mode.settings, cpu);
    // The first run stops after 4 scans; what it leaves is what `minemap watch` saves.
    LiveMapper first(mode.settings, cpu);
    for (std::size_t i = 0; i < 4; ++i) first.add(survey.scans[i]);
    const MappingResult saved = first.result();
    const std::vector<std::size_t> queue = first.queue();
    if (mode.settings.mode == MatchingMode::kSimultaneous) {
      EXPECT_FALSE(queue.empty());
    }

    LiveMapper resumed(mode.settings, cpu);
    for (std::size_t i = 0; i < 4; ++i) resumed.restore(survey.scans[i], saved.scans[i]);
    resumed.restore_queue(queue);
    resumed.restore_counters(saved);
    for (std::size_t i = 4; i < survey.scans.size(); ++i) resumed.add(survey.scans[i]);
    resumed.finish();
    expect_same_run(offline, resumed.result());
  }
}

TEST(LiveMapper, RefusesAQueueBeyondItsScans) {
  const auto survey = survey_of(2);
  CpuBackend cpu;
  LiveMapper live(MappingSettings::simultaneous(), cpu);
  live.add(survey.scans[0]);
  EXPECT_THROW(live.restore_queue({3}), std::invalid_argument);
}

}  // namespace
}  // namespace minemap
