#include "minemap/registration/point_to_plane.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <cmath>

namespace minemap {

std::optional<Pose> plane_step(const PlaneSums& sums) {
  Eigen::Matrix<double, 6, 6> normal = sums.normal_matrix();
  const Eigen::Matrix<double, 6, 1> gradient = sums.gradient_vector();
  if (sums.count < 6.0 || !normal.allFinite() || !gradient.allFinite()) return std::nullopt;
  normal.diagonal() *= 1.0 + 1e-6;
  const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> solver(normal);
  if (solver.info() != Eigen::Success || !solver.isPositive()) return std::nullopt;
  const Eigen::Matrix<double, 6, 1> x = solver.solve(-gradient);
  if (!x.allFinite()) return std::nullopt;
  // U about the reference c: y -> R (y - c) + c + t.
  const Eigen::Vector3d w = x.head<3>();
  const double angle = w.norm();
  const Eigen::Matrix3d rotation =
      angle > 0.0 ? Eigen::AngleAxisd(angle, w / angle).toRotationMatrix() : Eigen::Matrix3d::Identity();
  Pose model_motion = Pose::Identity();
  model_motion.block<3, 3>(0, 0) = rotation;
  model_motion.block<3, 1>(0, 3) = sums.reference_cm - rotation * sums.reference_cm + x.tail<3>();
  return rigid_inverse(model_motion);
}

}  // namespace minemap
