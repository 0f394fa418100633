#pragma once
// Per-query closest-point search on the flat kd-tree, shared by the CPU backend and the tests.
// kernels/correspondence.cl implements the same traversal in OpenCL C; the two are kept
// step-for-step alike (same visiting order, same strict '<' tie rule) so they find the same pairs.
#include <Eigen/Core>
#include <bit>
#include <cstdint>

#include "minemap/search/kdtree.hpp"

namespace minemap::detail {

/// A rigid transform in float for the hot loop (R row-major, then t).
struct RigidF {
  Eigen::Matrix3f rotation;
  Eigen::Vector3f translation;
  /// Written out (not Eigen's product) so the rounding order equals kernels/common.cl's.
  Eigen::Vector3f apply(const Eigen::Vector3f& p) const {
    const Eigen::Matrix3f& r = rotation;
    return {((r(0, 0) * p.x() + r(0, 1) * p.y()) + r(0, 2) * p.z()) + translation.x(),
            ((r(1, 0) * p.x() + r(1, 1) * p.y()) + r(1, 2) * p.z()) + translation.y(),
            ((r(2, 0) * p.x() + r(2, 1) * p.y()) + r(2, 2) * p.z()) + translation.z()};
  }
};

/// Result of one query against one tree.
struct TreeHit {
  float squared_distance = 0.0f;  ///< only meaningful when point >= 0 or mean_leaf >= 0
  std::int32_t point = -1;        ///< index into tree.points() (exact, brute force)
  std::int32_t mean_leaf = -1;    ///< leaf index (approximate)
};

inline float squared_distance(float px, float py, float pz, const Eigen::Vector3f& q) {
  const float dx = px - q.x(), dy = py - q.y(), dz = pz - q.z();
  return (dx * dx + dy * dy) + dz * dz;
}

inline float squared_distance(const KdPoint& p, const Eigen::Vector3f& q) { return squared_distance(p.x, p.y, p.z, q); }

/// Squared distance from `q` to the tree's bounding box (0 inside): a cheap reject per model.
inline float squared_distance_to_bounds(const KdTree& tree, const Eigen::Vector3f& q) {
  const Eigen::Vector3f below = (tree.bounds_min() - q).cwiseMax(0.0f);
  const Eigen::Vector3f above = (q - tree.bounds_max()).cwiseMax(0.0f);
  const Eigen::Vector3f d = below + above;
  return (d.x() * d.x() + d.y() * d.y()) + d.z() * d.z();
}

/// Exact nearest neighbour with backtracking; only points closer than sqrt(best) are accepted,
/// so `best` doubles as the maximum pair distance bound (radius-bounded descent).
inline void exact_nearest(const KdTree& tree, const Eigen::Vector3f& q, float& best, std::int32_t& best_point) {
  struct Pending {
    std::int32_t node;
    float plane_squared_distance;
  };
  Pending stack[kMaxKdDepth];
  int top = 0;
  const KdNode* nodes = tree.nodes().data();
  const KdPoint* points = tree.points().data();
  std::int32_t node = 0;
  for (;;) {
    while (nodes[node].axis != KdNode::kLeaf) {
      const KdNode& n = nodes[node];
      const float diff = q[n.axis] - std::bit_cast<float>(n.split_bits);
      const std::int32_t near_child = diff < 0.0f ? n.a : n.b;
      const std::int32_t far_child = diff < 0.0f ? n.b : n.a;
      const float plane = diff * diff;
      if (plane < best) stack[top++] = {far_child, plane};
      node = near_child;
    }
    const KdNode& leaf = nodes[node];
    for (std::int32_t i = leaf.a, end = leaf.a + leaf.b; i < end; ++i) {
      const float d = squared_distance(points[i], q);
      if (d < best) {
        best = d;
        best_point = i;
      }
    }
    // Backtrack: only buckets whose cut plane lies inside the current ball can hold a closer point.
    do {
      if (top == 0) return;
      --top;
    } while (stack[top].plane_squared_distance >= best);
    node = stack[top].node;
  }
}

/// Approximate kd-tree: the leaf whose region holds `q`, represented by its precomputed mean.
inline std::int32_t approximate_leaf(const KdTree& tree, const Eigen::Vector3f& q) {
  const KdNode* nodes = tree.nodes().data();
  std::int32_t node = 0;
  while (nodes[node].axis != KdNode::kLeaf) {
    const KdNode& n = nodes[node];
    node = q[n.axis] < std::bit_cast<float>(n.split_bits) ? n.a : n.b;
  }
  return nodes[node].split_bits;
}

/// Brute force over every tree point (reordered order, as the OpenCL kernel).
inline void brute_force_nearest(const KdTree& tree, const Eigen::Vector3f& q, float& best, std::int32_t& best_point) {
  const KdPoint* points = tree.points().data();
  for (std::int32_t i = 0, n = static_cast<std::int32_t>(tree.size()); i < n; ++i) {
    const float d = squared_distance(points[i], q);
    if (d < best) {
      best = d;
      best_point = i;
    }
  }
}

}  // namespace minemap::detail
