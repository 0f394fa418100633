// The `minemap` command line (cli.hpp): simulate the built-in mine survey, and map a survey into one
// consistent 3D map. Exit codes in cli/exit_codes.hpp, the bad-input cases in docs/bad-input.md.
#include "minemap/cli/cli.hpp"

#include <signal.h>
#include <tbb/info.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <thread>

#include "minemap/cli/exit_codes.hpp"
#include "minemap/core/atomic_file.hpp"
#include "minemap/core/error.hpp"
#include "minemap/report/live_state.hpp"
#include "minemap/report/map_output.hpp"
#include "minemap/sim/mine_simulator.hpp"

namespace minemap::cli {
namespace {

/// SIGINT/SIGTERM received while run() maps (or watches): `map` stops at the next scan boundary at
/// the first; `watch` finishes the map at the first, and stops at the next boundary at the second.
volatile std::sig_atomic_t g_interrupted = 0;
extern "C" void on_interrupt(int) {
  if (g_interrupted < 2) g_interrupted = g_interrupted + 1;
}

struct Interrupted {};

/// Installs the interrupt handlers while alive and restores the previous ones (the Python
/// interpreter's, when the package runs the command line).
class InterruptHandlers {
 public:
  InterruptHandlers() {
    g_interrupted = 0;
    struct sigaction action {};
    action.sa_handler = on_interrupt;
    action.sa_flags = SA_RESTART;  // as std::signal: reads and writes in flight are not cut short
    sigemptyset(&action.sa_mask);
    ::sigaction(SIGINT, &action, &previous_int_);
    ::sigaction(SIGTERM, &action, &previous_term_);
  }
  ~InterruptHandlers() {
    ::sigaction(SIGINT, &previous_int_, nullptr);
    ::sigaction(SIGTERM, &previous_term_, nullptr);
  }
  InterruptHandlers(const InterruptHandlers&) = delete;
  InterruptHandlers& operator=(const InterruptHandlers&) = delete;

 private:
  struct sigaction previous_int_ {};
  struct sigaction previous_term_ {};
};

/// Blocks SIGINT and SIGTERM while alive: outputs are written completely or not at all, and a
/// signal that arrived meanwhile is delivered (and honoured) once the writing is done.
class SignalsBlocked {
 public:
  SignalsBlocked() {
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, SIGINT);
    sigaddset(&set, SIGTERM);
    ::pthread_sigmask(SIG_BLOCK, &set, &previous_);
  }
  ~SignalsBlocked() { ::pthread_sigmask(SIG_SETMASK, &previous_, nullptr); }
  SignalsBlocked(const SignalsBlocked&) = delete;
  SignalsBlocked& operator=(const SignalsBlocked&) = delete;

