#include "minemap/slam/recovery.hpp"

#include <cmath>

namespace minemap::detail {

RecoveredStart Recovery::find(const SurveyState& state, std::size_t i) const {
  const Pose frame = state.pose(i - 1);
  const PreparedScan& scan = state.prepared(i);
  // The previous scan's local map, thinned as its sweep's own was (a sensor's origin is its frame's).
  const double thin_cm = scan.sweep_s > 0.0 ? settings_.motion.local_map_cell_cm : 0.0;
  const std::shared_ptr<const PreparedCloud> map = local_map_.metascan(
      state, i, frame, frame, frame, settings_.recovery.reach_cm, thin_cm);
  const GlobalRegistrationSettings& global = settings_.recovery.global;
  const FeatureCloud model = describe_fpfh(map->points(), Eigen::Vector3f::Zero(), global.features);
  const FeatureCloud data = describe_fpfh(scan.cloud->points(), Eigen::Vector3f::Zero(), global.features);
  RecoveredStart found;
  found.global = register_globally(data, model, global);
  found.start = frame * found.global.model_from_data;
  return found;
}

double rms_moved_cm(const PreparedCloud& cloud, const Pose& from, const Pose& to) {
  const Pose change = rigid_inverse(from) * to;  // in the points' frame
  const Eigen::Matrix3d rotation_minus_identity = change.block<3, 3>(0, 0) - Eigen::Matrix3d::Identity();
  const Eigen::Vector3d translation = change.block<3, 1>(0, 3);
  double sum = 0.0;
  for (const Eigen::Vector3f& p : cloud.points()) {
    sum += (rotation_minus_identity * p.cast<double>() + translation).squaredNorm();
  }
  return cloud.points().empty() ? 0.0 : std::sqrt(sum / double(cloud.points().size()));
}

}  // namespace minemap::detail
