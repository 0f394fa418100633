#include "minemap/slam/local_map.hpp"

#include <tbb/parallel_for.h>

#include <array>

namespace minemap::detail {

std::shared_ptr<const PreparedCloud> LocalMap::metascan(const SurveyState& state, std::size_t i, const Pose& standing,
                                                        const Pose& frame, const Pose& at, double grow_cm,
                                                        Scope scope) const {
  const bool whole_map = scope == Scope::kWholeMap;
  std::vector<std::size_t> near =
      state.nearby(i, standing, whole_map ? state.size() : i, double(settings_.icp.max_pair_dist_cm));
  if (settings_.loops.enabled && !whole_map) {  // recent scans only: a loop is the pose graph's to close
    const std::size_t gap = static_cast<std::size_t>(settings_.loops.min_scan_gap);
    std::erase_if(near, [&](std::size_t j) { return j + gap < i; });
  }
  return union_of(state, i, near, frame, at, grow_cm);
}

std::shared_ptr<const PreparedCloud> LocalMap::union_of(const SurveyState& state, std::size_t i,
                                                        const std::vector<std::size_t>& near, const Pose& frame,
                                                        const Pose& at, double grow_cm) const {
  const Pose frame_inverse = rigid_inverse(frame);
  const KdTree& own = state.prepared(i).cloud->tree();
  const std::array<Eigen::Vector3f, 2> corners = {own.bounds_min(), own.bounds_max()};
  const Bounds3d reach = world_bounds(corners, frame_inverse * at);
  const Eigen::Vector3d reach_min = reach.min_cm.array() - grow_cm, reach_max = reach.max_cm.array() + grow_cm;
  // One task per scan, concatenated in the list's order: the same union for any thread count.
  std::vector<std::vector<Eigen::Vector3f>> parts(near.size());
  tbb::parallel_for(std::size_t{0}, near.size(), [&](std::size_t k) {
    const Pose to_frame = frame_inverse * state.pose(near[k]);
    const Eigen::Matrix3d rotation = to_frame.block<3, 3>(0, 0);
    const Eigen::Vector3d translation = to_frame.block<3, 1>(0, 3);
    for (const Eigen::Vector3f& p : state.prepared(near[k]).model_cloud->points()) {
      const Eigen::Vector3d q = rotation * p.cast<double>() + translation;
      if ((q.array() < reach_min.array()).any() || (q.array() > reach_max.array()).any()) continue;
      parts[k].push_back(q.cast<float>());
    }
  });
  std::size_t total = 0;
  for (const auto& part : parts) total += part.size();
  std::vector<Eigen::Vector3f> union_points;
  union_points.reserve(total);
  for (const auto& part : parts) union_points.insert(union_points.end(), part.begin(), part.end());
  return backend_.prepare(std::move(union_points), settings_.tree);
}

}  // namespace minemap::detail
