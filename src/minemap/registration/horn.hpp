#pragma once
// Horn's closed-form absolute orientation with unit quaternions (paper, section IV.A; Horn 1987).
#include <optional>

#include "minemap/core/pose.hpp"
#include "minemap/search/pair_sums.hpp"

namespace minemap {

/// The 4x4 symmetric matrix N of Horn's method from the cross-covariance S, S(a,b) = sum p'_a m'_b
/// (p: data, m: model, both centred on their centroids). Its eigenvector of the largest eigenvalue
/// is the unit quaternion of the rotation taking data onto model.
Eigen::Matrix4d horn_matrix(const Eigen::Matrix3d& cross_covariance);

/// The rigid transform T minimising sum |m - T p|^2 over the pairs summarised by `sums` (in the data
/// frame): R from the largest eigenvector of N (double, on the host), t = c_m - R c_p.
/// nullopt when fewer than 3 pairs or the sums are not finite.
std::optional<Pose> horn_transform(const PairSums& sums);

}  // namespace minemap
