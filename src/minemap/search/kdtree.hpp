#pragma once
// The paper's bucket kd-tree (section IV.D): terminal buckets of `bucket_size` points; each inner
// node cuts the volume of its points into two equal halves along the longest extent, storing the
// cut dimension and value. Leaves also store the mean of their points for the approximate kd-tree
// (Greenspan and Yurick's Apr-kd-tree with the paper's twist: return the bucket mean, no scan).
//
// The tree is flat (nodes, reordered points, leaf means), so the CPU search and the OpenCL kernels
// traverse the very same arrays; the OpenCL backend uploads them unchanged.
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "minemap/shared/minemap_shared.h"

namespace minemap {

struct KdTreeSettings {
  int bucket_size = 10;  ///< points per terminal bucket (paper: 10; Fig. 5 sweeps 1..100)
  bool operator==(const KdTreeSettings&) const = default;
};

/// 32 bytes, laid out as OpenCL's int4 {axis, a, b, split bits} + float4 {left_max, right_min, 0, 0}.
/// Inner node: axis in 0..2, a = left child, b = right child, split = cut value (cm); left_max /
/// right_min = the extent of the children's points along the axis (the gap between them lets the
/// exact search prune more than the cut plane alone).
/// Leaf: axis = kLeaf, a = first point in `points`, b = the points to scan, split bits = leaf index
/// (int). b is the bucket's size, or 1 for a bucket of copies of one point (the first of equals
/// wins, so scanning one copy finds what scanning all would); its leaf mean still counts them all.
struct KdNode {
  static constexpr std::int32_t kLeaf = -1;
  std::int32_t axis = kLeaf;
  std::int32_t a = 0;
  std::int32_t b = 0;
  std::int32_t split_bits = 0;  ///< float cut value (inner) or int leaf index (leaf), bit-cast
  float left_max = 0.0f;
  float right_min = 0.0f;
  float unused[2] = {0.0f, 0.0f};
};
static_assert(sizeof(KdNode) == 32);

/// Point stored in the tree: xyz in cm, w = the point's index in the input cloud (int bits).
struct KdPoint {
  float x, y, z;
  std::int32_t original_index;
};
static_assert(sizeof(KdPoint) == 16);

/// Model points a search leaves out: those whose original index (their place in the model cloud
/// as prepared) lies in [first, first + count). One tree over several scans' union then serves a
/// search that must not see one of them (the judging after the loops: a scan's own points in its
/// block's tree). Exact search only (the approximate kd-tree's bucket means and the brute force
/// take no skip: ComputeBackend::nearest and pair_and_sum refuse one). A bucket of copies of one
/// point is searched as its first copy (KdNode), so it is left out when that copy is: copies of one
/// point from a skipped and a kept scan would have to be the same float coordinates.
struct SkippedPoints {
  std::int32_t first = 0;
  std::int32_t count = 0;  ///< 0: none left out
  bool leaves_out(std::int32_t original_index) const {
    return static_cast<std::uint32_t>(original_index) - static_cast<std::uint32_t>(first) <
           static_cast<std::uint32_t>(count);
  }
  bool operator==(const SkippedPoints&) const = default;
};

/// An immutable bucket kd-tree over a float cloud. Thread-safety: const after construction, so any
/// number of threads may search it at once. Units: those of the input points (cm in minemap).
class KdTree {
 public:
  KdTree() = default;
  KdTree(std::span<const Eigen::Vector3f> points, const KdTreeSettings& settings = {});

  std::span<const KdNode> nodes() const { return nodes_; }
  std::span<const KdPoint> points() const { return points_; }
  /// Leaf means as float4 (w = point count), indexed by leaf index.
  std::span<const std::array<float, 4>> leaf_means() const { return leaf_means_; }
  std::size_t size() const { return points_.size(); }
  bool empty() const { return points_.empty(); }
  int depth() const { return depth_; }
  const Eigen::Vector3f& bounds_min() const { return bounds_min_; }
  const Eigen::Vector3f& bounds_max() const { return bounds_max_; }
  int bucket_size() const { return settings_.bucket_size; }
  /// What the tree holds in memory (its nodes, points and leaf means), bytes.
  std::size_t memory_bytes() const {
    return nodes_.capacity() * sizeof(KdNode) + points_.capacity() * sizeof(KdPoint) +
           leaf_means_.capacity() * sizeof(std::array<float, 4>);
  }

 private:
  struct Builder;

  KdTreeSettings settings_;
  std::vector<KdNode> nodes_;
  std::vector<KdPoint> points_;
  std::vector<std::array<float, 4>> leaf_means_;
  Eigen::Vector3f bounds_min_ = Eigen::Vector3f::Zero();
  Eigen::Vector3f bounds_max_ = Eigen::Vector3f::Zero();
  int depth_ = 0;
};

/// The deepest tree the builder makes, and so the traversal stack every search (C++ and kernels)
/// holds: the builder stops cutting at this depth (a bucket then holds more than bucket_size points).
inline constexpr int kMaxKdDepth = MM_MAX_KD_DEPTH;

}  // namespace minemap
