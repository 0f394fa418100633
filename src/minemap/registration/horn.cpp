#include "minemap/registration/horn.hpp"

#include <Eigen/Eigenvalues>
#include <cmath>

namespace minemap {

Eigen::Matrix4d horn_matrix(const Eigen::Matrix3d& s) {
  const double sxx = s(0, 0), sxy = s(0, 1), sxz = s(0, 2);
  const double syx = s(1, 0), syy = s(1, 1), syz = s(1, 2);
  const double szx = s(2, 0), szy = s(2, 1), szz = s(2, 2);
  Eigen::Matrix4d n;
  n << sxx + syy + szz, syz - szy, szx - sxz, sxy - syx,  //
      syz - szy, sxx - syy - szz, sxy + syx, szx + sxz,    //
      szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy,   //
      sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz;
  return n;
}

std::optional<Pose> horn_transform(const PairSums& sums) {
  // The weighted centroids and cross-covariance (weighted Horn: the same closed form); the weights
  // sum to the pair count when unweighted.
  if (!(sums.count >= 3.0) || !(sums.weight > 0.0)) return std::nullopt;
  const double n = sums.weight;
  const Eigen::Vector3d centroid_data = sums.sum_data / n;
  const Eigen::Vector3d centroid_model = sums.sum_model / n;
  const Eigen::Matrix3d cross = sums.sum_data_model - n * centroid_data * centroid_model.transpose();
  if (!cross.allFinite() || !centroid_data.allFinite() || !centroid_model.allFinite()) return std::nullopt;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> solver(horn_matrix(cross));
  if (solver.info() != Eigen::Success) return std::nullopt;
  Eigen::Vector4d q = solver.eigenvectors().col(3);  // eigenvalues ascend: the last is the largest
  if (q(0) < 0) q = -q;                               // q0 >= 0, as in the paper
  const Eigen::Quaterniond rotation(q(0), q(1), q(2), q(3));
  Pose t = Pose::Identity();
  t.block<3, 3>(0, 0) = rotation.normalized().toRotationMatrix();
  // Centroids are relative to the reference point r; t = (c_m + r) - R (c_p + r).
  const Eigen::Vector3d r = sums.reference_cm;
  t.block<3, 1>(0, 3) = (centroid_model + r) - t.block<3, 3>(0, 0) * (centroid_data + r);
  if (!t.allFinite()) return std::nullopt;
  return t;
}

}  // namespace minemap
