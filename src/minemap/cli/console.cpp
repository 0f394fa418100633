#include "minemap/cli/console.hpp"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

#include "minemap/cli/exit_codes.hpp"

namespace minemap::cli {

ProgressBar::ProgressBar(bool enabled) : enabled_(enabled), terminal_(::isatty(STDERR_FILENO) != 0) {}

ProgressBar::~ProgressBar() {
  if (enabled_ && drawn_) std::fputs("\n", stderr);
}

void ProgressBar::operator()(std::size_t done, std::size_t total, const std::string& phase) {
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

namespace {

void print_errors(const char* label, const PoseErrors& e, double unit_per_cm, const char* unit) {
  std::printf("  %-10s mean %.3f %s (%.3f%% of %.1f %s driven), max %.3f %s, mean rotation %.3f deg\n", label,
              e.mean_translation_cm * unit_per_cm, unit,
              e.path_length_cm > 0 ? 100.0 * e.mean_translation_cm / e.path_length_cm : 0.0,
              e.path_length_cm * unit_per_cm, unit, e.max_translation_cm * unit_per_cm, unit, e.mean_rotation_deg);
}

}  // namespace

void print_truth(const MapRun& run) {
  if (!run.truth) return;
  const double unit_per_cm = 1.0 / centimetres_per(run.survey.unit);
  std::printf("pose error against the reference poses (relative to the first scan):\n");
  print_errors("odometry", run.truth->odometry, unit_per_cm, to_string(run.survey.unit));
  print_errors("registered", run.truth->registered, unit_per_cm, to_string(run.survey.unit));
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

void print_loops(const MapOptions& options, const MappingResult& result) {
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
}

Verdict judge_run(const MappingResult& result, const std::vector<std::string>& sources) {
  Verdict verdict;
  for (std::size_t i = 0; i < result.scans.size(); ++i) {
    const ScanOutcome& s = result.scans[i];
    if (s.registered) continue;
    verdict.all_registered = false;
    std::fprintf(stderr, "minemap: %s: scan %s not registered: %s\n", sources[i].c_str(), s.name.c_str(),
                 s.failure.c_str());
  }
  verdict.doubtful = result.doubtful();
  for (const std::size_t i : verdict.doubtful) {
    std::fprintf(stderr, "minemap: %s: scan %s registered, but doubtful: %s\n", sources[i].c_str(),
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
