// `minemap watch`: maps a survey folder while its scans arrive (io::ready_scan_names says when a
// scan is complete), with the settings `map` would use. Each new scan is read, matched (LiveMapper:
// the mode's match, then the relaxation's per-scan budget, as `map` matches it), and the outputs are
// written again, atomically file by file, with OUT/watch.json, the checkpoint a restart resumes from
// (watch_state.hpp). At the first Ctrl-C (or --scans, or --idle-timeout-s) the map is finished as
// `map` finishes it (the rest of the relaxation queue, loops) and written: then OUT holds what
// `minemap map` writes for the same folder, bit for bit (report.json's times aside). A second Ctrl-C
// stops at once, leaving the last scan's outputs, and exits 130.
#include <chrono>
#include <cstdio>
#include <map>
#include <set>
#include <thread>

#include "minemap/cli/commands.hpp"
#include "minemap/cli/console.hpp"
#include "minemap/cli/exit_codes.hpp"
#include "minemap/cli/signals.hpp"
#include "minemap/cli/watch_state.hpp"
#include "minemap/core/atomic_file.hpp"
#include "minemap/core/error.hpp"

namespace minemap::cli {

MapSubcommand add_watch_command(CLI::App& app, MapCommand& command, WatchOptions& watch) {
  MapSubcommand sub;
  sub.app = app.add_subcommand("watch", "Map a survey folder while its scans arrive (live mapping)");
  sub.app->footer(
      "Each new scan is matched and every output rewritten (atomically, file by file). Ctrl-C finishes the map:\n"
      "the outputs are then those of `map` of the folder. A second Ctrl-C stops at once. A restart resumes from\n"
      "OUT/watch.json. A uos scan is complete when its .pose file exists; other formats: write each file under a\n"
      "temporary name (a leading '.', or .part) and rename it. Scans must arrive in the order of their names.");
  const char* g = groups::kWatch;
  sub.app->add_option("survey", command.options.survey, "Survey folder the scans arrive in (uos, pcd, ply or kitti)")
      ->required()
      ->group(g);
  sub.app->add_option("--out", command.options.out, "Output folder")->required()->group(g);
  sub.app->add_option("--scans", watch.stop_after_scans, "Finish once this many scans are matched (0: on Ctrl-C)")
      ->group(g);
  sub.app->add_option("--idle-timeout-s", watch.idle_timeout_s,
                      "Finish after this many seconds without a new scan (0: never)")
      ->group(g);
  sub.app->add_option("--poll-ms", watch.poll_ms, "How often the folder is looked at (milliseconds)")
      ->capture_default_str()
      ->check(CLI::Range(10, 60000))
      ->group(g);
  sub.options = std::make_unique<MapOptionTable>(*sub.app, command);
  return sub;
}

namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

/// One watch of one folder. Thread-safety: the thread running the command.
class Watch {
 public:
  Watch(const MapCommand& command, const WatchOptions& watch, const std::string& options_text, const Hooks& hooks)
      : command_(command),
        options_(command.options),
        watch_(watch),
        options_text_(options_text),
        hooks_(hooks),
        state_path_(options_.out / "watch.json"),
        backend_(make_backend_for(options_)),
        live_(command.settings, *backend_.backend, [this] { return hard_stop(); }) {
    run_.backend.message = backend_.message;
  }

  int run();

 private:
  bool hard_stop() const { return signals::interrupted_twice() || (hooks_.stop_requested && hooks_.stop_requested()); }
  bool enough() const { return watch_.stop_after_scans > 0 && live_.size() >= watch_.stop_after_scans; }
  io::Survey read_scans(std::size_t first, std::size_t count);
  void resume();
  void check_order(const std::vector<std::string>& names) const;
  bool add_ready(const std::vector<std::string>& names);
  void write_snapshot(MappingResult result);
  void write_state(const MappingResult& unfinished, bool finished) const;
  int finish();

