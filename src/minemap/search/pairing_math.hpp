#pragma once
// Per-query closest-point search on the flat kd-tree, shared by the CPU backend and the tests.
// Internal: not installed.
// kernels/correspondence.cl implements the same traversal in OpenCL C; the two are kept
// step-for-step alike (same visiting order, same strict '<' tie rule) so they find the same pairs.
#include <Eigen/Core>
#include <bit>
#include <cmath>
#include <limits>
#include <cstdint>
#if defined(__SSE2__)
#include <xmmintrin.h>
#endif

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
  return shared::mm_squared_distance3(px, py, pz, q.x(), q.y(), q.z());
}

inline float squared_distance(const KdPoint& p, const Eigen::Vector3f& q) { return squared_distance(p.x, p.y, p.z, q); }

/// Squared distance from `q` to the tree's bounding box (0 inside): a cheap reject per model.
inline float squared_distance_to_bounds(const KdTree& tree, const Eigen::Vector3f& q) {
  const Eigen::Vector3f below = (tree.bounds_min() - q).cwiseMax(0.0f);
  const Eigen::Vector3f above = (q - tree.bounds_max()).cwiseMax(0.0f);
  const Eigen::Vector3f d = below + above;
  return (d.x() * d.x() + d.y() * d.y()) + d.z() * d.z();
}

/// Scans tree points [begin, end) for one closer than `best` (strict '<', first wins), updating
/// `best` and `best_point` exactly as a sequential scan would. With SSE2, four points are tested
/// at once and a group with no closer point costs one mask test; the same float operations in the
/// same order keep the distances bit-identical to the scalar path and to the OpenCL kernel. With
/// kSkips, a point `skip` leaves out is passed over as if it were not in the tree.
template <bool kSkips = false>
inline void scan_bucket(const KdPoint* points, std::int32_t begin, std::int32_t end, const Eigen::Vector3f& q,
                        float& best, std::int32_t& best_point, SkippedPoints skip = {}) {
  std::int32_t i = begin;
#if defined(__SSE2__)
  const __m128 qx = _mm_set1_ps(q.x()), qy = _mm_set1_ps(q.y()), qz = _mm_set1_ps(q.z());
  for (; i + 4 <= end; i += 4) {
    __m128 r0 = _mm_loadu_ps(&points[i].x);
    __m128 r1 = _mm_loadu_ps(&points[i + 1].x);
    __m128 r2 = _mm_loadu_ps(&points[i + 2].x);
    __m128 r3 = _mm_loadu_ps(&points[i + 3].x);
    _MM_TRANSPOSE4_PS(r0, r1, r2, r3);  // r0 = x of the four points, r1 = y, r2 = z
    const __m128 dx = _mm_sub_ps(r0, qx), dy = _mm_sub_ps(r1, qy), dz = _mm_sub_ps(r2, qz);
    const __m128 d = _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)), _mm_mul_ps(dz, dz));
    if (_mm_movemask_ps(_mm_cmplt_ps(d, _mm_set1_ps(best))) == 0) continue;
    alignas(16) float lanes[4];
    _mm_store_ps(lanes, d);
    for (int k = 0; k < 4; ++k) {
      if (lanes[k] < best && !(kSkips && skip.leaves_out(points[i + k].original_index))) {
        best = lanes[k];
        best_point = i + k;
      }
    }
  }
#endif
  for (; i < end; ++i) {
    const float d = squared_distance(points[i], q);
    const bool closer = d < best && !(kSkips && skip.leaves_out(points[i].original_index));
    best = closer ? d : best;
    best_point = closer ? i : best_point;
  }
}

/// How far above the hint's squared distance exact_nearest starts its bound (relative). The lower
/// bounds of subtrees add and subtract squared gaps level by level in float, so they may overshoot
/// the true distance to the box by up to about 2 * kMaxKdDepth * 2^-24 (7.6e-6) of the bound; a
/// bound one ulp above the hint's distance (as before 2026-12-04) let such a subtree, holding the
/// hint itself, be skipped, and the CPU then found no pair where the kernel found one (the Jinchuan
/// scans at a 200 cm bound: one point in 200 000). 2^-12 is 30 times that error and still as tight a
/// bound as the hint gives.
inline constexpr float kHintBoundMargin = 1.0f / 4096.0f;

