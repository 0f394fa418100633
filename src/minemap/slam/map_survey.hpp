#pragma once
// Matching many scans (paper, section IV.B): map_survey registers a whole survey, LiveMapper the
// same survey scan by scan as it arrives (`minemap watch`). Both run one matcher
// (slam/survey_matcher.hpp), so scans added in order and finished give map_survey's result bit for
// bit.
//  * pairwise: scan i against scan i-1, from odometry corrected by scan i-1's correction.
//  * incremental (minemap's default): scan i against the metascan, one kd-tree of the registered
//    scans near it (cropped to what scan i can reach), as 3DTK's slam6D `--metascan` does; then
//    loops closed by a pose graph.
//  * simultaneous, the paper's queue-based global relaxation: a new scan is matched pairwise, then
//    a queue starts with it and each scan taken from the queue is matched against the union of the
//    scans overlapping it, re-queueing its neighbours when it moved (slam/relaxation.hpp).
//
// The search, the sums and the slice filter run in the compute backend the caller hands in
// (backend/compute_backend.hpp); the voxel reduction, Horn's method and the schedule on the host.
#include <filesystem>
#include <memory>
#include <vector>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/core/scan.hpp"
#include "minemap/slam/mapping_result.hpp"
#include "minemap/slam/mapping_settings.hpp"
#include "minemap/slam/progress.hpp"

namespace minemap {

/// Registers `scans` (pose_cm = odometry / initial guess; scan 0 is the master and stays fixed) on
/// `backend`. Throws std::invalid_argument on an empty survey or invalid settings. Registration
/// failures do not throw: the scan keeps its odometry-based pose, `registered` is false and
/// `failure` says why. A BackendError (a device fault) makes it match the whole survey again on a
/// fresh CPU backend, saying so in `notes`: the poses are then the CPU run's.
MappingResult map_survey(const std::vector<Scan>& scans, const MappingSettings& settings, ComputeBackend& backend,
                         const ProgressCallback& progress = {}, const StopRequested& stop_requested = {});

/// map_survey, letting the scans' points go: each scan's points and attributes are freed as soon as
/// it is prepared (a moving sensor's sweep once it is matched), so a survey's raw points are not held
/// beside its reduced clouds while it is matched; names, sources and poses stay. The same result.
/// On a backend other than the CPU the points are kept: a device failure matches everything again
/// on the CPU, from them.
MappingResult map_survey_releasing_points(std::vector<Scan>& scans, const MappingSettings& settings,
                                          ComputeBackend& backend, const ProgressCallback& progress = {},
                                          const StopRequested& stop_requested = {});

namespace detail {
class SurveyMatcher;
}

/// What a PartwiseMapper holds of a long survey (docs/scaling.md): the prepared clouds of the scans
/// used least recently are written to a spill file and read back when a scan is needed again (a
/// metascan near a return, a loop, the map's points), so memory follows the bound, not the survey.
/// The result is the same with any bound.
struct MemoryBound {
  /// What `minemap map` holds: about 1 200 simulated scans' clouds while they are only matched (0.3 MB
  /// each; a loop's trees make them bigger), so a straight survey of a thousand scans is never
  /// spilled, and 10 000 scans, or a thousand passing one place ten times, stay under 1.5 GB
  /// (docs/scaling.md).
  static constexpr std::size_t kSuggestedHeldCloudsMb = 384;
  /// Prepared clouds held at most (estimated: points, their kd-trees, planes), MB; 0: all held.
  std::size_t held_clouds_mb = 0;
  /// The folder the spill file is made in (it must exist; the file is unlinked at once: nothing stays
  /// there): the output folder, or the nearest one above it.
  std::filesystem::path spill_folder;
};

/// map_survey fed a part at a time, as io::read_survey_in_parts reads a survey: each part is
/// prepared and matched as it arrives, and its scans' points are freed once prepared (a moving
/// sensor's sweep once matched), so a survey's raw points are never all held (docs/scaling.md). The
/// same result as map_survey: the matcher's scan i depends only on scans 0..i (LiveMapper's
/// guarantee). For the CPU backend: a device's failure (BackendError) is thrown, not matched again
/// on the CPU (the points it would need are gone). Thread-safety: one thread at a time.
class PartwiseMapper {
 public:
  /// Throws std::invalid_argument for a memory bound on a backend other than the CPU (a device's
  /// clouds live on it), or without a spill folder.
  PartwiseMapper(const MappingSettings& settings, ComputeBackend& backend, const ProgressCallback& progress = {},
                 const StopRequested& stop_requested = {}, const MemoryBound& bound = {});
  ~PartwiseMapper();
  /// The next part (the survey has `total` scans). false: a stop was requested; add no more.
  bool add(std::vector<Scan>& part, std::size_t total);
  /// After the last part: loops and the rest of the relaxation (unless stopped); the result.
  MappingResult finish();

 private:
  MappingSettings settings_;  // the matcher refers to it
  std::unique_ptr<detail::SurveyMatcher> matcher_;
  bool stopped_ = false;
};

/// The many-scan matcher fed scan by scan, as scans arrive (`minemap watch`). add() prepares a scan
/// and matches it as map_survey matches the i-th scan (its mode's match, and for kSimultaneous the
/// relaxation's per-scan budget); finish() does what map_survey does after the last scan (the rest of
/// the relaxation queue, loop closing). Adding a survey's scans in order and finishing gives
/// map_survey's result bit for bit (times aside): the live run is the offline run. result() between
/// scans is the map so far (not finished: the relaxation's leftovers and loops wait for finish()).
/// `stop_requested` is asked between relaxation matches, as map_survey asks it; a stop there leaves
/// the queue for the next scan, which the offline run would not have done.
/// Thread-safety: one thread at a time. A BackendError propagates: start again on a CpuBackend (as
/// map_survey does) by adding the scans again.
class LiveMapper {
 public:
  LiveMapper(const MappingSettings& settings, ComputeBackend& backend, StopRequested stop_requested = {});
  ~LiveMapper();
  LiveMapper(const LiveMapper&) = delete;
  LiveMapper& operator=(const LiveMapper&) = delete;

  void add(const Scan& scan);
  /// Resuming: a scan an earlier run matched, prepared but not matched again; `outcome` is what that
  /// run left for it (pose, frames, match, health). Restore scans in order, then restore_queue()
  /// and restore_counters().
  void restore(const Scan& scan, const ScanOutcome& outcome);
  /// kSimultaneous: the scans waiting for a relaxation match, front first (what a resume needs).
  std::vector<std::size_t> queue() const;
  /// Throws std::invalid_argument for a scan not restored.
  void restore_queue(const std::vector<std::size_t>& queue);
  /// The earlier run's counters: ICP iterations, relaxation matches, notes, stage times.
  void restore_counters(const MappingResult& saved);
  /// The run so far, as a value.
  MappingResult result() const;
  /// Scan i's outcome so far (i < size()).
  const ScanOutcome& scan(std::size_t i) const;
  void finish();
  std::size_t size() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace minemap
