#include "minemap/core/scan.hpp"

#include <cmath>
#include <stdexcept>

namespace minemap {

Pose Scan::world_from_points() const {
  Pose offset = Pose::Identity();
  offset.block<3, 1>(0, 3) = local_origin_cm;
  return pose_cm * offset;
}

void Scan::set_world_from_points(const Pose& world_from_points) {
  Pose inverse_offset = Pose::Identity();
  inverse_offset.block<3, 1>(0, 3) = -local_origin_cm;
  pose_cm = world_from_points * inverse_offset;
}

void Scan::recentre_if_far(double threshold_cm) {
  if (points_cm.empty()) return;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const auto& p : points_cm) sum += p.cast<double>();
  const Eigen::Vector3d centroid = sum / static_cast<double>(points_cm.size());
  if (centroid.norm() <= threshold_cm) return;
  const Eigen::Vector3d shift = centroid.array().round().matrix();  // whole cm keeps text round trips exact
  for (auto& p : points_cm) p = (p.cast<double>() - shift).cast<float>();
  local_origin_cm += shift;
}

void Scan::validate() const {
  if (!slice_offsets.empty()) {
    if (slice_offsets.size() < 2 || slice_offsets.front() != 0 || slice_offsets.back() != points_cm.size()) {
      throw std::invalid_argument("scan " + name + ": slice offsets do not cover the points");
    }
    for (std::size_t i = 1; i < slice_offsets.size(); ++i) {
      if (slice_offsets[i] < slice_offsets[i - 1]) {
        throw std::invalid_argument("scan " + name + ": slice offsets decrease at slice " + std::to_string(i));
      }
    }
  }
  for (std::size_t i = 0; i < points_cm.size(); ++i) {
    if (!points_cm[i].allFinite()) {
      throw std::invalid_argument("scan " + name + ": point " + std::to_string(i) + " is not finite");
    }
  }
  if (!is_valid_rigid(pose_cm, 1e-4)) throw std::invalid_argument("scan " + name + ": pose is not a rigid transform");
}

Bounds3d world_bounds(std::span<const Eigen::Vector3f> points, const Pose& world_from_points) {
  Bounds3d local;
  for (const auto& p : points) local.extend(p.cast<double>());
  Bounds3d world;
  if (local.empty()) return world;
  for (int corner = 0; corner < 8; ++corner) {
    const Eigen::Vector3d c((corner & 1) ? local.max_cm.x() : local.min_cm.x(),
                            (corner & 2) ? local.max_cm.y() : local.min_cm.y(),
                            (corner & 4) ? local.max_cm.z() : local.min_cm.z());
    world.extend(world_from_points.block<3, 3>(0, 0) * c + world_from_points.block<3, 1>(0, 3));
  }
  return world;
}

}  // namespace minemap
