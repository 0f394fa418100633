#include "minemap/search/plane_sums.hpp"

#include <tbb/parallel_for.h>

#include <cmath>
#include <stdexcept>
#include <vector>

#include "minemap/search/pair_sums.hpp"

namespace minemap {

double PlaneSums::rms_cm() const { return count > 0.0 ? std::sqrt(sum_squared_distance_cm2 / count) : 0.0; }

Eigen::Matrix<double, 6, 6> PlaneSums::normal_matrix() const {
  Eigen::Matrix<double, 6, 6> matrix;
  int k = 0;
  for (int r = 0; r < 6; ++r) {
    for (int c = r; c < 6; ++c, ++k) matrix(r, c) = matrix(c, r) = normal[k];
  }
  return matrix;
}

Eigen::Matrix<double, 6, 1> PlaneSums::gradient_vector() const {
  return Eigen::Map<const Eigen::Matrix<double, 6, 1>>(gradient);
}

PlaneSums& PlaneSums::operator+=(const PlaneSums& other) {
  for (int k = 0; k < 21; ++k) normal[k] += other.normal[k];
  for (int k = 0; k < 6; ++k) gradient[k] += other.gradient[k];
  count += other.count;
  plane_pairs += other.plane_pairs;
  sum_squared_distance_cm2 += other.sum_squared_distance_cm2;
  sum_squared_residual_cm2 += other.sum_squared_residual_cm2;
  return *this;
}

void PlaneSums::add(const Eigen::Vector3f& data_point_cm, const Eigen::Vector3f& normal_f, const NearestPair& pair) {
  if (pair.squared_distance_cm2 < 0.0f) return;
  // J^T J by hand, the 21 products of the upper triangle: Eigen's rank update of a fixed 6x6 goes
  // through its general matrix product, and cost a tenth of a sweep's match.
  const auto add_row = [this](const double row[6], double residual) {
    int k = 0;
    for (int r = 0; r < 6; ++r) {
      for (int c = r; c < 6; ++c, ++k) normal[k] += row[r] * row[c];
      gradient[r] += row[r] * residual;
    }
  };
  const Eigen::Vector3d m = pair.position_cm.cast<double>() - reference_cm;
  const Eigen::Vector3d p = data_point_cm.cast<double>() - reference_cm;
  const Eigen::Vector3d difference = m - p;
  count += 1.0;
  sum_squared_distance_cm2 += pair.squared_distance_cm2;
  if (normal_f.squaredNorm() > 0.0f) {
    const Eigen::Vector3d n = normal_f.cast<double>();
    const Eigen::Vector3d moment = m.cross(n);
    const double row[6] = {moment.x(), moment.y(), moment.z(), n.x(), n.y(), n.z()};
    const double residual = difference.dot(n);
    add_row(row, residual);
    sum_squared_residual_cm2 += residual * residual;
    plane_pairs += 1.0;
    return;
  }
  const double rows[3][6] = {{0.0, m.z(), -m.y(), 1.0, 0.0, 0.0},
                             {-m.z(), 0.0, m.x(), 0.0, 1.0, 0.0},
                             {m.y(), -m.x(), 0.0, 0.0, 0.0, 1.0}};
  for (int axis = 0; axis < 3; ++axis) add_row(rows[axis], difference[axis]);
  sum_squared_residual_cm2 += difference.squaredNorm();
}

PlaneSums plane_sums(std::span<const NearestPair> pairs, std::span<const Eigen::Vector3f> data_points_cm,
                     std::span<const Eigen::Vector3f> data_normals, const Eigen::Vector3d& reference_cm) {
  if (pairs.size() != data_points_cm.size() || data_normals.size() != data_points_cm.size()) {
    throw std::invalid_argument("point-to-plane sums: one pair and one normal per data point expected");
  }
  const auto block = static_cast<std::size_t>(kPairSumBlock);
  const std::size_t blocks = (pairs.size() + block - 1) / block;
  std::vector<PlaneSums> partial(blocks);
  tbb::parallel_for(std::size_t{0}, blocks, [&](std::size_t b) {
    PlaneSums& sums = partial[b];
    sums.reference_cm = reference_cm;
    const std::size_t end = std::min(pairs.size(), (b + 1) * block);
    for (std::size_t i = b * block; i < end; ++i) sums.add(data_points_cm[i], data_normals[i], pairs[i]);
  });
  PlaneSums total;
  total.reference_cm = reference_cm;
  for (const PlaneSums& sums : partial) total += sums;
  return total;
}

}  // namespace minemap
