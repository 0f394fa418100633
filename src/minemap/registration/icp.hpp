#pragma once
// ICP (paper, section IV.A): closest-point pairs, Horn's closed form, iterate. With the approximate
// kd-tree the paper's schedule applies: approximate search while the error E(R, t) keeps falling,
// then exact search until convergence (usually 1-3 more iterations).
#include <span>
#include <string>

#include "minemap/core/pose.hpp"
#include "minemap/search/pairing.hpp"

namespace minemap {

struct IcpSettings {
  /// kExact: exact kd-tree only. kApproximate: the paper's schedule (approximate, then exact).
  /// kBruteForce: brute force only (the Table I baseline).
  SearchMethod method = SearchMethod::kApproximate;
  float max_pair_dist_cm = 25.0f;          ///< 3DTK's default
  /// After converging at max_pair_dist_cm, continue with exact search at this tighter bound until
  /// converged again (0 = off). Pairs up to 25 cm include wrong ones at occlusion edges, which bias
  /// point-to-point ICP by about 1 cm per 4 m step in a mine; 10 cm removes most of that.
  float refine_max_pair_dist_cm = 0.0f;
  int max_iterations = 100;                ///< approximate and exact together
  double min_translation_step_cm = 0.01;   ///< converged when one iteration moves less than this...
  double min_rotation_step_deg = 0.001;    ///< ...and turns less than this
  int min_pairs = 250;                     ///< fewer pairs: no overlap, registration fails
  /// Anderson acceleration of the exact-search iterations (AA-ICP, Pavlov et al. 2018): the next
  /// pose extrapolates the last acceleration_history plain ICP steps. Where point-to-point ICP creeps
  /// along a shallow valley (a rotation about a tunnel's axis), it reaches the valley's end in fewer
  /// iterations. A jump that does not lower ICP's objective (squared pair distances, the bound
  /// squared for unpaired points) is taken back and the plain step kept; that costs one pairing.
  /// Off: plain ICP, as in the paper.
  bool accelerate = false;
  int acceleration_history = 5;  ///< steps the extrapolation uses (AA-ICP's m)
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
  int refine_iterations = 0;      ///< of which at refine_max_pair_dist_cm
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
};

/// Registers `data` (initially at `world_from_data`) against the union of `models`.
IcpResult register_icp(PairingBackend& backend, const PreparedCloud& data, const Pose& world_from_data,
                       std::span<const WorldModel> models, const IcpSettings& settings);

/// Pairs between `data` and one model at the given poses (exact search): the paper's overlap test.
std::size_t count_pairs(PairingBackend& backend, const PreparedCloud& data, const Pose& world_from_data,
                        const WorldModel& model, float max_pair_dist_cm);

}  // namespace minemap
