#pragma once
// A global relaxation over the scan graph, as 3DTK's LUM does after a loop is found: every scan is
// a node (its 6-DoF pose), every match an edge (the relative pose it measured), and all poses move
// at once to the least-squares compromise. The straight chain of matches only fixes each step; a
// loop edge (the last scans matched against the first) adds the constraint that spreads the
// survey's drift over the whole loop instead of leaving it as one jump at the end.
//
// Units: centimetres and radians. Thread-safety: pure functions of their arguments.
#include <cstddef>
#include <span>
#include <vector>

#include "minemap/core/pose.hpp"

namespace minemap {

/// One measurement: T_from^-1 * T_to as a match found it.
struct PoseGraphEdge {
  std::size_t from = 0;
  std::size_t to = 0;
  Pose from_to = Pose::Identity();
  double weight = 1.0;  ///< multiplies the edge's information (e.g. several for a trusted loop edge)
  /// The edge's information over [translation cm, rotation rad] (in the `to` frame; e.g. from its
  /// match's geometry, registration/match_information.hpp). Zero: the settings' sigmas, alike in
  /// every direction.
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
};

struct PoseGraphSettings {
  /// One standard deviation of an edge's translation and rotation: they weigh centimetres against
  /// radians. 1 cm and 0.002 rad (0.11 deg) are about what one mine scan match gets wrong
  /// (docs/benchmarks.md: steps of 0.5-0.6 cm and 0.06 deg).
  double translation_sigma_cm = 1.0;
  double rotation_sigma_rad = 0.002;
  int max_iterations = 20;
  /// Stop when no pose moves more than this (cm, and the same in radians times 100 cm).
  double min_update_cm = 1e-3;
  bool operator==(const PoseGraphSettings&) const = default;
};

struct PoseGraphResult {
  std::vector<Pose> poses;         ///< T_world_scan; poses[fixed] unchanged
  int iterations = 0;
  double initial_cost = 0.0;       ///< sum of the edges' squared, weighted residuals
  double final_cost = 0.0;
  bool converged = false;
};

/// Gauss-Newton over all poses but `fixed` (the master scan): each pose moves by a right
/// perturbation T * Exp(dx) (dx = [translation cm, rotation rad]); the residual of an edge is
/// [translation, rotation vector] of (from_to^-1 * T_from^-1 * T_to), its Jacobians by central
/// differences; the normal equations are sparse (one 6x6 block per node and per edge) and solved
/// by a sparse Cholesky factorisation. Deterministic. Throws std::invalid_argument for an edge
/// naming a missing node.
PoseGraphResult optimise_pose_graph(std::vector<Pose> poses, std::span<const PoseGraphEdge> edges, std::size_t fixed,
                                    const PoseGraphSettings& settings = {});

/// The residual of one edge at the given poses: [translation cm, rotation vector rad].
Eigen::Matrix<double, 6, 1> pose_graph_residual(const Pose& from, const Pose& to, const Pose& from_to);

}  // namespace minemap
