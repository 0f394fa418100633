#pragma once
// The sums of point-to-plane ICP (Chen and Medioni 1991; not in the paper), as registration/
// point_to_plane.hpp solves them. The planes are the DATA cloud's own (one normal per data point,
// zero where it lies on no plane), so no normal is estimated for any model or local map. A pair
// (p, m), both in the data frame and centred on `reference_cm`, costs ((U m - p) . n)^2, where U
// is the small motion of the model in the data frame (the inverse of the data's step); a pair
// whose data point lies on no plane costs |U m - p|^2, the paper's term. U is linearised about
// the reference (rotation vector w, translation t: U m = m + w x m + t), so each plane pair adds
// the row J = [m x n, n] with residual (m - p) . n, each other pair the three rows [-[m]x, I] with
// residual m - p, and the sums are J^T J (6x6) and J^T r.
//
// Like the point-to-point sums (pair_sums.hpp), pairs are summed in double per block of
// kPairSumBlock data points in index order, and the blocks are added in order: the same pairs
// give the same bits for any thread count and on every backend (the CPU backend sums while it
// searches; others pair on their device and sum here, ComputeBackend::pair_and_plane_sum).
//
// Units: centimetres and radians. Thread-safety: values and pure functions.
#include <Eigen/Core>
#include <span>

#include "minemap/search/pairing.hpp"

namespace minemap {

struct PlaneSums {
  /// J^T J, its upper triangle row by row (w then t: (0,0), (0,1) ... (0,5), (1,1) ... (5,5)).
  double normal[21] = {};
  double gradient[6] = {};                ///< J^T r
  double count = 0.0;                     ///< pairs
  double plane_pairs = 0.0;               ///< of which on a plane of the data
  double sum_squared_distance_cm2 = 0.0;  ///< sum of |m - p|^2 (the pairs' RMS, as point-to-point)
  double sum_squared_residual_cm2 = 0.0;  ///< the objective: the planes' distances squared, |m - p|^2 off them
  Eigen::Vector3d reference_cm = Eigen::Vector3d::Zero();

  double rms_cm() const;
  Eigen::Matrix<double, 6, 6> normal_matrix() const;  ///< J^T J, whole
  Eigen::Matrix<double, 6, 1> gradient_vector() const;
  PlaneSums& operator+=(const PlaneSums& other);  ///< both must share reference_cm

  /// Adds the pair of `data_point_cm` (`normal`: unit, or zero), if it has one (squared distance >= 0).
  void add(const Eigen::Vector3f& data_point_cm, const Eigen::Vector3f& normal, const NearestPair& pair);
};

/// The sums of `pairs` (one per data point, as ComputeBackend::nearest returns them), in blocks of
/// kPairSumBlock, in parallel (TBB), the blocks added in order. Throws std::invalid_argument unless
/// there is one pair and one normal per data point.
PlaneSums plane_sums(std::span<const NearestPair> pairs, std::span<const Eigen::Vector3f> data_points_cm,
                     std::span<const Eigen::Vector3f> data_normals, const Eigen::Vector3d& reference_cm);

}  // namespace minemap
