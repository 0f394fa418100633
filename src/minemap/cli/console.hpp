#pragma once
// Internal to the command line. What `map` and `watch` print (stdout: what happened; stderr:
// progress, warnings and what went wrong, each naming the scan's file), and the one exit policy
// both follow (a scan not registered: 4; a doubtful match: 13 unless --accept-doubtful).
//
// Thread-safety: the thread running the command.
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "minemap/cli/cli.hpp"

namespace minemap::cli {

/// Prints like std::fprintf to `stream` (stdout: what happened; stderr: what went wrong) and keeps
/// the text for OUT/minemap.log. Thread-safety: the thread running the command.
void say(std::FILE* stream, const char* format, ...) __attribute__((format(printf, 2, 3)));
/// Starts the log of a command (its words, program first).
void begin_log(const std::vector<std::string>& command_line);
/// Writes OUT/minemap.log (atomically, where OUT exists): the version, the command line and what
/// the command printed so far but its progress lines.
void write_log(const fs::path& out_dir, const char* version);

/// Progress on stderr: a one-line bar on a terminal; otherwise (a log file, a batch job) a plain
/// line per matched scan, and one when the reduction is done.
class ProgressBar {
 public:
  explicit ProgressBar(bool enabled);
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;
  /// Draws `done` of `total` in `phase`, with the pace (per second) and an ETA from the phase's start.
  /// In a log (stderr not a terminal) a line per hundredth of the phase and at least one every
  /// kLogEvery_s, always its first and last: a survey of 10 000 scans logs about 100 lines, one of
  /// 100 scans a line a scan.
  void operator()(std::size_t done, std::size_t total, const std::string& phase);
  /// Ends the bar's line (before the run's own output on stdout), if one is drawn.
  void finish();

 private:
  std::string pace(std::size_t done, std::size_t total) const;

  bool enabled_;
  bool terminal_;
  bool drawn_ = false;
  std::string phase_;
  std::size_t phase_first_done_ = 0;
  std::chrono::steady_clock::time_point phase_start_ = std::chrono::steady_clock::now();
  std::size_t logged_done_ = 0;  ///< the last line logged in this phase
  std::chrono::steady_clock::time_point logged_at_ = std::chrono::steady_clock::now();
  static constexpr double kLogEvery_s = 10.0;
};

/// The survey read (scans, order, warnings) and the backend chosen.
void print_survey(const MapOptions& options, const MapRun& run);
/// The pose errors against the reference poses, when the survey has them.
void print_truth(const MapRun& run);
/// Each loop candidate, closed or not (an unclosed one only when no loop closed).
void print_loops(const MapOptions& options, const MappingResult& result);
/// What the matches came to, in one paragraph: scans trusted, retried, doubtful and not registered,
/// the median and worst rms, the loops closed (print_loops gives their gaps).
void print_summary(const MappingResult& result);
/// A tie to control: the residual of each control point (E N H and 3D, mm), blunders named.
void print_control(const MapOptions& options, const MappingResult& result);

/// What the matches came to: the scans not registered and the doubtful ones, each named on stderr
/// with its file (`sources`, one per scan).
struct Verdict {
  bool all_registered = true;
  std::vector<std::size_t> doubtful;
};
Verdict judge_run(const MappingResult& result, const std::vector<std::string>& sources);
/// True when the outputs are written despite a scan not registered (--write-unregistered); else
/// says that nothing was written.
bool write_despite(const Verdict& verdict, const MapOptions& options);
/// The exit code of a finished run, with the closing line on the doubtful scans.
int exit_code_of(const Verdict& verdict, const MapOptions& options, std::size_t scans);

/// Each scan's file, for messages.
std::vector<std::string> sources_of(const io::Survey& survey);

}  // namespace minemap::cli
