#pragma once
// Matching many scans (paper, section IV.B): pairwise, incremental and simultaneous matching.
//  * pairwise: scan i against scan i-1, from odometry corrected by scan i-1's correction.
//  * incremental (minemap's default): scan i against the metascan, one kd-tree of the registered
//    scans near it (cropped to what scan i can reach), as 3DTK's slam6D `--metascan` does.
//  * simultaneous, the paper's queue-based global relaxation:
//    1. a new scan is matched pairwise;
//    2. a queue is initialised with the new scan;
//    3. until the queue is empty: the front scan (unless it is the master, scan 0, which is fixed)
//       is matched against the union of all scans overlapping it (overlap: more than 250 point
//       pairs); if that moved it, each neighbour not in the queue is appended.
//    The union is one kd-tree of the neighbours' points that the scan can reach (a metascan, as
//    in the incremental mode): a query searches one tree, not one per neighbour. Neighbour
//    candidates are prefiltered by world bounds, so finding them costs one pairing pass per nearby
//    scan, not an ICP run per scan pair. minemap's default bounds both the union and the matches
//    after each new scan (MappingSettings::max_relaxation_*), so the cost per scan stays flat.
//
// The search, the sums and the slice filter run in the compute backend the caller hands in
// (backend/compute_backend.hpp); the voxel reduction, Horn's method and the matching schedule run
// on the host.
#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/core/pose.hpp"
#include "minemap/core/scan.hpp"
#include "minemap/filter/slice_filter.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/registration/health.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/slam/pose_graph.hpp"

