#pragma once
// Whether a registration can be trusted. ICP always ends somewhere: started outside its pair
// bound's reach, it settles in a wrong minimum with a small residual (a car LiDAR pair 0.86 m apart
// matched at 25 cm "found" 6.6 cm of motion). The residual alone cannot tell, so a match is judged
// by where the data's closest model points lie at the final pose, searched out to a wider bound:
//  * paired fraction: data points with a model point within the pair bound. Low: little overlap.
//  * beyond-bound fraction: of the data points with a model point within wide_factor x the bound,
//    those whose closest one lies beyond the bound. Right, the surfaces coincide and such points
//    are only where one scan sees what the other does not; stuck short of the right pose, the
//    surfaces sit apart and many counterparts lie just beyond the bound.
//  * edge fraction: of the pairs within the bound, those in its outer half. Right, pair distances
//    crowd near zero (sensor noise); wrong, they spread across the whole bound.
//  * reach: how far the match moved the paired data points (RMS, start to end) in multiples of
//    the bound. ICP finds what lies within its bound's reach; a scan moved much farther started out
//    of reach, and a bound wide enough to let it (metres) also pairs a street's ground with any
//    shifted copy of itself: the figures above then look fine while the pose is metres off.
//  * constraint (when the data's planes are given): of the point-to-plane information of the pairs
//    (registration/match_information.hpp), the weakest translation over the strongest. Near zero,
//    the surfaces cannot fix one direction: in a smooth tunnel a match may slide along it, and the
//    figures above cannot tell, since the slid surfaces coincide.
// The thresholds are in HealthSettings; docs/benchmarks.md has the figures they come from
// (simulated surveys, the real LiDAR in ../shared/data, right and deliberately wrong starts).
//
// Thread-safety: judge_registration uses the backend (one thread at a time, as every backend call).
#include <span>
#include <string>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/core/pose.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/registration/match_information.hpp"

namespace minemap {

/// When a match is doubtful. One source of truth for the thresholds; a plain value.
struct HealthSettings {
  bool enabled = true;
  float wide_factor = 4.0f;                 ///< the wide search bound, in multiples of the pair bound
  /// Mapping judges every n-th data point (the wide search costs several ICP iterations per point).
  int probe_stride = 4;
  double min_paired_fraction = 0.10;        ///< fewer data points paired: the scans hardly overlap
  double max_beyond_bound_fraction = 0.35;  ///< more counterparts just beyond the bound: surfaces apart
  /// More pairs in the bound's outer half: not settled onto a surface. Loose, because a model seen
  /// from far away is sampled sparsely and its right pairs lie farther apart (38% in the outer half
  /// for two simulated scans 8 m apart, within 0.3 cm of the truth).
  double max_edge_fraction = 0.5;
  double max_reach = 1.5;                   ///< data points moved farther (RMS) than this many bounds: started out of reach
  /// The weakest translation the pairs' planes pin, over the strongest, below this: degenerate (free
  /// to slide along one direction).
  double min_translation_constraint = 0.002;
  /// Throws std::invalid_argument naming the bad setting.
  void validate() const;
  bool operator==(const HealthSettings&) const = default;
};

/// Which test a doubtful match failed (the first, in the order below).
/// kUnpinnedTurn: not one match's test but the motion's (slam/sweep_matching.cpp,
/// doubt_unpinned_turn), kept when the scans are judged again after the loops.
enum class HealthTest { kNone, kReach, kPaired, kBeyondBound, kEdge, kConstraint, kUnpinnedTurn };

/// The figures of one judged match, and the verdict.
struct RegistrationHealth {
  bool judged = false;             ///< false: not judged (the master scan, an unregistered scan, or judging off)
  std::size_t data_points = 0;
  double paired_fraction = 0.0;
  double beyond_bound_fraction = 0.0;
  double edge_fraction = 0.0;
  double rms_cm = 0.0;             ///< RMS distance of the pairs within the bound
  double correction_cm = 0.0;      ///< how far the match moved the scan from where it started...
  double correction_deg = 0.0;     ///< ...and how far it turned it
  double moved_cm = 0.0;           ///< RMS distance the paired data points moved, start to end
  /// Weakest over strongest translation information of the pairs (< 0: not measured, no planes given).
  double translation_constraint = -1.0;
  Eigen::Vector3d weakest_direction = Eigen::Vector3d::Zero();  ///< in the data frame (unit; 0: not measured)
  /// Weakest over strongest rotation information (turns about the data frame's origin; < 0: not
  /// measured), and the axis of the weakest, in the data frame (unit). Not a test of the match
  /// alone: a turn the surfaces cannot pin is judged over the recent sweeps
  /// (MotionSettings::max_unpinned_turn_deg).
  double rotation_constraint = -1.0;
  Eigen::Vector3d weakest_axis = Eigen::Vector3d::Zero();
  float pair_bound_cm = 0.0f;      ///< the bound it was judged at (the match's own)
  float retry_bound_cm = 0.0f;     ///< > 0: trusted after a retry that started at this wider bound
  /// > 0: the match from the motion model's start was not trusted; this one started where a
  /// registration without a start put the scan (MappingSettings::recovery), with this many of its
  /// feature pairs agreeing. The correction and reach are from the motion model's start.
  std::size_t recovered_inliers = 0;
  std::string doubt;               ///< empty: trusted; otherwise which test failed, with its figures
  bool out_of_reach = false;       ///< the reach test failed (a good fit does not clear that doubt)
  HealthTest failed = HealthTest::kNone;  ///< the test that made it doubtful
  /// Where a doubt was cleared by more than these figures (two independent starts that ended at
  /// one pose), how: said in report.json and map.html.
  std::string note;
  /// Judged again at the pose a loop closure's relaxation gave it, against every scan near it (the
  /// fit figures are from then; the correction and reach from its match).
  bool after_loop_closure = false;
  bool doubtful() const { return judged && !doubt.empty(); }
};

/// Judges `data` at `world_from_data` (moved there from `start`) against `models`, at the pair
/// bound `icp.max_pair_dist_cm` (exact search); the reach test uses `reach_bound_cm` when > 0 (a
/// match that began at a wider bound, coarse to fine). `data_planes`: the data scan's planes in its
/// own frame, for the constraint test (nullptr: not measured).
RegistrationHealth judge_registration(ComputeBackend& backend, const PreparedCloud& data, const Pose& world_from_data,
                                      const Pose& start, std::span<const WorldModel> models, const IcpSettings& icp,
                                      const HealthSettings& settings, float reach_bound_cm = 0.0f,
                                      const SurfaceNormals* data_planes = nullptr);

}  // namespace minemap