/// Exact nearest neighbour with backtracking; only points closer than sqrt(best) are accepted,
/// so `best` doubles as the maximum pair distance bound (radius-bounded descent). A subtree is
/// visited only if a lower bound of its distance beats `best`: the bound adds up, per axis, the
/// squared gap between the query and the children's actual extents (nanoflann's incremental
/// distance, with the gap between the two children instead of the bare cut plane).
///
/// `hint` (a tree point index, or -1) only tightens the starting bound to just above the hint's
/// distance (kHintBoundMargin); the hint itself is not taken as a result. The traversal then visits
/// a subset of the unhinted traversal's nodes in the same order: every subtree it skips has a lower
/// bound above the tightened bound, so holds no point as close as the hint, and every node holding
/// the first closest point is still visited (its lower bound is at most that distance plus the lower
/// bound's rounding, below the tightened bound). So the result is bit-for-bit the unhinted one (the
/// OpenCL kernel's, which has no hint): same point, ties included.
///
/// `skip` leaves points out (SkippedPoints) as the kernel does: a hint must be a point it keeps.
template <bool kSkips>
inline void exact_nearest_in(const KdTree& tree, const Eigen::Vector3f& q, float& best, std::int32_t& best_point,
                             std::int32_t hint, SkippedPoints skip) {
  const KdPoint* points = tree.points().data();
  if (hint >= 0) {
    const float hint_bound = std::nextafter(squared_distance(points[hint], q) * (1.0f + kHintBoundMargin),
                                            std::numeric_limits<float>::infinity());
    if (hint_bound < best) best = hint_bound;
  }
  struct Pending {
    std::int32_t node;
    float lower_bound;
    float offset[3];
  };
  Pending stack[kMaxKdDepth];
  int top = 0;
  const KdNode* nodes = tree.nodes().data();
  std::int32_t node = 0;
  float lower_bound = 0.0f;
  float offset[3] = {0.0f, 0.0f, 0.0f};
  for (;;) {
    while (nodes[node].axis != KdNode::kLeaf) {
      const KdNode& n = nodes[node];
      const float v = q[n.axis];
      const bool go_left = v < std::bit_cast<float>(n.split_bits);
      const float gap = go_left ? n.right_min - v : v - n.left_max;
      const float far_bound = (lower_bound - offset[n.axis] * offset[n.axis]) + gap * gap;
      // Written always and kept only when the far side may hold a closer point: the descent
      // direction and the push are data-dependent coin flips, and mispredicted branches, not
      // memory, were the cost of the descent.
      Pending& pending = stack[top];
      pending.node = go_left ? n.b : n.a;
      pending.lower_bound = far_bound;
      pending.offset[0] = offset[0];
      pending.offset[1] = offset[1];
      pending.offset[2] = offset[2];
      pending.offset[n.axis] = gap;
      top += far_bound < best ? 1 : 0;
      node = go_left ? n.a : n.b;
    }
    const KdNode& leaf = nodes[node];
    scan_bucket<kSkips>(points, leaf.a, leaf.a + leaf.b, q, best, best_point, skip);
    do {
      if (top == 0) return;
      --top;
    } while (stack[top].lower_bound >= best);
    const Pending& next = stack[top];
    node = next.node;
    lower_bound = next.lower_bound;
    offset[0] = next.offset[0];
    offset[1] = next.offset[1];
    offset[2] = next.offset[2];
  }
}

inline void exact_nearest(const KdTree& tree, const Eigen::Vector3f& q, float& best, std::int32_t& best_point,
                          std::int32_t hint = -1, SkippedPoints skip = {}) {
  // Two traversals, so that the matching's searches (no skip) pay nothing for the judging's.
  if (skip.count > 0) {
    exact_nearest_in<true>(tree, q, best, best_point, hint, skip);
  } else {
    exact_nearest_in<false>(tree, q, best, best_point, hint, skip);
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

/// Brute force over every tree point (reordered order, as the OpenCL kernel), four at a time:
/// scan_bucket keeps the sequential scan's result (first closest point, strict '<').
inline void brute_force_nearest(const KdTree& tree, const Eigen::Vector3f& q, float& best, std::int32_t& best_point) {
  scan_bucket(tree.points().data(), 0, static_cast<std::int32_t>(tree.size()), q, best, best_point);
}

}  // namespace minemap::detail
