#include "minemap/search/kdtree.hpp"

#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <bit>
#include <limits>
#include <stdexcept>

namespace minemap {

/// Builds subtrees into its own node and leaf lists. Large subtrees are built in parallel, each
/// half by its own builder over its own range of points; the right half's lists are then appended
/// with their indices shifted, which gives the very nodes, leaves and order of a sequential
/// depth-first build: the tree is the same for any thread count.
struct KdTree::Builder {
  /// Subtrees of at least this many points build their halves in parallel (smaller ones are not
  /// worth a task). The midpoint cut splits unevenly, so a metascan of 30-40 thousand points needs
  /// tasks this small to keep two cores busy (2 threads against 1: 1.4x at 16384, 1.6x at 4096).
  static constexpr std::int32_t kParallelPoints = 4096;

  std::vector<KdPoint>& points;
  const KdTreeSettings& settings;
  std::vector<KdNode> nodes;
  std::vector<std::array<float, 4>> leaf_means;
  int depth = 0;

  /// Builds the subtree over points[begin, end), whose bounds are lo, hi; returns its node.
  std::int32_t build(std::int32_t begin, std::int32_t end, int level, const float lo[3], const float hi[3]);
  /// Appends `other`'s nodes and leaves after this builder's own.
  void append(const Builder& other);
};

void KdTree::Builder::append(const Builder& other) {
  const auto node_offset = static_cast<std::int32_t>(nodes.size());
  const auto leaf_offset = static_cast<std::int32_t>(leaf_means.size());
  for (KdNode node : other.nodes) {
    if (node.axis == KdNode::kLeaf) {
      node.split_bits += leaf_offset;  // the leaf index; `a` indexes the shared points
    } else {
      node.a += node_offset;
      node.b += node_offset;
    }
    nodes.push_back(node);
  }
  leaf_means.insert(leaf_means.end(), other.leaf_means.begin(), other.leaf_means.end());
  depth = std::max(depth, other.depth);
}

KdTree::KdTree(std::span<const Eigen::Vector3f> points, const KdTreeSettings& settings) : settings_(settings) {
  if (settings_.bucket_size < 1) throw std::invalid_argument("kd-tree bucket size must be >= 1");
  if (points.size() > static_cast<std::size_t>(INT32_MAX / 2)) throw std::invalid_argument("kd-tree: too many points");
  points_.resize(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    points_[i] = {points[i].x(), points[i].y(), points[i].z(), static_cast<std::int32_t>(i)};
  }
  if (points_.empty()) return;
  Builder builder{points_, settings_, {}, {}, 0};
  builder.nodes.reserve(2 * (points_.size() / static_cast<std::size_t>(settings_.bucket_size) + 1));
  float lo[3] = {points_[0].x, points_[0].y, points_[0].z}, hi[3] = {lo[0], lo[1], lo[2]};
  for (const KdPoint& p : points_) {
    const float c[3] = {p.x, p.y, p.z};
    for (int d = 0; d < 3; ++d) {
      lo[d] = std::min(lo[d], c[d]);
      hi[d] = std::max(hi[d], c[d]);
    }
  }
  builder.build(0, static_cast<std::int32_t>(points_.size()), 1, lo, hi);
  nodes_ = std::move(builder.nodes);
  leaf_means_ = std::move(builder.leaf_means);
  depth_ = builder.depth;
  bounds_min_ = bounds_max_ = points[0];
  for (const auto& p : points) {
    bounds_min_ = bounds_min_.cwiseMin(p);
    bounds_max_ = bounds_max_.cwiseMax(p);
  }
}

std::int32_t KdTree::Builder::build(std::int32_t begin, std::int32_t end, int level, const float lo[3],
                                    const float hi[3]) {
  depth = std::max(depth, level);
  const auto node_index = static_cast<std::int32_t>(nodes.size());
  nodes.emplace_back();

  int axis = 0;
  for (int d = 1; d < 3; ++d) {
    if (hi[d] - lo[d] > hi[axis] - lo[axis]) axis = d;
  }
  // The paper: "cuts recursively the scanned volume in two equal-sized halves".
  const float split = lo[axis] + 0.5f * (hi[axis] - lo[axis]);
  auto coordinate = [axis](const KdPoint& p) { return axis == 0 ? p.x : (axis == 1 ? p.y : p.z); };

  // The partition (std::partition's own swaps, in its order) and, in the same pass, the bounds of
  // each half: each child gets its bounds without a pass of its own.
  float left_lo[3], left_hi[3], right_lo[3], right_hi[3];
  for (int d = 0; d < 3; ++d) {
    left_lo[d] = right_lo[d] = std::numeric_limits<float>::infinity();
    left_hi[d] = right_hi[d] = -std::numeric_limits<float>::infinity();
  }
  const auto grow = [](float box_lo[3], float box_hi[3], const KdPoint& p) {
    const float c[3] = {p.x, p.y, p.z};
    for (int d = 0; d < 3; ++d) {
      box_lo[d] = std::min(box_lo[d], c[d]);
      box_hi[d] = std::max(box_hi[d], c[d]);
    }
  };
  std::int32_t middle = end;
  const bool small_enough = end - begin <= settings.bucket_size;
  if (!small_enough && level < kMaxKdDepth) {
    std::int32_t first = begin, last = end;
    while (true) {
      while (first != last && coordinate(points[first]) < split) grow(left_lo, left_hi, points[first++]);
      if (first == last) break;
      --last;
      while (first != last && !(coordinate(points[last]) < split)) grow(right_lo, right_hi, points[last--]);
      if (first == last) {
        grow(right_lo, right_hi, points[first]);  // the one std::partition stopped on: not below the cut
        break;
      }
      std::swap(points[first], points[last]);
      grow(left_lo, left_hi, points[first++]);
      grow(right_lo, right_hi, points[last]);
    }
    middle = first;
  }
  // A leaf when small, too deep, or when the cut separates nothing (all points equal on the axis,
  // or the midpoint rounds onto the lower coordinate): duplicates end up in one oversized bucket.
  if (small_enough || middle == begin || middle == end) {
    float sum[3] = {0.f, 0.f, 0.f};
    double sum_d[3] = {0.0, 0.0, 0.0};
    for (std::int32_t i = begin; i < end; ++i) {
      sum_d[0] += points[i].x;
      sum_d[1] += points[i].y;
      sum_d[2] += points[i].z;
    }
    const double count = static_cast<double>(end - begin);
    for (int d = 0; d < 3; ++d) sum[d] = static_cast<float>(sum_d[d] / count);
    const auto leaf_index = static_cast<std::int32_t>(leaf_means.size());
    leaf_means.push_back({sum[0], sum[1], sum[2], static_cast<float>(count)});
    // A bucket of copies of one point (a LiDAR's no-return points at its origin, thousands in a
    // real scan; docs/benchmarks.md) is searched as its first point alone. Every copy is at the
    // same distance and a search keeps the first of equals, so the results do not change; a query
    // near such a pile no longer scans all of it.
    const KdPoint& first = points[begin];
    bool copies = true;
    for (std::int32_t i = begin + 1; i < end && copies; ++i) {
      copies = points[i].x == first.x && points[i].y == first.y && points[i].z == first.z;
    }
    nodes[node_index] = {KdNode::kLeaf, begin, copies ? 1 : end - begin, leaf_index};
    return node_index;
  }
  std::int32_t left = 0, right = 0;
  if (end - begin >= kParallelPoints) {
    Builder right_half{points, settings, {}, {}, 0};
    std::int32_t right_root = 0;
    tbb::parallel_invoke([&] { left = build(begin, middle, level + 1, left_lo, left_hi); },
                         [&] { right_root = right_half.build(middle, end, level + 1, right_lo, right_hi); });
    right = static_cast<std::int32_t>(nodes.size()) + right_root;
    append(right_half);
  } else {
    left = build(begin, middle, level + 1, left_lo, left_hi);
    right = build(middle, end, level + 1, right_lo, right_hi);
  }
  KdNode& node = nodes[node_index];
  node.axis = axis;
  node.a = left;
  node.b = right;
  node.split_bits = std::bit_cast<std::int32_t>(split);
  node.left_max = left_hi[axis];
  node.right_min = right_lo[axis];
  return node_index;
}

}  // namespace minemap
