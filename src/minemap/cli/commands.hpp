#pragma once
// Internal to the command line: the subcommands app.cpp dispatches to, one file each.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "minemap/cli/cli.hpp"
#include "minemap/cli/map_options.hpp"
#include "minemap/sim/mine_simulator.hpp"
#include "minemap/sim/moving_lidar.hpp"

namespace minemap::cli {

/// A subcommand that takes `map`'s options: its CLI11 app and the table that declared them.
struct MapSubcommand {
  CLI::App* app = nullptr;
  std::unique_ptr<MapOptionTable> options;
};

/// `minemap map` (command_map.cpp): reads, maps and writes a survey; returns the exit code.
int run_map(const MapCommand& command, const Hooks& hooks);
MapSubcommand add_map_command(CLI::App& app, MapCommand& command);

/// What `watch` takes beyond `map`'s options.
struct WatchOptions {
  std::size_t stop_after_scans = 0;  ///< finish once this many scans are matched (0: on Ctrl-C)
  double idle_timeout_s = 0.0;       ///< finish after this long without a new scan (0: never)
  int poll_ms = 500;                 ///< how often the folder is looked at
};
/// `minemap watch` (command_watch.cpp). `options_text`: the options that change the poses
/// (mapping_options_text), which a resume must match.
int run_watch(const MapCommand& command, const WatchOptions& watch, const std::string& options_text,
              const Hooks& hooks);
MapSubcommand add_watch_command(CLI::App& app, MapCommand& command, WatchOptions& watch);

/// What `export` takes.
struct ExportOptions {
  fs::path out;     ///< a finished map's folder (its report.json)
  fs::path to;      ///< the file to write; its extension picks the format
  ExportSettings settings;
  std::string frame = "z-up";
  std::string scans;  ///< comma-separated scan names (empty: every registered scan)
  bool quiet = false;
};
/// `minemap export` (command_export.cpp).
int run_export(const ExportOptions& options, const Hooks& hooks);
CLI::App* add_export_command(CLI::App& app, ExportOptions& options, MapOptions& process);

struct SimulateOptions {
  fs::path out;
  int scans = 0;  ///< tilting: scans; moving sensors: sweeps (0: the whole path)
  std::uint32_t seed = sim::MineSettings{}.seed;
  double loop_m = 0.0;
  double step_m = sim::MineSettings{}.mean_step_cm / 100.0;  ///< tilting only
  bool step_given = false;                                    ///< --step-m was on the command line
  /// "tilting" (the stop-and-go uos survey, the default) or a moving sensor (sim::kMovingSensorNames).
  std::string sensor = "tilting";
  // Moving sensors only (unset: the settings' defaults, sim::MovingSimulationSettings).
  std::optional<double> speed_mps;
  std::optional<double> rate_hz;
  std::optional<int> beams;
  std::optional<double> turn_deg_s;
  bool odometry = false;
  // Tilting only: survey control (DIR/control.txt).
  int control_stations = 0;
  int control_targets = 0;
  double control_blunder_m = 0.0;
};
/// `minemap simulate` (command_simulate.cpp).
int run_simulate(const SimulateOptions& options);
CLI::App* add_simulate_command(CLI::App& app, SimulateOptions& options, MapOptions& process);

}  // namespace minemap::cli