namespace minemap {

enum class MatchingMode { kPairwise, kIncremental, kSimultaneous };

/// How each scan is reduced before matching.
enum class Reduction {
  kSlices,  ///< the paper's slice filter (median, 10 cm along each slice, every third slice)
  kVoxel,   ///< the mean of each voxel_cm cell, every point (filter/voxel_filter.hpp), as slam6D's octree
};
const char* to_string(Reduction reduction);
Reduction parse_reduction(const std::string& text);  ///< "slices", "voxel"
const char* to_string(MatchingMode mode);
MatchingMode parse_matching_mode(const std::string& text);  ///< "pairwise", "incremental", "simultaneous"

/// Closing loops (pairwise and incremental matching; slam/pose_graph.hpp). After the last scan, a
/// scan that stands near one at least min_scan_gap scans earlier is matched against it; each trusted
/// match is an edge of the scan graph, with the chain of matches from scan to scan, and a global
/// relaxation of the graph spreads what the loop measured over the whole loop, as 3DTK's LUM does.
/// While matching, the metascan then holds only the last min_scan_gap scans, so a loop is closed by
/// the relaxation, not by one scan's jump where the drive meets its start.
struct LoopClosureSettings {
  bool enabled = true;
  int min_scan_gap = 12;             ///< a loop joins scans at least this many apart (48 m at 4 m steps)
  double max_distance_cm = 1000.0;   ///< candidates: scans whose positions are this close...
  /// ...with at least this much drive between them (along the scan positions): in a survey of
  /// scans half a metre apart, 12 scans back is still the same stretch of tunnel, not a loop.
  double min_path_cm = 4000.0;
  /// The pair bounds a loop match tries, coarse to fine, until one is trusted: what has drifted
  /// further than this over the loop is not closed (and said so).
  std::vector<float> bound_factors = {1.0f, 4.0f, 16.0f};
  /// Each edge's information from its match's geometry (point-to-plane, on the planes of the scan it
  /// ends at: MappingSettings::plane_cell_cm), as LUM takes its covariances from the point pairs: the
  /// relaxation then bends a step along what its match could not see (a slide along a tunnel) rather
  /// than every step alike. Off: every edge has graph's sigmas, alike in every direction.
  bool information_from_geometry = true;
  /// Every direction keeps at least this fraction of graph's information, however blind its match.
  double min_information_fraction = 0.01;
  PoseGraphSettings graph;
  void validate() const;
};

/// Everything map_survey takes. MappingSettings{} is minemap's default, the whole-survey mode: each
/// scan, reduced to 15 cm voxel means, is matched once against the metascan of the registered scans
/// near it (10 cm voxel means), with the mapping ICP (25 cm, then 7.5 cm). simultaneous() is the
/// paper's queue-based relaxation on slice-filtered scans with minemap's ICP (the default before
/// 2026-12); paper() is the paper's method as published. The figures behind each choice, and
/// against 3DTK's slam6D, are in docs/benchmarks.md.
/// Thread-safety: a plain value.
struct MappingSettings {
  MatchingMode mode = MatchingMode::kIncremental;
  bool filter_enabled = true;             ///< the slice filter (reduction kSlices, scans with slices)
  SliceFilterSettings filter;
  /// kVoxel reduces every scan, sliced or not, to voxel means (the slice filter does not apply).
  Reduction reduction = Reduction::kVoxel;
  float voxel_cm = 15.0f;                 ///< kVoxel: the data's voxel size
  /// kVoxel with dense_models: models are the voxel means at this finer size (0 or >= voxel_cm:
  /// the data clouds themselves).
  float model_voxel_cm = 10.0f;
  int unstructured_point_stride = 1;      ///< kSlices, scans without slices: keep every n-th point
  KdTreeSettings tree;
  /// Coarse-to-fine (25 cm, then 7.5 cm) and Anderson-accelerated; paper(): plain, 25 cm only.
  IcpSettings icp = mapping_icp();
  /// Models (the scans a scan is matched *against*) may be denser than the data being matched, as
  /// in KISS-ICP's double downsampling: a pair then measures the distance to the other scan's
  /// surface rather than to its sampling, which removes much of point-to-point ICP's bias on
  /// reduced data. kVoxel: models are model_voxel_cm means. kSlices: a model keeps every
  /// `model_slice_stride`-th slice, filtered otherwise as `filter` says (scans without slices:
  /// every point). Off: models are the data clouds, as in the paper.
  bool dense_models = true;
  int model_slice_stride = 1;
  /// kIncremental: the metascan keeps the model points within the new scan's box (at its predicted
  /// pose) grown by the pair bound and this: the largest correction ICP is expected to make.
  double metascan_margin_cm = 200.0;
  /// The paper: scans overlap iff more than this many pairs. ICP's own minimum (icp.termination.
  /// min_pairs) never exceeds it in mapping: a pair of scans that overlaps can be registered.
  int min_overlap_pairs = 250;
  double moved_translation_cm = 5.0;      ///< step 3c: a match "moved" the scan beyond this...
  double moved_rotation_deg = 0.25;       ///< ...or this
  /// kSimultaneous, step 3: a scan is matched against the union of at most this many scans that
  /// overlap it, the nearest first (0: every one, as the paper). Where every scan sees every other
  /// (a hall, a handheld loop) the union, and the cost of each new scan, would grow with the survey.
  int max_relaxation_neighbours = 8;
  /// kSimultaneous, step 3: matches after one new scan. What is still queued then waits for the
  /// next scan (the queue persists, the new scan goes first), and after the last scan the queue is
  /// matched until it is empty or 2 x scans matches were made: the cost per new scan stays flat as
  /// the survey grows (docs/benchmarks.md, time per scan). 0: the queue is emptied after every scan,
  /// as the paper, with at most 4 x scans so far matches.
  int max_relaxation_matches_per_scan = 8;
  /// kSimultaneous, step 3: a relaxation match starts where its scan already sits, so it is
  /// converged once a step moves less than this and turns less than relaxation_min_step_deg: still
  /// well under the 1.5 cm range noise, with about half the iterations of ICP's own 0.01 cm /
  /// 0.001 deg at the same error (docs/benchmarks.md; 0.1 cm / 0.01 deg saved more and lost
  /// accuracy). 0: ICP's own thresholds, as paper() keeps.
  double relaxation_min_step_cm = 0.03;
  double relaxation_min_step_deg = 0.003;
  /// Every match is judged (registration/health.hpp); a doubtful one is named in ScanOutcome::health.
  HealthSettings health;
  /// Each scan's surfaces are cut into cubes of this size, and a plane fitted in each (a normal):
  /// what the health's constraint test and the loop edges' information measure with.
  float plane_cell_cm = 50.0f;
  /// Pairwise and incremental matching: a doubtful match is tried again from the same start at these
  /// multiples of the pair bound, coarse to fine, until one is trusted (1 m, then 4 m for 25 cm):
  /// a start out of the 25 cm bound's reach (LiDAR without odometry) then still ends right, and
  /// a survey whose matches are all trusted pays nothing. Empty: no retries.
  std::vector<float> retry_bound_factors = {4.0f, 16.0f};
  /// No retry starts wider than this: at tens of metres every surface pairs with some other one.
  float max_retry_bound_cm = 400.0f;
  LoopClosureSettings loops;

