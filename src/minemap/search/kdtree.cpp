#include "minemap/search/kdtree.hpp"

#include <algorithm>
#include <bit>
#include <stdexcept>

namespace minemap {

KdTree::KdTree(std::span<const Eigen::Vector3f> points, const KdTreeSettings& settings) : settings_(settings) {
  if (settings_.bucket_size < 1) throw std::invalid_argument("kd-tree bucket size must be >= 1");
  if (points.size() > static_cast<std::size_t>(INT32_MAX / 2)) throw std::invalid_argument("kd-tree: too many points");
  points_.resize(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    points_[i] = {points[i].x(), points[i].y(), points[i].z(), static_cast<std::int32_t>(i)};
  }
  if (points_.empty()) return;
  nodes_.reserve(2 * (points_.size() / static_cast<std::size_t>(settings_.bucket_size) + 1));
  float lo[3], hi[3];
  build(0, static_cast<std::int32_t>(points_.size()), 1, lo, hi);
  bounds_min_ = bounds_max_ = points[0];
  for (const auto& p : points) {
    bounds_min_ = bounds_min_.cwiseMin(p);
    bounds_max_ = bounds_max_.cwiseMax(p);
  }
}

std::int32_t KdTree::build(std::int32_t begin, std::int32_t end, int depth, float lo[3], float hi[3]) {
  depth_ = std::max(depth_, depth);
  const auto node_index = static_cast<std::int32_t>(nodes_.size());
  nodes_.emplace_back();

  lo[0] = hi[0] = points_[begin].x;
  lo[1] = hi[1] = points_[begin].y;
  lo[2] = hi[2] = points_[begin].z;
  for (std::int32_t i = begin + 1; i < end; ++i) {
    const float c[3] = {points_[i].x, points_[i].y, points_[i].z};
    for (int d = 0; d < 3; ++d) {
      lo[d] = std::min(lo[d], c[d]);
      hi[d] = std::max(hi[d], c[d]);
    }
  }
  int axis = 0;
  for (int d = 1; d < 3; ++d) {
    if (hi[d] - lo[d] > hi[axis] - lo[axis]) axis = d;
  }
  // The paper: "cuts recursively the scanned volume in two equal-sized halves".
  const float split = lo[axis] + 0.5f * (hi[axis] - lo[axis]);
  auto coordinate = [axis](const KdPoint& p) { return axis == 0 ? p.x : (axis == 1 ? p.y : p.z); };

  std::int32_t middle = end;
  const bool small_enough = end - begin <= settings_.bucket_size;
  if (!small_enough && depth < kMaxKdDepth) {
    middle = static_cast<std::int32_t>(
        std::partition(points_.begin() + begin, points_.begin() + end,
                       [&](const KdPoint& p) { return coordinate(p) < split; }) -
        points_.begin());
  }
  // A leaf when small, too deep, or when the cut separates nothing (all points equal on the axis,
  // or the midpoint rounds onto the lower coordinate): duplicates end up in one oversized bucket.
  if (small_enough || middle == begin || middle == end) {
    float sum[3] = {0.f, 0.f, 0.f};
    double sum_d[3] = {0.0, 0.0, 0.0};
    for (std::int32_t i = begin; i < end; ++i) {
      sum_d[0] += points_[i].x;
      sum_d[1] += points_[i].y;
      sum_d[2] += points_[i].z;
    }
    const double count = static_cast<double>(end - begin);
    for (int d = 0; d < 3; ++d) sum[d] = static_cast<float>(sum_d[d] / count);
    const auto leaf_index = static_cast<std::int32_t>(leaf_means_.size());
    leaf_means_.push_back({sum[0], sum[1], sum[2], static_cast<float>(count)});
    // A bucket of copies of one point (a LiDAR's no-return points at its origin, thousands in a
    // real scan; docs/benchmarks.md) is searched as its first point alone. Every copy is at the
    // same distance and a search keeps the first of equals, so the results do not change; a query
    // near such a pile no longer scans all of it.
    const KdPoint& first = points_[begin];
    bool copies = true;
    for (std::int32_t i = begin + 1; i < end && copies; ++i) {
      copies = points_[i].x == first.x && points_[i].y == first.y && points_[i].z == first.z;
    }
    nodes_[node_index] = {KdNode::kLeaf, begin, copies ? 1 : end - begin, leaf_index};
    return node_index;
  }
  float left_lo[3], left_hi[3], right_lo[3], right_hi[3];
  const std::int32_t left = build(begin, middle, depth + 1, left_lo, left_hi);
  const std::int32_t right = build(middle, end, depth + 1, right_lo, right_hi);
  KdNode& node = nodes_[node_index];
  node.axis = axis;
  node.a = left;
  node.b = right;
  node.split_bits = std::bit_cast<std::int32_t>(split);
  node.left_max = left_hi[axis];
  node.right_min = right_lo[axis];
  return node_index;
}

}  // namespace minemap