 private:
  sigset_t previous_;
};

int exit_code(ExitCode code) { return static_cast<int>(code); }

struct SimulateOptions {
  fs::path out;
  int scans = 0;
  std::uint32_t seed = 1;
  double loop_m = 0.0;
  double step_m = sim::MineSettings{}.mean_step_cm / 100.0;
};

/// What `watch` takes beyond `map`'s options.
struct WatchOptions {
  std::size_t stop_after_scans = 0;  ///< finish once this many scans are matched (0: on Ctrl-C)
  double idle_timeout_s = 0.0;       ///< finish after this long without a new scan (0: never)
  int poll_ms = 500;                 ///< how often the folder is looked at
};

/// The options of a parsed `watch` that change what is computed, one "name=value" per line, sorted
/// (CLI11's config text of what was given): a resume with others would not continue the same run.
/// Where the survey and outputs are, threads, backend and device, and the watch's own options
/// do not change the poses.
std::string mapping_options_text(const CLI::App& command) {
  static const std::vector<std::string> neutral = {"survey", "out", "threads", "backend", "opencl-device", "quiet",
                                                   "accept-doubtful", "write-unregistered", "scans",
                                                   "idle-timeout-s", "poll-ms"};
  std::istringstream config(command.config_to_str(false, false));
  std::vector<std::string> kept;
  for (std::string line; std::getline(config, line);) {
    const std::string name = line.substr(0, line.find('='));
    if (line.empty() || std::find(neutral.begin(), neutral.end(), name) != neutral.end()) continue;
    kept.push_back(line);
  }
  std::sort(kept.begin(), kept.end());
  std::string text;
  for (const auto& k : kept) text += k + "\n";
  return text;
}

/// The value of `--preset` anywhere in `args` ("default" when absent or malformed: the parser then
/// reports the malformed one).
std::string preset_argument(const std::vector<std::string>& args) {
  std::string preset = "default";
  for (std::size_t i = 0; i < args.size(); ++i) {
    if (args[i] == "--preset" && i + 1 < args.size()) preset = args[i + 1];
    if (args[i].rfind("--preset=", 0) == 0) preset = args[i].substr(9);
  }
  return preset;
}

MappingSettings preset_settings(const std::string& preset) {
  if (preset == "simultaneous") return MappingSettings::simultaneous();
  if (preset == "paper") return MappingSettings::paper();
  return {};
}

void add_threads(CLI::App& command, int& threads) {
  command.add_option("--threads", threads, "Worker threads (0 = all cores)");
}
void add_opencl_device(CLI::App& command, std::string& device) {
  command.add_option("--opencl-device", device,
                     "OpenCL device: a substring of 'platform / device' (same as MINEMAP_OPENCL_DEVICE)");
}

/// Every option of `map` but the survey and --out, bound to `target` (whose settings hold the
/// preset's values already: --help shows them as the defaults).
void add_map_options(CLI::App& cmd, MapCommand& target) {
  MapOptions& map = target.options;
  MappingSettings& mapping = target.settings;
  SliceFilterSettings& filter = mapping.filter;
  IcpSettings& icp = mapping.icp;
  add_threads(cmd, map.threads);
  add_opencl_device(cmd, map.opencl_device);
  // Choices by name, parsed by the library's own parse functions (one list of names each).
  const auto add_choice = [&](const std::string& name, auto& value, auto parse, std::vector<std::string> names,
                              const std::string& help) {
    cmd.add_option_function<std::string>(name, [&value, parse](const std::string& text) { value = parse(text); }, help)
        ->check(CLI::IsMember(names))
        ->default_str(to_string(value));
  };
  cmd.add_option("--preset", map.preset,
                 "default (whole-survey: voxel means, metascan) | simultaneous (the paper's relaxation, minemap's "
                 "ICP) | paper (as published); the options below adjust it")
      ->check(CLI::IsMember(std::vector<std::string>{"default", "simultaneous", "paper"}))
      ->default_str("default");
  add_choice("--mode", mapping.mode, parse_matching_mode, {"pairwise", "incremental", "simultaneous"},
             "How scans are matched (the paper's section IV.B)");
  add_choice("--search", icp.method, parse_search_method, {"kd", "apx", "brute"},
             "kd (exact) | apx (approximate, then exact) | brute");
  add_choice("--backend", map.backend, parse_backend, {"auto", "cpu", "opencl"}, "Where the search runs");
  add_choice("--reduction", mapping.reduction, parse_reduction, {"slices", "voxel"},
             "slices (the paper's slice filter) | voxel (the mean of each --voxel-cm cell, every scan)");
  cmd.add_option("--voxel-cm", mapping.voxel_cm, "Voxel size of --reduction voxel")->capture_default_str();
  cmd.add_option("--model-voxel-cm", mapping.model_voxel_cm, "Voxel size of the models of --reduction voxel (0 = the data)")
      ->capture_default_str();
  cmd.add_flag("--no-filter", map.no_filter, "Skip the slice filter (median + reduction + every 3rd slice)");
  cmd.add_option("--max-pair-dist-cm", icp.max_pair_dist_cm, "Maximum point-pair distance")->capture_default_str();
  cmd.add_option("--refine-fraction", icp.refine_pair_dist_fraction,
                 "After converging, refine at this fraction of the pair bound (0 = off)")
      ->capture_default_str();
  cmd.add_option("--max-iterations", icp.termination.max_iterations, "ICP iteration cap")->capture_default_str();
  cmd.add_option("--min-step-cm", icp.termination.min_translation_step_cm, "ICP converged: a step moves less than this...")
      ->capture_default_str();
  cmd.add_option("--min-step-deg", icp.termination.min_rotation_step_deg, "...and turns less than this")
      ->capture_default_str();
  cmd.add_option("--unit", map.unit, "Unit of the survey files: m or cm (default: cm for uos, m otherwise)");
  cmd.add_option("--bucket-size", mapping.tree.bucket_size, "kd-tree bucket size")->capture_default_str();
  cmd.add_option("--median-window", filter.median_window, "Median filter window (points)")->capture_default_str();
  cmd.add_option("--outlier-threshold-cm", filter.outlier_threshold_cm, "Median filter threshold")->capture_default_str();
  cmd.add_option("--min-point-spacing-cm", filter.min_point_spacing_cm, "Reduction spacing")->capture_default_str();
  cmd.add_option("--slice-stride", filter.slice_stride, "Keep every n-th slice")->capture_default_str();
  cmd.add_option("--model-slice-stride", mapping.model_slice_stride,
                 "Scans matched against keep every n-th slice (denser than the data: less bias)")
      ->capture_default_str();
  cmd.add_flag("--sparse-models", map.sparse_models,
               "Match against clouds reduced like the data, as the paper does (faster, less accurate)");
  cmd.add_flag("--plain-icp", map.plain_icp,
               "ICP as in the paper, without Anderson acceleration (the default accelerates: fewer iterations)");
  cmd.add_option("--point-stride", mapping.unstructured_point_stride, "Scans without slices: keep every n-th point")
      ->capture_default_str();
  cmd.add_option("--min-overlap-pairs", mapping.min_overlap_pairs, "Overlap threshold (pairs)")->capture_default_str();
  cmd.add_option("--moved-translation-cm", mapping.moved_translation_cm,
                 "Relaxation: a match that moves a scan more than this re-queues its neighbours")
      ->capture_default_str();
  cmd.add_option("--moved-rotation-deg", mapping.moved_rotation_deg, "...or turns it more than this")
      ->capture_default_str();
  cmd.add_option("--max-relaxation-matches", mapping.max_relaxation_matches_per_scan,
                 "Relaxation matches after each new scan; the rest wait for the next scan (0 = empty the "
                 "queue every time, as the paper)")
      ->capture_default_str();
  cmd.add_option("--max-relaxation-neighbours", mapping.max_relaxation_neighbours,
                 "Relaxation: match a scan against at most this many overlapping scans, nearest first "
                 "(0 = all, as the paper)")
      ->capture_default_str();
  cmd.add_option("--points-per-slice", map.points_per_slice,
                 "uos files without slice markers: points per slice (default: found from the scanner order)");
  cmd.add_flag("--no-slice-detection", map.no_slice_detection,
               "uos files without slice markers: do not look for slices in the order of the points");
  cmd.add_option("--initial-poses", map.initial_poses,
                 "Initial poses (TUM, KITTI, 4x4 or graph file; commas allowed), one per scan in the order printed");
  cmd.add_option("--reference-poses", map.reference_poses,
                 "Reference poses for the error report, any survey (formats as --initial-poses)");
  cmd.add_flag("--right-handed-to-3dtk", map.right_handed_to_3dtk, "Convert right-handed input to 3DTK's frame");
  cmd.add_flag("--quiet", map.quiet, "Print nothing but errors");
  cmd.add_flag("--no-retry", map.no_retry,
               "Do not try a doubtful match again from 4x and 16x the pair bound (coarse to fine)");
  cmd.add_flag("--no-loop-closing", map.no_loops,
               "Do not close loops (a scan near one 12+ scans earlier matched against it, then the scan "
               "graph relaxed); the metascan then holds every nearby scan");
  cmd.add_option("--loop-distance-cm", mapping.loops.max_distance_cm,
                 "Loop candidates: scans whose positions are this close (cm)")
      ->capture_default_str();
  cmd.add_flag("--accept-doubtful", map.accept_doubtful,
               "Exit 0 even when a match was judged doubtful (still named on stderr and in report.json)");
  cmd.add_flag("--write-unregistered", map.write_unregistered,
               "Write the outputs even when a scan could not be registered (exit code 4 still)");
}

/// The flags that switch parts of the settings off, applied once parsing is done; then validated.
void finish_settings(MapCommand& command) {
  const MapOptions& options = command.options;
  MappingSettings& settings = command.settings;
  if (options.no_filter) settings.filter_enabled = false;
  if (options.sparse_models) settings.dense_models = false;
  if (options.plain_icp) settings.icp.accelerate = false;
  if (options.no_retry) settings.retry_bound_factors.clear();
  if (options.no_loops) settings.loops.enabled = false;
  settings.validate();
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

/// Progress on stderr: a one-line bar on a terminal; otherwise (a log file, a batch job) a plain
/// line per matched scan, and one when the reduction is done.
class ProgressBar {
 public:
  explicit ProgressBar(bool enabled) : enabled_(enabled), terminal_(::isatty(STDERR_FILENO) != 0) {}
  ~ProgressBar() {
    if (enabled_ && drawn_) std::fputs("\n", stderr);
  }
  void operator()(std::size_t done, std::size_t total, const std::string& phase) {
    if (!enabled_ || total == 0) return;
    if (!terminal_) {
      // Scan 0 is the master: matching reports scans 2..n, the reduction only its end.
      if (phase == "filtering" && done != total) return;
      std::fprintf(stderr, "minemap: progress: %s %zu/%zu\n", phase.c_str(), done, total);
      std::fflush(stderr);
      return;
    }
    constexpr int kWidth = 40;
    const int filled = static_cast<int>(kWidth * done / total);
    std::fprintf(stderr, "\r%-13s [%s%s] %zu/%zu", phase.c_str(), std::string(filled, '#').c_str(),
                 std::string(kWidth - filled, '.').c_str(), done, total);
    std::fflush(stderr);
    drawn_ = true;
  }

 private:
  bool enabled_;
  bool terminal_;
  bool drawn_ = false;
};

void print_errors(const char* label, const PoseErrors& e, double unit_per_cm, const char* unit) {
  std::printf("  %-10s mean %.3f %s (%.3f%% of %.1f %s driven), max %.3f %s, mean rotation %.3f deg\n", label,
              e.mean_translation_cm * unit_per_cm, unit,
              e.path_length_cm > 0 ? 100.0 * e.mean_translation_cm / e.path_length_cm : 0.0,
              e.path_length_cm * unit_per_cm, unit, e.max_translation_cm * unit_per_cm, unit, e.mean_rotation_deg);
}

void print_survey(const MapOptions& options, const MapRun& run) {
  const io::Survey& survey = run.survey;
  std::printf("read %zu %s scans from %s in %.2f s (unit %s)\n", survey.scans.size(), survey.format.c_str(),
              options.survey.c_str(), run.load_s, to_string(survey.unit));
  for (const auto& warning : survey.warnings) std::fprintf(stderr, "minemap: warning: %s\n", warning.c_str());
  // The order scans are matched in (and --initial-poses lines are paired with): natural order.
  std::string order;
  const std::size_t n = survey.scans.size();
  for (std::size_t i = 0; i < n; ++i) {
    if (n > 6 && i == 3) {
      order += ", ...";
      i = n - 3;
    }
    order += (i == 0 ? "" : ", ") + survey.scans[i].name;
  }
  std::printf("scan order: %s\n", order.c_str());
  if (survey.scans.size() == 1) {
    std::printf("note: a survey of one scan: nothing to register; the map is %s at its initial pose\n",
                survey.scans.front().name.c_str());
  }
  std::printf("backend: %s\n", run.backend.message.c_str());
}

/// Names each scan that could not be registered on stderr (with its file: sources[i]); true when
/// there is none.
bool say_unregistered(const MappingResult& result, const std::vector<std::string>& sources) {
  bool all = true;
  for (std::size_t i = 0; i < result.scans.size(); ++i) {
    const ScanOutcome& s = result.scans[i];
    if (s.registered) continue;
    all = false;
    std::fprintf(stderr, "minemap: %s: scan %s not registered: %s\n", sources[i].c_str(), s.name.c_str(),
                 s.failure.c_str());
  }
  return all;
}

/// Names each registered scan whose match was judged doubtful on stderr; returns their indices.
std::vector<std::size_t> say_doubtful(const MappingResult& result, const std::vector<std::string>& sources) {
  const std::vector<std::size_t> doubtful = result.doubtful();
  for (const std::size_t i : doubtful) {
    std::fprintf(stderr, "minemap: %s: scan %s registered, but doubtful: %s\n", sources[i].c_str(),
                 result.scans[i].name.c_str(), result.scans[i].health.doubt.c_str());
  }
  return doubtful;
}

int run_map(const MapCommand& command, const Hooks& hooks) {
  const MapOptions& options = command.options;
  ProgressBar bar(!options.quiet);
  // Ctrl-C or SIGTERM stops the run between scans (and between relaxation matches); what was
  // matched by then is written below, marked partial, and the exit code is 130.
  MapRun run = run_map_command(
      command, [&](std::size_t done, std::size_t total, const std::string& phase) { bar(done, total, phase); },
      [&] { return g_interrupted != 0 || (hooks.stop_requested && hooks.stop_requested()); });
  const MappingResult& result = run.result;
  if (!options.quiet) {
    for (const auto& note : result.notes) std::printf("note: %s\n", note.c_str());
  }

  // A scan that could not be registered (no overlap, too few pairs) makes the map untrustworthy:
  // by default nothing is written and the output folder stays as it was, as for bad input.
  // --write-unregistered writes the outputs anyway, the scan at its odometry pose, for inspection.
  std::vector<std::string> sources;
  for (const Scan& scan : run.survey.scans) sources.push_back(scan.source_path);
  const bool failed = !say_unregistered(result, sources);
  if (failed) {
    if (!options.write_unregistered) {
      std::fprintf(stderr,
                   "minemap: nothing was written to %s; --write-unregistered writes the map with these scans at "
                   "their odometry poses (report.json marks them)\n",
                   options.out.c_str());
      return exit_code(ExitCode::kRegistrationFailed);
    }
  }

  // Registered but judged doubtful (registration/health.hpp): written, named, and a distinct exit code.
  const std::vector<std::size_t> doubtful = say_doubtful(result, sources);
  write_outputs(command, run, hooks.extra_outputs);
  if (result.interrupted) {
    std::fprintf(stderr, "minemap: interrupted: wrote the %zu of %zu scans matched so far to %s (report.json: partial)\n",
                 result.scans.size(), run.survey_scans, options.out.c_str());
    return exit_code(ExitCode::kInterrupted);
  }
  if (g_interrupted) throw Interrupted{};  // arrived while writing: the outputs are complete

  // Loops: each candidate said, closed or not (an unclosed one leaves the drift it would have removed).
  // A candidate not matched is normal when another scan of the same loop closed it (a scan in a
  // cross-cut sees little of the start); only a survey whose candidates all failed is told so.
  const bool any_closed =
      std::any_of(result.loops.begin(), result.loops.end(), [](const LoopClosure& loop) { return loop.closed; });
  for (const LoopClosure& loop : result.loops) {
    const std::string& from = result.scans[loop.from].name;
    const std::string& to = result.scans[loop.to].name;
    if (loop.closed && !options.quiet) {
      std::printf("loop closed: %s with %s: %.1f cm / %.2f deg apart before the relaxation, %.1f cm / %.2f deg after\n",
                  to.c_str(), from.c_str(), loop.gap_before_cm, loop.gap_before_deg, loop.gap_after_cm,
                  loop.gap_after_deg);
    } else if (!loop.closed && !any_closed) {
      std::fprintf(stderr,
                   "minemap: loop not closed: %s stands near %s, but no match of the two was trusted (%s): the "
                   "drift over the loop stays in the map\n",
                   to.c_str(), from.c_str(), loop.doubt.c_str());
    }
  }
  if (!options.quiet) {
    std::printf("matched %zu scans: %d ICP iterations pairwise, %d in %d relaxation matches; %.2f s filter, "
                "%.2f s trees, %.2f s pairwise, %.2f s relaxation\n",
                result.scans.size(), result.step1_icp_iterations, result.step3_icp_iterations,
                result.relaxation_matches, result.times.filter_s, result.times.tree_build_s, result.times.pairwise_s,
                result.times.relaxation_s);
    if (auto comparison = compare_with_truth(result, run.survey.truth_cm)) {
      const double unit_per_cm = 1.0 / centimetres_per(run.survey.unit);
      std::printf("pose error against the reference poses (relative to the first scan):\n");
      print_errors("odometry", comparison->odometry, unit_per_cm, to_string(run.survey.unit));
      print_errors("registered", comparison->registered, unit_per_cm, to_string(run.survey.unit));
    }
    std::printf("wrote %s (frames, poses, trajectory.tum, map.ply, report.json, top.png, side.png, map.html)\n",
                options.out.c_str());
  }
  if (failed) return exit_code(ExitCode::kRegistrationFailed);
  if (!doubtful.empty()) {
    std::fprintf(stderr,
                 "minemap: %zu of %zu scans doubtful (report.json: doubtful_scans); the map in %s may be wrong there%s\n",
                 doubtful.size(), result.scans.size(), options.out.c_str(),
                 options.accept_doubtful ? " (accepted: --accept-doubtful)" : "; --accept-doubtful exits 0 anyway");
    if (!options.accept_doubtful) return exit_code(ExitCode::kDoubtfulMap);
  }
  return 0;
}

/// The exit code of a finished watch, with the messages `map` prints (unregistered, doubtful).
int verdict(const MapOptions& options, const MappingResult& result, const std::vector<std::string>& sources) {
  const bool failed = !say_unregistered(result, sources);
  const bool doubtful = !say_doubtful(result, sources).empty();
  if (failed) return exit_code(ExitCode::kRegistrationFailed);
  if (doubtful && !options.accept_doubtful) return exit_code(ExitCode::kDoubtfulMap);
  return 0;
}

/// `minemap watch`: maps a survey folder while its scans arrive (io::ready_scan_names says when a
/// scan is complete), with the settings `map` would use. Each new scan is read, matched (LiveMapper:
/// pairwise, then the relaxation's per-scan budget, as `map` matches it), and the outputs are written
/// again, atomically file by file, with OUT/watch.json, the state a restart resumes from. At the
/// first Ctrl-C (or --scans, or --idle-timeout-s) the map is finished as `map` finishes it (the rest
/// of the relaxation queue, loops) and written: then OUT holds what `minemap map` writes for the
/// same folder, bit for bit (report.json's times aside). A second Ctrl-C stops at once, leaving the
/// last scan's outputs, and exits 130.
int run_watch(const MapCommand& command, const WatchOptions& watch, const std::string& options_text,
              const Hooks& hooks) {
  const MapOptions& options = command.options;
  std::error_code error;
  if (!fs::is_directory(options.survey, error)) {
    throw InputError(FileLocation{options.survey.string()}, "is not a folder (watch maps a survey folder as scans arrive)");
  }
  if (io::is_foreign_survey(options.survey)) {
    throw InputError(FileLocation{options.survey.string()},
                     "watch reads uos, PCD, PLY and KITTI folders; map LAS/LAZ and E57 surveys with `map`");
  }
  MapRun run;  // the outputs' view: the survey's unit, format and truth, no points
  run.backend = make_backend_for(options);
  const auto hard_stop = [&] { return g_interrupted >= 2 || (hooks.stop_requested && hooks.stop_requested()); };
  LiveMapper live(command.settings, *run.backend.backend, hard_stop);
  std::vector<std::string> sources;
  const fs::path state_path = options.out / "watch.json";
  tbb::task_arena arena(thread_count(options));

  // Reads scans [first, first + count) of the folder as `map` reads them (unit, poses, truth).
  const auto read_scans = [&](std::size_t first, std::size_t count) {
    io::SurveyReadSettings read = survey_read_settings(options);
    read.first_scan = first;
    read.max_scans = count;
    io::Survey part = io::read_survey(options.survey, read);
    if (run.survey.format.empty()) {
      run.survey.format = part.format;
      run.survey.unit = part.unit;
      run.survey.origin_cm = part.origin_cm;
    }
    if (part.truth_cm) {
      if (!run.survey.truth_cm) run.survey.truth_cm.emplace();
      run.survey.truth_cm->insert(run.survey.truth_cm->end(), part.truth_cm->begin(), part.truth_cm->end());
    }
    for (const auto& warning : part.warnings) {
      if (!options.quiet) std::fprintf(stderr, "minemap: warning: %s\n", warning.c_str());
    }
    return part;
  };
  const auto write_state = [&](const MappingResult& unfinished, bool finished) {
    LiveState state;
    state.options = options_text;
    state.finished = finished;
    state.sources = sources;
    state.result = unfinished;
    for (ScanOutcome& scan : state.result.scans) scan.used_points_cm.clear();
    state.queue = live.queue();
    write_file_atomically(state_path, live_state_json(state));
  };
  // The map so far, written as `map` writes one (a partial survey is not "partial": its scans are all matched).
  const auto write_snapshot = [&](MappingResult result) {
    result.scans_matched = result.scans.size();
    run.result = std::move(result);
    run.survey_scans = run.result.scans.size();
    if (run.survey.truth_cm && run.survey.truth_cm->size() != run.result.scans.size()) run.survey.truth_cm.reset();
    write_outputs(command, run, hooks.extra_outputs);
  };

  // Resume from what an earlier watch of this folder left in OUT.
  if (fs::exists(state_path, error)) {
    LiveState state = read_live_state(state_path);
    if (state.options != options_text) {
      throw InputError(FileLocation{state_path.string()},
                       "was written with other mapping options; resume with the same ones, or watch into another "
                       "--out (saved:\n" + state.options + "given:\n" + options_text + ")",
                       InputProblem::kInconsistentSurvey);
    }
    const std::size_t k = state.result.scans.size();
    if (k > 0) {
      io::Survey part = read_scans(0, k);
      if (part.scans.size() != k) {
        throw InputError(FileLocation{options.survey.string()},
                         "holds " + std::to_string(part.scans.size()) + " scans, but " + state_path.string() +
                             " matched " + std::to_string(k),
                         InputProblem::kInconsistentSurvey);
      }
      arena.execute([&] {
        for (std::size_t i = 0; i < k; ++i) {
          if (part.scans[i].name != state.result.scans[i].name) {
            throw InputError(FileLocation{part.scans[i].source_path},
                             "is not " + state.result.scans[i].name + ", which " + state_path.string() +
                                 " matched in its place",
                             InputProblem::kInconsistentSurvey);
          }
          live.restore(part.scans[i], state.result.scans[i]);
          sources.push_back(part.scans[i].source_path);
        }
      });
      live.restore_queue(state.queue);
      MappingResult& counters = live.result();
      counters.step1_icp_iterations = state.result.step1_icp_iterations;
      counters.step3_icp_iterations = state.result.step3_icp_iterations;
      counters.relaxation_matches = state.result.relaxation_matches;
      counters.notes = state.result.notes;
      counters.times = state.result.times;
    }
    if (!options.quiet) std::printf("resumed from %s: %zu scans matched before\n", state_path.c_str(), k);
  }

  if (!options.quiet) {
    std::printf("watching %s (backend: %s); Ctrl-C finishes the map, a second Ctrl-C stops at once\n",
                options.survey.c_str(), run.backend.message.c_str());
    std::fflush(stdout);
  }
  auto last_arrival = std::chrono::steady_clock::now();
  const auto enough = [&] { return watch.stop_after_scans > 0 && live.size() >= watch.stop_after_scans; };
  while (g_interrupted == 0 && !enough()) {
    const std::vector<std::string> names = io::ready_scan_names(options.survey);
    for (std::size_t i = 0; i < std::min(names.size(), live.size()); ++i) {
      if (names[i] != live.result().scans[i].name) {
        throw InputError(FileLocation{(options.survey / names[i]).string()},
                         "arrived after " + live.result().scans[i].name + " was matched in its place: scans must "
                         "arrive in the order of their names",
                         InputProblem::kInconsistentSurvey);
      }
    }
    bool added = false;
    while (live.size() < names.size() && g_interrupted == 0 && !enough()) {
      const auto start = std::chrono::steady_clock::now();
      io::Survey part = read_scans(live.size(), 1);
      const double read_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      arena.execute([&] { live.add(part.scans.front()); });
      sources.push_back(part.scans.front().source_path);
      if (g_interrupted >= 2) break;
      const auto written = std::chrono::steady_clock::now();
      write_snapshot(live.result());
      write_state(live.result(), false);
      const double write_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - written).count();
      if (!options.quiet) {
        const ScanOutcome& scan = live.result().scans.back();
        std::printf("%s: read %.2f s, matched %.2f s, outputs %.2f s (%zu scans)%s%s\n", scan.name.c_str(), read_s,
                    scan.match_s, write_s, live.size(), scan.health.doubtful() ? "; doubtful: " : "",
                    scan.health.doubtful() ? scan.health.doubt.c_str() : "");
        std::fflush(stdout);
      }
      added = true;
      last_arrival = std::chrono::steady_clock::now();
    }
    if (g_interrupted != 0 || enough()) break;
    if (!added && watch.idle_timeout_s > 0 &&
        std::chrono::duration<double>(std::chrono::steady_clock::now() - last_arrival).count() >= watch.idle_timeout_s) {
      break;
    }
    for (int slept = 0; slept < watch.poll_ms && g_interrupted == 0; slept += 20) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }
  if (g_interrupted >= 2) {
    std::fprintf(stderr, "minemap: stopped: %s holds the map of the %zu scans matched before (not finished)\n",
                 options.out.c_str(), live.size());
    return exit_code(ExitCode::kInterrupted);
  }
  if (live.size() == 0) {
    std::fprintf(stderr, "minemap: no complete scan arrived in %s: nothing written\n", options.survey.c_str());
    return exit_code(ExitCode::kEmptyInput);
  }
  // Finish as `map` does; the state keeps the unfinished run, which later scans continue.
  const MappingResult unfinished = live.result();
  if (!options.quiet) std::printf("finishing the map of %zu scans\n", live.size());
  arena.execute([&] { live.finish(); });
  if (live.result().interrupted) {
    std::fprintf(stderr, "minemap: stopped while finishing: %s holds the map of the %zu scans matched before\n",
                 options.out.c_str(), live.size());
    return exit_code(ExitCode::kInterrupted);
  }
  run.result = live.result();
  run.survey_scans = run.result.scans.size();
  if (run.survey.truth_cm && run.survey.truth_cm->size() != run.result.scans.size()) run.survey.truth_cm.reset();
  write_outputs(command, run, hooks.extra_outputs);
  write_state(unfinished, true);
  if (!options.quiet) {
    if (auto comparison = compare_with_truth(run.result, run.survey.truth_cm)) {
      const double unit_per_cm = 1.0 / centimetres_per(run.survey.unit);
      std::printf("pose error against the reference poses (relative to the first scan):\n");
      print_errors("odometry", comparison->odometry, unit_per_cm, to_string(run.survey.unit));
      print_errors("registered", comparison->registered, unit_per_cm, to_string(run.survey.unit));
    }
    std::printf("wrote the finished map of %zu scans to %s\n", live.size(), options.out.c_str());
  }
  return verdict(options, run.result, sources);
}

}  // namespace

