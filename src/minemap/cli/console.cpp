#include "minemap/cli/console.hpp"

#include "minemap/slam/control_tie.hpp"

#include <chrono>
#include <unistd.h>

#include <algorithm>
#include <cstdarg>
#include <cstdio>

#include "minemap/cli/exit_codes.hpp"
#include "minemap/core/atomic_file.hpp"

namespace minemap::cli {
namespace {

/// What the running command printed (OUT/minemap.log). One command at a time (cli::run is not
/// reentrant).
struct RunLog {
  std::vector<std::string> command_line;
  std::string text;
};
RunLog& run_log() {
  static RunLog log;
  return log;
}

}  // namespace

void say(std::FILE* stream, const char* format, ...) {
  std::va_list args;
  va_start(args, format);
  std::va_list copy;
  va_copy(copy, args);
  std::vfprintf(stream, format, args);
  va_end(args);
  char buffer[4096];
  const int length = std::vsnprintf(buffer, sizeof buffer, format, copy);
  va_end(copy);
  if (length > 0) run_log().text.append(buffer, std::min<std::size_t>(static_cast<std::size_t>(length), sizeof buffer - 1));
}

void begin_log(const std::vector<std::string>& command_line) {
  run_log() = RunLog{command_line, {}};
}

void write_log(const fs::path& out_dir, const char* version) {
  std::string text = std::string("minemap ") + version + "\n";
  for (const std::string& word : run_log().command_line) text += (text.back() == '\n' ? "" : " ") + word;
  text += "\n\n" + run_log().text;
  std::error_code error;
  if (fs::is_directory(out_dir, error)) write_file_atomically(out_dir / "minemap.log", text);
}

ProgressBar::ProgressBar(bool enabled) : enabled_(enabled), terminal_(::isatty(STDERR_FILENO) != 0) {}

ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::finish() {
  if (enabled_ && drawn_) std::fputs("\n", stderr);
  std::fflush(stderr);
  drawn_ = false;
}

std::string ProgressBar::pace(std::size_t done, std::size_t total) const {
  const double elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - phase_start_).count();
  // The first report of a phase starts its clock: the pace counts what was done after it.
  if (done <= phase_first_done_ || elapsed_s <= 0.0) return {};
  const double rate = static_cast<double>(done - phase_first_done_) / elapsed_s;
  char text[64];
  if (done >= total) {
    std::snprintf(text, sizeof text, " (%.1f/s, %.1f s)", rate, elapsed_s);
  } else {
    std::snprintf(text, sizeof text, " (%.1f/s, ETA %.0f s)", rate, static_cast<double>(total - done) / rate);
  }
  return text;
}

void ProgressBar::operator()(std::size_t done, std::size_t total, const std::string& phase) {
  if (!enabled_ || total == 0) return;
  if (phase != phase_) {  // a new stage: its own clock, and its own line on a terminal
    if (drawn_) finish();
    phase_ = phase;
    phase_start_ = std::chrono::steady_clock::now();
    phase_first_done_ = done;
    logged_done_ = 0;
  }
  if (!terminal_) {
    const auto now = std::chrono::steady_clock::now();
    const bool first = logged_done_ == 0, last = done >= total;
    const bool hundredth = (done - logged_done_) * 100 >= total;
    const bool while_ago = std::chrono::duration<double>(now - logged_at_).count() >= kLogEvery_s;
    if (!first && !last && !hundredth && !while_ago) return;
    logged_done_ = done;
    logged_at_ = now;
    // Scan 0 is the master: matching reports scans 2..n.
    std::fprintf(stderr, "minemap: progress: %s %zu/%zu%s\n", phase.c_str(), done, total,
                 pace(done, total).c_str());  // not logged
    std::fflush(stderr);
    return;
  }
  constexpr int kWidth = 40;
  const int filled = static_cast<int>(kWidth * done / total);
  std::fprintf(stderr, "\r%-13s [%s%s] %zu/%zu%-24s", phase.c_str(), std::string(filled, '#').c_str(),
               std::string(kWidth - filled, '.').c_str(), done, total, pace(done, total).c_str());
  std::fflush(stderr);
  drawn_ = true;
}

namespace {

void print_errors(const char* label, const PoseErrors& e, double unit_per_cm, const char* unit) {
  say(stdout, "  %-10s mean %.3f %s (%.3f%% of %.1f %s driven), max %.3f %s, mean rotation %.3f deg\n", label,
              e.mean_translation_cm * unit_per_cm, unit,
              e.path_length_cm > 0 ? 100.0 * e.mean_translation_cm / e.path_length_cm : 0.0,
              e.path_length_cm * unit_per_cm, unit, e.max_translation_cm * unit_per_cm, unit, e.mean_rotation_deg);
}

}  // namespace

