#pragma once
// Internal (not installed). The metascan: one kd-tree over the points of the registered scans near
// a scan, as the paper (and slam6D's --metascan) match against. One tree answers each query once,
// where searching every neighbour's own tree in turn costs a search per overlapping scan. It holds
// only the model points the scan can reach (inside its box grown by a margin: in a tunnel the
// nearby scans hold about ten times the points that lie there, docs/benchmarks.md), expressed in a
// frame near the scan so its float coordinates stay small wherever the survey is. The relaxation's
// union of neighbours (paper, IV.B step 3) is built by the same code. The judging after the loops,
// one pass over a quarter of a scan's points, does not pay back such a build: it searches trees
// kept from one judged scan to the next (JudgingClouds below; slam/loop_closing.cpp).
//
// Thread-safety: uses the backend, one thread at a time; assembles in parallel, deterministically.
#include <memory>
#include <unordered_map>
#include <vector>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/slam/mapping_settings.hpp"
#include "minemap/slam/survey_state.hpp"

namespace minemap::detail {

/// The points of `parts`, in order, one after the other.
std::vector<Eigen::Vector3f> concatenated(const std::vector<std::vector<Eigen::Vector3f>>& parts);

/// The points of `parts`, in order, keeping only the first point in each cube of `cell_cm` (cubes
/// [k c, (k+1) c) on each axis): a moving sensor's local map (MotionSettings::local_map_cell_cm),
/// where the parts are the nearest scan's first. Cells are told apart within 2^20 cells of the
/// origin on each axis (105 km at 10 cm); a metascan sits in the previous scan's frame, near it.
/// Parallel (keys per part, then cells dealt to shards by hash, each shard walking the points in
/// order): the same points, in the same order, for any thread count.
std::vector<Eigen::Vector3f> first_point_per_cell(const std::vector<std::vector<Eigen::Vector3f>>& parts,
                                                  double cell_cm);

/// Of the scans `near` scan i (in the order given), those of at most `most` visits to its place
/// (0: all). A visit is a run of the scans `at_place` (those of `near` standing at i's place) whose
/// indices lie within `gap` of the next: the drive passing there once (i belongs to the run it
/// falls in); every scan of `near` belongs to the visit nearest it in the drive (the earlier of two
/// alike), so a visit keeps what the drive saw of the place from afar too. Kept first: i's own
/// visit, then the earliest, then the others nearest to i in the drive. A place passed at most
/// `most` times keeps every scan; one passed lap after lap keeps whole laps, not the same few metres
/// of each (LoopClosureSettings::judge_max_visits).
std::vector<std::size_t> nearest_visits(const std::vector<std::size_t>& near, std::size_t i,
                                        const std::vector<std::size_t>& at_place, std::size_t gap, std::size_t most);

class LocalMap {
 public:
  LocalMap(const MappingSettings& settings, ComputeBackend& backend) : settings_(settings), backend_(backend) {}

  /// The metascan of scan i: the registered scans before it near where it stands (`standing`,
  /// SurveyState::nearby; with loops on, only the last loops.min_scan_gap, so a loop is the pose
  /// graph's to close), in the frame `frame`, holding their model points within its box at `at`
  /// grown by `grow_cm`. thin_cm > 0: at most one point in each cell of that size (the nearest
  /// scan's), as a moving sensor's local map (MotionSettings::local_map_cell_cm).
  std::shared_ptr<const PreparedCloud> metascan(const SurveyState& state, std::size_t i, const Pose& standing,
                                                const Pose& frame, const Pose& at, double grow_cm,
                                                double thin_cm = 0.0) const;

  /// The scans scan i is judged against in the finished map: those near it where it stands,
  /// earlier or later, of loops.judge_max_visits visits to its place, the nearest
  /// loops.judge_max_scans; nearest first.
  std::vector<std::size_t> judging_scans(const SurveyState& state, std::size_t i, const Pose& standing) const;

  /// One kd-tree, in the frame `frame`, of the model points of scans `near` that scan i can reach
  /// at `at`: inside its box grown by `grow_cm`. Concatenated in the order of `near`; thin_cm > 0
  /// keeps the first point of each cell of that size in that order.
  std::shared_ptr<const PreparedCloud> union_of(const SurveyState& state, std::size_t i,
                                                const std::vector<std::size_t>& near, const Pose& frame,
                                                const Pose& at, double grow_cm, double thin_cm = 0.0) const;