BackendChoice make_backend_for(const MapOptions& options) {
  BackendOptions backend_options = backend_options_from_environment(options.backend);
  if (!options.opencl_device.empty()) backend_options.opencl.device = options.opencl_device;
  return make_backend(backend_options);
}

int thread_count(const MapOptions& options) {
  const int max_threads = tbb::info::default_concurrency();
  return options.threads > 0 ? std::min(options.threads, max_threads) : max_threads;
}

io::SurveyReadSettings survey_read_settings(const MapOptions& options) {
  io::SurveyReadSettings read;
  if (!options.unit.empty()) read.read.unit = parse_length_unit(options.unit);
  read.read.points_per_slice = options.points_per_slice;
  read.read.detect_slices = !options.no_slice_detection;
  read.read.right_handed_to_3dtk = options.right_handed_to_3dtk;
  if (!options.initial_poses.empty()) read.initial_poses = options.initial_poses;
  if (!options.reference_poses.empty()) read.reference_poses = options.reference_poses;
  return read;
}

MapCommand parse_map_options(const std::vector<std::string>& args) {
  MapCommand command;
  command.settings = preset_settings(preset_argument(args));
  CLI::App app{"minemap map options"};
  add_map_options(app, command);
  // CLI11 takes the arguments reversed (it pops from the back).
  std::vector<std::string> reversed(args.rbegin(), args.rend());
  try {
    app.parse(reversed);
  } catch (const CLI::ParseError& e) {
    throw std::invalid_argument(e.what());
  }
  finish_settings(command);
  return command;
}

