#pragma once
// Internal (not installed). Closing loops after the last scan (MappingSettings::loops; pairwise and
// incremental matching), as 3DTK's LUM does:
//  1. find returns by position: for each scan the nearest scan at least min_scan_gap earlier and
//     min_path_cm of drive back, when near enough; scans in a row that all have one are one return
//     (cut every loops.max_return_path_cm of drive);
//  2. match each return's closest pair, coarse to fine (ScanRegistration::match_from_wide_bound),
//     the next closest when a match is not trusted; a trusted match carries its scan and all after
//     it to where it found the scan before the next return is looked for (a patrol's later laps
//     drift metres from its first);
//  3. one pose graph: the chain of scan-to-scan steps as matched plus the trusted loop edges, each
//     weighted by its match's geometry (point-to-plane information, registration/match_information.hpp);
//  4. apply the relaxed poses, and judge every scan again where it ended, against the whole map
//     near it; a loop that closed more than loops.max_misclosure_fraction of its drive apart makes
//     its later scan doubtful, and so does a return where loop matches converged but none was
//     trusted (the drift stays in the map: "never silently wrong").
//
// Thread-safety: uses the backend, one thread at a time.
#include <optional>
#include <string>
#include <vector>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/slam/local_map.hpp"
#include "minemap/slam/pose_graph.hpp"
#include "minemap/slam/run_control.hpp"
#include "minemap/slam/scan_registration.hpp"
#include "minemap/slam/survey_state.hpp"

namespace minemap::detail {

class LoopClosing {
 public:
  LoopClosing(const MappingSettings& settings, ComputeBackend& backend, const ScanRegistration& registration,
              const LocalMap& local_map)
      : settings_(settings), backend_(backend), registration_(registration), local_map_(local_map) {}

  /// Every loop candidate tried (closed or not); the scans it moved are placed in `state`. A stop
  /// request ends it early with what it tried by then. Its parts' times go to control.times()
  /// (StageTimes::loop_matches_s ...). `graph` (when given) receives the pose graph
  /// the relaxation solved, the chain as matched and the loops' edges; empty when no loop closed.
  std::vector<LoopClosure> close(SurveyState& state, RunControl& control,
                                 std::vector<PoseGraphEdge>* graph = nullptr) const;
  /// The chain of scan-to-scan steps as the scans stand, each with its match's information: the
  /// pose graph's first edges (and the whole graph of a survey with no loop). `control`: where its
  /// progress goes ("pose graph").
  std::vector<PoseGraphEdge> chain(SurveyState& state, const RunControl& control) const;
  /// Step 2's carry after a closed loop: moves `guess[to]` and every later guess rigidly, so that
  /// `to` stands at `from_to` from `from`. The move is a rigid motion however many loops came before
  /// (its rotation part orthonormalised). Guesses only: the scans' poses move in the relaxation.
  static void carry(std::vector<Pose>& guess, std::size_t from, std::size_t to, const Pose& from_to);

 private:
  struct Candidate {
    std::size_t from, to;
    double distance_cm;
  };
  /// A return to a known place: its candidates closest first; the next is looked for from `end` on.
  struct Return {
    std::vector<Candidate> candidates;
    std::size_t end = 0;
  };
  /// Step 1: the next return at or after scan `first`, by the positions of `guess` (the chain as
  /// the loops closed so far moved it); `driven`: the chain's drive to each scan (cm).
  Return next_return(const SurveyState& state, const std::vector<Pose>& guess, const std::vector<double>& driven,
                     std::size_t first) const;
  /// Step 2: a trusted match of scan j against scan i alone, from `start` (j's pose in the state's
  /// frame), at each bound of loops.bound_factors in turn. A narrow-field timed sweep is matched
  /// against i's visit instead: the sweeps within loops.visit_sweeps of i, nearest first, as one
  /// local map (LocalMap::union_of, thinned as the metascan is) cropped to j's reach at the widest
  /// bound. Empty when none is trusted; `doubt` then
  /// says why. `converged`: some bound's match converged and was judged doubtful (not: no overlap).
  std::optional<Pose> loop_match(const SurveyState& state, std::size_t i, std::size_t j, const Pose& start,
                                 std::string& doubt, bool& converged) const;
  /// A loop match of a return whose scans an earlier loop moved (`start`: where that put `loop.to`):
  /// kept only when it moves the scan at most loops.max_misclosure_fraction of the loop's drive from
  /// there. Such a start has been measured already, so a match far from it is a look-alike place or
  /// a wrong start, and one carried edge would take every later lap with it; otherwise empty, with
  /// `loop.doubt` saying so and `converged` set.
  std::optional<Pose> agreeing(const Pose& matched, const Pose& start, LoopClosure& loop, bool& converged) const;
  /// A loop match that turns `loop.to` more than loops.max_turn_deg_per_100m (per 100 m of the
  /// loop's drive) from `start` (where the chain, or the loops closed before when `carried`, put it):
  /// empty, with `loop.doubt` saying so and `converged` set; else `matched`. No drift turns a map
  /// that fast; a corridor seen the other way fits as well as the right place.
  std::optional<Pose> within_turn(const Pose& matched, const Pose& start, bool carried, LoopClosure& loop,
                                  bool& converged) const;
  /// A return none of whose candidates closed, where a match converged but was not trusted: the
  /// map's drift over the loop stays, unmeasured; the return's scan is judged doubtful.
  void doubt_unclosed_return(SurveyState& state, const LoopClosure& loop) const;
  /// The information of the edge `from` -> `to` (`to` at `to_pose`), from the geometry of their pairs.
  Matrix6d edge_information(const SurveyState& state, std::size_t from, std::size_t to, const Pose& to_pose) const;
  /// Whether edge information comes from geometry for an edge ending at scan k (its planes exist).
  bool geometric(const SurveyState& state, std::size_t k) const;
  /// A closed loop whose gap before the relaxation was more than loops.max_misclosure_fraction of
  /// its drive: its later scan is judged doubtful (the run then says so, exit 13).
  void doubt_misclosure(SurveyState& state, const LoopClosure& loop) const;
  /// Step 4's judging of every matched scan at its final pose against the whole map near it.
  void judge_again(SurveyState& state, const RunControl& control) const;

  const MappingSettings& settings_;
  ComputeBackend& backend_;
  const ScanRegistration& registration_;
  const LocalMap& local_map_;
};

}  // namespace minemap::detail