  const MapCommand& command_;
  const MapOptions& options_;
  const WatchOptions& watch_;
  const std::string& options_text_;
  const Hooks& hooks_;
  const fs::path state_path_;
  BackendChoice backend_;
  LiveMapper live_;
  MapRun run_;  ///< the outputs' view: the survey's unit, format and truth, no points
  std::vector<std::string> sources_;
};

/// Scans [first, first + count) of the folder as `map` reads them (unit, poses, truth).
io::Survey Watch::read_scans(std::size_t first, std::size_t count) {
  io::SurveyReadSettings read = survey_read_settings(options_, command_.settings);
  read.first_scan = first;
  read.max_scans = count;
  io::Survey& survey = run_.survey;
  if (!survey.format.empty()) read.origin_cm = survey.origin_cm;  // the origin the first part chose
  io::Survey part = io::read_survey(options_.survey, read);
  if (survey.format.empty()) {
    survey.format = part.format;
    survey.unit = part.unit;
    survey.origin_cm = part.origin_cm;
    survey.frame_3dtk = part.frame_3dtk;
  }
  if (part.truth_cm) {
    if (!survey.truth_cm) survey.truth_cm.emplace();
    survey.truth_cm->insert(survey.truth_cm->end(), part.truth_cm->begin(), part.truth_cm->end());
  }
  for (const auto& warning : part.warnings) {
    if (!options_.quiet) say(stderr, "minemap: warning: %s\n", warning.c_str());
  }
  return part;
}

/// Resumes from what an earlier watch of this folder left in OUT/watch.json.
/// The options two option texts ("name=value" lines, mapping_options_text) set differently, as
/// "--voxel-cm: saved 15, given 20; --mode: saved (default), given simultaneous".
std::string options_difference(const std::string& saved, const std::string& given) {
  const auto parse = [](const std::string& text) {
    std::map<std::string, std::string> values;
    std::size_t start = 0;
    while (start < text.size()) {
      std::size_t end = text.find('\n', start);
      if (end == std::string::npos) end = text.size();
      const std::string line = text.substr(start, end - start);
      const std::size_t equals = line.find('=');
      if (!line.empty()) values[line.substr(0, equals)] = equals == std::string::npos ? "" : line.substr(equals + 1);
      start = end + 1;
    }
    return values;
  };
  const auto a = parse(saved), b = parse(given);
  std::set<std::string> names;
  for (const auto& [name, value] : a) names.insert(name);
  for (const auto& [name, value] : b) names.insert(name);
  std::string out;
  for (const std::string& name : names) {
    const auto x = a.find(name), y = b.find(name);
    const std::string was = x == a.end() ? "(default)" : x->second, now = y == b.end() ? "(default)" : y->second;
    if (was == now) continue;
    if (!out.empty()) out += "; ";
    out += "--" + name + ": saved " + was + ", given " + now;
  }
  return out.empty() ? "in their order" : out;
}

void Watch::resume() {
  const WatchState state = read_watch_state(state_path_);
  if (state.options != options_text_) {
    throw InputError(FileLocation{state_path_.string()},
                     "was written with other mapping options (" + options_difference(state.options, options_text_) +
                         "); resume with the same ones, or watch into another --out",
                     InputProblem::kInconsistentSurvey);
  }
  const std::size_t k = state.result.scans.size();
  if (k > 0) {
    io::Survey part = read_scans(0, k);
    if (part.scans.size() != k) {
      throw InputError(FileLocation{options_.survey.string()},
                       "holds " + std::to_string(part.scans.size()) + " scans, but " + state_path_.string() +
                           " matched " + std::to_string(k),
                       InputProblem::kInconsistentSurvey);
    }
    with_threads(options_, [&] {
      for (std::size_t i = 0; i < k; ++i) {
        if (part.scans[i].name != state.result.scans[i].name) {
          throw InputError(FileLocation{part.scans[i].source_path},
                           "is not " + state.result.scans[i].name + ", which " + state_path_.string() +
                               " matched in its place",
                           InputProblem::kInconsistentSurvey);
        }
        live_.restore(part.scans[i], state.result.scans[i]);
        sources_.push_back(part.scans[i].source_path);
      }
    });
    live_.restore_queue(state.queue);
    live_.restore_counters(state.result);
  }
  if (!options_.quiet) say(stdout, "resumed from %s: %zu scans matched before\n", state_path_.c_str(), k);
}

void Watch::check_order(const std::vector<std::string>& names) const {
  for (std::size_t i = 0; i < std::min(names.size(), live_.size()); ++i) {
    if (names[i] != live_.scan(i).name) {
      throw InputError(FileLocation{(options_.survey / names[i]).string()},
                       "arrived after " + live_.scan(i).name + " was matched in its place: scans must arrive in "
                       "the order of their names",
                       InputProblem::kInconsistentSurvey);
    }
  }
}

/// Reads, matches and writes the scans of `names` not matched yet; true when one was added.
bool Watch::add_ready(const std::vector<std::string>& names) {
  bool added = false;
  while (live_.size() < names.size() && !signals::interrupted() && !enough()) {
    const auto start = std::chrono::steady_clock::now();
    io::Survey part = read_scans(live_.size(), 1);
    const double read_s = seconds_since(start);
    with_threads(options_, [&] { live_.add(part.scans.front()); });
    sources_.push_back(part.scans.front().source_path);
    if (signals::interrupted_twice()) break;
    const auto written = std::chrono::steady_clock::now();
    const MappingResult so_far = live_.result();
    write_snapshot(so_far);
    write_state(so_far, false);
    if (!options_.quiet) {
      const ScanOutcome& scan = live_.scan(live_.size() - 1);
      say(stdout, "%s: read %.2f s, matched %.2f s, outputs %.2f s (%zu scan%s)%s%s\n", scan.name.c_str(), read_s,
                  scan.match_s, seconds_since(written), live_.size(), live_.size() == 1 ? "" : "s",
                  scan.health.doubtful() ? "; doubtful: " : "",
                  scan.health.doubtful() ? scan.health.doubt.c_str() : "");
      std::fflush(stdout);
    }
    added = true;
  }
  return added;
}

/// The map so far, written as `map` writes one (a partial survey is not "partial": its scans are
/// all matched).
void Watch::write_snapshot(MappingResult result) {
  result.scans_matched = result.scans.size();
  run_.result = std::move(result);
  run_.sources = sources_;
  run_.survey_scans = run_.result.scans.size();
  if (run_.survey.truth_cm && run_.survey.truth_cm->size() != run_.result.scans.size()) run_.survey.truth_cm.reset();
  run_.truth = compare_with_truth(run_.result, run_.survey.truth_cm);
  write_outputs(command_, run_, hooks_.extra_outputs);
}

void Watch::write_state(const MappingResult& unfinished, bool finished) const {
  WatchState state;
  state.options = options_text_;
  state.finished = finished;
  state.sources = sources_;
  state.result = unfinished;
  state.queue = live_.queue();
  write_file_atomically(state_path_, watch_state_json(state));
}

/// Finishes as `map` does; the state keeps the unfinished run, which later scans continue.
int Watch::finish() {
  const MappingResult unfinished = live_.result();
  if (!options_.quiet) say(stdout, "finishing the map of %zu scans\n", live_.size());
  with_threads(options_, [&] { live_.finish(); });
  MappingResult finished = live_.result();
  if (finished.interrupted) {
    say(stderr, "minemap: stopped while finishing: %s holds the map of the %zu scans matched before\n",
                 options_.out.c_str(), live_.size());
    return static_cast<int>(ExitCode::kInterrupted);
  }
  write_snapshot(std::move(finished));
  write_state(unfinished, true);
  if (!options_.quiet) {
    print_loops(options_, run_.result);
    print_summary(run_.result);
    print_truth(run_);
    say(stdout, "wrote the finished map of %zu scans to %s\n", live_.size(), options_.out.c_str());
  }
  const int code = exit_code_of(judge_run(run_.result, sources_), options_, run_.result.scans.size());
  write_log(options_.out, version());
  return code;
}

int Watch::run() {
  begin_log(command_.command_line);
  std::error_code error;
  if (fs::exists(state_path_, error)) resume();
  if (!options_.quiet) {
    say(stdout, "watching %s (backend: %s); Ctrl-C finishes the map, a second Ctrl-C stops at once\n",
                options_.survey.c_str(), backend_.message.c_str());
    std::fflush(stdout);
  }
  auto last_arrival = std::chrono::steady_clock::now();
  while (!signals::interrupted() && !enough()) {
    const std::vector<std::string> names = io::ready_scan_names(options_.survey);
    check_order(names);
    const bool added = add_ready(names);
    if (added) last_arrival = std::chrono::steady_clock::now();
    if (signals::interrupted() || enough()) break;
    if (!added && watch_.idle_timeout_s > 0 && seconds_since(last_arrival) >= watch_.idle_timeout_s) break;
    for (int slept = 0; slept < watch_.poll_ms && !signals::interrupted(); slept += 20) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }
  if (signals::interrupted_twice()) {
    say(stderr, "minemap: stopped: %s holds the map of the %zu scans matched before (not finished)\n",
                 options_.out.c_str(), live_.size());
    write_log(options_.out, version());
    return static_cast<int>(ExitCode::kInterrupted);
  }
  if (live_.size() == 0) {
    say(stderr, "minemap: no complete scan arrived in %s: nothing written\n", options_.survey.c_str());
    return static_cast<int>(ExitCode::kEmptyInput);
  }
  return finish();
}

}  // namespace

int run_watch(const MapCommand& command, const WatchOptions& watch, const std::string& options_text,
              const Hooks& hooks) {
  std::error_code error;
  if (!fs::is_directory(command.options.survey, error)) {
    throw InputError(FileLocation{command.options.survey.string()},
                     "is not a folder (watch maps a survey folder as scans arrive)");
  }
  if (io::is_foreign_survey(command.options.survey)) {
    throw InputError(FileLocation{command.options.survey.string()},
                     "watch reads uos, PCD, PLY and KITTI folders; map LAS/LAZ and E57 surveys with `map`");
  }
  if (!command.options.control.empty()) {
    // Not silently ignored: the tie adjusts the finished survey as a whole.
    throw std::invalid_argument("--control ties a finished survey to its control: map the folder with `minemap map "
                                "--control` once the scans are in (watch maps them as they arrive)");
  }
  check_output_folder(command.options.out, command.options.survey);
  return Watch(command, watch, options_text, hooks).run();
}

}  // namespace minemap::cli