std::vector<OptionInfo> map_options(const std::string& preset) {
  MapCommand command;
  command.settings = preset_settings(preset);
  CLI::App app{"minemap map options"};
  add_map_options(app, command);
  std::vector<OptionInfo> list;
  for (const CLI::Option* option : app.get_options()) {
    if (option->get_name() == "--help" || option->get_name() == "-h,--help") continue;
    std::string name = option->get_single_name();
    if (name == "help" || name == "h") continue;
    list.push_back({"--" + name, option->get_default_str(), option->get_description(), option->get_expected_min() == 0});
  }
  return list;
}

MapRun run_map_command(const MapCommand& command, const ProgressCallback& progress,
                       const StopRequested& stop_requested) {
  const MapOptions& options = command.options;
  MapRun run;
  // Read everything before touching the output folder: bad input leaves it as it was.
  const auto start = std::chrono::steady_clock::now();
  run.survey = io::read_survey(options.survey, survey_read_settings(options));
  run.load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // The composition root: the backend is made here, from the options and the environment.
  run.backend = make_backend_for(options);
  if (!options.quiet) print_survey(options, run);
  tbb::task_arena arena(thread_count(options));
  run.result = arena.execute(
      [&] { return map_survey(run.survey.scans, command.settings, *run.backend.backend, progress, stop_requested); });
  run.survey_scans = run.result.scans.size();
  if (run.result.interrupted) {
    run.result.scans.resize(run.result.scans_matched);
    if (run.survey.truth_cm) run.survey.truth_cm->resize(run.result.scans_matched);
  }
  return run;
}

