// The `minemap` program: simulate a mine survey, map a survey. See README.md.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "minemap/core/error.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/sim/mine_simulator.hpp"

namespace {

int run_simulate(const std::filesystem::path& out_dir, int scans, std::uint32_t seed) {
  minemap::sim::SimulationSettings settings;
  settings.mine.scans = scans;
  settings.mine.seed = seed;
  const auto survey = minemap::sim::simulate_mine_survey(settings);
  std::filesystem::create_directories(out_dir);
  minemap::io::write_uos_survey(out_dir, survey.scans, survey.truth_cm);
  std::size_t points = 0;
  for (const auto& scan : survey.scans) points += scan.size();
  std::printf("simulated %zu scans (%zu points, %.1f m driven) into %s\n", survey.scans.size(), points,
              survey.driven_distance_cm / 100.0, out_dir.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"minemap: 6D SLAM for 3D laser scans of mines (Nuechter et al.)"};
  app.require_subcommand(1);

  std::filesystem::path sim_out;
  int sim_scans = 0;
  std::uint32_t sim_seed = 1;
  auto* simulate = app.add_subcommand("simulate", "Write the built-in simulated mine survey (uos format)");
  simulate->add_option("--out", sim_out, "Output folder")->required();
  simulate->add_option("--scans", sim_scans, "Number of scans (0 = the whole 250 m drive)");
  simulate->add_option("--seed", sim_seed, "Random seed");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : static_cast<int>(minemap::ExitCode::kUsage);
  }
  try {
    if (*simulate) return run_simulate(sim_out, sim_scans, sim_seed);
  } catch (const minemap::InputError& e) {
    std::cerr << "minemap: " << e.what() << "\n";
    return static_cast<int>(minemap::ExitCode::kInputError);
  } catch (const minemap::OutputError& e) {
    std::cerr << "minemap: " << e.what() << "\n";
    return static_cast<int>(minemap::ExitCode::kOutputError);
  } catch (const std::exception& e) {
    std::cerr << "minemap: internal error: " << e.what() << "\n";
    return static_cast<int>(minemap::ExitCode::kInternal);
  }
  return 0;
}