void print_truth(const MapRun& run) {
  if (!run.truth) return;
  const double unit_per_cm = 1.0 / centimetres_per(run.survey.unit);
  say(stdout, "pose error against the reference poses (relative to the first scan):\n");
  // A survey without odometry (KITTI, PLY, PCD without --initial-poses) starts every scan at the
  // identity: the first row is then the error of those starts, not of an odometry.
  bool identity_starts = true;
  for (const ScanOutcome& scan : run.result.scans) identity_starts = identity_starts && scan.initial_pose_cm.isIdentity();
  print_errors(identity_starts ? "start" : "odometry", run.truth->odometry, unit_per_cm, to_string(run.survey.unit));
  if (identity_starts) say(stdout, "  (start: every scan at the identity, the survey has no odometry)\n");
  print_errors("registered", run.truth->registered, unit_per_cm, to_string(run.survey.unit));
}

void print_survey(const MapOptions& options, const MapRun& run) {
  const io::Survey& survey = run.survey;
  say(stdout, "read %zu %s scans from %s in %.2f s (unit %s)\n", survey.scans.size(), survey.format.c_str(),
              options.survey.c_str(), run.load_s, to_string(survey.unit));
  for (const auto& warning : survey.warnings) say(stderr, "minemap: warning: %s\n", warning.c_str());
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
  say(stdout, "scan order: %s\n", order.c_str());
  if (survey.scans.size() == 1) {
    say(stdout, "note: a survey of one scan: nothing to register; the map is %s at its initial pose\n",
                survey.scans.front().name.c_str());
  }
  say(stdout, "backend: %s\n", run.backend.message.c_str());
}

void print_loops(const MapOptions& options, const MappingResult& result) {
  // A candidate not matched is normal when another scan of the same loop closed it (a scan in a
  // cross-cut sees little of the start); only a survey whose candidates all failed is told so.
  const bool any_closed =
      std::any_of(result.loops.begin(), result.loops.end(), [](const LoopClosure& loop) { return loop.closed; });
  // A return tries every scan near the start, closest first: the first few say why, the rest count.
  constexpr std::size_t kUnclosedShown = 3;
  std::size_t unclosed = 0;
  for (const LoopClosure& loop : result.loops) {
    const std::string& from = result.scans[loop.from].name;
    const std::string& to = result.scans[loop.to].name;
    if (loop.closed && !options.quiet) {
      say(stdout,
          "loop closed: %s with %s: %.1f cm / %.2f deg apart before the relaxation (%.2f %% of %.1f m driven: "
          "%.0f ppm, %.1f mm a scan), %.1f cm / %.2f deg after\n",
          to.c_str(), from.c_str(), loop.gap_before_cm, loop.gap_before_deg,
          100.0 * loop.misclosure_fraction(), loop.path_cm / 100.0, loop.misclosure_ppm(),
          10.0 * loop.gap_per_scan_cm(), loop.gap_after_cm, loop.gap_after_deg);
    } else if (!loop.closed && !any_closed && ++unclosed <= kUnclosedShown) {
      std::fprintf(stderr,
                   "minemap: loop not closed: %s stands near %s, but no match of the two was trusted (%s): the "
                   "drift over the loop stays in the map\n",
                   to.c_str(), from.c_str(), loop.doubt.c_str());
    }
  }
  if (unclosed > kUnclosedShown) {
    std::fprintf(stderr, "minemap: loop not closed: and %zu more candidates, none trusted (report.json loop_closures)\n",
                 unclosed - kUnclosedShown);
  }
}

void print_control(const MapOptions& options, const MappingResult& result) {
  if (!result.control) return;
  const ControlTie& tie = *result.control;
  if (!tie.checked_for_blunders) {
    // Not silently trusted: with 3 points a wrong one is met as exactly as the right ones.
    std::fprintf(stderr,
                 "minemap: control: only %zu points: a blunder among them cannot be found (each is checked against "
                 "the map tied to 3 others: give 4 or more)\n",
                 tie.residuals.size());
  }
  if (options.quiet) return;
  say(stdout, "control: %d of %zu points tied (rms %.1f mm; the map bent up to %.1f cm beyond a rigid move)%s\n",
      tie.points_used, tie.residuals.size(), 1000.0 * tie.rms_m, tie.bent_max_cm,
      tie.epsg ? (", EPSG:" + std::to_string(*tie.epsg)).c_str() : "");
  say(stdout, "  closure on the control before the tie: %.0f ppm of %.1f m driven (the map as matched, moved rigidly)\n",
      tie.closure_ppm, tie.drive_cm / 100.0);
  say(stdout, "  %-10s %9s %9s %9s %9s %7s %12s\n", "point", "E mm", "N mm", "H mm", "3D mm", "sigmas", "before mm");
  for (const ControlResidual& r : tie.residuals) {
    say(stdout, "  %-10s %+9.1f %+9.1f %+9.1f %9.1f %7.2f %12.1f%s\n", r.point.c_str(), 1000.0 * r.residual_m.x(),
        1000.0 * r.residual_m.y(), 1000.0 * r.residual_m.z(), 1000.0 * r.residual_m.norm(), r.sigmas,
        1000.0 * r.before_m.norm(), r.blunder ? "  blunder: left out" : "");
  }
  double largest_cm = 0.0;
  std::size_t largest = 0;
  for (std::size_t i = 0; i < result.scans.size(); ++i) {
    const double axis = scan_sigma(result.scans[i]).axes_cm.x();
    if (axis > largest_cm) {
      largest_cm = axis;
      largest = i;
    }
  }
  if (!result.scans.empty()) {
    say(stdout, "  scan sigma: largest %.1f cm (%s); report.json scans[].sigma\n", largest_cm,
        result.scans[largest].name.c_str());
  }
}

