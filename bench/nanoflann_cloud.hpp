#pragma once
// nanoflann over a minemap cloud (std::vector<Eigen::Vector3f>), as the benchmarks' baseline.
#include <Eigen/Core>
#include <nanoflann.hpp>
#include <vector>

namespace minemap::bench {

struct NanoflannCloud {
  const std::vector<Eigen::Vector3f>* points;
  std::size_t kdtree_get_point_count() const { return points->size(); }
  float kdtree_get_pt(std::size_t i, std::size_t d) const { return (*points)[i][static_cast<int>(d)]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const { return false; }  // let nanoflann compute the bounds
};

/// nanoflann's kd-tree with leaf size set by its params (the benchmarks use 10, as minemap).
using NanoflannTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, NanoflannCloud>, NanoflannCloud, 3>;

}  // namespace minemap::bench
