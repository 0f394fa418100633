#pragma once
// ICP (paper, section IV.A): pair every data point with its closest model point, move the data by
// Horn's closed form (horn.hpp), repeat. register_icp runs the paper's schedule as phases:
//   1. approximate kd-tree while the error E(R, t) keeps falling (SearchMethod::kApproximate only);
//   2. exact search until the step is small (usually 1-3 more iterations after phase 1);
//   3. optionally, exact search again at a tighter pair bound (refinement), until the step is small.
// Anderson acceleration (AA-ICP), when on, wraps the exact phases with its own accept/reject test.
// The objective is point-to-point (search/pair_sums.hpp; the search and the sums run in the backend),
// or, where asked, point-to-plane on the data's planes (point_to_plane.hpp; the backend pairs, the
// host sums).
#include <span>
#include <string>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/core/pose.hpp"

namespace minemap {

/// When ICP stops: every stopping rule in one place.
struct IcpTermination {
  /// ICP iterations over all phases (each takes one pairing pass and, unless it is a rejected
  /// acceleration, one Horn step); at the cap the last pose is returned (IcpStop::kMaxIterations).
  int max_iterations = 100;
  double min_translation_step_cm = 0.01;  ///< a phase has converged when one step moves less than this...
  double min_rotation_step_deg = 0.001;   ///< ...and turns less than this
  /// Fewer pairs: the clouds do not overlap, registration fails. The one definition of the 250 pairs:
  /// the paper's overlap test (MappingSettings::min_overlap_pairs) starts from it.
  int min_pairs = 250;
  bool operator==(const IcpTermination&) const = default;
};

/// What one ICP step minimises.
enum class IcpObjective {
  kPointToPoint,  ///< the paper's: squared distances of the pairs, Horn's closed form
  kPointToPlane,  ///< squared distances to the data's planes (point_to_plane.hpp); needs the data's normals
};

/// ICP's settings. IcpSettings{} (= paper()) is the paper's ICP. The mapping presets' ICPs are in
/// slam/mapping_settings.hpp (MappingSettings::default_icp(), simultaneous_icp()), and what each
/// match of a survey runs is derived there (pairwise_icp(), relaxation_icp()).
struct IcpSettings {
  /// kApproximate: the paper's schedule (approximate, then exact). kExact: exact kd-tree only.
  /// kBruteForce: brute force only (the Table I baseline).
  SearchMethod method = SearchMethod::kApproximate;
  float max_pair_dist_cm = PairingSettings{}.max_pair_dist_cm;  ///< 3DTK's default, 25 cm
  /// After converging at max_pair_dist_cm, continue with exact search at this fraction of it until
  /// converged again (0 = off). Pairs up to 25 cm include wrong ones at occlusion edges, which bias
  /// point-to-point ICP by about 1 cm per 4 m step in a mine; 10 cm (0.4) removes most of that.
  float refine_pair_dist_fraction = 0.0f;
  IcpTermination termination;
  /// Anderson acceleration of the exact phases (AA-ICP, Pavlov et al. 2018): the next pose
  /// extrapolates the last acceleration_history plain ICP steps. Where point-to-point ICP creeps
  /// along a shallow valley (a rotation about a tunnel's axis), it reaches the valley's end in fewer
  /// iterations. A jump that does not lower ICP's objective (squared pair distances, the bound
  /// squared for unpaired points) is taken back and the plain step kept; that costs one pairing.
  /// Off: plain ICP, as in the paper.
  bool accelerate = false;
  int acceleration_history = 5;  ///< steps the extrapolation uses (AA-ICP's m)
  /// Each pair weighed by the Geman-McClure kernel (PairingSettings::robust_scale_cm) at this
  /// fraction of the pair bound, Horn's method then taking the weighted sums (KISS-ICP: a third).
  /// 0: every pair weighs 1, the paper's ICP.
  float robust_scale_fraction = 0.0f;
  /// kPointToPlane: register_icp must be given the data's normals; the robust kernel is then not
  /// applied (the planes' residuals are unweighted).
  IcpObjective objective = IcpObjective::kPointToPoint;
  /// A spring that holds the data frame's origin (a sensor's own position) to where the run's start
  /// put it: Horn's sums also hold that one pair, weighing as much as this many point pairs, and
  /// ICP's objective its squared length times as much. Along a direction the surfaces pin, the
  /// pairs outweigh it by far; along one they hardly pin (a corridor's axis, a wall seen alone), no
  /// pair pulls, and a few that pair wrongly slide the match far: there the start holds instead.
  /// Translation only: the point at the origin gives the turn no lever. 0: none (the paper's ICP).
  float start_spring_pairs = 0.0f;

  /// The paper's ICP: approximate then exact search, 25 cm, plain steps.
  static IcpSettings paper() { return {}; }
  /// The refinement's pair bound in cm (0 when off).
  float refine_max_pair_dist_cm() const { return refine_pair_dist_fraction * max_pair_dist_cm; }
  /// Throws std::invalid_argument naming the bad setting.
  void validate() const;
  bool operator==(const IcpSettings&) const = default;
};

enum class IcpStop {
  kConverged,      ///< the step fell below both thresholds
  kMaxIterations,  ///< the iteration cap was reached (the pose is still returned)
  kTooFewPairs,    ///< fewer than min_pairs pairs: the scans do not overlap (failure)
  kNumericFailure, ///< NaN or degenerate geometry (failure)
};
const char* to_string(IcpStop stop);

/// One registration's outcome. On failure (`ok()` false) `world_from_data` is the initial pose.
struct IcpResult {
  Pose world_from_data = Pose::Identity();  ///< T_world_points of the data cloud
  int approximate_iterations = 0;
  int exact_iterations = 0;       ///< includes the refinement at the tighter bound
  int refine_iterations = 0;      ///< of which at the refinement's bound
  int accelerations = 0;          ///< accelerated poses kept (IcpSettings::accelerate)
  int rejected_accelerations = 0; ///< taken back because the objective rose (each cost one pairing, counted in exact_iterations)
  std::size_t pairs = 0;  ///< pairs in the last iteration
  double rms_cm = 0.0;    ///< RMS pair distance in the last iteration
  IcpStop stop = IcpStop::kConverged;
  bool ok() const { return stop == IcpStop::kConverged || stop == IcpStop::kMaxIterations; }
  bool converged() const { return stop == IcpStop::kConverged; }
  int iterations() const { return approximate_iterations + exact_iterations; }
};

/// A model cloud placed in the world (T_world_points of the model).
struct WorldModel {
  const PreparedCloud* cloud = nullptr;
  Pose world_from_model = Pose::Identity();
  SkippedPoints skip{};  ///< points the search leaves out (exact search only: ModelPlacement::skip)
};

/// Registers `data` (initially at `world_from_data`) against the union of `models`. The clouds
/// must come from `backend`. `settings` are not checked here (IcpSettings::validate).
/// `data_normals`: one per data point (unit, or zero where the point lies on no plane), required
/// for IcpObjective::kPointToPlane (std::invalid_argument otherwise), unused for point-to-point.
IcpResult register_icp(ComputeBackend& backend, const PreparedCloud& data, const Pose& world_from_data,
                       std::span<const WorldModel> models, const IcpSettings& settings,
                       std::span<const Eigen::Vector3f> data_normals = {});

/// Pairs between `data` and one model at the given poses (exact search): the paper's overlap test.
std::size_t count_pairs(ComputeBackend& backend, const PreparedCloud& data, const Pose& world_from_data,
                        const WorldModel& model, float max_pair_dist_cm);

}  // namespace minemap