void print_summary(const MappingResult& result) {
  std::size_t trusted = 0, retried = 0, recovered = 0, doubtful = 0, failed = 0;
  std::vector<std::pair<double, std::size_t>> rms;
  for (std::size_t i = 1; i < result.scans.size(); ++i) {  // scan 0 is the master: never matched
    const ScanOutcome& s = result.scans[i];
    if (!s.registered) {
      ++failed;
      continue;
    }
    if (s.health.doubtful()) ++doubtful;
    else ++trusted;
    if (s.health.retry_bound_cm > 0.0f) ++retried;
    if (s.health.recovered_inliers > 0) ++recovered;
    rms.emplace_back(s.last_match.rms_cm, i);
  }
  say(stdout, "summary: %zu scans: %zu trusted (%zu after a retry at a wider bound", result.scans.size(), trusted, retried);
  if (recovered > 0) say(stdout, ", %zu recovered without a start", recovered);
  say(stdout, "), %zu doubtful, %zu not registered", doubtful, failed);
  if (!rms.empty()) {
    std::sort(rms.begin(), rms.end());
    const auto& worst = rms.back();
    say(stdout, "; rms median %.2f cm, worst %.2f cm (%s)", rms[rms.size() / 2].first, worst.first,
        result.scans[worst.second].name.c_str());
  }
  std::size_t closed = 0;
  for (const LoopClosure& loop : result.loops) closed += loop.closed ? 1 : 0;
  if (!result.loops.empty()) say(stdout, "; loops: %zu of %zu candidates closed", closed, result.loops.size());
  say(stdout, "\n");
}

Verdict judge_run(const MappingResult& result, const std::vector<std::string>& sources) {
  Verdict verdict;
  for (std::size_t i = 0; i < result.scans.size(); ++i) {
    const ScanOutcome& s = result.scans[i];
    if (s.registered) continue;
    verdict.all_registered = false;
    say(stderr, "minemap: %s: scan %s not registered: %s\n", sources[i].c_str(), s.name.c_str(),
                 s.failure.c_str());
  }
  std::size_t too_few_pairs = 0;
  for (const ScanOutcome& s : result.scans) too_few_pairs += !s.registered && s.failure.rfind("too few pairs", 0) == 0;
  if (too_few_pairs > 0) {
    // Each names its pairs; what to change is the same for all, so it is said once.
    say(stderr,
        "minemap: %zu scan(s) found too few pairs: the scans may not start within --max-pair-dist-cm of their "
        "place (give --initial-poses), their unit may be wrong (--unit), or they are small: "
        "--min-overlap-pairs sets how many pairs a match needs (default %d)\n",
        too_few_pairs, MappingSettings{}.min_overlap_pairs);
  }
  verdict.doubtful = result.doubtful();
  for (const std::size_t i : verdict.doubtful) {
    say(stderr, "minemap: %s: scan %s registered, but doubtful: %s\n", sources[i].c_str(),
                 result.scans[i].name.c_str(), result.scans[i].health.doubt.c_str());
  }
  return verdict;
}

bool write_despite(const Verdict& verdict, const MapOptions& options) {
  // A scan that could not be registered (no overlap, too few pairs) makes the map untrustworthy:
  // by default nothing is written and the output folder stays as it was, as for bad input.
  // --write-unregistered writes the outputs anyway, the scan at its odometry pose, for inspection.
  if (verdict.all_registered || options.write_unregistered) return true;
  std::fprintf(stderr,
               "minemap: nothing was written to %s; --write-unregistered writes the map with these scans at their "
               "odometry poses (report.json marks them)\n",
               options.out.c_str());
  return false;
}

int exit_code_of(const Verdict& verdict, const MapOptions& options, std::size_t scans) {
  if (!verdict.all_registered) return static_cast<int>(ExitCode::kRegistrationFailed);
  if (verdict.doubtful.empty()) return static_cast<int>(ExitCode::kOk);
  std::fprintf(stderr,
               "minemap: %zu of %zu scans doubtful (report.json: doubtful_scans); the map in %s may be wrong there%s\n",
               verdict.doubtful.size(), scans, options.out.c_str(),
               options.accept_doubtful ? " (accepted: --accept-doubtful)" : "; --accept-doubtful exits 0 anyway");
  return static_cast<int>(options.accept_doubtful ? ExitCode::kOk : ExitCode::kDoubtfulMap);
}

std::vector<std::string> sources_of(const io::Survey& survey) {
  std::vector<std::string> sources;
  for (const Scan& scan : survey.scans) sources.push_back(scan.source_path);
  return sources;
}

}  // namespace minemap::cli