  /// minemap's mapping ICP: IcpSettings::mapping() refined at 7.5 cm (0.3 x 25 cm), a phase
  /// converged when a step moves less than 1 mm and turns less than 0.01° (1.7 mm at 10 m), well
  /// under the 1.5 cm range noise (docs/benchmarks.md: half the iterations on the default survey,
  /// the same error per step).
  static IcpSettings mapping_icp() {
    IcpSettings icp = IcpSettings::mapping();
    icp.refine_pair_dist_fraction = 0.3f;
    icp.termination.min_translation_step_cm = 0.1;
    icp.termination.min_rotation_step_deg = 0.01;
    return icp;
  }
  /// The paper's simultaneous matching (queue-based relaxation) of slice-filtered scans against
  /// dense models, with minemap's ICP.
  static MappingSettings simultaneous() {
    MappingSettings settings;
    settings.mode = MatchingMode::kSimultaneous;
    settings.reduction = Reduction::kSlices;
    settings.icp = IcpSettings::mapping();
    settings.loops.enabled = false;  // the relaxation is the paper's own
    return settings;
  }
  /// The paper's method: simultaneous matching, slice filter, models reduced like the data, plain
  /// ICP at 25 cm (Table I's rows).
  static MappingSettings paper() {
    MappingSettings settings = simultaneous();
    settings.icp = IcpSettings::paper();
    settings.dense_models = false;
    settings.max_relaxation_neighbours = 0;
    settings.max_relaxation_matches_per_scan = 0;
    settings.relaxation_min_step_cm = 0.0;
    settings.relaxation_min_step_deg = 0.0;
    return settings;
  }
  /// Throws std::invalid_argument naming the bad setting (map_survey calls it once, at entry).
  void validate() const;
};

/// How one scan ended up.
struct ScanOutcome {
  std::string name;
  Pose pose_cm = Pose::Identity();          ///< final T_world_file (cm)
  Pose initial_pose_cm = Pose::Identity();  ///< the odometry pose it started from
  std::vector<io::FrameLine> frames;        ///< every pose it took, 3DTK .frames style (last = final)
  IcpResult last_match;                     ///< the last ICP run that moved it (pairwise or relaxation)
  RegistrationHealth health;                ///< how far last_match can be trusted
  int relaxation_matches = 0;               ///< step-3 matches of this scan
  /// Seconds spent when this scan arrived: its own match and (kSimultaneous) the relaxation after
  /// it; the cost per new scan (loop closing and the last relaxation are in MappingResult::times).
  double match_s = 0;
  std::size_t points_in = 0;                ///< points read
  std::size_t points_used = 0;              ///< points after filtering, used for matching
  std::size_t outliers_replaced = 0;
  std::vector<Eigen::Vector3f> used_points_cm;  ///< the filtered points, in the points frame
  Pose world_from_points = Pose::Identity();    ///< final T_world_points (places used_points_cm)
  bool registered = true;                   ///< false: no registration succeeded; pose from odometry
  std::string failure;                      ///< why, when !registered
};

struct StageTimes {
  double filter_s = 0, tree_build_s = 0, pairwise_s = 0, relaxation_s = 0, loop_closure_s = 0;
};

/// A loop the closing step found: scan `to` stands near the earlier scan `from`.
struct LoopClosure {
  std::size_t from = 0, to = 0;
  bool closed = false;              ///< a trusted match joined them (an edge of the relaxation)
  std::string doubt;                ///< when not closed: why
  double gap_before_cm = 0, gap_before_deg = 0;  ///< where the match put `to`, against its pose before
  double gap_after_cm = 0, gap_after_deg = 0;    ///< the same after the relaxation
};

struct MappingResult {
  std::vector<ScanOutcome> scans;
  std::string backend;       ///< the backend that made the poses: "cpu: ..." / "opencl: <device>"
  std::string backend_note;  ///< empty, or why another backend than the one handed in made them
  std::vector<std::string> notes;  ///< fallbacks, skipped filters
  StageTimes times;
  int step1_icp_iterations = 0;  ///< Table I: ICP iterations of the pairwise step
  int step3_icp_iterations = 0;  ///< Table I: ICP iterations of the relaxation
  int relaxation_matches = 0;
  std::vector<LoopClosure> loops;  ///< every loop candidate tried (MappingSettings::loops)
  /// Stopped on request (map_survey's stop_requested) after `scans_matched` scans (0..k-1 hold their
  /// final poses; the rest are untouched); a complete run has scans_matched == scans.size().
  bool interrupted = false;
  std::size_t scans_matched = 0;
  bool all_registered() const;
  /// Indices of the registered scans whose last match was judged doubtful (ScanOutcome::health).
  std::vector<std::size_t> doubtful() const;
};

/// Reports progress: scans done of total, and a short phase name.
using ProgressCallback = std::function<void(std::size_t done, std::size_t total, const std::string& phase)>;
/// Asked between scans (and between relaxation matches): true stops the run, which returns what it
/// finished (MappingResult::interrupted). Called from the thread that called map_survey.
using StopRequested = std::function<bool()>;

/// Registers `scans` (pose_cm = odometry / initial guess; scan 0 is the master and stays fixed) on
/// `backend`. Throws std::invalid_argument on an empty survey or invalid settings. Registration
/// failures do not throw: the scan keeps its odometry-based pose, `registered` is false and
/// `failure` says why. A BackendError (a device fault) makes it match the whole survey again on a
/// fresh CPU backend, saying so in `notes`: the poses are then the CPU run's.
MappingResult map_survey(const std::vector<Scan>& scans, const MappingSettings& settings, ComputeBackend& backend,
                         const ProgressCallback& progress = {}, const StopRequested& stop_requested = {});

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
  /// run left for it (pose, frames, match, health). Restore scans in order, then restore_queue().
  void restore(const Scan& scan, const ScanOutcome& outcome);
  /// kSimultaneous: the scans waiting for a relaxation match, front first (what a resume needs).
  std::vector<std::size_t> queue() const;
  void restore_queue(const std::vector<std::size_t>& queue);
  /// The run so far; resuming restores its counters (iterations, matches, times, notes) here.
  MappingResult& result();
  const MappingResult& result() const;
  void finish();
  std::size_t size() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Pose errors of `estimated` against `reference`, both expressed relative to scan 0 (the master
/// fixes the frame): translation in cm, rotation in degrees.
struct PoseErrors {
  double mean_translation_cm = 0, max_translation_cm = 0;
  double mean_rotation_deg = 0, max_rotation_deg = 0;
  double mean_relative_translation_cm = 0, max_relative_translation_cm = 0;  ///< consecutive pairs
  double mean_relative_rotation_deg = 0, max_relative_rotation_deg = 0;
  double path_length_cm = 0;  ///< along the reference
};
PoseErrors pose_errors(const std::vector<Pose>& estimated, const std::vector<Pose>& reference);

}  // namespace minemap
