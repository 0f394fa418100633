// `minemap simulate`: the built-in simulated mine survey, written as a uos survey with its truth.
#include <chrono>
#include <cstdio>

#include "minemap/cli/commands.hpp"

namespace minemap::cli {

CLI::App* add_simulate_command(CLI::App& app, SimulateOptions& options, MapOptions& process) {
  auto* command = app.add_subcommand("simulate", "Write the built-in simulated mine survey (uos format)");
  command->add_option("--threads", process.threads, "Worker threads (0 = all cores)")->group(groups::kRun);
  const sim::MineSettings mine;
  command->add_option("--out", options.out, "Output folder")->required();
  char drive[64];
  std::snprintf(drive, sizeof drive, "Number of scans (0 = the whole %g m drive)", mine.drive_length_cm / 100.0);
  command->add_option("--scans", options.scans, drive);
  command->add_option("--seed", options.seed, "Random seed")->capture_default_str();
  command->add_option("--loop", options.loop_m,
                      "Drive a loop of about this many metres around the pillars right of the drive, back to the "
                      "first scan's place, instead of the straight drive (0 = straight)")
      ->check(CLI::NonNegativeNumber);
  command->add_option("--step-m", options.step_m,
                      "Mean distance between scan positions (metres): 4 for stop-and-go as the paper, under 1 for a "
                      "survey where most scans see each other, as a moving LiDAR's")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  return command;
}

int run_simulate(const SimulateOptions& options) {
  sim::SimulationSettings settings;
  settings.mine.scans = options.scans;
  settings.mine.seed = options.seed;
  settings.mine.loop_length_cm = 100.0 * options.loop_m;
  settings.mine.mean_step_cm = 100.0 * options.step_m;
  const auto start = std::chrono::steady_clock::now();
  const auto survey = sim::simulate_mine_survey(settings);
  fs::create_directories(options.out);
  io::write_uos_survey(options.out, survey.scans, survey.truth_cm);
  std::size_t points = 0;
  for (const auto& scan : survey.scans) points += scan.size();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("simulated %zu scans (%zu points, %.1f m driven) into %s in %.1f s\n", survey.scans.size(), points,
              survey.driven_distance_cm / 100.0, options.out.c_str(), seconds);
  return 0;
}

}  // namespace minemap::cli
