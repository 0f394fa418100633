// The composition root of `map` and `watch` (cli.hpp): the options become a backend, threads, read
// settings, a mapping and its output settings here, once, for the program and the Python package.
#include <tbb/info.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>

#include "minemap/cli/cli.hpp"
#include "minemap/cli/console.hpp"
#include "minemap/cli/map_options.hpp"
#include "minemap/cli/signals.hpp"
#include "minemap/core/error.hpp"
#include "minemap/slam/control_tie.hpp"

namespace minemap::cli {

BackendChoice make_backend_for(const MapOptions& options) {
  BackendOptions backend_options = backend_options_from_environment(options.backend);
  if (!options.opencl_device.empty()) backend_options.opencl.device = options.opencl_device;
  return make_backend(backend_options);
}

int thread_count(const MapOptions& options) {
  const int max_threads = tbb::info::default_concurrency();
  return options.threads > 0 ? std::min(options.threads, max_threads) : max_threads;
}

io::SurveyReadSettings survey_read_settings(const MapOptions& options, const MappingSettings& mapping) {
  io::SurveyReadSettings read;
  if (!options.unit.empty()) read.read.unit = parse_length_unit(options.unit);
  // The matching reads coordinates, and the points' times to deskew a moving sensor's sweeps; the 3D
  // view colours by intensity.
  read.read.attributes = kIntensity;
  if (mapping.motion.deskew != DeskewMode::kOff) read.read.attributes = static_cast<std::uint8_t>(kIntensity | kTime);
  read.read.points_per_slice = options.points_per_slice;
  read.read.detect_slices = !options.no_slice_detection;
  read.read.right_handed_to_3dtk = options.right_handed_to_3dtk;
  if (!options.initial_poses.empty()) read.initial_poses = options.initial_poses;
  if (!options.reference_poses.empty()) read.reference_poses = options.reference_poses;
  return read;
}

MapCommand parse_map_options(const std::vector<std::string>& args) {
  MapCommand command;
  command.options.preset = preset_argument(args);
  command.settings = MappingSettings::preset(command.options.preset);
  CLI::App app{"minemap map options"};
  const MapOptionTable table(app, command);
  // CLI11 takes the arguments reversed (it pops from the back).
  std::vector<std::string> reversed(args.rbegin(), args.rend());
  try {
    app.parse(reversed);
  } catch (const CLI::ParseError& e) {
    throw std::invalid_argument(e.what());
  }
  command.recorded = table.record();
  command.command_line = args;
  finish_settings(command);
  return command;
}

std::vector<OptionInfo> map_options(Preset preset) {
  MapCommand command;
  command.options.preset = preset;
  command.settings = MappingSettings::preset(preset);
  CLI::App app{"minemap map options"};
  const MapOptionTable table(app, command);
  std::vector<OptionInfo> list;
  for (const CLI::Option* option : app.get_options()) {
    const std::string name = option->get_single_name();
    if (name == "help" || name == "h") continue;
    list.push_back({"--" + name, option->get_default_str(), option->get_description(), option->get_expected_min() == 0});
  }
  return list;
}

namespace {

/// A mapped run's survey-wide figures: how many scans, the interrupted run cut to what it matched,
/// the tie to control (a whole run's), the comparison with the truth.
void finish_run(const MapCommand& command, MapRun& run) {
  run.survey_scans = run.result.scans.size();
  if (run.result.interrupted) {
    run.result.scans.resize(run.result.scans_matched);
    if (run.survey.truth_cm) run.survey.truth_cm->resize(run.result.scans_matched);
  } else if (run.control) {
    const auto start = std::chrono::steady_clock::now();
    with_threads(command.options, [&] {
      tie_to_control(run.result, *run.control, run.survey.frame_3dtk, command.settings.control,
                     command.settings.loops.graph);
    });
    run.result.times.control_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  run.truth = compare_with_truth(run.result, run.survey.truth_cm);
}

/// --control, read before anything is mapped (a bad file costs no mapping), its scans checked
/// against the survey folder's where the folder names them first.
std::optional<io::ControlFile> read_control_for(const MapOptions& options) {
  if (options.control.empty()) return std::nullopt;
  io::ControlFile control = io::read_control(options.control);
  if (!options.survey.empty() && !io::is_foreign_survey(options.survey)) {
    const std::vector<std::string> names = io::ready_scan_names(options.survey);
    if (!names.empty()) io::check_control_scans(control, names);
  }
  return control;
}

MapRun map_with(const MapCommand& command, io::Survey survey, double load_s, BackendChoice backend,
                const ProgressCallback& progress, const StopRequested& stop_requested) {
  const MapOptions& options = command.options;
  MapRun run;
  run.control = read_control_for(options);
  run.survey = std::move(survey);
  run.sources = sources_of(run.survey);
  run.load_s = load_s;
  run.backend = std::move(backend);
  if (!options.quiet) print_survey(options, run);
  run.result = with_threads(options, [&] {
    // The scans' points are let go as they are prepared: the outputs need only the reduced clouds.
    return map_survey_releasing_points(run.survey.scans, command.settings, *run.backend.backend, progress,
                                       stop_requested);
  });
  finish_run(command, run);
  return run;
}

/// Where a run's spill file is made (MemoryBound; unlinked at once): the output folder, or, while it
/// does not exist yet, the nearest folder above it that does (a run that fails must not leave an
/// empty output folder behind); the temp folder for a run with no output folder (the Python API).
fs::path spill_folder(const fs::path& out) {
  std::error_code error;
  fs::path folder = out.empty() ? fs::temp_directory_path(error) : fs::absolute(out, error);
  while (!fs::is_directory(folder, error) && folder.has_parent_path() && folder != folder.parent_path()) {
    folder = folder.parent_path();
  }
  return folder;
}

/// The survey read a part at a time and each part mapped as it comes (PartwiseMapper): its raw
/// points are never all held. The console's survey lines come after the matching.
MapRun map_in_parts(const MapCommand& command, BackendChoice backend, const ProgressCallback& progress,
                    const StopRequested& stop_requested) {
  const MapOptions& options = command.options;
  MapRun run;
  run.control = read_control_for(options);
  run.backend = std::move(backend);
  using Clock = std::chrono::steady_clock;
  double read_s = 0.0;
  std::size_t survey_scans = 0;  // the folder's, however many were read before a stop
  with_threads(options, [&] {
    PartwiseMapper mapper(command.settings, *run.backend.backend, progress, stop_requested,
                          MemoryBound{.held_clouds_mb = options.held_clouds_mb, .spill_folder = spill_folder(options.out)});
    auto reading = Clock::now();
    // A part of 4 scans a thread: the files are parsed in parallel, and matched as the next is read.
    const std::size_t part_scans = 4 * static_cast<std::size_t>(thread_count(options));
    run.survey = io::read_survey_in_parts(
        options.survey, survey_read_settings(options, command.settings), part_scans,
        [&](std::vector<Scan>& part, std::size_t, std::size_t total) {
          read_s += std::chrono::duration<double>(Clock::now() - reading).count();
          survey_scans = total;
          const bool go = mapper.add(part, total);
          reading = Clock::now();
          return go;
        });
    read_s += std::chrono::duration<double>(Clock::now() - reading).count();
    run.result = mapper.finish();
  });
  run.load_s = read_s;
  run.sources = sources_of(run.survey);
  if (!options.quiet) print_survey(options, run);
  finish_run(command, run);
  run.survey_scans = std::max(run.survey_scans, survey_scans);
  return run;
}

}  // namespace

MapRun map_read_survey(const MapCommand& command, io::Survey survey, double load_s, const ProgressCallback& progress,
                       const StopRequested& stop_requested) {
  // The composition root: the backend is made here, from the options and the environment.
  return map_with(command, std::move(survey), load_s, make_backend_for(command.options), progress, stop_requested);
}

void check_output_folder(const std::filesystem::path& out, const std::filesystem::path& survey) {
  namespace fs = std::filesystem;
  if (out.empty()) return;  // the library's and the package's runs without outputs
  std::error_code error;
  if (fs::exists(survey, error) && fs::exists(out, error) && fs::equivalent(out, survey, error)) {
    throw OutputError("--out " + out.string() + " is the survey folder: its outputs (map.ply, scanNNN.pose, ...) would "
                      "overwrite the survey's own files and be read as scans by the next run; give another folder");
  }
  if (fs::exists(out, error) && !fs::is_directory(out, error)) {
    throw OutputError("--out " + out.string() + " is a file, not a folder: give a folder (it is created if missing)");
  }
  // The nearest folder that exists must be one we can write in.
  fs::path existing = fs::absolute(out, error);
  while (!existing.empty() && !fs::exists(existing, error) && existing != existing.parent_path()) {
    existing = existing.parent_path();
  }
  if (!fs::is_directory(existing, error)) {
    throw OutputError("--out " + out.string() + " lies under " + existing.string() +
                      ", which is a file, not a folder: give a folder that can be created");
  }
  if (::access(existing.c_str(), W_OK | X_OK) != 0) {
    throw OutputError("--out " + out.string() + ": cannot write in " + existing.string() + " (" + std::strerror(errno) +
                      "): give a folder you can write to");
  }
}

MapRun run_map_command(const MapCommand& command, const ProgressCallback& progress,
                       const StopRequested& stop_requested) {
  // Read everything before touching the output folder: bad input leaves it as it was. Whether it
  // can be written is asked first, so a long run does not end in a folder it cannot use.
  check_output_folder(command.options.out, command.options.survey);
  BackendChoice backend = make_backend_for(command.options);
  // On the CPU the survey is read and mapped a part at a time. A device keeps every scan: its
  // failure matches the whole survey again on the CPU (map_survey).
  if (backend.backend->name() == "cpu") return map_in_parts(command, std::move(backend), progress, stop_requested);
  const auto start = std::chrono::steady_clock::now();
  io::Survey survey = io::read_survey(command.options.survey, survey_read_settings(command.options, command.settings));
  const double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return map_with(command, std::move(survey), load_s, std::move(backend), progress, stop_requested);
}

MapOutputSettings output_settings(const MapCommand& command, const MapRun& run) {
  const MapOptions& options = command.options;
  MapOutputSettings output;
  output.unit = run.survey.unit;
  output.survey_in_3dtk_frame = run.survey.frame_3dtk;  // the reader says which frame the survey is in
  // Arrays given in Python have no folder to read again (an export refuses them by their format).
  const bool arrays = run.survey.format == "arrays";
  output.survey = options.survey.empty() || arrays ? "" : fs::absolute(options.survey).lexically_normal().string();
  output.format = run.survey.format;
  output.sources = run.sources;
  output.title = "minemap " + std::string(to_string(command.settings.mode)) + ": " + options.survey.filename().string();
  output.load_s = run.load_s;
  output.backend_choice = run.backend.message;
  output.survey_scans = run.survey_scans;
  output.origin_cm = run.survey.origin_cm;
  output.version = version();
  output.command_line = command.command_line;
  output.settings = command.recorded;
  return output;
}

std::string write_outputs(const MapCommand& command, MapRun& run, const ExtraOutputs& extra) {
  const MapOutputSettings output = output_settings(command, run);
  const signals::SignalsBlocked no_interrupts_while_writing;
  return with_threads(command.options, [&] {
    std::string report = write_map_outputs(command.options.out, run.result, run.survey.truth_cm, run.truth,
                                           command.settings, output);
    if (extra) extra(command.options.out, command, run);
    return report;
  });
}

}  // namespace minemap::cli
