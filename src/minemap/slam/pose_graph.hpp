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

/// A known position of one point of a scan (survey control: a station's mark under the scanner, a
/// target on a wall): T_node * point_cm should be position_cm, to within its information (1/cm^2,
/// in the graph's frame). The graph's frame is the positions' frame.
struct PoseGraphPrior {
  std::size_t node = 0;
  Eigen::Vector3d point_cm = Eigen::Vector3d::Zero();     ///< in the node's frame
  Eigen::Vector3d position_cm = Eigen::Vector3d::Zero();  ///< where it is known to be
  Eigen::Matrix3d information = Eigen::Matrix3d::Zero();
};

/// A known direction of a scan's rotation: the component along `axis_world` (a unit vector, graph
/// frame) of the rotation vector log(R_node R_known^-1) should be zero, to within `information`
/// (1/rad^2). What holds a graph in a direction its positions cannot: the roll about a line of
/// control points that all lie on it.
struct PoseGraphRotationPrior {
  std::size_t node = 0;
  Eigen::Matrix3d known = Eigen::Matrix3d::Identity();
  Eigen::Vector3d axis_world = Eigen::Vector3d::UnitX();
  double information = 0.0;
};

/// What pins the graph's frame: one fixed pose (the master scan), or priors alone (kNoFixedPose).
inline constexpr std::size_t kNoFixedPose = static_cast<std::size_t>(-1);

struct PoseGraphSettings {
  /// One standard deviation of an edge's translation and rotation: they weigh centimetres against
  /// radians. 1 cm and 0.002 rad (0.11 deg) are about what one mine scan match gets wrong
  /// (docs/benchmarks.md: steps of 0.5-0.6 cm and 0.06 deg).
  double translation_sigma_cm = 1.0;
  double rotation_sigma_rad = 0.002;
  int max_iterations = 20;
  /// Stop when no pose moves more than this (cm, and the same in radians times 100 cm).
  double min_update_cm = 1e-3;
  /// Also each pose's marginal covariance at the solution (PoseGraphResult::covariances): the
  /// inverse of the normal equations' matrix, block by block (6 solves a pose).
  bool covariances = false;
  /// Levenberg-Marquardt instead of Gauss-Newton: a step is kept only when it lowers the cost. For
  /// graphs with a direction their terms hardly pin (a tie to control points nearly in a line), where
  /// a Gauss-Newton step along it turns the whole graph by anything.
  bool damped = false;
  bool operator==(const PoseGraphSettings&) const = default;
};

struct PoseGraphResult {
  std::vector<Pose> poses;         ///< T_world_scan; poses[fixed] unchanged
  int iterations = 0;
  double initial_cost = 0.0;       ///< sum of the edges' squared, weighted residuals
  double final_cost = 0.0;
  bool converged = false;
  /// With PoseGraphSettings::covariances: per pose, the covariance of its right perturbation
  /// [translation cm, rotation rad] (zero for the fixed pose); empty otherwise.
  std::vector<Eigen::Matrix<double, 6, 6>> covariances;
};

/// Gauss-Newton over all poses but `fixed` (the master scan): each pose moves by a right
/// perturbation T * Exp(dx) (dx = [translation cm, rotation rad]); the residual of an edge is
/// [translation, rotation vector] of (from_to^-1 * T_from^-1 * T_to), its Jacobians by central
/// differences; the normal equations are sparse (one 6x6 block per node and per edge) and solved
/// by a sparse Cholesky factorisation. Deterministic. Throws std::invalid_argument for an edge
/// naming a missing node.
PoseGraphResult optimise_pose_graph(std::vector<Pose> poses, std::span<const PoseGraphEdge> edges, std::size_t fixed,
                                    const PoseGraphSettings& settings = {});

/// The same with priors (`fixed` may be kNoFixedPose: the priors then pin the frame, and must: a
/// graph they leave free in some direction keeps it where it starts). Priors count in the costs.
/// Throws std::invalid_argument for a prior naming a missing node, or not finite.
PoseGraphResult optimise_pose_graph(std::vector<Pose> poses, std::span<const PoseGraphEdge> edges,
                                    std::span<const PoseGraphPrior> priors,
                                    std::span<const PoseGraphRotationPrior> rotation_priors, std::size_t fixed,
                                    const PoseGraphSettings& settings = {});

/// The marginal covariances of `nodes` (their right perturbations [cm, rad]) of the graph at `poses`
/// (a solution of optimise_pose_graph): blocks of the inverse of its normal equations' matrix.
/// Zero for the fixed pose.
std::vector<Eigen::Matrix<double, 6, 6>> pose_graph_covariances(const std::vector<Pose>& poses,
                                                                std::span<const PoseGraphEdge> edges,
                                                                std::span<const PoseGraphPrior> priors,
                                                                std::span<const PoseGraphRotationPrior> rotation_priors,
                                                                std::size_t fixed, const PoseGraphSettings& settings,
                                                                std::span<const std::size_t> nodes);

/// The residual of one edge at the given poses: [translation cm, rotation vector rad].
Eigen::Matrix<double, 6, 1> pose_graph_residual(const Pose& from, const Pose& to, const Pose& from_to);

}  // namespace minemap
