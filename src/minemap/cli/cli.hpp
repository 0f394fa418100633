#pragma once
// The `minemap` command line as a library: the program (cli/main.cpp) and the Python package
// (src/minemap/python/module.cpp, `python -m minemap`) run the same code, and the Python API's
// keyword arguments are parsed by the same option definitions as `minemap map`'s flags, so names,
// defaults and checks have one source of truth. See README.md; exit codes in cli/exit_codes.hpp.
//
// The rooms behind this face (internal):
//   app.cpp                the subcommands, and the one exception -> exit code table
//   map_options.*          `map`'s options by stage, presets, the record report.json keeps
//   composition.cpp        backend, threads, reading, mapping, output settings (this header's functions)
//   console.*              progress, summaries, the exit policy of map and watch
//   signals.*              Ctrl-C and SIGTERM
//   command_map.cpp, command_watch.cpp, command_simulate.cpp, watch_state.* (watch.json)
#include <tbb/task_arena.h>

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "minemap/backend/make_backend.hpp"
#include "minemap/io/control.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/report/map_output.hpp"
#include "minemap/slam/map_survey.hpp"
#include "minemap/report/survey_export.hpp"
#include "minemap/slam/survey_matching.hpp"

namespace minemap::cli {

namespace fs = std::filesystem;

/// minemap's version: "0.1.0" and, in a build from a git checkout, the commit ("0.1.0 (git 1a2b3c4)").
const char* version();

/// What `map` takes beyond MappingSettings (which the options bind to directly: its defaults are
/// the ones --help shows, and a library user gets the same).
struct MapOptions {
  fs::path survey;
  fs::path out;
  Backend backend = Backend::kAuto;
  Preset preset = Preset::kDefault;  ///< applied before the other options (they adjust it)
  bool no_filter = false;
  bool no_median = false;
  bool no_spacing_reduction = false;
  bool sparse_models = false;
  bool plain_icp = false;
  bool no_health_check = false;
  bool loop_edges_alike = false;
  std::string unit;  ///< empty: the format's default
  std::uint32_t points_per_slice = 0;
  bool no_slice_detection = false;
  fs::path initial_poses;
  fs::path reference_poses;
  fs::path control;  ///< survey control (io/control.hpp): the map tied to the mine's grid
  bool right_handed_to_3dtk = false;
  bool quiet = false;
  bool write_unregistered = false;
  bool accept_doubtful = false;
  bool no_retry = false;
  bool no_recovery = false;
  bool no_first_sweep_fit = false;
  bool provisional_all_points = false;
  bool wide_coarse_all_points = false;
  bool moving_point_to_plane = false;
  bool no_loops = false;
  int threads = 0;            ///< worker threads (0: all cores)
  /// The prepared clouds a long survey holds at most on the CPU (MemoryBound), MB; 0: all.
  std::size_t held_clouds_mb = MemoryBound::kSuggestedHeldCloudsMb;
  std::string opencl_device;  ///< a substring of "platform / device" (empty: MINEMAP_OPENCL_DEVICE)
};

/// `map`'s options parsed: the settings map_survey takes (the flags that switch parts off already
/// applied, validated), the rest, and what report.json records of them.
struct MapCommand {
  MapOptions options;
  MappingSettings settings;
  std::vector<RecordedSetting> recorded;  ///< every option's value after parsing (report.json "settings")
  std::vector<std::string> command_line;  ///< as the user gave it, program first (report.json)
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
std::vector<OptionInfo> map_options(Preset preset = Preset::kDefault);

/// The backend `options` ask for (--backend, --opencl-device, and the environment's
/// MINEMAP_OPENCL*): the composition root's one way to make it.
BackendChoice make_backend_for(const MapOptions& options);

/// The worker threads `options` ask for: --threads, at most the machine's; 0 means all cores.
int thread_count(const MapOptions& options);

/// Runs `work` on thread_count(options) worker threads: a task_arena of its own, so the process's
/// TBB settings stay as they are. Returns what `work` returns.
template <typename Work>
decltype(auto) with_threads(const MapOptions& options, Work&& work) {
  tbb::task_arena arena(thread_count(options));
  return arena.execute(std::forward<Work>(work));
}

/// The survey reading settings `map`'s options ask for (the points' times too, for the deskew,
/// unless `mapping` turns it off).
io::SurveyReadSettings survey_read_settings(const MapOptions& options, const MappingSettings& mapping);

/// A survey read and mapped (run_map_command).
struct MapRun {
  io::Survey survey;
  BackendChoice backend;
  MappingResult result;  ///< interrupted: only the scans matched (survey.truth_cm cut alike)
  std::size_t survey_scans = 0;  ///< the survey's scan count (more than result's when interrupted)
  std::vector<std::string> sources;  ///< each scan's file (report.json), in survey order
  double load_s = 0.0;
  /// The errors against the survey's reference poses (where it has them), computed once for the
  /// console and report.json alike.
  std::optional<TruthComparison> truth;
  /// --control, read before the mapping (slam/control_tie.hpp ties the result to it).
  std::optional<io::ControlFile> control;
};

/// Writes a run's outputs into options.out, atomically file by file (report/map_output.hpp).
/// `extra_outputs` runs after them (the Python package writes map.laz and the E57 there).
using ExtraOutputs = std::function<void(const fs::path& out_dir, const MapCommand& command, const MapRun& run)>;

/// Writes an export in a format the C++ core does not write (LAS/LAZ, COPC, E57: the Python
/// package), from the scans `scans` hands out, to `path` atomically; `stop` is asked between scans.
using ExportWriter =
    std::function<ExportSummary(SurveyExport& scans, const fs::path& path, const std::function<bool()>& stop)>;

/// What an embedding program adds to the command line.
struct Hooks {
  /// Polled between scans and relaxation matches, with SIGINT/SIGTERM: true stops the run there.
  std::function<bool()> stop_requested;
  ExtraOutputs extra_outputs;
  /// The files extra_outputs writes ("map.laz"), for the run's "wrote OUT (...)" line.
  std::vector<std::string> extra_output_names;
  ExportWriter export_writer;
};

/// Runs the command line (`args` without the program's name: {"map", "SURVEY", "--out", ...}) and
/// returns the exit code. Installs SIGINT/SIGTERM handlers for `map` and `watch` and restores the
/// previous ones before returning. Not reentrant (the signal count is process-wide).
int run(const std::vector<std::string>& args, const Hooks& hooks = {});

/// Refuses (OutputError, exit 5) an output folder that is the survey folder, a file, under a file,
/// or in a folder that cannot be written; touches nothing. An empty `out` (no outputs) passes.
void check_output_folder(const std::filesystem::path& out, const std::filesystem::path& survey);

/// Reads options.survey, makes the backend and maps the survey: what `minemap map` does before it
/// writes. Throws InputError on bad input (nothing written), std::invalid_argument on bad settings.
MapRun run_map_command(const MapCommand& command, const ProgressCallback& progress = {},
                       const StopRequested& stop_requested = {});

/// Maps a survey already in memory (read, or given as arrays by the Python package) as
/// run_map_command maps what it reads: backend, threads, an interrupted run cut to the scans
/// matched, the truth comparison.
MapRun map_read_survey(const MapCommand& command, io::Survey survey, double load_s = 0.0,
                       const ProgressCallback& progress = {}, const StopRequested& stop_requested = {});

/// What report.json and the pictures say of `run` besides its result (unit, frame, title, times,
/// backend, origin, version, command line, every option).
MapOutputSettings output_settings(const MapCommand& command, const MapRun& run);

/// Writes `run`'s outputs into options.out as `minemap map` does (the same files, bit for bit);
/// an interrupted run's partial map included. Returns report.json's text.
std::string write_outputs(const MapCommand& command, MapRun& run, const ExtraOutputs& extra = {});

}  // namespace minemap::cli