std::string write_outputs(const MapCommand& command, MapRun& run, const ExtraOutputs& extra) {
  const MapOptions& options = command.options;
  MapOutputSettings output;
  output.unit = run.survey.unit;
  output.up_axis = (run.survey.format == "uos" || options.right_handed_to_3dtk) ? 1 : 2;
  output.title = "minemap " + std::string(to_string(command.settings.mode)) + ": " + options.survey.filename().string();
  output.load_s = run.load_s;
  output.backend_choice = run.backend.message;
  output.survey_scans = run.survey_scans;
  output.origin_cm = run.survey.origin_cm;
  tbb::task_arena arena(thread_count(options));
  const SignalsBlocked no_interrupts_while_writing;
  return arena.execute([&] {
    std::string report = write_map_outputs(options.out, run.result, run.survey.truth_cm, command.settings, output);
    if (extra) extra(options.out, run);
    return report;
  });
}

int run(const std::vector<std::string>& args, const Hooks& hooks) {
  CLI::App app{"minemap: 6D SLAM for 3D laser scans of mines (Nuechter et al.)"};
  app.name("minemap");
  app.require_subcommand(1);
  // Process-wide options: accepted before the subcommand and after it (where users type them), and
  // listed in each subcommand's --help; both places write the same variables.
  MapCommand map;
  map.settings = preset_settings(preset_argument(args));
  add_threads(app, map.options.threads);
  add_opencl_device(app, map.options.opencl_device);

  SimulateOptions sim;
  auto* simulate = app.add_subcommand("simulate", "Write the built-in simulated mine survey (uos format)");
  add_threads(*simulate, map.options.threads);
  simulate->add_option("--out", sim.out, "Output folder")->required();
  simulate->add_option("--scans", sim.scans, "Number of scans (0 = the whole 250 m drive)");
  simulate->add_option("--seed", sim.seed, "Random seed");
  simulate->add_option("--loop", sim.loop_m,
                       "Drive a loop of about this many metres around the pillars right of the drive, back to the "
                       "first scan's place, instead of the straight drive (0 = straight)")
      ->check(CLI::NonNegativeNumber);
  simulate->add_option("--step-m", sim.step_m,
                       "Mean distance between scan positions (metres): 4 for stop-and-go as the paper, under 1 for a "
                       "survey where most scans see each other, as a moving LiDAR's")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);

  auto* map_cmd = app.add_subcommand("map", "Register a survey into one consistent map");
  map_cmd->add_option("survey", map.options.survey,
                      "Survey folder (uos, pcd, ply or kitti layout; LAS/LAZ and E57 through the Python package)")
      ->required();
  map_cmd->add_option("--out", map.options.out, "Output folder")->required();
  add_map_options(*map_cmd, map);

  MapCommand watch = map;  // its own copy: CLI11 binds each subcommand's options to their targets
  WatchOptions watch_options;
  auto* watch_cmd = app.add_subcommand("watch", "Map a survey folder while its scans arrive (live mapping)");
  watch_cmd->footer(
      "Each new scan is matched and every output rewritten (atomically, file by file). Ctrl-C finishes the map:\n"
      "the outputs are then those of `map` of the folder. A second Ctrl-C stops at once. A restart resumes from\n"
      "OUT/watch.json. A uos scan is complete when its .pose file exists; other formats: write each file under a\n"
      "temporary name (a leading '.', or .part) and rename it. Scans must arrive in the order of their names.");
  watch_cmd->add_option("survey", watch.options.survey, "Survey folder the scans arrive in (uos, pcd, ply or kitti)")
      ->required();
  watch_cmd->add_option("--out", watch.options.out, "Output folder")->required();
  watch_cmd->add_option("--scans", watch_options.stop_after_scans, "Finish once this many scans are matched (0: on Ctrl-C)");
  watch_cmd->add_option("--idle-timeout-s", watch_options.idle_timeout_s,
                        "Finish after this many seconds without a new scan (0: never)");
  watch_cmd->add_option("--poll-ms", watch_options.poll_ms, "How often the folder is looked at (milliseconds)")
      ->capture_default_str()
      ->check(CLI::Range(10, 60000));
  add_map_options(*watch_cmd, watch);

  try {
    std::vector<std::string> reversed(args.rbegin(), args.rend());
    app.parse(reversed);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : exit_code(ExitCode::kUsage);
  }
  // `map` stops at a scan boundary on Ctrl-C (SIGINT) or SIGTERM; other commands die as usual.
  std::optional<InterruptHandlers> handlers;
  if (*map_cmd || *watch_cmd) handlers.emplace();
  try {
    if (*simulate) {
      tbb::task_arena arena(thread_count(map.options));
      return arena.execute([&] { return run_simulate(sim); });
    }
    if (*watch_cmd) {
      // Process-wide options given before the subcommand.
      if (watch.options.threads == 0) watch.options.threads = map.options.threads;
      if (watch.options.opencl_device.empty()) watch.options.opencl_device = map.options.opencl_device;
      finish_settings(watch);
      return run_watch(watch, watch_options, mapping_options_text(*watch_cmd), hooks);
    }
    finish_settings(map);
    return run_map(map, hooks);
  } catch (const Interrupted&) {
    if (*map_cmd) remove_stale_temp_files(map.options.out);
    std::cerr << "minemap: interrupted; outputs already written are complete, nothing was half-written\n";
    return exit_code(ExitCode::kInterrupted);
  } catch (const InputError& e) {
    // Thrown while reading, before the output folder is touched: it is left as it was.
    std::cerr << "minemap: " << e.what() << "\n";
    return exit_code(exit_code_for(e.problem()));
  } catch (const OutputError& e) {
    std::cerr << "minemap: " << e.what() << "\n";
    return exit_code(ExitCode::kOutputError);
  } catch (const BackendError& e) {
    std::cerr << "minemap: " << e.what() << "\n";
    return exit_code(ExitCode::kBackendUnavailable);
  } catch (const std::invalid_argument& e) {
    std::cerr << "minemap: " << e.what() << "\n";
    return exit_code(ExitCode::kUsage);
  } catch (const std::exception& e) {
    std::cerr << "minemap: error: " << e.what() << "\n";
    return exit_code(ExitCode::kInternal);
  }
}

}  // namespace minemap::cli
