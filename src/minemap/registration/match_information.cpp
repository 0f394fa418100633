#include "minemap/registration/match_information.hpp"

#include <Eigen/Eigenvalues>
#include <cmath>
#include <stdexcept>

namespace minemap {

std::int64_t SurfaceNormals::key_of(const Eigen::Vector3f& point_cm) const {
  // 21 bits per axis: cells of 50 cm reach +-5 km, beyond any scan's range.
  const auto cell = [&](float v) {
    return static_cast<std::int64_t>(std::floor(v * inverse_cell_)) & ((std::int64_t{1} << 21) - 1);
  };
  return cell(point_cm.x()) << 42 | cell(point_cm.y()) << 21 | cell(point_cm.z());
}

SurfaceNormals::SurfaceNormals(std::span<const Eigen::Vector3f> points_cm, float cell_cm) {
  if (!(cell_cm > 0.0f) || !std::isfinite(cell_cm)) throw std::invalid_argument("normal cell must be > 0 cm");
  inverse_cell_ = 1.0f / cell_cm;
  struct Moments {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    Eigen::Matrix3d outer = Eigen::Matrix3d::Zero();
    int count = 0;
  };
  std::unordered_map<std::int64_t, Moments> cells;
  for (const Eigen::Vector3f& p : points_cm) {
    Moments& m = cells[key_of(p)];
    const Eigen::Vector3d q = p.cast<double>();
    m.sum += q;
    m.outer += q * q.transpose();
    ++m.count;
  }
  for (const auto& [key, m] : cells) {
    if (m.count < 5) continue;
    const Eigen::Vector3d mean = m.sum / m.count;
    const Eigen::Matrix3d covariance = m.outer / m.count - mean * mean.transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(covariance);  // ascending eigenvalues
    const Eigen::Vector3d spread = eigen.eigenvalues();
    if (!(spread[0] < 0.1 * spread[1])) continue;
    normals_.emplace(key, eigen.eigenvectors().col(0).cast<float>());
  }
}

const Eigen::Vector3f* SurfaceNormals::at(const Eigen::Vector3f& point_cm) const {
  const auto found = normals_.find(key_of(point_cm));
  return found == normals_.end() ? nullptr : &found->second;
}

Matrix6d point_to_plane_information(std::span<const Eigen::Vector3f> points_cm, const SurfaceNormals& normals,
                                    std::size_t* pairs) {
  Matrix6d information = Matrix6d::Zero();
  std::size_t counted = 0;
  for (const Eigen::Vector3f& p : points_cm) {
    const Eigen::Vector3f* n = normals.at(p);
    if (n == nullptr) continue;
    Eigen::Matrix<double, 6, 1> row;
    row.head<3>() = n->cast<double>();
    row.tail<3>() = p.cast<double>().cross(n->cast<double>());
    information += row * row.transpose();
    ++counted;
  }
  if (pairs != nullptr) *pairs = counted;
  return counted > 0 ? Matrix6d(information / static_cast<double>(counted)) : information;
}

double rotation_constraint_ratio(const Matrix6d& information, Eigen::Vector3d* weakest) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(information.bottomRightCorner<3, 3>());
  const Eigen::Vector3d values = eigen.eigenvalues();
  if (weakest != nullptr) *weakest = eigen.eigenvectors().col(0);
  return values[2] > 0.0 ? std::max(0.0, values[0]) / values[2] : 0.0;
}

double translation_constraint_ratio(const Matrix6d& information, Eigen::Vector3d* weakest) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(information.topLeftCorner<3, 3>());
  const Eigen::Vector3d values = eigen.eigenvalues();
  if (weakest != nullptr) *weakest = eigen.eigenvectors().col(0);
  return values[2] > 0.0 ? std::max(0.0, values[0]) / values[2] : 0.0;
}

}  // namespace minemap