  /// One kd-tree, in the frame `frame`, of all the model points of `scans` (where they stand),
  /// concatenated in the order given: none cropped, none thinned. `starts`, when given, gets where
  /// each scan's points begin in the union (their original indices), and the union's size last.
  std::shared_ptr<const PreparedCloud> whole_union(const SurveyState& state, const std::vector<std::size_t>& scans,
                                                   const Pose& frame,
                                                   std::vector<std::int32_t>* starts = nullptr) const;

 private:
  const MappingSettings& settings_;
  ComputeBackend& backend_;

  friend class JudgingClouds;
};

/// The model clouds the judging after the loops searches, each with a kd-tree of its own, built
/// the first time a judged scan needs it and let go of once the scans judged since have not needed
/// it: a block's (kBlockScans scans in a row standing at one place) in its first scan's frame, or a
/// scan's model points in its own frame. A block is searched as one tree whenever those of its
/// scans that are not among a judged scan's neighbours form one run (the judged scan itself, or the
/// block's first or last few): that run's points are left out of the search (SkippedPoints), so
/// each probe point's nearest model point is the one among the neighbours' points, as one tree over
/// the neighbours' union would find it (to the last bits of a float: each distance is taken in its
/// tree's frame), without the union's crop to the scan's box grown by the pair bound
/// (docs/scaling.md, "Loops at scale"). The judge reads distances only.
///
/// Thread-safety: one thread. The scans must not move while it lives (one per judging pass): the
/// clouds and whether a block stands at one place are kept as first found.
class JudgingClouds {
 public:
  /// How many scans in a row (indices kBlockScans b ... kBlockScans b + kBlockScans - 1, the
  /// survey's last block fewer) one block tree holds. A dense sequence (hand-held keyframes, sweeps
  /// half a second apart) judges each scan against hundreds of neighbours, each probe point
  /// searched in every tree; they come in runs of the drive, so most of them fill whole blocks, one
  /// search each (64 against 16: 5 trees a judged scan against 20, docs/benchmarks.md, "The
  /// judging after the loops, in blocks of 64").
  static constexpr std::size_t kBlockScans = 64;
  /// Only blocks whose scans stand at one place: their drive no longer than loops.max_distance_cm
  /// (a loop candidate's distance) for each kOnePlaceScans of them, a mean step of 62.5 cm at the
  /// default 10 m. Stop-and-go scans metres apart see different stretches of the mine, each scan's
  /// own box leaves out more of the search than a block's, and the block's tree is one more to
  /// build (docs/benchmarks.md, "The judging after the loops, in blocks").
  static constexpr std::size_t kOnePlaceScans = 16;
  /// How many judged scans a cloud outlives its last use by: a scan comes back into reach after a
  /// few at most, and then its tree is not built again.
  static constexpr std::size_t kKeptFor = 8;

  explicit JudgingClouds(const LocalMap& local_map) : local_map_(local_map) {}

  /// The clouds scan `judged` is judged against, `near` its neighbours (LocalMap::judging_scans,
  /// without `judged`): one per block searched whole (above, with the points it leaves out), one
  /// per other scan of `near`; in the order of `near` (a block where the first of its scans
  /// stands), each with the world pose of its frame.
  std::vector<WorldModel> models(const SurveyState& state, const std::vector<std::size_t>& near, std::size_t judged);
  /// Lets go of the clouds none of the last kKeptFor judged scans used (a block's: kKeptFor + kBlockScans).
  void forget_unused(std::size_t judged);
  /// How many trees are held (the test of the blocks).
  std::size_t held() const { return scans_.size() + blocks_.size(); }

 private:
  struct Held {
    std::shared_ptr<const PreparedCloud> cloud;
    std::size_t last_used = 0;
    std::vector<std::int32_t> starts;  ///< a block's: where each scan's points begin, and its size
  };
  const PreparedCloud* scan(const SurveyState& state, std::size_t j, std::size_t judged);
  const Held& block(const SurveyState& state, std::size_t b, std::size_t judged);
  /// Whether block b's scans stand at one place (kBlockScans), as they stand now.
  bool at_one_place(const SurveyState& state, std::size_t b);
  /// How many scans block b holds: kBlockScans, or fewer for the survey's last block.
  static std::size_t block_size(const SurveyState& state, std::size_t b);

  const LocalMap& local_map_;
  std::unordered_map<std::size_t, Held> scans_;
  std::unordered_map<std::size_t, Held> blocks_;
  std::unordered_map<std::size_t, bool> one_place_;
};

}  // namespace minemap::detail
