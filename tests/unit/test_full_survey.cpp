// The accuracy goal on the whole default survey (64 scans, 250 m), not just its start:
// simultaneous matching within 0.2 % of the distance driven. About a minute on 2 cores, so it
// carries the CTest label "long" (scripts/sanitize.sh leaves such tests out of sanitizer runs).
#include <gtest/gtest.h>

#include <cstdio>

#include "minemap/backend/cpu_backend.hpp"
#include "minemap/sim/mine_simulator.hpp"
#include "minemap/slam/survey_matching.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

TEST(MappingFullSurvey, DefaultSurveyIsWithinTwoPerMilleOfTheDrive) {
  const auto survey = sim::simulate_mine_survey(sim::SimulationSettings{});  // seed 1 = `minemap simulate`
  ASSERT_EQ(survey.scans.size(), 64u);
  MappingSettings settings;  // the defaults of `minemap map`
  CpuBackend cpu;
  const auto result = map_survey(survey.scans, settings, cpu);
  ASSERT_TRUE(result.all_registered());
  const auto registered = pose_errors(test::poses_of(result), survey.truth_cm);
  const auto drifted = pose_errors(test::odometry_of(survey.scans), survey.truth_cm);
  std::printf("full survey: odometry %.1f cm, simultaneous %.1f cm mean error over %.1f m (%.3f %%), %d relaxation matches\n",
              drifted.mean_translation_cm, registered.mean_translation_cm, registered.path_length_cm / 100.0,
              100.0 * registered.mean_translation_cm / registered.path_length_cm, result.relaxation_matches);
  EXPECT_LE(registered.mean_translation_cm, 0.002 * registered.path_length_cm);
  EXPECT_LT(registered.mean_translation_cm, 0.1 * drifted.mean_translation_cm);
}

}  // namespace
}  // namespace minemap
