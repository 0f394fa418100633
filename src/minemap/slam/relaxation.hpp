#pragma once
// Internal (not installed). The paper's simultaneous matching, section IV.B step 3: a queue of scans;
// the front scan (unless it is the master, scan 0, which is fixed) is matched against the union of
// the scans overlapping it (overlap: more than min_overlap_pairs pairs), and if that moved it, each
// neighbour not in the queue is appended. Neighbour candidates are prefiltered by world bounds, so
// finding them costs one pairing pass per nearby scan, not an ICP run per scan pair. The queue
// outlives each new scan: after scan i at most a budget of matches is made, the new scan first, and
// what is left waits for the next scan (MappingSettings::max_relaxation_*), so the cost per scan
// stays flat.
//
// Thread-safety: uses the backend, one thread at a time.
#include <deque>
#include <vector>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/slam/local_map.hpp"
#include "minemap/slam/run_control.hpp"
#include "minemap/slam/scan_registration.hpp"
#include "minemap/slam/survey_state.hpp"

namespace minemap::detail {

class Relaxation {
 public:
  Relaxation(const MappingSettings& settings, ComputeBackend& backend, const ScanRegistration& registration,
             const LocalMap& local_map)
      : settings_(settings),
        backend_(backend),
        registration_(registration),
        local_map_(local_map),
        icp_(settings.relaxation_icp()) {}

  /// Step 2: scan i (the newest) goes to the front of the queue.
  void queue_first(std::size_t i);
  /// Step 3 after scan `newest` arrived, over scans 0..newest: at most `budget` matches (fewer when
  /// the queue empties or `control` asks to stop). Each match places its scan in `state`.
  struct Tally {
    int matches = 0;
    int iterations = 0;  ///< Table I's step 3
  };
  Tally relax(SurveyState& state, std::size_t newest, int budget, const RunControl& control);

  bool empty() const { return queue_.empty(); }
  /// The scans waiting, front first (what a resume needs).
  std::vector<std::size_t> queue() const { return {queue_.begin(), queue_.end()}; }
  /// A resume: the queue as an earlier run left it. Throws std::invalid_argument for a scan at or
  /// beyond `scans`.
  void restore_queue(const std::vector<std::size_t>& queue, std::size_t scans);

 private:
  /// The scans overlapping `current` among 0..newest, nearest first, at most max_relaxation_neighbours.
  std::vector<std::size_t> neighbours(const SurveyState& state, std::size_t current, std::size_t newest) const;

  const MappingSettings& settings_;
  ComputeBackend& backend_;
  const ScanRegistration& registration_;
  const LocalMap& local_map_;
  IcpSettings icp_;                ///< MappingSettings::relaxation_icp()
  std::deque<std::size_t> queue_;  ///< scans waiting for a relaxation match
  std::vector<bool> queued_;       ///< queued_[j]: scan j is in queue_
};

}  // namespace minemap::detail
