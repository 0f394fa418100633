#pragma once
// A reduction for any cloud, sliced or not: one point per cubic cell of `voxel_cm`, the mean of the
// cell's points. It is how 3DTK's slam6D (an octree, `-r`) and KISS-ICP (a voxel grid) reduce
// every scan, and what minemap's whole-survey mode uses (MappingSettings::reduction): it samples
// surfaces about evenly in all directions, where the paper's slice filter keeps dense scan lines
// with sparse gaps between them.
//
// Deterministic: cells are numbered in the order their first point appears, each mean is summed in
// double in point order. Thread-safety: a pure function.
#include <Eigen/Core>
#include <span>
#include <vector>

namespace minemap {

/// The mean of the points in each occupied cell of a grid of `voxel_cm` (cells aligned at the
/// cloud's frame origin), in order of first appearance. `voxel_cm` must be > 0.
std::vector<Eigen::Vector3f> voxel_mean_filter(std::span<const Eigen::Vector3f> points_cm, float voxel_cm);

/// voxel_mean_filter, and the mean of `values` (one per point: an intensity) in each cell, summed in
/// double in point order, into `value_means`. The point means are voxel_mean_filter's, bit for bit.
std::vector<Eigen::Vector3f> voxel_mean_filter(std::span<const Eigen::Vector3f> points_cm, float voxel_cm,
                                               std::span<const float> values, std::vector<float>& value_means);

/// The first point of each occupied cell of a grid of `voxel` (the points' unit; cells aligned at
/// their frame's origin), in point order: a thinning that keeps real points with their own
/// attributes (exports; a mean colour or time would be no point's).
std::vector<std::size_t> voxel_first_points(std::span<const Eigen::Vector3d> points, double voxel);

}  // namespace minemap
