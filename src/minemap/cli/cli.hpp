#pragma once
// The `minemap` command line as a library: the program (cli/main.cpp) and the Python package
// (src/minemap/python/module.cpp, `python -m minemap`) run the same code, and the Python API's
// keyword arguments are parsed by the same option definitions as `minemap map`'s flags, so names,
// defaults and checks have one source of truth. See README.md; exit codes in cli/exit_codes.hpp.
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "minemap/backend/make_backend.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/slam/survey_matching.hpp"

namespace minemap::cli {

namespace fs = std::filesystem;

/// What `map` takes beyond MappingSettings (which the options bind to directly: its defaults are
/// the ones --help shows, and a library user gets the same).
struct MapOptions {
  fs::path survey;
  fs::path out;
  Backend backend = Backend::kAuto;
  std::string preset = "default";  ///< applied before the other options (they adjust it)
  bool no_filter = false;
  bool sparse_models = false;
  bool plain_icp = false;
  std::string unit;  ///< empty: the format's default
  std::uint32_t points_per_slice = 0;
  bool no_slice_detection = false;
  fs::path initial_poses;
  fs::path reference_poses;
  bool right_handed_to_3dtk = false;
  bool quiet = false;
  bool write_unregistered = false;
  bool accept_doubtful = false;
  bool no_retry = false;
  bool no_loops = false;
  int threads = 0;            ///< worker threads (0: all cores)
  std::string opencl_device;  ///< a substring of "platform / device" (empty: MINEMAP_OPENCL_DEVICE)
};

/// `map`'s options parsed: the settings map_survey takes (the flags that switch parts off already
/// applied, validated) and the rest.
struct MapCommand {
  MapOptions options;
  MappingSettings settings;
};

/// Parses `map` options without the survey and --out ("--voxel-cm", "10", "--no-filter", ...), as
/// `minemap map` would. Throws std::invalid_argument with the parser's message on an unknown
/// option or a bad value. Thread-safety: reentrant.
MapCommand parse_map_options(const std::vector<std::string>& args);

/// One `map` option as --help lists it: "--voxel-cm", its default (empty for flags), and its help.
struct OptionInfo {
  std::string name;
  std::string default_value;
  std::string help;
  bool flag = false;
};
/// Every option parse_map_options takes, with `preset`'s defaults.
std::vector<OptionInfo> map_options(const std::string& preset = "default");

/// The backend `options` ask for (--backend, --opencl-device, and the environment's
/// MINEMAP_OPENCL*): the composition root's one way to make it.
BackendChoice make_backend_for(const MapOptions& options);

/// The worker threads `options` ask for: --threads, at most the machine's; 0 means all cores.
int thread_count(const MapOptions& options);

/// The survey reading settings `map`'s options ask for.
io::SurveyReadSettings survey_read_settings(const MapOptions& options);

/// A survey read and mapped (run_map_command).
struct MapRun {
  io::Survey survey;
  BackendChoice backend;
  MappingResult result;  ///< interrupted: only the scans matched (survey.truth_cm cut alike)
  std::size_t survey_scans = 0;  ///< the survey's scan count (more than result's when interrupted)
  double load_s = 0.0;
};

/// Writes a run's outputs into options.out, atomically file by file (report/map_output.hpp).
/// `extra_outputs` runs after them (the Python package writes map.laz and the E57 there).
using ExtraOutputs = std::function<void(const fs::path& out_dir, const MapRun& run)>;

/// What an embedding program adds to the command line.
struct Hooks {
  /// Polled between scans and relaxation matches, with SIGINT/SIGTERM: true stops the run there.
  std::function<bool()> stop_requested;
  ExtraOutputs extra_outputs;
};

/// Runs the command line (`args` without the program's name: {"map", "SURVEY", "--out", ...}) and
/// returns the exit code. Installs SIGINT/SIGTERM handlers for `map` and restores the previous
/// ones before returning. Not reentrant (the signal flag is process-wide).
int run(const std::vector<std::string>& args, const Hooks& hooks = {});

/// Reads options.survey, makes the backend and maps the survey: what `minemap map` does before it
/// writes. Throws InputError on bad input (nothing written), std::invalid_argument on bad settings.
MapRun run_map_command(const MapCommand& command, const ProgressCallback& progress = {},
                       const StopRequested& stop_requested = {});

/// Writes `run`'s outputs into options.out as `minemap map` does (the same files, bit for bit);
/// an interrupted run's partial map included. Returns report.json's text.
std::string write_outputs(const MapCommand& command, MapRun& run, const ExtraOutputs& extra = {});

}  // namespace minemap::cli
